"""Drop segment pairs whose disparity disagrees with the dense disparity image (paper Sec 1, Fig 5 → 6).

"First, we match vertical line segments using the segment-based stereo matching, and then false
matched segments are filtered out by comparing with the disparity image obtained from the
area-based stereo matching."
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import ImageError, InputError, expected
from .segment_stereo import SegmentPairs
from .segments import Segments

__all__ = ["filter_pairs"]


def filter_pairs(
    pairs: SegmentPairs,
    left_segments: Segments,
    disparity_left: np.ndarray,
    valid: np.ndarray,
    tolerance: float = 1.0,
    min_support: float = 0.5,
    *,
    search_radius: int = 2,
) -> np.ndarray:
    """Which segment pairs the area-based disparity image confirms.

    An edge sits at a depth discontinuity as often as not, and the area-based disparity there
    belongs to one side or the other. So for each edge pixel ``(u, v)`` of the pair's left
    segment, the disparities at ``(u - search_radius … u + search_radius, v)`` are looked at and the
    one closest to the pair's disparity is taken; the pixel *supports* the pair if that one is valid
    and within ``tolerance`` of it. The pair is kept if the supporting fraction of the left
    segment's edge pixels is at least ``min_support``.

    Parameters
    ----------
    pairs : M segment pairs (left image is the reference).
    left_segments : the left segments ``pairs.left_index`` refers to.
    disparity_left : (H, W) float, left-reference disparity [px], NaN where invalid.
    valid : (H, W) bool, True where ``disparity_left`` is trusted (e.g. left-right consistent).
    tolerance : maximum ``|d_image - d_pair|`` of a supporting pixel [px], > 0.
    min_support : fraction of the segment's pixels that must support the pair, in [0, 1].
    search_radius : columns looked at on either side of each edge pixel [px], >= 0.

    Returns
    -------
    (M,) bool, True for the pairs to keep.

    Raises
    ------
    ImageError
        If the disparity image or the mask has the wrong shape or type, or a segment pixel lies
        outside it.
    InputError
        If a parameter is out of range or ``pairs`` refers to segments that do not exist.
    """
    disp = np.asarray(disparity_left)
    mask = np.asarray(valid)
    if disp.ndim != 2 or not np.issubdtype(disp.dtype, np.floating):
        raise ImageError(expected("a 2-D float disparity image", f"{disp.dtype} {disp.shape}", where="disparity_left"))
    if mask.shape != disp.shape or mask.dtype != bool:
        raise ImageError(expected(f"a bool mask of shape {disp.shape}", f"{mask.dtype} {mask.shape}", where="valid"))
    if not tolerance > 0:
        raise InputError(expected("a positive number [px]", tolerance, where="tolerance"))
    if not 0 <= min_support <= 1:
        raise InputError(expected("a fraction in [0, 1]", min_support, where="min_support"))
    if isinstance(search_radius, bool) or not isinstance(search_radius, (int, np.integer)) or search_radius < 0:
        raise InputError(expected("a non-negative integer [px]", search_radius, where="search_radius"))
    n = len(pairs)
    if n == 0:
        return np.zeros(0, bool)
    li = pairs.left_index
    if li.min() < 0 or li.max() >= len(left_segments):
        raise InputError(
            expected(f"left indices in [0, {len(left_segments)})", (int(li.min()), int(li.max())),
                     where="pairs.left_index")
        )  # fmt: skip

    H, W = disp.shape
    if disp.dtype not in (np.float32, np.float64):
        disp = disp.astype(np.float64)  # the same values (numba has no float16)
    li = np.ascontiguousarray(li, dtype=np.int64)
    support, counts, outside = _support(np.ascontiguousarray(disp), np.ascontiguousarray(mask),
                                        left_segments.pixel_offsets, left_segments.pixel_uv, li,
                                        np.ascontiguousarray(pairs.disparity, dtype=np.float64), float(tolerance),
                                        int(search_radius))  # fmt: skip
    if outside:
        raise ImageError(expected(f"segment pixels inside the {W}x{H} disparity image", "pixels outside it",
                                  where="left_segments"))  # fmt: skip
    return (support >= min_support) & (counts > 0)


@njit(cache=True)
def _support(disp, mask, offsets, pixel_uv, left_index, d_pair, tolerance, radius):  # pragma: no cover - numba
    """Per pair k: the fraction of its left segment's pixels ``(u, v)`` with a valid, finite disparity within
    ``tolerance`` of ``d_pair[k]`` among columns ``u − radius … u + radius`` of row v (in the image), and its
    pixel count; and whether any of those pixels lies outside the image (then nothing else is meaningful)."""
    H, W = disp.shape
    n = left_index.shape[0]
    support = np.zeros(n)
    counts = np.zeros(n, np.int64)
    for k in range(n):
        seg = left_index[k]
        a, b = offsets[seg], offsets[seg + 1]
        counts[k] = b - a
        hits = 0.0
        for p in range(a, b):
            u = np.int64(pixel_uv[p, 0])
            v = np.int64(pixel_uv[p, 1])
            if u < 0 or u >= W or v < 0 or v >= H:
                return support, counts, True
            for c in range(max(0, u - radius), min(W, u + radius + 1)):
                x = disp[v, c]
                if mask[v, c] and np.isfinite(x) and abs(np.float64(x) - d_pair[k]) <= tolerance:
                    hits += 1.0
                    break
        support[k] = hits / max(b - a, 1)
    return support, counts, False
