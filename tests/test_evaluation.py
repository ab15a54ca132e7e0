import csv
import json
import math

import numpy as np
import pytest

from stablemarks.cli import main
from stablemarks.errors import InputError
from stablemarks.evaluation import (
    SUMMARY_KEYS,
    available_methods,
    check_backend,
    check_goals,
    goals_caveats,
    make_trials,
    summarize,
    trial_seeds,
    truncate_run,
)
from stablemarks.sim import load_scenario, simulate_run

METHODS = available_methods()


@pytest.fixture(scope="module")
def lab_eval(tmp_path_factory):
    """The CLI on 2 trials of the lab's first 3 frames, all methods (the only expensive part of this file)."""
    out = tmp_path_factory.mktemp("eval") / "out"
    code = main(["eval", "lab", "--trials", "2", "--jobs", "1", "--frames", "3", "--out", str(out)])
    return code, out


def test_cli_writes_every_output(lab_eval, capsys):
    code, out = lab_eval
    assert code == 0
    names = {p.name for p in out.iterdir()}
    assert names == {"trials.jsonl", "summary.json", "summary.csv", "report.md", "nees_pose.png", "ate.png",
                     "reobservation.png"}
    report = (out / "report.md").read_text()
    assert "## lab" in report and "![nees](nees_pose.png)" in report and "## Definitions" in report


def test_trials_are_independent_runs_of_every_method(lab_eval):
    _, out = lab_eval
    lines = [json.loads(x) for x in (out / "trials.jsonl").read_text().splitlines()]
    assert [(r["trial"], r["method"]) for r in lines] == [(t, m) for t in (0, 1) for m in METHODS]
    assert all(r["frames"] == 3 and len(r["nees_pose"]) == 3 for r in lines)
    seeds = {r["trial"]: r["seed"] for r in lines}
    assert seeds[0] != seeds[1]
    assert seeds == dict(enumerate(trial_seeds(load_scenario("lab").seed, 2)))
    # Same trial: the same run for every method (dead reckoning has no landmarks, the others do).
    by = {(r["trial"], r["method"]): r for r in lines}
    assert by[(0, "dead_reckoning")]["n_landmarks"] == 0
    assert by[(0, "stablemarks")]["n_landmarks"] > 0
    assert by[(0, "dead_reckoning")]["ate_rmse"] != by[(1, "dead_reckoning")]["ate_rmse"]


def test_summary_has_all_keys(lab_eval):
    _, out = lab_eval
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary) == ["lab"] and list(summary["lab"]) == list(METHODS)
    for method, s in summary["lab"].items():
        assert set(SUMMARY_KEYS) <= set(s), method
        assert s["trials"] == 2 and s["frames"] == 3
        assert s["nees_pose_bounds"] == pytest.approx([0.6187, 7.2247], abs=1e-3)  # χ²(6) / 2
        assert 0.0 <= s["nees_pose_fraction_inside"] <= 1.0 and 0.0 <= s["nees_pose_fraction_above"] <= 1.0
        assert s["nees_pose_fraction_inside"] + s["nees_pose_fraction_above"] <= 1.0
    full = summary["lab"]["stablemarks"]
    assert full["nis_count"] > 0 and full["nees_landmark_count"] > 0
    assert 0.0 <= full["selection_precision"] <= 1.0 and 0.0 <= full["selection_recall"] <= 1.0
    assert summary["lab"]["dead_reckoning"]["nis_mean"] is None  # NaN in JSON
    rows = list(csv.DictReader((out / "summary.csv").read_text().splitlines()))
    assert [r["method"] for r in rows] == list(METHODS)
    assert {"nees_pose_bounds_lo", "nees_pose_bounds_hi", "ate_rmse"} <= set(rows[0])


def test_seeds_spawn_independent_trials():
    seeds = trial_seeds(7, 3)
    assert len(set(seeds)) == 3 and seeds == trial_seeds(7, 3) and seeds[:2] == trial_seeds(7, 2)
    sc = load_scenario("lab")
    odo = [np.array([u.as_array() for u in simulate_run(sc, s).odometry[1:]]) for s in seeds]
    assert not np.allclose(odo[0], odo[1]) and not np.allclose(odo[1], odo[2])
    run = simulate_run(sc, seeds[0])
    short = truncate_run(run, 4)
    assert len(short) == 4 and short.odometry == run.odometry[:4] and truncate_run(run, None) is run


