"""Shared fixtures: the lab scenario's first view, processed once per test session."""

from __future__ import annotations

import numpy as np
import pytest

COV_PRIOR = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2


@pytest.fixture(scope="session")
def lab_scenario():
    from stablemarks.sim.scenario import load_scenario

    return load_scenario("lab")


@pytest.fixture(scope="session")
def lab_sim(lab_scenario):
    from stablemarks.sim.run import simulate_run

    return simulate_run(lab_scenario)


@pytest.fixture(scope="session")
def lab_first_frame(lab_sim):
    return lab_sim.render(0)


@pytest.fixture(scope="session")
def lab_first_view(lab_scenario, lab_sim, lab_first_frame):
    """The full pipeline on the lab's first view with the start pose as prior, with the paper's noise values
    (the ``paper`` preset, which reproduces Table 1)."""
    from stablemarks.config import Config
    from stablemarks.pipeline import process_frame

    camera = lab_scenario.camera.with_pan(lab_sim.pans[0])
    X0 = lab_sim.poses[0].as_array()
    return process_frame(lab_first_frame.left, lab_first_frame.right, camera, lab_scenario.map, X0, COV_PRIOR,
                         Config.preset("paper"))


SCENARIO_NAMES = ("lab", "corridor", "office", "hall")


@pytest.fixture(scope="session")
def scenario_frames():
    """Two frames of each of :data:`SCENARIO_NAMES` (the first and the middle one): ``(name, k, left, right, camera,
    map, true pose)``, rendered once per session for the tests that compare a fast path with its reference."""
    from stablemarks.sim.run import simulate_run
    from stablemarks.sim.scenario import load_scenario

    out = []
    for name in SCENARIO_NAMES:
        run = simulate_run(load_scenario(name))
        for k in (0, len(run) // 2):
            f = run.render(k)
            out.append((name, k, f.left, f.right, run.scenario.camera.with_pan(run.pans[k]), run.scenario.map,
                        run.poses[k].as_array()))
    return out


@pytest.fixture(scope="session")
def scenario_models(scenario_frames):
    """The landmark model of every frame of :func:`scenario_frames` (the pipeline in regions, from the true pose
    with the prior :data:`COV_PRIOR`): ``(name, k, front end, model)``."""
    from stablemarks.config import Config
    from stablemarks.pipeline import plane_regions, run_front_end, select_landmarks

    config = Config()
    out = []
    for name, k, left, right, camera, world_map, X in scenario_frames:
        reg = plane_regions(camera, X, COV_PRIOR, world_map, config, left.shape)
        front = run_front_end(left, right, config, reg)
        out.append((name, k, front, select_landmarks(front, camera, world_map, X, COV_PRIOR, config)))
    return out
