"""Area-based stereo matching with the sum of absolute differences (paper Sec 2.2, Eq 2).

"To extract planar surfaces, we use the area-based stereo matching method of which SAD is utilized
as a criterion of matching. [...] With two SAD results calculated from Eq. (2), we obtain a reliable
matched disparity image by comparing disparity values between pixels in one disparity image and
corresponding pixels in the other disparity image."

Eq 2, for a square window ``W`` of ``block_size × block_size`` pixels around the pixel::

    SAD_LR(u, v, d) = Σ_W |I_L(u+i, v+j) − I_R(u+i−d, v+j)|    left pixel u,  match u − d in the right
    SAD_RL(u, v, d) = Σ_W |I_R(u+i, v+j) − I_L(u+i+d, v+j)|    right pixel u, match u + d in the left

The window is symmetric, so ``SAD_RL(u, v, d) == SAD_LR(u + d, v, d)``: one cost per
(pixel, disparity) serves both disparity images. :func:`compute_disparity` computes every cost once
with running (box) sums — O(1) per pixel and disparity, whatever the block size — and takes from
the same costs

1. the left-reference disparity ``d_L(u) = argmin_d SAD_LR(u, d)`` and the right-reference one
   ``d_R(u) = argmin_d SAD_RL(u, d)`` (winner takes all; ties go to the smaller disparity);
2. the uniqueness test (StereoBM's): every cost outside ``d* ± 1`` must exceed the best by more than
   ``uniqueness_ratio`` percent;
3. the texture test: the window's mean ``|∂I/∂u|`` must reach ``texture_threshold`` (flat regions
   match anywhere);
4. sub-pixel refinement by a parabola through the costs at ``d* − 1, d*, d* + 1``;
5. the left-right consistency check of the paper: ``|d_L(u) − d_R(round(u − d_L(u)))| ≤ lr_tolerance``
   (and symmetrically for the right image).

SAD is computed on the images after an optional prefilter. The default is StereoBM's x-Sobel
prefilter, ``clip(Sobel_x(I), −cap, cap) + cap``: with a small cap it makes SAD insensitive to
gain and offset differences between the cameras and to the strong edges of depth discontinuities,
which halves the bad matches on Middlebury's Motorcycle (see ``tests/test_area_stereo.py``).

Image convention (DESIGN §3): ``u`` column to the right, ``v`` row down, rectified pair with the left
camera as reference, disparity ``d = u_left − u_right``. Pixels whose window or disparity range
leaves the image are invalid (NaN).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from ..errors import ConfigError, ImageError, expected
from ..io.images import to_gray8

__all__ = [
    "DisparityResult",
    "SADConfig",
    "compute_disparity",
    "sad_cost_volume",
    "sad_reference",
]

PREFILTERS = ("xsobel", "none")
BACKENDS = ("numba", "opencv")
_KEY_LIMIT = 2**31  # winner-take-all keys (cost << shift | disparity index) are int32


@dataclass(frozen=True)
class SADConfig:
    """Parameters of :func:`compute_disparity`.

    The defaults reach, on Middlebury 2014 Motorcycle at quarter size with 64 disparities, about
    63 % valid pixels with 2 % of them off by more than 2 px (StereoBM with the same 1 px
    left-right check: 71 % valid, 5.5 % off by more than 2 px).

    Attributes
    ----------
    block_size : side of the square SAD window ``W`` of Eq 2 [px], odd, >= 3.
    num_disparities : number of disparities searched, ``min_disparity ... min_disparity +
        num_disparities - 1`` [px].
    min_disparity : smallest disparity searched [px] (may be negative).
    lr_tolerance : left-right consistency tolerance [px]: a left pixel is valid only if the right
        disparity at its match differs from its own by at most this much.
    uniqueness_ratio : margin in percent (StereoBM's ``uniquenessRatio``): a pixel is invalid if any
        cost outside ``d* ± 1`` is at most ``(1 + ratio/100)`` times the best cost; 0 switches the
        test off.
    texture_threshold : minimum mean absolute horizontal intensity gradient in the window
        (``|Sobel_x| / 8`` of the 8-bit input, grey levels per pixel); flatter windows are invalid.
        0 switches the test off.
    prefilter : ``"xsobel"`` (StereoBM's x-Sobel prefilter, clipped to ``±prefilter_cap``) or
        ``"none"`` (SAD on the raw 8-bit intensities).
    prefilter_cap : clipping level of the x-Sobel prefilter, 1 ... 63 (StereoBM's ``preFilterCap``).
    subpixel : refine each disparity by a parabola through the costs at ``d* − 1, d*, d* + 1``.
    backend : ``"numba"`` (our single-pass kernel) or ``"opencv"`` (two ``cv2.StereoBM`` calls, the
        second on the flipped, swapped pair, and the same consistency and texture tests).
    """

    block_size: int = 15
    num_disparities: int = 64
    min_disparity: int = 0
    lr_tolerance: float = 1.0
    uniqueness_ratio: int = 40
    texture_threshold: float = 0.5
    prefilter: str = "xsobel"
    prefilter_cap: int = 5
    subpixel: bool = True
    backend: str = "numba"

    def __post_init__(self) -> None:
        where = "SADConfig"
        _check_int(self.block_size, "block_size", 3)
        if self.block_size % 2 == 0:
            raise ConfigError(expected("an odd block size >= 3", self.block_size, where=f"{where}.block_size"))
        _check_int(self.num_disparities, "num_disparities", 1)
        _check_int(self.min_disparity, "min_disparity", None)
        _check_int(self.uniqueness_ratio, "uniqueness_ratio", 0)
        _check_int(self.prefilter_cap, "prefilter_cap", 1)
        if self.prefilter_cap > 63:
            raise ConfigError(expected("an integer in 1 ... 63", self.prefilter_cap, where=f"{where}.prefilter_cap"))
        for name in ("lr_tolerance", "texture_threshold"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (np.isfinite(value) and value >= 0):
                raise ConfigError(expected("a finite number >= 0", value, where=f"{where}.{name}"))
        if not isinstance(self.subpixel, bool):
            raise ConfigError(expected("True or False", self.subpixel, where=f"{where}.subpixel"))
        if self.prefilter not in PREFILTERS:
            raise ConfigError(expected(f"one of {PREFILTERS}", self.prefilter, where=f"{where}.prefilter"))
        if self.backend not in BACKENDS:
            raise ConfigError(expected(f"one of {BACKENDS}", self.backend, where=f"{where}.backend"))
        if self.max_cost << _key_shift(self.num_disparities) >= _KEY_LIMIT:
            raise ConfigError(
                f"{where}.block_size, num_disparities: expected max intensity × block_size² × "
                f"2^ceil(log2 num_disparities) < 2^31, got block_size={self.block_size}, "
                f"num_disparities={self.num_disparities}"
            )
        if self.backend == "opencv":
            if self.num_disparities % 16:
                raise ConfigError(
                    expected(
                        "a multiple of 16 with backend 'opencv'", self.num_disparities, where=f"{where}.num_disparities"
                    )
                )
            if self.block_size < 5:
                raise ConfigError(
                    expected("block_size >= 5 with backend 'opencv'", self.block_size, where=f"{where}.block_size")
                )
            if self.prefilter != "xsobel":
                raise ConfigError(
                    expected(
                        "'xsobel' with backend 'opencv' (StereoBM always prefilters)",
                        self.prefilter,
                        where=f"{where}.prefilter",
                    )
                )

    @property
    def max_disparity(self) -> int:
        """Largest disparity searched [px]."""
        return self.min_disparity + self.num_disparities - 1

    @property
    def max_pixel(self) -> int:
        """Largest value of the (prefiltered) images SAD runs on."""
        return 2 * self.prefilter_cap if self.prefilter == "xsobel" else 255

    @property
    def max_cost(self) -> int:
        """Largest possible SAD of one window."""
        return self.max_pixel * self.block_size**2


def _check_int(value, name: str, minimum: int | None) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or (minimum is not None and value < minimum):
        what = "an integer" if minimum is None else f"an integer >= {minimum}"
        raise ConfigError(expected(what, value, where=f"SADConfig.{name}"))


def _key_shift(num_disparities: int) -> int:
    """Bits taken by the disparity index in a winner-take-all key."""
    return max(1, int(num_disparities - 1).bit_length())


@dataclass(frozen=True)
class DisparityResult:
    """Disparity images of a rectified pair (Eq 2 and the left-right check of Sec 2.2).

    Attributes
    ----------
    left : (H, W) float32, left-reference disparity [px]: left pixel ``u`` matches right pixel
        ``u − d``; NaN where invalid (equal to ``valid``).
    right : (H, W) float32, right-reference disparity [px]: right pixel ``u`` matches left pixel
        ``u + d``; NaN where invalid (the same tests, with the right image as reference).
    valid : (H, W) bool, left pixels that passed every test, the left-right check included.
    """

    left: np.ndarray
    right: np.ndarray
    valid: np.ndarray

    @property
    def valid_fraction(self) -> float:
        """Fraction of all left pixels that are valid."""
        return float(self.valid.mean()) if self.valid.size else 0.0

    def bad_fraction(self, truth: np.ndarray, threshold: float) -> float:
        """Fraction of valid left pixels with a finite ``truth`` (H, W) [px] that are off by more than ``threshold``.

        Middlebury's ground truth marks unknown pixels with ``+inf``; NaN is treated the same.
        Returns NaN when no valid pixel has a finite truth.
        """
        truth = np.asarray(truth, dtype=np.float64)
        if truth.shape != self.left.shape:
            raise ImageError(expected(f"a ground truth of shape {self.left.shape}", truth.shape, where="truth"))
        scored = self.valid & np.isfinite(truth)
        if not scored.any():
            return float("nan")
        return float(np.mean(np.abs(self.left[scored] - truth[scored]) > threshold))


def compute_disparity(left: np.ndarray, right: np.ndarray, config: SADConfig = SADConfig()) -> DisparityResult:
    """Left- and right-reference disparity images of a rectified pair by SAD matching (Eq 2).

    Parameters
    ----------
    left, right : (H, W) grayscale images, ``uint8`` or float in [0, 1] (quantized to 8 bits).
    config : matching parameters; ``config.backend`` selects our numba kernel or OpenCV's StereoBM.

    Returns
    -------
    DisparityResult with NaN wherever a test failed or the window or disparity range does not fit.
    Raises :class:`ImageError` for images that are not 2-D, of different shapes, or of another type.
    """
    left8 = _gray8(left, "left")
    right8 = _gray8(right, "right")
    if left8.shape != right8.shape:
        raise ImageError(expected(f"right image of the left's shape {left8.shape}", right8.shape, where="right"))
    tex_left = _textured(left8, config)
    tex_right = _textured(right8, config)
    if config.backend == "opencv":
        return _opencv_disparity(left8, right8, tex_left, tex_right, config)
    return _numba_disparity(left8, right8, tex_left, tex_right, config)


def _gray8(image, name: str) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2:
        raise ImageError(expected("a 2-D grayscale image (H, W)", img.shape, where=name))
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    if img.dtype.kind != "f":
        raise ImageError(expected("uint8 or float pixels", str(img.dtype), where=name))
    if img.size and not (np.isfinite(img).all() and img.min() >= 0.0 and img.max() <= 1.0):
        raise ImageError(expected("float pixels in [0, 1]", (float(np.nanmin(img)), float(np.nanmax(img))), where=name))
    return to_gray8(img, name)


def _xsobel(image8: np.ndarray) -> np.ndarray:
    """Unnormalized horizontal Sobel derivative (H, W) int16, borders reflected (StereoBM's)."""
    return cv2.Sobel(image8, cv2.CV_16S, 1, 0, ksize=3, borderType=cv2.BORDER_REFLECT_101)


def _textured(image8: np.ndarray, config: SADConfig) -> np.ndarray:
    """(H, W) bool: the window's mean ``|Sobel_x| / 8`` reaches ``config.texture_threshold``."""
    if config.texture_threshold <= 0:
        return np.ones(image8.shape, dtype=bool)
    grad = np.abs(_xsobel(image8)).astype(np.float32)
    b = config.block_size
    mean = cv2.boxFilter(grad, cv2.CV_32F, (b, b), normalize=True, borderType=cv2.BORDER_CONSTANT)
    return mean >= np.float32(8.0 * config.texture_threshold)


def _prefiltered(image8: np.ndarray, config: SADConfig) -> np.ndarray:
    """The image SAD runs on, (H, W) int16 with values in ``0 ... config.max_pixel``."""
    if config.prefilter == "none":
        return image8.astype(np.int16)
    cap = config.prefilter_cap
    return np.clip(_xsobel(image8), -cap, cap) + np.int16(cap)


# ---------------------------------------------------------------------------------------------
# numba backend
#
# Costs are kept per image row in "lanes" k = 0 ... D-1 for the disparity index j = D-1-k
# (d = min_disparity + j), so that the right-image pixels a left column x meets, x - d, are
# contiguous and increasing in k. The right image is padded on the left by pad_l columns so the
# right pixel u sits at column u + pad_l; lane k of left column x reads right column x + off + k
# with off = pad_l - min_disparity - (D - 1) >= 0.
#
# The hot loops index flat arrays with unsigned integers: numba then neither builds an array view
# per column nor checks for negative indices, and LLVM vectorizes the loops over lanes.
# ---------------------------------------------------------------------------------------------


def _padding(config: SADConfig) -> tuple[int, int, int]:
    """(pad_l, pad_r, off) of the padded right image for the lane layout above."""
    pad_l = max(0, config.max_disparity)
    pad_r = max(0, -config.min_disparity)
    return pad_l, pad_r, pad_l - config.max_disparity


@njit(cache=True, boundscheck=False)
def _accumulate_columns(colsum, left, right, row_add, row_sub, n_cols, n_padded, off, subtract):  # pragma: no cover
    """Slide the column sums (W·D, flat) down one row: ``colsum[x, k] += |L[row_add, x] − R[row_add, x+off+k]|``,
    minus the same for ``row_sub`` when ``subtract``; ``left`` (H·W) and ``right`` (H·W_padded) flat."""
    n_disp = np.uint64(colsum.shape[0]) // n_cols
    for x in range(n_cols):
        cb = x * n_disp
        la = left[row_add * n_cols + x]
        ra = row_add * n_padded + x + off
        if subtract:
            ls = left[row_sub * n_cols + x]
            rs = row_sub * n_padded + x + off
            for k in range(n_disp):
                colsum[cb + k] += abs(np.int16(la - right[ra + k])) - abs(np.int16(ls - right[rs + k]))
        else:
            for k in range(n_disp):
                colsum[cb + k] += abs(np.int16(la - right[ra + k]))


@njit(cache=True, boundscheck=False)
def _row_costs(costs, colsum, left, right, y, r, n_cols, n_padded, off):  # pragma: no cover - numba
    """Eq 2 costs of image row ``y`` (``r <= y < H − r``): ``costs[x, k]`` (row stride D + 1, flat) for
    ``r <= x < W − r``, updating the column sums ``colsum`` (W·D, flat) from row ``y − 1``."""
    n_disp = np.uint64(colsum.shape[0]) // n_cols
    stride = n_disp + np.uint64(1)
    if y == r:
        colsum[:] = 0
        for yy in range(np.uint64(2 * r + 1)):
            _accumulate_columns(colsum, left, right, yy, yy, n_cols, n_padded, off, False)
    else:
        _accumulate_columns(colsum, left, right, np.uint64(y + r), np.uint64(y - r - 1), n_cols, n_padded, off, True)
    # box sums along the row: costs[x] = Σ_{x' = x−r}^{x+r} colsum[x'], running in ``window``
    window = colsum[:n_disp].copy()
    for xx in range(np.uint64(1), np.uint64(2 * r + 1)):
        for k in range(n_disp):
            window[k] += colsum[xx * n_disp + k]
    first = np.uint64(r) * stride
    for k in range(n_disp):
        costs[first + k] = window[k]
    for x in range(np.uint64(r + 1), n_cols - np.uint64(r)):
        cur = x * stride
        add = (x + np.uint64(r)) * n_disp
        sub = (x - np.uint64(r + 1)) * n_disp
        for k in range(n_disp):
            window[k] += colsum[add + k] - colsum[sub + k]
            costs[cur + k] = window[k]


@njit(cache=True)
def _parabola(c_minus, c0, c_plus):  # pragma: no cover - numba
    """Vertex offset of the parabola through the integer costs at ``d − 1, d, d + 1`` (``c0`` the smallest),
    in [−0.5, 0.5]."""
    denom = np.int64(c_minus) + np.int64(c_plus) - 2 * np.int64(c0)
    if denom <= 0:
        return 0.0
    return (np.int64(c_minus) - np.int64(c_plus)) / (2.0 * denom)


@njit(cache=True)
def _unique(cost, second, uniqueness, top):  # pragma: no cover - numba
    """StereoBM's uniqueness test: the best cost outside ``d* ± 1`` (``>= top``: none) exceeds the best by more
    than ``uniqueness`` %."""
    return second >= top or np.int64(second) * 100 > np.int64(cost) * (100 + uniqueness)


# A winner-take-all key packs a cost and its disparity index j into one int32, cost · scale + j with
# scale = 2^shift > j, so that one min() finds the best cost and, among equal costs, the smallest
# disparity. ``scale`` is passed in at run time: a multiplication by it vectorizes in 32 bits, where
# a shift by a run-time amount would be done in 64.
#
# The right image's winners are running minima along the diagonals SAD_RL(u, d) = SAD_LR(u + d, d):
# column x offers lane k to right pixel u = x + k - d_max, whose candidates thus arrive in increasing
# disparity as x increases. For the uniqueness test each right pixel also keeps, streaming,
#   second[u]: the smallest cost outside j* ± 1 of its current best j*,
#   prefix[u]: the smallest cost up to j − 2 of the candidate j it is offered next,
# so that when a new best arrives at j, second becomes prefix, and otherwise the candidate enters
# second if it lies beyond j* + 1. The cost of the previous candidate j − 1 is lane k + 1 of column
# x − 1 (the cost rows have one more lane, always "infinite", for k = D − 1).


@njit(cache=True, boundscheck=False)
def _scan(costs, key_left, key_right, x0, x1, off, n_disp, scale, jvec):  # pragma: no cover - numba
    """Columns ``x0 ... x1 − 1``: offer each column's costs to the right pixels' running minima
    (``key_right[x + off + k]``) and keep its best key (over all lanes) in ``key_left[x]``."""
    stride = n_disp + np.uint64(1)
    for x in range(x0, x1):
        cb = x * stride
        rb = x + off
        best = np.int32(2**31 - 1)
        for k in range(n_disp):
            key = np.int32(np.int32(costs[cb + k]) * scale + jvec[k])
            best = min(best, key)
            key_right[rb + k] = min(key_right[rb + k], key)
        key_left[x] = best


@njit(cache=True, boundscheck=False)
def _scan_tracking_second(
    costs, key_left, key_right, second, prefix, x0, x1, off, n_disp, scale, jvec
):  # pragma: no cover
    """:func:`_scan`, also keeping the right pixels' ``second`` and ``prefix`` costs (see above); the previous
    candidate of lane k is lane k + 1 of the previous column."""
    stride = n_disp + np.uint64(1)
    for x in range(x0, x1):
        cb = x * stride
        pb = cb - n_disp
        rb = x + off
        best = np.int32(2**31 - 1)
        for k in range(n_disp):
            cost = np.int32(costs[cb + k])
            key = np.int32(cost * scale + jvec[k])
            old = key_right[rb + k]
            p = prefix[rb + k]
            beyond = jvec[k] > np.int32((old & (scale - 1)) + 1)
            kept = min(second[rb + k], cost) if beyond else second[rb + k]
            second[rb + k] = p if key < old else kept
            prefix[rb + k] = min(p, np.int32(costs[pb + k]))
            key_right[rb + k] = min(old, key)
            best = min(best, key)
        key_left[x] = best


@njit(cache=True, boundscheck=False)
def _best_in(costs, cb, k0, k1, scale, jvec):  # pragma: no cover - numba
    """Best key among lanes ``k0 ... k1 − 1`` of the column costs at ``cb``."""
    best = np.int32(2**31 - 1)
    for k in range(k0, k1):
        best = min(best, np.int32(np.int32(costs[cb + k]) * scale + jvec[k]))
    return best


@njit(cache=True, boundscheck=False)
def _second_left(costs, cb, kb, n_disp, top):  # pragma: no cover - numba
    """Smallest column cost outside lanes ``kb ± 1``: raise those three, take the minimum, restore them."""
    k_lo = cb + max(kb, np.uint64(1)) - np.uint64(1)
    k_hi = cb + min(kb + np.uint64(1), n_disp - np.uint64(1))
    c_lo, c_mid, c_hi = costs[k_lo], costs[cb + kb], costs[k_hi]
    costs[k_lo] = top
    costs[cb + kb] = top
    costs[k_hi] = top
    second = top
    for k in range(n_disp):
        second = min(second, costs[cb + k])
    costs[k_lo] = c_lo
    costs[cb + kb] = c_mid
    costs[k_hi] = c_hi
    return second


@njit(cache=True, boundscheck=False)
def _sad_kernel(  # pragma: no cover - numba
    left,
    right_pad,
    tex_left,
    tex_right,
    r,
    min_disp,
    off,
    shift,
    uniqueness,
    subpixel,
    tol,
    colsum,
    costs,
    out_left,
    out_right,
    out_valid,
):
    """Both disparity images from one pass of Eq 2 costs; see the lane layout above.

    left (H, W) and right_pad (H, W + pads) int16 prefiltered images; tex_* (H, W) bool texture
    masks; colsum (W·D,) and costs (W·(D + 1),) scratch of the cost dtype; outputs (H, W) float32 /
    bool, set only where valid (the caller fills them with NaN / False).
    """
    u64 = np.uint64
    n_rows, n_cols = left.shape
    tex_left = tex_left.reshape(tex_left.size)
    tex_right = tex_right.reshape(tex_right.size)
    out_left = out_left.reshape(out_left.size)
    out_right = out_right.reshape(out_right.size)
    out_valid = out_valid.reshape(out_valid.size)
    n_disp = colsum.shape[0] // n_cols
    nd = u64(n_disp)
    stride = nd + u64(1)
    wu = u64(n_cols)
    wp = u64(right_pad.shape[1])
    lf = left.reshape(left.size)
    rf = right_pad.reshape(right_pad.size)
    big = np.int32(2**31 - 1)
    top = costs.dtype.type(np.iinfo(costs.dtype).max)
    scale = np.int32(2**shift)
    mask = scale - 1
    jvec = np.arange(n_disp - 1, -1, -1).astype(np.int32)
    max_disp = min_disp + n_disp - 1
    pad_l = off + max_disp
    track = uniqueness > 0
    costs[:] = top  # columns x < r and lane D are never written
    key_right = np.empty(right_pad.shape[1], np.int32)  # right pixel u at u + pad_l
    second_right = np.empty(right_pad.shape[1], np.int32)
    prefix_right = np.empty(right_pad.shape[1], np.int32)
    key_left = np.empty(n_cols, np.int32)
    d_left = np.empty(n_cols, np.float64)  # the row's disparities before the tests
    d_right = np.empty(n_cols, np.float64)
    # columns where the window fits for every disparity
    lo_left, hi_left = max(r, r + max_disp), min(n_cols - 1 - r, n_cols - 1 - r + min_disp)
    lo_right, hi_right = max(r, r - min_disp), min(n_cols - 1 - r, n_cols - 1 - r - max_disp)
    for y in range(r, n_rows - r):
        _row_costs(costs, colsum, lf, rf, y, r, wu, wp, u64(off))
        key_right[:] = big
        second_right[:] = big
        prefix_right[:] = big
        d_left[:] = np.nan
        d_right[:] = np.nan
        if track:
            _scan_tracking_second(
                costs,
                key_left,
                key_right,
                second_right,
                prefix_right,
                u64(r),
                u64(n_cols - r),
                u64(off),
                nd,
                scale,
                jvec,
            )
        else:
            _scan(costs, key_left, key_right, u64(r), u64(n_cols - r), u64(off), nd, scale, jvec)
        # left disparities before the tests; the partial columns serve only the right image's check
        for x in range(r, n_cols - r):
            cb = u64(x) * stride
            key = key_left[x]
            k0, k1 = 0, n_disp
            if x < lo_left or x > hi_left:  # only lanes whose right window fits: r <= x + k - d_max < W - r
                k0 = max(0, r - (x - max_disp))
                k1 = min(n_disp, n_cols - r - (x - max_disp))
                if k0 >= k1:
                    continue
                key = _best_in(costs, cb, u64(k0), u64(k1), scale, jvec)
                key_left[x] = key
            j = key & mask
            offset = 0.0
            kb = u64(n_disp - 1 - j)
            if subpixel and k0 < n_disp - 1 - j < k1 - 1:
                offset = _parabola(costs[cb + kb + u64(1)], key >> shift, costs[cb + kb - u64(1)])
            d_left[x] = min_disp + j + offset
        # right disparities before the tests: SAD_RL(u, d) = SAD_LR(u + d, d)
        for u in range(r, n_cols - r):
            key = key_right[u + pad_l]
            if key == big:
                continue
            j = key & mask
            x = u + min_disp + j  # the left column of the match
            offset = 0.0
            if subpixel and 0 < j < n_disp - 1 and r < x < n_cols - 1 - r:
                kb = u64(n_disp - 1 - j)
                cb = u64(x) * stride
                offset = _parabola(costs[cb - stride + kb + u64(1)], key >> shift, costs[cb + stride + kb - u64(1)])
            d_right[u] = min_disp + j + offset
        # tests: texture, left-right consistency, uniqueness; x - d_left + 0.5 and u + d_right + 0.5 are
        # >= r > 0 on these columns, so int() rounds them
        row = u64(y) * wu
        for x in range(u64(lo_left), u64(hi_left + 1)):
            d = d_left[x]
            u = u64(x - d + 0.5)
            if not (tex_left[row + x] and u < wu and abs(d - d_right[u]) <= tol):
                continue
            if track:
                key = key_left[x]
                kb = u64(n_disp - 1 - (key & mask))
                if not _unique(key >> shift, _second_left(costs, x * stride, kb, nd, top), uniqueness, top):
                    continue
            out_left[row + x] = d
            out_valid[row + x] = True
        for u in range(u64(lo_right), u64(hi_right + 1)):
            d = d_right[u]
            x = u64(u + d + 0.5)
            if not (tex_right[row + u] and x < wu and abs(d - d_left[x]) <= tol):
                continue
            if track and not _unique(key_right[u + u64(pad_l)] >> shift, second_right[u + u64(pad_l)], uniqueness, top):
                continue
            out_right[row + u] = d


def _cost_dtype(config: SADConfig):
    return np.uint16 if config.max_cost <= np.iinfo(np.uint16).max else np.int32


def _padded_right(right: np.ndarray, config: SADConfig) -> tuple[np.ndarray, int]:
    pad_l, pad_r, off = _padding(config)
    return np.pad(right, ((0, 0), (pad_l, pad_r))), off


def _numba_disparity(left8, right8, tex_left, tex_right, config: SADConfig) -> DisparityResult:
    n_rows, n_cols = left8.shape
    out_left = np.full((n_rows, n_cols), np.nan, np.float32)
    out_right = np.full((n_rows, n_cols), np.nan, np.float32)
    valid = np.zeros((n_rows, n_cols), bool)
    r = config.block_size // 2
    if n_rows > 2 * r and n_cols > 2 * r:
        right_pad, off = _padded_right(_prefiltered(right8, config), config)
        dtype = _cost_dtype(config)
        _sad_kernel(
            _prefiltered(left8, config),
            right_pad,
            tex_left,
            tex_right,
            r,
            config.min_disparity,
            off,
            _key_shift(config.num_disparities),
            config.uniqueness_ratio,
            config.subpixel,
            float(config.lr_tolerance),
            np.zeros(n_cols * config.num_disparities, dtype),
            np.zeros(n_cols * (config.num_disparities + 1), dtype),
            out_left,
            out_right,
            valid,
        )
    return _frozen(out_left, out_right, valid)


def _frozen(left, right, valid) -> DisparityResult:
    for a in (left, right, valid):
        a.setflags(write=False)
    return DisparityResult(left=left, right=right, valid=valid)


# ---------------------------------------------------------------------------------------------
# OpenCV backend
# ---------------------------------------------------------------------------------------------


def _opencv_disparity(left8, right8, tex_left, tex_right, config: SADConfig) -> DisparityResult:
    bm = cv2.StereoBM_create(numDisparities=config.num_disparities, blockSize=config.block_size)
    bm.setMinDisparity(config.min_disparity)
    bm.setPreFilterType(cv2.STEREO_BM_PREFILTER_XSOBEL)
    bm.setPreFilterCap(config.prefilter_cap)
    bm.setTextureThreshold(0)  # ours is applied below, the same for both backends
    bm.setUniquenessRatio(config.uniqueness_ratio)
    bm.setSpeckleWindowSize(0)
    bm.setDisp12MaxDiff(-1)
    raw_left = _from_fixed_point(bm.compute(left8, right8), config)
    flipped = bm.compute(np.ascontiguousarray(right8[:, ::-1]), np.ascontiguousarray(left8[:, ::-1]))
    raw_right = _from_fixed_point(flipped[:, ::-1], config)
    n_rows, n_cols = left8.shape
    r = config.block_size // 2
    inside = np.zeros((n_rows, n_cols), bool)
    inside[r : n_rows - r, max(r, r + config.max_disparity) : n_cols - r + min(0, config.min_disparity)] = True
    valid = inside & tex_left & _consistent(raw_left, raw_right, -1.0, config.lr_tolerance)
    inside_r = np.zeros((n_rows, n_cols), bool)
    inside_r[r : n_rows - r, max(r, r - config.min_disparity) : n_cols - r - max(0, config.max_disparity)] = True
    valid_r = inside_r & tex_right & _consistent(raw_right, raw_left, 1.0, config.lr_tolerance)
    return _frozen(
        np.where(valid, raw_left, np.nan).astype(np.float32),
        np.where(valid_r, raw_right, np.nan).astype(np.float32),
        valid,
    )


def _from_fixed_point(disp16: np.ndarray, config: SADConfig) -> np.ndarray:
    """StereoBM's int16 output (16 × disparity; ``(min_disparity − 1) · 16`` invalid) → float32, NaN invalid."""
    disp = disp16.astype(np.float32) / np.float32(16.0)
    if not config.subpixel:
        disp = np.rint(disp)
    disp[disp16 < config.min_disparity * 16] = np.nan
    return disp


def _consistent(disp: np.ndarray, other: np.ndarray, sign: float, tol: float) -> np.ndarray:
    """(H, W) bool: ``|disp(u) − other(round(u + sign·disp(u)))| <= tol`` (False where either is NaN or outside)."""
    n_rows, n_cols = disp.shape
    u = np.arange(n_cols, dtype=np.float64)[None, :]
    with np.errstate(invalid="ignore"):
        match = np.floor(u + sign * disp + 0.5)
        inside = (match >= 0) & (match < n_cols)
    cols = np.where(inside, match, 0).astype(np.intp)
    other_at = np.take_along_axis(other, cols, axis=1)
    with np.errstate(invalid="ignore"):
        return inside & (np.abs(disp - other_at) <= tol)


# ---------------------------------------------------------------------------------------------
# Cost volumes: the exact NumPy oracle and the kernel's own costs
# ---------------------------------------------------------------------------------------------


def sad_reference(
    left: np.ndarray, right: np.ndarray, block_size: int, num_disparities: int, min_disparity: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Eq 2 by brute force (a test oracle): the cost volumes ``(SAD_LR, SAD_RL)``.

    Parameters
    ----------
    left, right : (H, W) images (any real dtype; differences are taken in float64).
    block_size : odd window side [px]; num_disparities, min_disparity : disparities
        ``d = min_disparity + j`` for ``j = 0 ... num_disparities − 1``.

    Returns
    -------
    sad_lr, sad_rl : (H, W, num_disparities) float64; ``sad_lr[v, u, j]`` is the SAD between the left
        window at ``u`` and the right window at ``u − d``, ``sad_rl[v, u, j]`` between the right window at
        ``u`` and the left window at ``u + d``; ``inf`` where a window leaves the image.
    """
    L = np.asarray(left, dtype=np.float64)
    R = np.asarray(right, dtype=np.float64)
    n_rows, n_cols = L.shape
    r = block_size // 2
    shape = (n_rows, n_cols, num_disparities)
    sad_lr = np.full(shape, np.inf)
    sad_rl = np.full(shape, np.inf)
    rows = slice(r, n_rows - r)
    for j in range(num_disparities):
        d = min_disparity + j
        for out, a, b, sign in ((sad_lr, L, R, -1), (sad_rl, R, L, 1)):
            # a window at u against b's window at u + sign·d, for every u where both fit
            for u in range(r, n_cols - r):
                m = u + sign * d
                if r <= m < n_cols - r:
                    diff = np.abs(a[:, u - r : u + r + 1] - b[:, m - r : m + r + 1])
                    win = np.lib.stride_tricks.sliding_window_view(diff, block_size, axis=0)
                    out[rows, u, j] = win.sum(axis=(1, 2))
    return sad_lr, sad_rl


@njit(cache=True, boundscheck=False)
def _cost_volume_kernel(left, right_pad, r, off, colsum, costs, volume):  # pragma: no cover - numba
    n_rows, n_cols = left.shape
    n_disp = volume.shape[2]
    lf = left.reshape(left.size)
    rf = right_pad.reshape(right_pad.size)
    for y in range(r, n_rows - r):
        _row_costs(costs, colsum, lf, rf, y, r, np.uint64(n_cols), np.uint64(right_pad.shape[1]), np.uint64(off))
        for x in range(r, n_cols - r):
            for k in range(n_disp):
                volume[y, x, n_disp - 1 - k] = costs[x * (n_disp + 1) + k]


def sad_cost_volume(
    left: np.ndarray, right: np.ndarray, block_size: int, num_disparities: int, min_disparity: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The numba kernel's Eq 2 costs on raw 8-bit images, in :func:`sad_reference`'s layout and units.

    For testing and inspection: :func:`compute_disparity` never stores the volume. ``left, right`` are
    (H, W) ``uint8`` or float in [0, 1]; returns ``(sad_lr, sad_rl)``, (H, W, num_disparities) float64,
    ``inf`` where a window leaves the image.
    """
    config = SADConfig(
        block_size=block_size, num_disparities=num_disparities, min_disparity=min_disparity, prefilter="none"
    )
    left8 = _gray8(left, "left")
    right8 = _gray8(right, "right")
    if left8.shape != right8.shape:
        raise ImageError(expected(f"right image of the left's shape {left8.shape}", right8.shape, where="right"))
    n_rows, n_cols = left8.shape
    r = block_size // 2
    costs = np.full((n_rows, n_cols, num_disparities), -1, np.int64)
    if n_rows > 2 * r and n_cols > 2 * r:
        right_pad, off = _padded_right(right8.astype(np.int16), config)
        dtype = _cost_dtype(config)
        _cost_volume_kernel(
            left8.astype(np.int16),
            right_pad,
            r,
            off,
            np.zeros(n_cols * num_disparities, dtype),
            np.zeros(n_cols * (num_disparities + 1), dtype),
            costs,
        )
    sad_lr = costs.astype(np.float64)
    u = np.arange(n_cols)[None, :, None]
    d = min_disparity + np.arange(num_disparities)[None, None, :]
    sad_lr[(costs < 0) | (u - d < r) | (u - d > n_cols - 1 - r)] = np.inf
    # SAD_RL(u, d) = SAD_LR(u + d, d)
    sad_rl = np.full_like(sad_lr, np.inf)
    for j in range(num_disparities):
        dj = min_disparity + j
        lo, hi = max(0, -dj), min(n_cols, n_cols - dj)
        if lo < hi:
            sad_rl[:, lo:hi, j] = sad_lr[:, lo + dj : hi + dj, j]
    return sad_lr, sad_rl
