"""Speed of every stage, measured against reference implementations in the same run.

All timings are single-threaded (BLAS via threadpoolctl, OpenCV via ``cv2.setNumThreads(1)``, numba
kernels are compiled single-threaded), after a warm-up, as the median of repeated runs; the machine is
shared, so ratios to a reference measured in the same run are the figures to read, not absolute times.

- Per frame at 640×480 with 64 disparities on a rendered ``lab`` pair: segment extraction (both images),
  segment matching, SAD disparity (both directions + left-right check), the disparity filter, plane
  prediction and fitting, boundary/modeling/selection, and one EKF update — next to one call of OpenCV's
  ``StereoBM`` (15×15, 64 disparities) on the same pair. ``ratio_pipeline_vs_stereobm`` is the whole
  per-frame pipeline over that call.
- The EKF update against filterpy's ``ExtendedKalmanFilter`` doing the same update on the same numbers,
  for 10 to 2000 landmarks (``ratio_ekf_vs_filterpy_1000``, ``max_abs_diff``).
- Memory: traced allocation peak per frame over a run of the on-line loop, to show it stays flat.
"""

from __future__ import annotations

import pickle
import statistics
import time
import tracemalloc
from collections.abc import Callable

import cv2
import numpy as np
from threadpoolctl import threadpool_limits


