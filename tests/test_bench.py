"""The benchmark helpers (the figures themselves are printed by ``stablemarks bench``, not asserted)."""

import numpy as np
import pytest

from stablemarks.bench import LapSource, long_run, memory_profile
from stablemarks.sim.source import SimulatedSource


def test_long_run_drives_the_loop_again_until_it_has_the_frames():
    one = long_run("loop", 10)
    many = long_run("loop", 1000)
    assert len(one) < 1000 <= len(many)
    # the same rectangle again and again: every position on the first run's path, the start passed many times
    xy_one = np.array([p.as_array()[:2] for p in one.poses])
    xy = np.array([p.as_array()[:2] for p in many.poses])
    gap = np.min(np.linalg.norm(xy[:, None, :] - xy_one[None, :, :], axis=-1), axis=1)
    assert gap.max() < 1e-9
    assert np.sum(np.linalg.norm(xy - xy_one[0], axis=1) < 1e-9) >= 3


def test_lap_source_makes_the_frames_of_the_long_run_one_at_a_time():
    """``LapSource`` streams what ``SimulatedSource(long_run(...))`` holds: the same true poses and dead
    reckoning (odometry noise drawn in the same order) across the laps, the same pans and images."""
    import itertools

    lazy = LapSource("loop", 1000)
    run = long_run("loop", 1000)
    assert len(lazy) == 1000 and len(run) > len(lazy.run)  # the source holds one pass of the path, not 1000 frames
    for k, (pose, believed) in enumerate(itertools.islice(lazy.truth(), 1000)):
        assert np.array_equal(pose.as_array(), run.poses[k].as_array()), k
        assert np.array_equal(believed.as_array(), run.dead_reckoning[k].as_array()), k
    held = SimulatedSource(run, frames=1000)
    for a, b in zip(itertools.islice(lazy, 3), itertools.islice(held, 3), strict=True):
        assert (a.index, a.stamp, a.pan) == (b.index, b.stamp, b.pan)
        for name in ("left", "right", "odometry", "true_pose"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    lazy.steer(lambda odometry: 0.25)  # steered, like the simulator under the localizer
    assert [f.pan for f in itertools.islice(lazy, 2)] == [0.25, 0.25]
    assert len(LapSource("loop", 3)) == 3


def test_memory_profile_reports_both_windows():
    """The soak's figures for the first and last window: time untraced, memory traced, landmarks."""
    seen = []
    out = memory_profile(12, "loop", progress=lambda k, n: seen.append((k, n)))
    assert seen == [(k, 12) for k in range(1, 13)]
    assert out["frames"] == 12 and out["window"] == 6 and out["seconds"] > 0
    for name in ("first", "last"):
        w = out[name]
        assert w["step_ms"] > 0 and w["frame_ms"] >= w["step_ms"] and w["rss_mb"] > 0
        assert w["traced_peak_mb_max"] >= w["traced_peak_mb"] > 0 and w["landmarks_max"] >= 1
        assert np.isfinite(w["held_kb_per_frame"])  # three traced frames: a slope
    assert out["first"]["frames"] == [0, 6] and out["last"]["frames"] == [6, 12]
    assert np.isfinite(out["rss_growth_kb_per_frame"]) and out["landmarks_final"] >= 1


def test_bench_command_takes_a_10000_frame_soak(monkeypatch, tmp_path, capsys):
    """``bench --memory-frames 10000`` is within the bounds; the soak's table is printed and its figures written
    as strict JSON (a slope that could not be fitted is null). The measurements themselves are faked here."""
    import json
    import math

    import stablemarks.bench as bench
    from stablemarks.cli import main

    keys = ("stereobm", "regions", "segments", "matching", "disparity", "filter", "planes", "landmarks", "ekf",
            "front_end", "pipeline", "disparity_alone", "disparity_dense", "disparity_dense_in_pipeline",
            "pipeline_dense")
    stages = {f"{k}_ms": 1.0 for k in keys} | {"pipeline_fps": 1000.0, "pipeline_dense_fps": 1000.0,
                                                "ratio_pipeline_vs_stereobm": 1.0}
    window = {"frames": [0, 1000], "step_ms": 20.0, "frame_ms": 130.0, "rss_mb": 300.0, "traced_peak_mb": 48.0,
              "traced_peak_mb_max": 52.0, "held_kb_per_frame": math.nan, "landmarks": 14.0, "landmarks_max": 16}
    asked = []

    def soak(frames, progress=None):
        asked.append(frames)
        progress(frames, frames)
        return {"scenario": "loop", "frames": frames, "window": 1000, "seconds": 1800.0, "seconds_per_frame": 0.18,
                "first": window, "last": window | {"frames": [9000, 10000]}, "rss_growth_kb_per_frame": 0.5,
                "rss_mb_end": 305.0, "landmarks_final": 15, "landmarks_dropped": 40}

    monkeypatch.setattr(bench, "stage_times", lambda repeats: stages)
    monkeypatch.setattr(bench, "ekf_vs_filterpy", lambda sizes: {"skipped": "faked"})
    monkeypatch.setattr(bench, "memory_profile", soak)
    assert main(["bench", "--memory-frames", "10000", "--json", str(tmp_path / "b.json")]) == 0
    assert asked == [10000]
    printed = " ".join(capsys.readouterr().out.split())  # the console wraps long lines
    assert "frames 9000–9999" in printed and "10000 frames in 30.0 min" in printed
    doc = json.loads((tmp_path / "b.json").read_text())
    assert doc["memory"]["first"]["held_kb_per_frame"] is None and doc["memory"]["landmarks_final"] == 15


def test_stage_times_time_the_pipeline_as_the_localizer_runs_it():
    """The per-stage figures come from the pipeline with disparity in regions (as ``Localizer.step`` runs it),
    next to the dense one, with the ratios ``stablemarks bench`` prints and writes."""
    from stablemarks.bench import stage_times

    out = stage_times(repeats=1, run_frames=(0,))
    for key in ("stereobm", "regions", "segments", "matching", "disparity", "filter", "planes", "landmarks", "ekf",
                "front_end", "pipeline", "disparity_alone", "disparity_dense", "disparity_dense_in_pipeline",
                "pipeline_dense", "run_pipeline", "run_pipeline_dense"):
        assert out[f"{key}_ms"] > 0, key
    for key in ("ratio_pipeline_vs_stereobm", "ratio_disparity_vs_stereobm", "ratio_pipeline_dense_vs_stereobm",
                "ratio_disparity_dense_vs_stereobm", "ratio_run_pipeline_vs_stereobm"):
        assert out[key] > 0, key
    assert out["pipeline_fps"] == pytest.approx(1000.0 / out["pipeline_ms"])
    for key, ratio in (("pipeline", "ratio_pipeline_vs_stereobm"), ("disparity_alone", "ratio_disparity_vs_stereobm"),
                       ("disparity_dense", "ratio_disparity_dense_vs_stereobm")):
        ref, own = out[f"paired_{key}_ms"]  # the goals' ratios: each against the StereoBM calls timed in turn with it
        assert ref > 0 and own > 0
        assert out[ratio] == pytest.approx(own / ref)
    assert out["run_frames"] == [0]


def test_paired_medians_time_both_in_turn():
    """Rounds of a block of reference calls then a block of the function's, the first of each block not counted;
    ``timing`` reads the function's own time from what it returns."""
    from stablemarks.bench import paired_medians

    calls = []
    ref, own = paired_medians(lambda: calls.append("r"), lambda: calls.append("f") or {"t": 0.25}, rounds=2,
                              block=3, timing=lambda out: out["t"])
    assert calls == ["r"] * 3 + ["f"] * 3 + ["r"] * 3 + ["f"] * 3
    assert own == 0.25 and 0 < ref < 0.25


def test_lap_source_renders_nothing_for_dead_reckoning(monkeypatch):
    from stablemarks.online import run_online
    from stablemarks.sim import render

    def refuse(self, X, pan, rng):
        raise AssertionError("a frame was rendered")

    monkeypatch.setattr(render.Renderer, "render", refuse)
    source = LapSource("loop", 4)
    result = run_online(source, method="dead_reckoning")
    assert result.n_frames == 4 and not source.rendering
    np.testing.assert_allclose(result.poses, result.dead_reckoning, atol=1e-12)
