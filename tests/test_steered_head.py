"""``stablemarks simulate`` records the pans the method commands (``--head method``, the default), so that a
recorded sequence replays the closed loop a robot whose localizer steers its head would have run."""

from __future__ import annotations

import numpy as np
import pytest

import stablemarks as sm
from stablemarks.cli import main
from stablemarks.online import run_online
from stablemarks.sim import SimulatedSource, load_scenario, simulate_run, steered_by_method

N = 6


@pytest.fixture(scope="module")
def lab_run():
    return simulate_run(load_scenario("lab"))


@pytest.fixture(scope="module")
def steered(lab_run):
    return steered_by_method(lab_run, N)


def test_steered_pans_are_the_closed_loops(lab_run, steered):
    """The first N pans are those a localizer steering a simulated source took; the rest are the run's own."""
    source = SimulatedSource(lab_run, frames=N)
    result = run_online(source)
    closed_loop = [r.pan for r in result.records]
    assert np.array_equal(np.asarray(steered.pans[:N]), np.asarray(closed_loop))
    assert steered.pans[N:] == lab_run.pans[N:]
    # everything but the pans is the run's
    assert steered.poses == lab_run.poses and steered.odometry == lab_run.odometry and steered.seed == lab_run.seed
    # the method's head does not point where the scenario's dead-reckoning rule does on every frame
    assert not np.allclose(steered.pans[:N], lab_run.pans[:N])


def test_replaying_a_steered_sequence_gives_the_closed_loop(tmp_path, lab_run, capsys):
    """`run` on the sequence `simulate` wrote gives the poses of the closed loop it recorded."""
    seq = tmp_path / "seq"
    assert main(["simulate", "lab", "--out", str(seq), "--frames", str(N)]) == 0
    assert "the head pointed by the method" in capsys.readouterr().out
    recorded = sm.open_sequence(seq)
    assert np.allclose([f.pan for f in recorded], steered_by_method(lab_run, N).pans[:N], atol=1e-9)
    closed = run_online(SimulatedSource(lab_run, frames=N))
    replay = run_online(sm.open_sequence(seq))
    assert np.allclose([r.pose for r in replay.records], [r.pose for r in closed.records], atol=1e-6)


def test_scenario_head_keeps_the_runs_pans(tmp_path, lab_run, capsys):
    seq = tmp_path / "seq"
    assert main(["simulate", "lab", "--out", str(seq), "--frames", "3", "--head", "scenario"]) == 0
    assert "scenario rule on dead reckoning" in capsys.readouterr().out
    pans = [f.pan for f in sm.open_sequence(seq)]
    assert np.allclose(pans, lab_run.pans[:3], atol=1e-9)
