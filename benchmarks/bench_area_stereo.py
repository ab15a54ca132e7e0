"""Speed of the SAD stereo (paper Sec 2.2, Eq 2: both disparity images + left-right check) against StereoBM.

Run: ``python benchmarks/bench_area_stereo.py [--repeats N] [--pair synthetic|lab] [--regions]``

The pair: a synthetic 640×480 rectified scene of random-texture planes at a few depths (a slanted
background, disparity 8 → 20 px, and three fronto-parallel boxes at 26, 38 and 52 px) with sensor
noise, or (``--pair lab``) the first rendered frame of the built-in ``lab`` scenario. Single-threaded:
BLAS via threadpoolctl, OpenCV via ``cv2.setNumThreads(1)``, our numba kernel is compiled without
``parallel``. After a warm-up (JIT), each of the ``repeats`` rounds times, interleaved on the same pair:

- ONE ``cv2.StereoBM`` call, 15×15 window, 64 disparities, OpenCV's defaults (the reference);
- ours: :func:`compute_disparity` with the default :class:`SADConfig` (15×15, 64 disparities), i.e. the
  left AND right disparity images from one pass of Eq 2 costs, uniqueness, texture and sub-pixel
  refinement and the left-right consistency check, input validation and prefilter included;
- two StereoBM calls (the second on the flipped, swapped pair) + the same check: the ``"opencv"`` backend.

Reported: medians [ms], the ratios to the one StereoBM call (wall time, and thread CPU time, which is
steadier on a shared machine), and the valid fraction and bad-pixel rates against the scene's truth.
Goal: both directions plus the check within 1.0× one StereoBM call.

With ``--regions``, also :func:`compute_disparity_regions` against the dense computation, in the same run,
for a growing fraction of the image (:func:`run_regions`): the predicted windows of reference planes
(rectangles) and bands around candidate segment pairs (±20 columns around slanted vertical lines).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from stablemarks.vision.area_stereo import SADConfig, compute_disparity, compute_disparity_regions

SHAPE = (480, 640)


def _texture(rng: np.random.Generator, shape: tuple[int, int], contrast: float = 35.0) -> np.ndarray:
    t = cv2.GaussianBlur(rng.standard_normal(shape), (0, 0), 1.2)
    return (contrast * t / t.std()).astype(np.float32)


def make_pair(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A rectified uint8 pair (H, W) of textured planes and the true left-reference disparity (H, W) [px].

    Each plane has disparity ``d(u) = d0 + k (u − u0)`` over its left-image columns ``[u0, u1)``; the right
    image samples the plane's texture where ``u − d(u)`` lands, so ``left(u) = right(u − d(u))``. Planes are
    painted far to near.
    """
    rng = np.random.default_rng(seed)
    H, W = SHAPE
    left = np.full(SHAPE, 128.0, np.float32)
    right = left.copy()
    truth = np.full(SHAPE, np.nan, np.float32)
    planes = [  # rows, left-image columns, d0, k
        ((0, H), (0, W), 8.0, 12.0 / W),
        ((60, 300), (120, 300), 26.0, 0.0),
        ((200, 440), (330, 470), 38.0, 0.0),
        ((120, 260), (480, 600), 52.0, 0.0),
    ]
    for (v0, v1), (u0, u1), d0, k in planes:
        tex = _texture(rng, (v1 - v0, u1 - u0 + 2)) + np.float32(rng.uniform(-30, 30))
        u = np.arange(u0, u1)
        truth[v0:v1, u0:u1] = d0 + k * (u - u0)
        left[v0:v1, u0:u1] = 128.0 + tex[:, : u1 - u0]
        # right column ur sees the plane's left column u with u - d(u) = ur
        ur = np.arange(int(np.ceil(u0 - d0)), int(np.floor(u1 - 1 - (d0 + k * (u1 - 1 - u0)))) + 1)
        ur = ur[(ur >= 0) & (ur < W)]
        x = ((ur + d0 - k * u0) / (1.0 - k) - u0).astype(np.float32)  # texture column, fractional
        map_x = np.broadcast_to(x, (v1 - v0, len(ur)))
        map_y = np.broadcast_to(np.arange(v1 - v0, dtype=np.float32)[:, None], (v1 - v0, len(ur)))
        right[v0:v1, ur] = 128.0 + cv2.remap(tex, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    left, right = (np.clip(np.rint(img + rng.normal(0.0, 1.5, SHAPE)), 0, 255).astype(np.uint8)
                   for img in (left, right))  # fmt: skip
    return left, right, truth


def lab_pair() -> tuple[np.ndarray, np.ndarray, None]:
    """The first rendered frame of the built-in ``lab`` scenario (no disparity truth)."""
    from stablemarks.bench import lab_pair as rendered

    frame = rendered()[0]
    return frame.left, frame.right, None


def run(left: np.ndarray, right: np.ndarray, config: SADConfig = SADConfig(), repeats: int = 25) -> dict[str, float]:
    """Median timings over ``repeats`` interleaved rounds on one rectified uint8 pair, single-threaded.

    Keys [ms]: ``stereobm_ms`` (one ``cv2.StereoBM`` call, 15×15, 64 disparities, OpenCV's defaults),
    ``ours_ms`` (:func:`compute_disparity` with ``config``, backend numba: both directions + left-right
    check), ``stereobm_two_check_ms`` (the same with backend ``"opencv"``: two StereoBM calls + check).
    Ratios to the one StereoBM call: ``ratio_ours``, ``ratio_two_stereobm`` (wall time) and
    ``ratio_ours_cpu``, ``ratio_two_stereobm_cpu`` (thread CPU time). Also ``valid_fraction_ours`` and
    ``valid_fraction_two_stereobm``.
    """
    ours_config = replace(config, backend="numba")
    bm_config = replace(config, backend="opencv")
    cv2.setNumThreads(1)
    bm = cv2.StereoBM_create(numDisparities=64, blockSize=15)
    jobs = {
        "stereobm": lambda: bm.compute(left, right),
        "ours": lambda: compute_disparity(left, right, ours_config),
        "stereobm_two_check": lambda: compute_disparity(left, right, bm_config),
    }
    wall = {name: [] for name in jobs}
    cpu = {name: [] for name in jobs}
    with threadpool_limits(limits=1):
        for job in jobs.values():  # warm-up: JIT compilation or cache load, first-touch allocations
            job()
            job()
        for _ in range(repeats):
            for name, job in jobs.items():
                t0, c0 = time.perf_counter(), time.thread_time()
                job()
                wall[name].append(1e3 * (time.perf_counter() - t0))
                cpu[name].append(1e3 * (time.thread_time() - c0))
    out = {f"{name}_ms": float(np.median(v)) for name, v in wall.items()}
    for name, key in (("ours", "ratio_ours"), ("stereobm_two_check", "ratio_two_stereobm")):
        out[key] = out[f"{name}_ms"] / out["stereobm_ms"]
        out[f"{key}_cpu"] = float(np.median(cpu[name]) / np.median(cpu["stereobm"]))
    out["valid_fraction_ours"] = compute_disparity(left, right, ours_config).valid_fraction
    out["valid_fraction_two_stereobm"] = compute_disparity(left, right, bm_config).valid_fraction
    return out


def window_regions(shape: tuple[int, int], fraction: float) -> np.ndarray:
    """(2, 4) rectangles (row0, row1, col0, col1) covering ``fraction`` of the image: two plane windows side by
    side, of the image's height less a margin, as the planes' predicted windows are."""
    H, W = shape
    h = int(0.8 * H)
    w = min(W // 2, int(round(fraction * H * W / (2 * h))))
    top = (H - h) // 2
    return np.array([[top, top + h, W // 4 - w // 2, W // 4 - w // 2 + w],
                     [top, top + h, 3 * W // 4 - w // 2, 3 * W // 4 - w // 2 + w]])  # fmt: skip


def band_regions(shape: tuple[int, int], fraction: float, half_width: int = 20, seed: int = 0) -> np.ndarray:
    """(H, W) bool: bands of ±``half_width`` columns around slanted vertical segments (as around candidate
    segment pairs), added until they cover ``fraction`` of the image (or all of it, for a fraction of 1)."""
    H, W = shape
    if fraction >= 1.0:
        return np.ones(shape, bool)
    rng = np.random.default_rng(seed)
    mask = np.zeros(shape, bool)
    rows = np.arange(H)
    while mask.mean() < fraction:
        v0 = int(rng.integers(0, H // 3))
        v1 = int(rng.integers(2 * H // 3, H + 1))
        u0, slope = rng.uniform(0, W), rng.uniform(-0.1, 0.1)
        u = np.rint(u0 + slope * (rows[v0:v1] - v0)).astype(int)
        cols = np.arange(W)[None, :]
        mask[v0:v1] |= np.abs(cols - u[:, None]) <= half_width
    return mask


def run_regions(
    left: np.ndarray,
    right: np.ndarray,
    config: SADConfig = SADConfig(),
    fractions: tuple[float, ...] = (0.1, 0.2, 0.3, 0.5, 0.75, 1.0),
    repeats: int = 15,
) -> list[dict[str, float]]:
    """Median time of :func:`compute_disparity_regions` for windows and for segment bands covering each of
    ``fractions`` of the left image (the right image's disparity not asked for), against the dense
    :func:`compute_disparity` and one StereoBM call timed in the same rounds (thread CPU time [ms]).

    Returns one dict per fraction: ``fraction``, ``area_windows``, ``area_bands`` (the exact fractions),
    ``windows_ms``, ``bands_ms``, ``dense_ms``, ``stereobm_ms`` and ``ratio_windows``, ``ratio_bands`` (to dense).
    """
    cv2.setNumThreads(1)
    bm = cv2.StereoBM_create(numDisparities=64, blockSize=15)
    rows = []
    with threadpool_limits(limits=1):
        for fraction in fractions:
            windows = window_regions(left.shape, fraction)
            bands = band_regions(left.shape, fraction)
            jobs = {
                "stereobm": lambda: bm.compute(left, right),
                "dense": lambda: compute_disparity(left, right, config),
                "windows": lambda w=windows: compute_disparity_regions(left, right, config, w),
                "bands": lambda b=bands: compute_disparity_regions(left, right, config, b),
            }
            cpu = {name: [] for name in jobs}
            for job in jobs.values():
                job()
            for _ in range(repeats):
                for name, job in jobs.items():
                    c0 = time.thread_time()
                    job()
                    cpu[name].append(1e3 * (time.thread_time() - c0))
            row = {"fraction": fraction, "area_bands": float(bands.mean())}
            mask = np.zeros(left.shape, bool)
            for r0, r1, c0, c1 in windows:
                mask[r0:r1, c0:c1] = True
            row["area_windows"] = float(mask.mean())
            row.update({f"{name}_ms": float(np.median(v)) for name, v in cpu.items()})
            row["ratio_windows"] = row["windows_ms"] / row["dense_ms"]
            row["ratio_bands"] = row["bands_ms"] / row["dense_ms"]
            rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=25, help="timed rounds (median reported), >= 20")
    parser.add_argument("--pair", choices=("synthetic", "lab"), default="synthetic", help="the stereo pair")
    parser.add_argument("--regions", action="store_true", help="also time disparity restricted to regions")
    args = parser.parse_args()
    repeats = max(20, args.repeats)
    left, right, truth = make_pair() if args.pair == "synthetic" else lab_pair()
    config = SADConfig()
    r = run(left, right, config, repeats)
    h, w = left.shape
    print(f"{w}x{h} {args.pair} pair, 15x15 window, 64 disparities; single-threaded, median of {repeats} rounds")
    print(f"  one StereoBM call                      {r['stereobm_ms']:7.2f} ms")
    print(f"  ours: both directions + LR check       {r['ours_ms']:7.2f} ms   {r['ratio_ours']:.2f}x StereoBM "
          f"(CPU time {r['ratio_ours_cpu']:.2f}x; goal <= 1.00x)")  # fmt: skip
    print(f"  two StereoBM calls + LR check          {r['stereobm_two_check_ms']:7.2f} ms   "
          f"{r['ratio_two_stereobm']:.2f}x StereoBM (CPU time {r['ratio_two_stereobm_cpu']:.2f}x)")  # fmt: skip
    print(f"  valid pixels: ours {r['valid_fraction_ours']:.1%}, two StereoBM {r['valid_fraction_two_stereobm']:.1%}")
    if truth is not None:
        for name, backend in (("ours", "numba"), ("two StereoBM", "opencv")):
            res = compute_disparity(left, right, replace(config, backend=backend))
            print(f"  {name:13s} valid pixels off by > 1 px: {res.bad_fraction(truth, 1.0):.2%}, "
                  f"> 2 px: {res.bad_fraction(truth, 2.0):.2%}")  # fmt: skip
    if args.regions:
        print("disparity only in regions of the left image (compute_disparity_regions), thread CPU time:")
        print("  fraction | windows: area    ms  vs dense | bands: area    ms  vs dense | dense ms | StereoBM ms")
        for row in run_regions(left, right, config, repeats=max(10, repeats // 2)):
            print(f"    {row['fraction']:4.2f}   |        {row['area_windows']:5.1%} {row['windows_ms']:6.2f}  "
                  f"{row['ratio_windows']:5.2f}x  |      {row['area_bands']:5.1%} {row['bands_ms']:6.2f}  "
                  f"{row['ratio_bands']:5.2f}x  | {row['dense_ms']:7.2f}  | {row['stereobm_ms']:7.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
