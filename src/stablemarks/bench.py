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
  (in regions, with what the landmark stage adds; ``disparity_ms`` is the same inside the pipeline, between the
  other stages; each run's outputs are let go before the next, as in the localizer's loop). The same with the
  dense disparity images (``*_dense``) for comparison, and both pipelines on frames across the lab run
  (``run_*``: the regions vary with the view). The three ratios with goals (``ratio_pipeline_vs_stereobm``,
  ``ratio_disparity_vs_stereobm``, ``ratio_disparity_dense_vs_stereobm``) are each timed in short blocks
  alternating with StereoBM's (:func:`paired_medians`, ``paired_*_ms``: the two medians), so that a burst of
  load on the shared machine falls on both. The per-stage rows come from blocks of their own.
- The EKF update against filterpy's ``ExtendedKalmanFilter`` doing the same update on the same numbers,
  for 10 to 2000 landmarks (``ratio_ekf_vs_filterpy_1000``, ``max_abs_diff``).
- The soak (``--memory-frames N``, :func:`memory_profile`): N frames of the on-line loop on the ``loop``
  scenario driven lap after lap, made frame by frame (:class:`LapSource`) with no per-frame record kept;
  time per frame, resident memory (RSS) per frame, traced allocations (``tracemalloc``, in half of each
  window only: it slows Python about twofold) and the landmark count, in the first and the last window of
  ``window`` frames (1000), to show that time and memory stay flat over a long run.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
import tracemalloc
from collections.abc import Callable, Iterator

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from .sim.source import SimulatedSource


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


