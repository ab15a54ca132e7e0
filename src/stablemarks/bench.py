"""Speed of every stage, measured against reference implementations in the same run.

All timings are single-threaded (BLAS via threadpoolctl, OpenCV via ``cv2.setNumThreads(1)``, numba
kernels are compiled single-threaded), after a warm-up, as the median of repeated runs; the machine is
shared, so ratios to a reference measured in the same run are the figures to read, not absolute times.

- Per frame at 640×480 with 64 disparities on a rendered ``lab`` pair, the pipeline as the localizer runs it
  (:meth:`~stablemarks.localizer.Localizer.step`): the planes' disparity regions from the pose prior
  (``plane_regions``), segment extraction (both images), segment matching, SAD disparity (both directions +
  left-right check) only where the method reads it, the disparity filter, plane prediction and fitting,
  boundary/modeling/selection, and one EKF association + update — next to one call of OpenCV's ``StereoBM``
  (15×15, 64 disparities) on the same pair. ``ratio_pipeline_vs_stereobm`` is the whole per-frame pipeline over
  that call (``pipeline_fps`` its frames per second), ``ratio_disparity_vs_stereobm`` the pipeline's SAD alone
  (in regions, with what the landmark stage adds; ``disparity_ms`` is the same inside the pipeline, where the
  other stages leave the caches cold). The same with the dense disparity images (``*_dense``) for comparison,
  and both pipelines on frames across the lab run (``run_*``: the regions vary with the view).
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


def _pipeline(left, right, camera, world_map, X, cov_X, config, ekf, regions: bool = True) -> dict:
    """One frame through the pipeline as :meth:`Localizer.step` runs it; the time of each stage [s]."""
    from .pipeline import plane_regions, run_front_end, select_landmarks

    t0 = time.perf_counter()
    reg = plane_regions(camera, X, cov_X, world_map, config, left.shape) if regions else None
    t1 = time.perf_counter()
    front = run_front_end(left, right, config, reg)
    model = select_landmarks(front, camera, world_map, X, cov_X, config)
    t2 = time.perf_counter()
    if ekf is not None and ekf.n_landmarks:
        pairs = front.kept_pairs
        measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
        e = ekf.copy()
        chosen = e.select_for_update(e.associate_joint(measured, 0.0))
        e.update([(i, measured[j]) for i, j in chosen])
    t3 = time.perf_counter()
    m = model.timings
    return {"regions": t1 - t0, "segments": front.timings["segments"], "matching": front.timings["matching"],
            "disparity": front.timings["disparity"] + m["disparity"], "filter": front.timings["filter"],
            "planes": m["total"] - m["landmarks"] - m["disparity"], "landmarks": m["landmarks"], "ekf": t3 - t2,
            "pipeline": t3 - t0, "_model": model}


def _frame_ekf(left, right, camera, world_map, X, cov_X, config):
    """The EKF as after this frame: a wall landmark for every selected candidate."""
    from .estimation import JointEKF, NewLandmark

    model = _pipeline(left, right, camera, world_map, X, cov_X, config, None)["_model"]
    ekf = JointEKF(camera, X, cov_X, config.ekf)
    if model.selected:
        ekf.add_landmarks([NewLandmark.wall(world_map[c.plane_id], c.s, c.edge) for c in model.selected],
                          np.diag([c.sigma_s**2 for c in model.selected]))
    return ekf


def _median_stages(fn: Callable[[], dict], repeats: int, warmup: int = 2) -> dict:
    """Median of each stage of ``fn()`` over ``repeats`` runs after ``warmup``."""
    for _ in range(warmup):
        fn()
    runs = [fn() for _ in range(repeats)]
    return {k: statistics.median(r[k] for r in runs) for k in runs[0] if not k.startswith("_")}


def stage_times(repeats: int = 15, run_frames: tuple[int, ...] = (0, 5, 10, 15, 20)) -> dict:
    """Per-frame time of every stage [ms] and the ratios to one StereoBM call on the same pair, the pipeline as
    the localizer runs it (disparity in regions) and with the dense disparity images; ``run_frames``: frames of
    the lab run timed too (mean over them of each frame's median)."""
    from .config import Config
    from .pipeline import edge_windows, front_disparity, plane_regions, prediction_regions
    from .vision.area_stereo import compute_disparity
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
        out["disparity_dense"] = median_time(lambda: compute_disparity(left, right, config.sad), repeats)
        ekf = _frame_ekf(left, right, camera, world_map, X, cov_X, config)
        stages = _median_stages(lambda: _pipeline(left, right, camera, world_map, X, cov_X, config, ekf), repeats)
        dense = _median_stages(lambda: _pipeline(left, right, camera, world_map, X, cov_X, config, ekf, False),
                               repeats)
        out.update(stages)
        out["pipeline_dense"] = dense["pipeline"]
        out["disparity_dense_in_pipeline"] = dense["disparity"]
        # the pipeline's SAD alone, like the StereoBM call: the front end's (in regions) and what the landmark
        # stage adds (the planes' pixels still missing, the border columns its edge windows need)
        reg = plane_regions(camera, X, cov_X, world_map, config, left.shape)
        seg_l = extract_vertical_segments(left, config.segments)
        pairs = match_segments(seg_l, extract_vertical_segments(right, config.segments), config.matching)

        def sad_in_regions():
            _, lazy = front_disparity(left, right, config, reg, pairs, seg_l)
            if lazy is not None:
                lazy.compute_regions(prediction_regions(reg.predictions, left.shape, config))
                lazy.decide_columns(edge_windows(reg.predictions, config))

        out["disparity_alone"] = median_time(sad_in_regions, repeats)
        # frames across the run, each from its true pose with the regions the localizer would compute there
        per_frame = []
        for k in (k for k in run_frames if k < len(run)):
            f = run.render(k)
            cam_k = scenario.camera.with_pan(run.pans[k])
            X_k = run.poses[k].as_array()
            ekf_k = _frame_ekf(f.left, f.right, cam_k, world_map, X_k, cov_X, config)
            row = [median_time(lambda f=f: bm.compute(f.left, f.right), repeats)]
            for regions in (True, False):
                row.append(_median_stages(lambda f=f, c=cam_k, x=X_k, e=ekf_k, r=regions: _pipeline(
                    f.left, f.right, c, world_map, x, cov_X, config, e, r), repeats)["pipeline"])
            per_frame.append(row)
    front = out["regions"] + out["segments"] + out["matching"] + out["disparity"] + out["filter"]
    pipeline = out["pipeline"]
    res = {f"{k}_ms": 1000 * v for k, v in out.items()}
    res.update(
        front_end_ms=1000 * front,
        pipeline_fps=1.0 / pipeline,
        pipeline_dense_fps=1.0 / out["pipeline_dense"],
        ratio_segments_vs_stereobm=out["segments"] / out["stereobm"],
        ratio_disparity_vs_stereobm=out["disparity_alone"] / out["stereobm"],
        ratio_disparity_dense_vs_stereobm=out["disparity_dense"] / out["stereobm"],
        ratio_disparity_in_pipeline_vs_dense=out["disparity"] / out["disparity_dense_in_pipeline"],
        ratio_front_end_vs_stereobm=front / out["stereobm"],
        ratio_pipeline_vs_stereobm=pipeline / out["stereobm"],
        ratio_pipeline_dense_vs_stereobm=out["pipeline_dense"] / out["stereobm"],
    )
    if per_frame:
        t = np.asarray(per_frame)
        res.update(run_frames=[k for k in run_frames if k < len(run)],  # each with its EKF update
                   run_stereobm_ms=1000 * float(t[:, 0].mean()), run_pipeline_ms=1000 * float(t[:, 1].mean()),
                   run_pipeline_dense_ms=1000 * float(t[:, 2].mean()),
                   ratio_run_pipeline_vs_stereobm=float(t[:, 1].mean() / t[:, 0].mean()),
                   ratio_run_pipeline_dense_vs_stereobm=float(t[:, 2].mean() / t[:, 0].mean()))
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
