"""Drop segment pairs whose disparity disagrees with the dense disparity image (paper Sec 1, Fig 5 → 6).

"First, we match vertical line segments using the segment-based stereo matching, and then false
matched segments are filtered out by comparing with the disparity image obtained from the
area-based stereo matching."
"""

from __future__ import annotations

import numpy as np

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

    own = left_segments.subset(li)  # segment k is pair k's left segment
    pix, counts = own.pixel_uv, np.diff(own.pixel_offsets)
    H, W = disp.shape
    u, v = pix[:, 0].astype(np.int64), pix[:, 1].astype(np.int64)
    if pix.size and (u.min() < 0 or u.max() >= W or v.min() < 0 or v.max() >= H):
        raise ImageError(expected(f"segment pixels inside the {W}x{H} disparity image", "pixels outside it",
                                  where="left_segments"))  # fmt: skip
    cols = u[:, None] + np.arange(-search_radius, search_radius + 1)[None, :]  # (P, 2r + 1)
    inside = (cols >= 0) & (cols < W)
    flat = v[:, None] * W + np.clip(cols, 0, W - 1)
    window = np.take(disp.reshape(-1), flat)
    usable = inside & np.take(mask.reshape(-1), flat) & np.isfinite(window)
    d_pair = np.repeat(pairs.disparity, counts)[:, None]
    supports = np.any(usable & (np.abs(np.where(usable, window, 0.0) - d_pair) <= tolerance), axis=1)
    owner = np.repeat(np.arange(n), counts)
    support = np.bincount(owner, weights=supports, minlength=n) / np.maximum(counts, 1)
    return (support >= min_support) & (counts > 0)