def test_make_trials_validates():
    trials = make_trials(["lab"], 2, ["dead_reckoning", "stablemarks"], seed=3, frames=2)
    assert [(t.index, t.method) for t in trials] == [(0, "dead_reckoning"), (0, "stablemarks"),
                                                     (1, "dead_reckoning"), (1, "stablemarks")]
    with pytest.raises(InputError, match="methods: expected one of"):
        make_trials(["lab"], 2, ["no_such_method"])
    with pytest.raises(InputError, match="trials: expected a positive number"):
        make_trials(["lab"], 0)
    with pytest.raises(InputError, match="frames: expected a positive number"):
        make_trials(["lab"], 1, frames=0)
    with pytest.raises(InputError, match="cov0: expected a positive definite"):
        make_trials(["lab"], 1, cov0=np.zeros((3, 3)))


def _fake(trial, method, *, nees, reobs, selected=(), rejected=(), nis=(2.0,), ate=0.1):
    return {"scenario": "s", "trial": trial, "seed": trial, "method": method, "frames": len(nees),
            "nees_pose": list(nees), "position_error": [0.0] * len(nees), "nis": list(nis), "ate_rmse": ate,
            "final_error": ate, "landmarks": [{"id": i, "truth": t, "nees": 1.0, "error": 0.01, "reobserved": list(r)}
                                              for i, (t, r) in enumerate(reobs.items())],
            "n_landmarks": len(reobs), "n_true_features": len(reobs), "eligible": ["a", "b"], "found": ["a"],
            "selected_truth": list(selected), "rejected_truth": list(rejected), "time_per_frame": 0.5,
            "stage_times": {}}


def test_summarize_by_hand():
    rs = []
    for t in (0, 1):
        rs.append(_fake(t, "stablemarks", nees=[3.0, 100.0], reobs={"a": (9, 10)}, selected=["a"],
                        rejected=["b", "a"], ate=0.05))
        rs.append(_fake(t, "plane_no_selection", nees=[3.0, 3.0], reobs={"a": (8, 10), "b": (1, 4)},
                        rejected=["b"], ate=0.08))
        rs.append(_fake(t, "dead_reckoning", nees=[3.0, 3.0], reobs={}, nis=(), ate=0.2))
    s = summarize(rs)["s"]
    full, nosel, dr = s["stablemarks"], s["plane_no_selection"], s["dead_reckoning"]
    assert full["nees_pose_fraction_inside"] == 0.5 and nosel["nees_pose_fraction_inside"] == 1.0
    assert full["nees_pose_fraction_above"] == 0.5 and nosel["nees_pose_fraction_above"] == 0.0
    assert full["nees_pose_mean"] == pytest.approx(51.5)
    assert full["nees_pose_time"] == [3.0, 100.0]
    assert full["ate_rmse"] == pytest.approx(0.05) and full["ate_ratio_dead_reckoning"] == pytest.approx(0.25)
    assert full["reobservation_selected"] == pytest.approx(0.9)
    # "a" was rejected once but selected: only "b" counts as rejected, measured in plane_no_selection.
    assert full["reobservation_rejected"] == pytest.approx(0.25)
    assert nosel["reobservation_selected"] == pytest.approx(0.8)
    assert full["selection_recall"] == 0.5 and full["selection_precision"] == 1.0
    assert full["nis_count"] == 2 and math.isnan(dr["nis_mean"]) and math.isnan(dr["selection_precision"])
    goals = {g.name: g for g in check_goals({"s": s})}
    assert goals["ATE / dead reckoning"].met is True
    assert goals["pose NEES frames inside 95 % bounds"].met is False
    assert goals["re-observation selected − rejected"].met is True