def wall_times(fn: Callable[[], object], repeats: int = 15, warmup: int = 2) -> list[float]:
    """Wall times of ``fn()`` [s] over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


def median_time(fn: Callable[[], object], repeats: int = 15, warmup: int = 2) -> float:
    """Median wall time of ``fn()`` [s] over ``repeats`` runs after ``warmup`` runs."""
    return statistics.median(wall_times(fn, repeats, warmup))


def lab_pair(seed: int = 1):
    """The lab's first rendered stereo pair, its scenario, run and the camera with the frame's pan."""
    from .sim.run import simulate_run
    from .sim.scenario import load_scenario

    scenario = load_scenario("lab")
    run = simulate_run(scenario, seed)
    frame = run.render(0)
    return frame, scenario, run, scenario.camera.with_pan(run.pans[0])


def stage_times(repeats: int = 15) -> dict:
    """Per-frame time of every stage [ms] and the ratios to one StereoBM call on the same pair."""
    from .config import Config
    from .estimation import JointEKF, NewLandmark
    from .landmarks import landmarks_on_plane
    from .pipeline import valid_columns
    from .planes import fit_plane, predict_planes
    from .vision.area_stereo import compute_disparity
    from .vision.filter import filter_pairs
    from .vision.segment_stereo import match_segments
    from .vision.segments import extract_vertical_segments

    config = Config()
    frame, scenario, run, camera = lab_pair()
    left, right = frame.left, frame.right
    X = run.poses[0].as_array()
    cov_X = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
    world_map = scenario.map  # built once, as the on-line loop holds it
    cv2.setNumThreads(1)
    out = {}
    with threadpool_limits(1):
        bm = cv2.StereoBM_create(numDisparities=64, blockSize=15)
        out["stereobm"] = median_time(lambda: bm.compute(left, right), repeats)
        seg_l = extract_vertical_segments(left, config.segments)
        seg_r = extract_vertical_segments(right, config.segments)
        out["segments"] = median_time(lambda: (extract_vertical_segments(left, config.segments),
                                               extract_vertical_segments(right, config.segments)), repeats)
        pairs = match_segments(seg_l, seg_r, config.matching)
        out["matching"] = median_time(lambda: match_segments(seg_l, seg_r, config.matching), repeats)
        disp = compute_disparity(left, right, config.sad)
        out["disparity"] = median_time(lambda: compute_disparity(left, right, config.sad), repeats)
        f = config.filter

        def run_filter():
            return filter_pairs(pairs, seg_l, disp.left, disp.valid, tolerance=f.tolerance,
                                min_support=f.min_support, search_radius=f.search_radius)

        kept = run_filter()
        out["filter"] = median_time(run_filter, repeats)
        kept_pairs = pairs.subset(kept)

        def planes():
            preds = predict_planes(camera, X, cov_X, world_map, config.planes)
            return [fit_plane(camera, X, disp.left, p, config.planes) for p in preds]

        fits = planes()
        out["planes"] = median_time(planes, repeats)

        def model():
            cols = valid_columns(disp)
            return [landmarks_on_plane(camera, fit, kept_pairs, seg_l, disp.right, config.landmarks,
                                       config.planes, float(config.sad.block_size), cols) for fit in fits if fit]

        models = model()
        out["landmarks"] = median_time(model, repeats)
        cands = [c for m in models for c in m.candidates if c.selected]
        ekf = JointEKF(camera, X, cov_X, config.ekf)
        ids = ekf.add_landmarks([NewLandmark.wall(world_map[c.plane_id], c.s, c.edge) for c in cands],
                                np.diag([c.sigma_s**2 for c in cands]))
        measured = np.stack([kept_pairs.u_left, kept_pairs.u_right], axis=-1)

        def ekf_step():
            e = ekf.copy()
            assoc = e.associate_joint(measured, 0.0)
            chosen = e.select_for_update(assoc)
            e.update([(i, measured[j]) for i, j in chosen])

        out["ekf"] = median_time(ekf_step, repeats)
        assert len(ids) == len(cands)
    front = out["segments"] + out["matching"] + out["disparity"] + out["filter"]
    pipeline = front + out["planes"] + out["landmarks"] + out["ekf"]
    res = {f"{k}_ms": 1000 * v for k, v in out.items()}
    res.update(
        front_end_ms=1000 * front,
        pipeline_ms=1000 * pipeline,
        ratio_segments_vs_stereobm=out["segments"] / out["stereobm"],
        ratio_disparity_vs_stereobm=out["disparity"] / out["stereobm"],
        ratio_front_end_vs_stereobm=front / out["stereobm"],
        ratio_pipeline_vs_stereobm=pipeline / out["stereobm"],
    )
    return res


def ekf_vs_filterpy(sizes=(10, 100, 500, 1000, 2000), m: int = 6, repeats: int = 7, seed: int = 0) -> dict:
    """EKF update time against filterpy's ExtendedKalmanFilter doing the same update on the same numbers."""
    try:
        from filterpy.kalman import ExtendedKalmanFilter
    except ImportError:  # pragma: no cover - filterpy is a dev/bench extra
        return {"skipped": "filterpy is not installed: pip install 'stablemarks[bench]'"}
    from .estimation import JointEKF, NewLandmark
    from .geometry import StereoCamera
    from .maps import ReferencePlane

    rng = np.random.default_rng(seed)
    cam = StereoCamera()
    X = np.array([0.0, 0.0, np.pi / 2])
    rows = []
    with threadpool_limits(1):
        for n in sizes:
            plane = ReferencePlane("w", (-3.0, 5.0), (3.0, 5.0), free_edges=("p1",))
            s = np.sort(rng.uniform(0.5, 5.5, n))
            ekf = JointEKF(cam, X, np.diag([0.05, 0.05, 0.02]) ** 2)
            A = rng.normal(size=(n, n)) * 1e-3
            ekf.add_landmarks([NewLandmark.wall(plane, v) for v in s], A @ A.T + 1e-4 * np.eye(n))
            ids = ekf.select_for_update([(i, 0) for i in ekf.visible(0.0)][: 4 * m], 0.0, k=m)
            ids = [i for i, _ in ids]
            h, H = ekf.observation_model(ids, 0.0)
            z = h(ekf.state) + rng.normal(0, 0.5, 2 * len(ids))
            obs = [(i, z[2 * j : 2 * j + 2]) for j, i in enumerate(ids)]

            # fresh filters made before timing: only the update itself is timed
            copies = [ekf.copy() for _ in range(repeats + 2)]

            def ours(copies=copies, obs=obs):
                e = copies.pop()
                e.update(obs)
                return e

            def make_filter(ekf=ekf, z=z):
                f = ExtendedKalmanFilter(dim_x=len(ekf.state), dim_z=len(z))
                f.x = ekf.state.copy()
                f.P = ekf.cov.copy()
                f.R = np.eye(len(z)) * 0.25
                return f

            filters = [make_filter() for _ in range(repeats + 2)]

            def reference(filters=filters, H=H, h=h, z=z):
                f = filters.pop()
                f.update(z, lambda x: H, lambda x: h(x))
                return f

            t_ours = median_time(ours, repeats, 1)
            t_ref = median_time(reference, repeats, 1)
            a, b = ours(), reference()  # the last fresh copy
            diff = max(float(np.abs(a.state - b.x).max()), float(np.abs(a.cov - b.P).max()))
            rows.append({"landmarks": n, "ours_ms": 1000 * t_ours, "filterpy_ms": 1000 * t_ref,
                         "ratio": t_ref / t_ours, "max_abs_diff": diff})
    out = {"rows": rows, "max_abs_diff": max(r["max_abs_diff"] for r in rows)}
    for r in rows:
        if r["landmarks"] == 1000:
            out["ratio_ekf_vs_filterpy_1000"] = r["ratio"]
    return out