def paired_medians(reference: Callable[[], object], fn: Callable[[], object], rounds: int = 8, block: int = 4,
                   timing: Callable[[object], float] | None = None) -> tuple[float, float]:
    """Median wall times [s] of ``reference()`` and ``fn()`` timed in alternating blocks: ``rounds`` times,
    ``block`` calls of the reference then ``block`` of ``fn``, the first call of each block not counted (it
    warms the caches the other one used). A burst of load on the shared machine then falls on both alike, where
    two long blocks timed one after the other can each catch a different one (the same pipeline came out at 11.4
    and 19.8 ms in two runs a minute apart while StereoBM stayed at 12 ms). Calls interleaved one by one would
    time both with caches the other has just filled: the pipeline then took 12.2–14.6 ms against StereoBM's
    12.1–12.7. ``timing``: the time of ``fn`` from what it returns (the pipeline's own, without its set-up); else
    the wall time of the call."""
    ref, own = [], []
    for _ in range(rounds):
        for k in range(block):
            t0 = time.perf_counter()
            reference()
            if k:
                ref.append(time.perf_counter() - t0)
        for k in range(block):
            t0 = time.perf_counter()
            out = fn()
            t1 = time.perf_counter()
            if k:
                own.append(timing(out) if timing is not None else t1 - t0)
            del out
    return statistics.median(ref), statistics.median(own)


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

    # a fresh copy of the filter for this run's update, made before timing: the localizer updates its own filter
    # in place, it does not copy it every frame
    e = ekf.copy() if ekf is not None and ekf.n_landmarks else None
    t0 = time.perf_counter()
    reg = plane_regions(camera, X, cov_X, world_map, config, left.shape) if regions else None
    t1 = time.perf_counter()
    front = run_front_end(left, right, config, reg)
    model = select_landmarks(front, camera, world_map, X, cov_X, config)
    t2 = time.perf_counter()
    if e is not None:
        pairs = front.kept_pairs
        measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
        chosen = e.select_for_update(e.associate_joint(measured, 0.0))
        e.update([(i, measured[j]) for i, j in chosen], iterations=config.ekf.iterations)
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
    """Median of each stage of ``fn()`` over ``repeats`` runs after ``warmup``.

    Only the timings of each run are kept, not its outputs (the ``_`` keys: the frame's model, which holds its
    front end, disparity images and prepared pair, ~6 MB): the localizer's loop lets go of a frame's images
    before the next (:func:`~stablemarks.online.run_online` keeps records, not front ends), so the allocator
    hands the next frame memory it has already mapped. Keeping every run's made each run's arrays fresh pages
    of the process, written for the first time: about 2.5 ms of page faults per frame at 640×480 (1.8 ms of
    them in the disparity stage), which the localizer does not pay (issue 13)."""
    for _ in range(warmup):
        fn()
    runs = []
    for _ in range(repeats):
        run = fn()
        runs.append({k: v for k, v in run.items() if not k.startswith("_")})
        del run
    return {k: statistics.median(r[k] for r in runs) for k in runs[0]}


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
    camera = config.camera(camera)  # with the configuration's σ_img once, as the Localizer holds its camera
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
        # StereoBM again after the stages, the smaller median kept: its first timing, right after the set-up, came
        # out 20-26 ms in runs where the same call took 14-15 ms later on (a shared 2-core machine); the smaller
        # reference can only make our ratios larger
        out["stereobm"] = min(out["stereobm"], median_time(lambda: bm.compute(left, right), repeats))
        # the three ratios with goals, each against StereoBM calls timed in blocks alternating with its own
        paired = {}
        rounds = max(2, (repeats + 2) // 3)  # 3 timed calls of each per round: about as many as the blocks above

        def pipeline_run():
            return _pipeline(left, right, camera, world_map, X, cov_X, config, ekf)

        for key, fn, timing in (("pipeline", pipeline_run, lambda r: r["pipeline"]),
                                ("disparity_alone", sad_in_regions, None),
                                ("disparity_dense", lambda: compute_disparity(left, right, config.sad), None)):
            paired[key] = paired_medians(lambda: bm.compute(left, right), fn, rounds, timing=timing)
        # frames across the run, each from its true pose with the regions the localizer would compute there
        per_frame = []
        for k in (k for k in run_frames if k < len(run)):
            f = run.render(k)
            cam_k = config.camera(scenario.camera).with_pan(run.pans[k])
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
    res.update({f"paired_{k}_ms": [1000 * v for v in pair] for k, pair in paired.items()})
    res.update(
        front_end_ms=1000 * front,
        pipeline_fps=1.0 / pipeline,
        pipeline_dense_fps=1.0 / out["pipeline_dense"],
        ratio_segments_vs_stereobm=out["segments"] / out["stereobm"],
        ratio_disparity_vs_stereobm=paired["disparity_alone"][1] / paired["disparity_alone"][0],
        ratio_disparity_dense_vs_stereobm=paired["disparity_dense"][1] / paired["disparity_dense"][0],
        ratio_disparity_in_pipeline_vs_dense=out["disparity"] / out["disparity_dense_in_pipeline"],
        ratio_front_end_vs_stereobm=front / out["stereobm"],
        ratio_pipeline_vs_stereobm=paired["pipeline"][1] / paired["pipeline"][0],
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
    frames (for a path that ends where it starts, like the ``loop``'s). It holds every frame's truth (poses,
    odometry, pans: all planned up front); :class:`LapSource` makes the same frames one at a time."""
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


class LapSource(SimulatedSource):
    """``frames`` frames of a scenario's path driven lap after lap, made one at a time: the frames of
    ``SimulatedSource(long_run(scenario, frames), frames=frames)`` — the same true poses, odometry noise,
    dead reckoning, pans and images — without planning or holding the whole run. It holds one lap's true
    poses and the current dead reckoning; the odometry noise is drawn from the run's odometry stream in
    frame order (as :func:`~stablemarks.sim.run.simulate_run` draws it), and each frame's images from its
    own stream. The head follows the localizer's pan commands (steerable); unsteered, the scenario's pan
    policy from dead reckoning, as the simulated run's pans."""

    def __init__(self, scenario, frames: int, seed: int | None = None, stamp_step: float = 0.5):
        from .sim.run import simulate_run
        from .sim.scenario import load_scenario

        sc = load_scenario(scenario) if isinstance(scenario, str) else scenario
        first = simulate_run(sc, seed)  # one pass of the path: the start, the seed, the source's settings
        super().__init__(first, stamp_step=stamp_step)
        again = self._lap(first.poses[-1]) if len(first) > 1 else []
        # a path that does not move again from where it ends (or no path) has only its first pass
        self._n = int(frames) if len(again) > 1 else min(int(frames), len(first))

    def _lap(self, start):
        from .motion import plan_path

        plan = self.scenario.robot
        return plan_path(start, plan.path, plan.frame_spacing, plan.frame_turn) if plan.path else [start]

    def truth(self) -> Iterator[tuple]:
        """``(true pose, dead reckoning)`` (SE2) of every frame, lap after lap."""
        plan = self.scenario.robot
        rng = np.random.default_rng(np.random.SeedSequence(self.run.seed, spawn_key=(0,)))
        pose = believed = plan.start
        yield pose, believed
        while True:
            lap = self._lap(pose)
            if len(lap) < 2:
                return
            for a, b in zip(lap[:-1], lap[1:], strict=True):
                believed = believed @ plan.odometry.sample(a.between(b), rng)
                yield b, believed
            pose = lap[-1]

    def _policy_pan(self, believed, previous: float | None) -> float:
        from .motion import look_at_free_edges

        sc, pan = self.scenario, self.scenario.robot.pan
        if pan.policy == "fixed":
            return float(np.clip(pan.angle, *sc.pan_limits))
        return look_at_free_edges(self.world_map, self.camera, believed.as_array(), limits=sc.pan_limits,
                                  default=pan.angle if previous is None else previous, view_fraction=None)

    def frame(self, k: int, pan: float | None = None):
        raise NotImplementedError("LapSource makes its frames in order: iterate over it")

    def __iter__(self):
        from .frames import Frame

        previous = None
        for k, (pose, believed) in enumerate(self.truth()):
            if k >= len(self):
                return
            odometry = believed.as_array()
            if self._pan_for is not None:
                pan = float(self._pan_for(odometry))
            else:
                pan = previous = self._policy_pan(believed, previous)
            left, right, truth = self._shot(k, pose.as_array(), pan)
            yield Frame(k, k * self.stamp_step, left, right, odometry, pan, true_pose=pose.as_array(), truth=truth)



def rss_mb() -> float:
    """The process's resident memory now [MB] (``/proc/self/statm``); where there is none, its peak so far
    (``ru_maxrss``), or NaN."""
    try:
        with open("/proc/self/statm", "rb") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError, AttributeError):
        pass
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return float("nan")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # pragma: no cover - not Linux
    return peak / 1e6 if sys.platform == "darwin" else peak / 1e3  # pragma: no cover


def _slope(y: np.ndarray) -> float:
    """Least-squares slope of ``y`` per sample (NaN with fewer than 3)."""
    return float(np.polyfit(np.arange(len(y)), y, 1)[0]) if len(y) >= 3 else float("nan")


def _median(y) -> float:
    return float(np.median(y)) if len(y) else float("nan")


def memory_profile(frames: int = 10_000, scenario: str = "loop", window: int = 1000,
                   progress: Callable[[int, int], None] | None = None) -> dict:
    """The soak: ``frames`` frames of the on-line loop on ``scenario`` driven lap after lap (the ``loop``
    closes on itself, so its laps continue seamlessly), streamed: frames made one at a time
    (:class:`LapSource`), no per-frame record kept (``run_online(..., keep="nothing")``), the measurements in
    preallocated arrays.

    Two windows of ``w = min(window, frames // 2)`` frames, the first and the last. In the first half of each
    window, untraced: the median wall time per frame of the localizer's step (``step_ms``) and with the
    frame's rendering (``frame_ms``), and the resident memory (``rss_mb``). In the second half, under
    ``tracemalloc`` (about twice as slow, hence not timed): the median and largest traced peak per frame
    (``traced_peak_mb``, ``traced_peak_mb_max``) and the growth of the memory held between frames
    (``held_kb_per_frame``, a straight-line fit). The landmark count (median and largest) over the window.
    Over the run: the RSS growth between the windows (``rss_growth_kb_per_frame``), the final landmark count,
    the landmarks dropped (their last estimates are kept: ``retired``) and the total wall time.
    ``progress(k, n)`` after each frame.
    """
    from .online import run_online

    source = LapSource(scenario, frames)
    n = len(source)
    w = max(1, min(int(window), n // 2))
    timed = max(1, w // 2)  # the untraced first part of each window
    windows = {"first": 0, "last": n - w}
    traced_at = {start + timed for start in windows.values() if timed < w}
    stop_at = {start + w for start in windows.values() if timed < w}
    step = np.full(n, np.nan)
    wall = np.full(n, np.nan)
    rss = np.full(n, np.nan)
    landmarks = np.zeros(n, dtype=int)
    peak = np.full(n, np.nan)
    held = np.full(n, np.nan)
    clock = [time.perf_counter()]

    def measure(frame, est, localizer):
        k = frame.index
        now = time.perf_counter()
        wall[k] = now - clock[0]
        step[k] = est.record.timings.get("total", np.nan)
        landmarks[k] = localizer.ekf.n_landmarks
        if tracemalloc.is_tracing():
            current, top = tracemalloc.get_traced_memory()
            held[k], peak[k] = current / 1e3, top / 1e6
            tracemalloc.reset_peak()
        else:
            rss[k] = rss_mb()
        if k + 1 in stop_at:
            tracemalloc.stop()
        if k + 1 in traced_at:
            tracemalloc.start()
        if progress is not None:
            progress(k + 1, n)
        clock[0] = time.perf_counter()

    t0 = time.perf_counter()
    try:
        result = run_online(source, observers=[measure], keep="nothing")
    finally:
        if tracemalloc.is_tracing():
            tracemalloc.stop()
    seconds = time.perf_counter() - t0
    out = {"scenario": scenario, "frames": result.n_frames, "window": w, "seconds": seconds,
           "seconds_per_frame": seconds / max(1, result.n_frames)}
    centres = {}
    for name, start in windows.items():
        t = slice(start, start + timed)
        tr = slice(start + timed, start + w)
        centres[name] = start + timed / 2
        out[name] = {
            "frames": [start, start + w],
            "step_ms": 1000 * _median(step[t]),
            "frame_ms": 1000 * _median(wall[t]),
            "rss_mb": _median(rss[t]),
            "traced_peak_mb": _median(peak[tr]),
            "traced_peak_mb_max": float(np.max(peak[tr])) if timed < w else float("nan"),
            "held_kb_per_frame": _slope(held[tr]),
            "landmarks": _median(landmarks[start:start + w]),
            "landmarks_max": int(landmarks[start:start + w].max()),
        }
    span = centres["last"] - centres["first"]
    out["rss_growth_kb_per_frame"] = (1000 * (out["last"]["rss_mb"] - out["first"]["rss_mb"]) / span
                                      if span > 0 else float("nan"))
    out["rss_mb_end"] = rss_mb()
    out["landmarks_final"] = result.ekf.n_landmarks
    out["landmarks_dropped"] = len(result.retired)
    return out