def test_goals_cover_each_pan_policy_against_its_own_references():
    rs = []
    for t in (0, 1):
        for policy, ate in (("fixed", 0.05), ("information", 0.3)):
            rs.append(_fake(t, f"stablemarks@{policy}", nees=[3.0, 3.0], reobs={"a": (9, 10)}, selected=["a"],
                            ate=ate))
            rs.append(_fake(t, f"dead_reckoning@{policy}", nees=[3.0, 3.0], reobs={}, nis=(), ate=0.2))
    s = summarize(rs)
    goals = check_goals(s)
    labels = {g.scenario for g in goals}
    assert labels == {"s @fixed", "s @information"}
    dr = {g.scenario: g.met for g in goals if g.name == "ATE / dead reckoning"}
    assert dr == {"s @fixed": True, "s @information": False}
    # two trials over every frame of the run: the note says N, and nothing about --frames
    notes = goals_caveats(s, None)
    assert len(notes) == 1 and "s N = 2" in notes[0]
    assert any("--frames 2" in n for n in goals_caveats(s, 2))
    assert not any("--frames" in n for n in goals_caveats(s, 5))


def test_bad_scenario_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["eval", "no-such-scenario", "--trials", "2", "--out", str(out)]) == 1
    assert "error" in capsys.readouterr().err
    assert not out.exists()
    assert main(["eval", "lab", "--methods", "stablemarks,nope", "--out", str(out)]) == 1
    assert main(["eval", "lab", "--trials", "0", "--out", str(out)]) == 1
    assert main(["eval", "lab", "--pose-sigma", "0,0.1,1deg", "--out", str(out)]) == 1
    assert not out.exists()


def test_missing_backend_says_what_to_install():
    check_backend("loky")
    pytest.importorskip("joblib")
    for backend in ("dask", "ray"):
        try:
            check_backend(backend)
        except InputError as exc:
            assert f"pip install 'stablemarks[{backend}]'" in str(exc)
    with pytest.raises(InputError, match="backend: expected one of loky, dask, ray"):
        check_backend("mpi")


def test_methods_of_one_run_share_its_rendered_frames(monkeypatch):
    """``run_trials`` renders each frame of a run once for all its methods (a head panned elsewhere gets its own
    rendering): fewer renderings than running the methods one by one, and the same results."""
    from stablemarks.evaluation import run_trials
    from stablemarks.sim import render

    calls = []
    original = render.Renderer.render

    def counted(self, X, pan, rng):
        calls.append((np.asarray(X, float).tobytes(), float(pan)))
        return original(self, X, pan, rng)

    monkeypatch.setattr(render.Renderer, "render", counted)
    methods = ["dead_reckoning", "stablemarks", "plane_no_selection"]
    trials = make_trials(["lab"], 1, methods, frames=3)
    shared = run_trials(trials)
    n_shared, distinct = len(calls), len(set(calls))
    calls.clear()
    alone = [run_trials([t])[0] for t in trials]
    assert n_shared == distinct < len(calls)  # every (pose, pan) rendered once
    assert len(calls) >= 3 * (len(methods) - 1)  # dead_reckoning renders nothing
    for a, b in zip(shared, alone, strict=True):
        assert "error" not in a
        for key in ("stage_times", "time_per_frame"):  # wall times
            a.pop(key), b.pop(key)
        assert json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)


def test_dead_reckoning_trials_render_nothing_and_measure_as_with_the_images(monkeypatch):
    """A dead_reckoning trial renders no frame, and its line of trials.jsonl is the one it had when every frame
    was rendered (the frames' random streams are their own; its truth bookkeeping is geometry)."""
    from stablemarks import evaluation
    from stablemarks.sim import render

    trial = make_trials(["lab"], 1, ["dead_reckoning"], frames=10)[0]

    class Rendered(evaluation.SimulatedSource):
        rendering = property(lambda self: True, lambda self, value: None)  # renders whatever the method

    with monkeypatch.context() as m:
        m.setattr(evaluation, "SimulatedSource", Rendered)
        calls = []
        original = render.Renderer.render
        m.setattr(render.Renderer, "render", lambda self, *a: calls.append(1) or original(self, *a))
        rendered = evaluation.run_trials([trial])[0]
        assert len(calls) == 10

    def refuse(self, X, pan, rng):
        raise AssertionError("a frame was rendered")

    monkeypatch.setattr(render.Renderer, "render", refuse)
    without = evaluation.run_trials([trial])[0]
    assert "error" not in without and "error" not in rendered
    assert without["frames"] == 10 and any(without["position_error"])
    for key in ("stage_times", "time_per_frame"):  # wall times
        without.pop(key), rendered.pop(key)
    assert json.dumps(without, sort_keys=True) == json.dumps(rendered, sort_keys=True)
