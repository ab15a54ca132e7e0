"""Speed of vertical segment extraction and segment stereo matching against one ``cv2.StereoBM`` call.

Run: ``python benchmarks/bench_segments.py [--repeats N]``

A synthetic 640×480 rectified pair: a textured, slanted wall (disparity 12 px at the left border
to 44 px at the right one) with 30 painted bars (60 vertical edges). Single-threaded (OpenCV and
BLAS pinned to one thread), JIT warmed, median over the runs; each run times, on the same pair:
segment extraction in BOTH images, segment matching, the disparity filter, and ONE ``StereoBM``
call (15×15, 64 disparities, the paper's SAD window). Goal (issue): extraction for both images
within 0.3× one StereoBM call.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from stablemarks.vision.filter import filter_pairs
from stablemarks.vision.segment_stereo import match_segments
from stablemarks.vision.segments import extract_vertical_segments

SHAPE = (480, 640)
DISPARITY_RANGE = (12.0, 44.0)  # a slanted wall: disparity grows linearly from the left to the right border


def make_pair(seed: int = 0, n_bars: int = 30) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A rectified uint8 pair (H, W) of a textured, slanted wall with ``n_bars`` painted bars, and
    the true ``(u_left, disparity)`` of each bar edge, (2 n_bars, 2).

    The wall's disparity is ``d(u) = d0 + k u`` in the left image, so a right-image column ``u_r``
    sees the left column ``(u_r + d0) / (1 - k)``.
    """
    rng = np.random.default_rng(seed)
    H, W = SHAPE
    d0, d1 = DISPARITY_RANGE
    k = (d1 - d0) / (W - 1)
    field = cv2.GaussianBlur(rng.standard_normal((H, W)), (0, 0), 1.5)
    left = 110.0 + 12.0 * field / field.std()
    map_u = np.broadcast_to(((np.arange(W) + d0) / (1.0 - k)).astype(np.float32), (H, W))
    map_v = np.broadcast_to(np.arange(H, dtype=np.float32)[:, None], (H, W))
    right = cv2.remap(left, map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    u_left = np.linspace(20.0, W - 30.0, n_bars) + rng.uniform(-3.0, 3.0, n_bars)
    u_right_edge = u_left + rng.uniform(4.0, 9.0, n_bars)
    top = rng.integers(20, 200, n_bars)
    bottom = rng.integers(280, H - 20, n_bars)
    value = np.where(rng.random(n_bars) < 0.5, 30.0, 200.0)
    cols = np.arange(W)[None, :]
    for img, scale, shift in ((left, 1.0, 0.0), (right, 1.0 - k, d0)):
        for b in range(n_bars):
            rows = np.arange(top[b], bottom[b] + 1)
            x0, x1 = scale * u_left[b] - shift, scale * u_right_edge[b] - shift
            cover = np.clip(np.minimum(cols + 0.5, x1) - np.maximum(cols - 0.5, x0), 0.0, 1.0)
            img[rows] = img[rows] * (1.0 - cover) + value[b] * cover
    left, right = (np.clip(np.rint(img + rng.normal(0.0, 2.0, img.shape)), 0, 255).astype(np.uint8)
                   for img in (left, right))  # fmt: skip
    edges = np.concatenate([u_left, u_right_edge])
    return left, right, np.stack([edges, d0 + k * edges], axis=1)


def _bm_disparity(bm, left, right) -> tuple[np.ndarray, np.ndarray]:
    raw = bm.compute(left, right)
    valid = raw >= 0
    return np.where(valid, raw / 16.0, np.nan).astype(np.float32), valid


def run(left: np.ndarray, right: np.ndarray, repeats: int = 25) -> dict[str, float]:
    """Median timings over ``repeats`` runs on one rectified uint8 pair, single-threaded.

    Keys: wall-clock ``extract_both_ms``, ``match_ms``, ``filter_ms``, ``stereobm_ms`` [ms]; the
    ratios ``extract_ratio`` (extraction in both images / one StereoBM call) and
    ``extract_match_ratio`` (extraction + matching / StereoBM); ``extract_ratio_cpu``, the same
    ratio in thread CPU time (steadier on a shared machine); and the counts ``n_left``,
    ``n_right``, ``n_pairs``, ``n_kept`` (pairs the filter keeps against the StereoBM disparity).
    """
    cv2.setNumThreads(1)
    bm = cv2.StereoBM_create(numDisparities=64, blockSize=15)
    with threadpool_limits(limits=1):
        sl, sr = extract_vertical_segments(left), extract_vertical_segments(right)  # JIT warm-up
        pairs = match_segments(sl, sr)
        disp, valid = _bm_disparity(bm, left, right)
        kept = filter_pairs(pairs, sl, disp, valid)
        wall = {"extract_both_ms": [], "match_ms": [], "stereobm_ms": [], "filter_ms": []}
        cpu = {"extract_both_ms": [], "stereobm_ms": []}
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.thread_time()
            sl, sr = extract_vertical_segments(left), extract_vertical_segments(right)
            t1, c1 = time.perf_counter(), time.thread_time()
            pairs = match_segments(sl, sr)
            t2, c2 = time.perf_counter(), time.thread_time()
            bm.compute(left, right)
            t3, c3 = time.perf_counter(), time.thread_time()
            kept = filter_pairs(pairs, sl, disp, valid)
            t4 = time.perf_counter()
            for key, dt in zip(wall, (t1 - t0, t2 - t1, t3 - t2, t4 - t3), strict=True):
                wall[key].append(1e3 * dt)
            cpu["extract_both_ms"].append(c1 - c0)
            cpu["stereobm_ms"].append(c3 - c2)
    result = {key: float(np.median(v)) for key, v in wall.items()}
    result["extract_ratio"] = result["extract_both_ms"] / result["stereobm_ms"]
    result["extract_match_ratio"] = (result["extract_both_ms"] + result["match_ms"]) / result["stereobm_ms"]
    result["extract_ratio_cpu"] = float(np.median(cpu["extract_both_ms"]) / np.median(cpu["stereobm_ms"]))
    result.update(n_left=len(sl), n_right=len(sr), n_pairs=len(pairs), n_kept=int(kept.sum()))
    return result


def _accuracy(pairs, truth, tol=0.5) -> tuple[int, int]:
    """(bar edges matched with their disparity within ``tol``, pairs off the wall's disparity by more).

    Pairs on texture edges count as right when their disparity is the wall's."""
    d0, d1 = DISPARITY_RANGE
    wall = d0 + (d1 - d0) / (SHAPE[1] - 1) * pairs.u_left
    good = (np.abs(pairs.u_left[:, None] - truth[None, :, 0]) < tol) & (
        np.abs(pairs.disparity[:, None] - truth[None, :, 1]) < tol
    )
    return int(good.any(axis=0).sum()), int(np.sum(np.abs(pairs.disparity - wall) >= tol))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=25, help="timed runs (median reported), >= 20")
    args = parser.parse_args()
    repeats = max(20, args.repeats)
    left, right, truth = make_pair()
    r = run(left, right, repeats=repeats)
    segments_left = extract_vertical_segments(left)
    pairs = match_segments(segments_left, extract_vertical_segments(right))
    disp, valid = _bm_disparity(cv2.StereoBM_create(numDisparities=64, blockSize=15), left, right)
    kept = pairs.subset(filter_pairs(pairs, segments_left, disp, valid))
    found, off_wall = _accuracy(pairs, truth)
    found_kept, off_wall_kept = _accuracy(kept, truth)
    print(f"640x480 synthetic pair, {len(truth)} vertical edges; single-threaded, median of {repeats} runs")
    print(f"  segments left / right        {r['n_left']:4d} / {r['n_right']:d}")
    print(f"  extraction, both images      {r['extract_both_ms']:7.2f} ms   {r['extract_ratio']:.2f}x StereoBM "
          f"(CPU time: {r['extract_ratio_cpu']:.2f}x; goal <= 0.30x)")  # fmt: skip
    print(f"  matching (DP)                {r['match_ms']:7.2f} ms")
    print(f"  extraction + matching        {r['extract_both_ms'] + r['match_ms']:7.2f} ms   "
          f"{r['extract_match_ratio']:.2f}x StereoBM")  # fmt: skip
    print(f"  filter against StereoBM      {r['filter_ms']:7.2f} ms")
    print(f"  one StereoBM (15x15, 64 d)   {r['stereobm_ms']:7.2f} ms")
    print(f"  pairs: {len(pairs)}; {found}/{len(truth)} bar edges matched with their disparity within 0.5 px; "
          f"{off_wall} pairs off the wall's disparity")  # fmt: skip
    print(f"  kept by the filter: {len(kept)}; {found_kept} bar edges, {off_wall_kept} off the wall "
          f"(StereoBM leaves the {64 + 15 // 2 - 1} leftmost columns invalid)")  # fmt: skip


if __name__ == "__main__":
    main()