def long_run(scenario: str, frames: int):
    """The simulated run of ``scenario`` with its path driven again and again until it has at least ``frames``
    frames (for a path that ends where it starts, like the ``loop``'s)."""
    import math
    from dataclasses import replace

    from .sim.run import simulate_run
    from .sim.scenario import load_scenario

    sc = load_scenario(scenario)
    run = simulate_run(sc)
    if frames > len(run) and sc.robot.path:
        laps = math.ceil(frames / len(run))
        run = simulate_run(replace(sc, robot=replace(sc.robot, path=sc.robot.path * laps)))
    return run


def memory_profile(frames: int = 200, scenario: str = "loop") -> dict:
    """Traced memory of each frame of the on-line loop on a simulated scenario, repeated along its path
    until it has ``frames`` frames (the ``loop`` closes on itself, so its laps continue seamlessly).

    Returns the median per-frame peak in the first and last quarter, the largest peak, the landmark count in
    both quarters, and the growth of the memory held between frames (``held_kb_per_frame``, a straight-line
    fit over the second half of the run): the per-frame records the loop returns (``FrameRecord``, for the
    log) are the only thing that should grow besides the landmark state.
    """
    from .online import run_online
    from .sim.source import SimulatedSource

    run = long_run(scenario, frames)
    n = min(frames, len(run))
    source = SimulatedSource(run, frames=n)
    peaks, held = [], []

    def progress(k, total):
        current, peak = tracemalloc.get_traced_memory()
        peaks.append(peak / 1e6)
        held.append(current / 1e3)
        tracemalloc.reset_peak()

    tracemalloc.start()
    try:
        result = run_online(source, progress=progress)
        record_kb = len(pickle.dumps(result.records)) / 1e3 / max(1, n)
    finally:
        tracemalloc.stop()
    sizes = [r.n_landmarks for r in result.records]
    q = max(1, n // 4)
    half = np.arange(n // 2, n)
    slope = float(np.polyfit(half, np.asarray(held)[half], 1)[0]) if len(half) > 2 else float("nan")
    return {
        "scenario": scenario,
        "frames": n,
        "landmarks_final": result.ekf.n_landmarks,
        "peak_mb_first_quarter": float(np.median(peaks[1:q + 1])),
        "peak_mb_last_quarter": float(np.median(peaks[-q:])),
        "peak_mb_max": float(max(peaks)),
        "landmarks_first_quarter": float(np.median(sizes[1:q + 1])),
        "landmarks_last_quarter": float(np.median(sizes[-q:])),
        "held_kb_per_frame": slope,
        "record_kb_per_frame": record_kb,
    }
