"""The benchmark helpers (the figures themselves are printed by ``stablemarks bench``, not asserted)."""

import numpy as np
import pytest

from stablemarks.bench import long_run, memory_profile


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


def test_memory_profile_reports_peaks_and_growth():
    out = memory_profile(4, "loop")
    assert out["frames"] == 4 and out["peak_mb_max"] > 0 and out["record_kb_per_frame"] > 0
    assert set(out) >= {"held_kb_per_frame", "landmarks_final", "peak_mb_first_quarter", "peak_mb_last_quarter"}


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
    assert out["run_frames"] == [0]
