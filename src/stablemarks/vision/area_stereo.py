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
4. sub-pixel refinement by an equiangular (V-shaped) line through the costs at ``d* − 1, d*, d* + 1``;
5. the left-right consistency check of the paper: ``|d_L(u) − d_R(round(u − d_L(u)))| ≤ lr_tolerance``
   with ``d_R`` the right image's winner (and symmetrically for the right image).

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
from numbers import Real

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
_KEY_LIMIT = 2**31  # winner-take-all keys (cost · 2^shift + disparity index) are int32


@dataclass(frozen=True)
class SADConfig:
    """Parameters of :func:`compute_disparity`.

    The defaults reach, on Middlebury 2014 Motorcycle at quarter size with 64 disparities, 62 % valid
    pixels with 3.6 % of them off by more than 1 px and 2.2 % by more than 2 px (the ``opencv`` backend,
    two StereoBM calls with the same check and texture test: 56 % valid, 3.0 % and 1.75 %).

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
    subpixel : refine each disparity by the equiangular line fit through the costs at ``d* − 1, d*,
        d* + 1`` (unbiased for SAD, where a parabola pulls toward integers by up to 0.1 px).
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
            if isinstance(value, bool) or not isinstance(value, Real) or not (np.isfinite(value) and value >= 0):
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
    sobel_left = _xsobel(left8)
    sobel_right = _xsobel(right8)
    tex_left = _textured(sobel_left, config)
    tex_right = _textured(sobel_right, config)
    if config.backend == "opencv":
        return _opencv_disparity(left8, right8, tex_left, tex_right, config)
    return _numba_disparity(
        _prefiltered(left8, sobel_left, config), _prefiltered(right8, sobel_right, config), tex_left, tex_right, config
    )


def _gray8(image, name: str) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2:
        raise ImageError(expected("a 2-D grayscale image (H, W)", img.shape, where=name))
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    if img.dtype.kind != "f":
        raise ImageError(expected("uint8 or float pixels", str(img.dtype), where=name))
    if not np.isfinite(img).all():
        raise ImageError(f"{name}: expected float pixels in [0, 1], got NaN or infinite values")
    if img.size and (img.min() < 0.0 or img.max() > 1.0):
        raise ImageError(f"{name}: expected float pixels in [0, 1], got values in [{img.min():g}, {img.max():g}]")
    return to_gray8(img, name)


def _xsobel(image8: np.ndarray) -> np.ndarray:
    """Unnormalized horizontal Sobel derivative (H, W) int16, borders reflected (StereoBM's)."""
    return cv2.Sobel(image8, cv2.CV_16S, 1, 0, ksize=3, borderType=cv2.BORDER_REFLECT_101)


def _textured(sobel: np.ndarray, config: SADConfig) -> np.ndarray:
    """(H, W) bool: the window's mean ``|Sobel_x| / 8`` (``|Sobel_x|`` saturated at 255) reaches
    ``config.texture_threshold``; ``sobel`` is :func:`_xsobel` of the image."""
    if config.texture_threshold <= 0:
        return np.ones(sobel.shape, dtype=bool)
    b = config.block_size
    depth = cv2.CV_16U if 255 * b * b <= np.iinfo(np.uint16).max else cv2.CV_32S
    sums = cv2.boxFilter(cv2.convertScaleAbs(sobel), depth, (b, b), normalize=False, borderType=cv2.BORDER_CONSTANT)
    return sums >= int(np.ceil(8.0 * config.texture_threshold * b * b))  # integer sums: the same test


def _prefiltered(image8: np.ndarray, sobel: np.ndarray, config: SADConfig) -> np.ndarray:
    """The image SAD runs on, (H, W) int16 with values in ``0 ... config.max_pixel``: the 8-bit image, or its
    x-Sobel derivative ``sobel`` clipped to ``±prefilter_cap`` and shifted by ``prefilter_cap`` (StereoBM's)."""
    if config.prefilter == "none":
        return image8.astype(np.int16)
    cap = config.prefilter_cap
    out = np.clip(sobel, -cap, cap)
    out += np.int16(cap)
    return out


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
def _column_sums(colsum, left, right, y, r, n_cols, n_padded, off):  # pragma: no cover - numba
    """The column sums (W·D, flat) of image row ``y`` (``r <= y < H − r``), updated from row ``y − 1``."""
    if y == r:
        colsum[:] = 0
        for yy in range(np.uint64(2 * r + 1)):
            _accumulate_columns(colsum, left, right, yy, yy, n_cols, n_padded, off, False)
    else:
        _accumulate_columns(colsum, left, right, np.uint64(y + r), np.uint64(y - r - 1), n_cols, n_padded, off, True)


@njit(cache=True)
def _subpixel(c_minus, c0, c_plus):  # pragma: no cover - numba
    """Sub-pixel offset in [−0.5, 0.5] from the integer costs at ``d − 1, d, d + 1`` (``c0`` the smallest).

    Equiangular line fit: the V of slopes ±(max(c_minus, c_plus) − c0) through the three costs. It is exact
    for the V-shaped cost curve of SAD, where a parabola biases the estimate toward integers by up to
    0.1 px (Shimizu and Okutomi, ICCV 2001; measured in ``tests/test_area_stereo.py``).
    """
    rise = max(np.int64(c_minus), np.int64(c_plus)) - np.int64(c0)
    if rise <= 0:
        return 0.0
    return (np.int64(c_minus) - np.int64(c_plus)) / (2.0 * rise)


@njit(cache=True)
def _unique(cost, second, uniqueness, top):  # pragma: no cover - numba
    """StereoBM's uniqueness test: the best cost outside ``d* ± 1`` (``>= top``: none) exceeds the best by more
    than ``uniqueness`` %."""
    return second >= top or np.int64(second) * 100 > np.int64(cost) * (100 + uniqueness)


# A winner-take-all key packs a cost and its disparity index j into one int32, cost · scale + j with
# scale = 2^shift > j, so that one min() finds the best cost and, among equal costs, the smallest
# disparity, whatever the order the candidates come in. ``scale`` is passed in at run time: a
# multiplication by it vectorizes in 32 bits, where a shift by a run-time amount would be done in 64.
#
# The right image's winners are running minima along the diagonals SAD_RL(u, d) = SAD_LR(u + d, d):
# column x offers lane k to right pixel u = x + k - d_max. The uniqueness test needs, for both images,
# the smallest cost outside the winner's j ± 1: a second pass over the row's costs once the winners are
# known (per column for the left image, again along the diagonals for the right one). Splitting the
# passes keeps every loop free of long dependency chains.


@njit(cache=True, boundscheck=False)
def _costs_and_winners(costs, colsum, key_left, key_right, r, off, scale, jvec):  # pragma: no cover - numba
    """Eq 2 costs of one row and their winners, for the columns ``r <= x < W − r``.

    ``costs[x, k]`` (row stride D + 1, flat) are box sums of the column sums ``colsum`` (W·D, flat) along the
    row, ``Σ_{x' = x−r}^{x+r} colsum[x']``, kept running in ``window``; each column's best key over all lanes
    goes to ``key_left[x]``, and each lane's key is offered to the right pixels' running minima
    ``key_right[x + off + k]``.
    """
    n_disp = np.uint64(jvec.shape[0])
    n_cols = np.uint64(colsum.shape[0]) // n_disp
    stride = n_disp + np.uint64(1)
    ur = np.uint64(r)
    window = colsum[:n_disp].copy()
    for xx in range(np.uint64(1), np.uint64(2 * r + 1)):
        for k in range(n_disp):
            window[k] += colsum[xx * n_disp + k]
    for x in range(ur, n_cols - ur):
        if x > ur:
            add = (x + ur) * n_disp
            sub = (x - ur - np.uint64(1)) * n_disp
            for k in range(n_disp):
                window[k] += colsum[add + k] - colsum[sub + k]
        cb = x * stride
        rb = x + off
        best = np.int32(2**31 - 1)
        for k in range(n_disp):
            c = window[k]
            costs[cb + k] = c
            key = np.int32(np.int32(c) * scale + jvec[k])
            best = min(best, key)
            key_right[rb + k] = min(key_right[rb + k], key)
        key_left[x] = best


@njit(cache=True, boundscheck=False)
def _seconds(costs, j_left, j_right, second_left, second_right, x0, x1, off, n_disp, jlane, top):  # pragma: no cover
    """The smallest cost outside the winner's j ± 1 (``top``: none), for the left pixels of columns ``x0 ... x1 − 1``
    (``second_left[x]``, winners ``j_left``) and along the diagonals for the right pixels (``second_right``,
    accumulated as a running minimum, winners ``j_right``, both at ``x + off + k``). Arrays in the cost dtype;
    ``jlane[k]`` is lane k's disparity index; "outside j ± 1" is ``(jlane − j + 1) mod 2^16 > 2``. (Casts keep
    the arithmetic in the cost dtype: 16 lanes per AVX2 operation for uint16 costs.)"""
    stride = n_disp + np.uint64(1)
    for x in range(x0, x1):
        cb = x * stride
        rb = x + off
        jb = j_left[x]
        second = top
        for k in range(n_disp):
            c = costs[cb + k]
            near_left = np.uint16(jlane[k] - jb + 1) <= 2
            second = min(second, max(c, costs.dtype.type(near_left * top)))
            near_right = np.uint16(jlane[k] - j_right[rb + k] + 1) <= 2
            second_right[rb + k] = min(second_right[rb + k], max(c, costs.dtype.type(near_right * top)))
        second_left[x] = second


@njit(cache=True, boundscheck=False)
def _best_in(costs, cb, k0, k1, scale, jvec):  # pragma: no cover - numba
    """Best key among lanes ``k0 ... k1 − 1`` of the column costs at ``cb``."""
    best = np.int32(2**31 - 1)
    for k in range(k0, k1):
        best = min(best, np.int32(np.int32(costs[cb + k]) * scale + jvec[k]))
    return best


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
    key_left = np.empty(n_cols, np.int32)
    key_right = np.empty(right_pad.shape[1], np.int32)  # right pixel u at u + pad_l
    # failed tests turn a disparity into NaN by setting its exponent bits and the quiet-NaN bit (a branch
    # per pixel would be mispredicted about as often as the tests fail)
    left_bits = out_left.view(np.uint32)
    right_bits = out_right.view(np.uint32)
    quiet_nan = np.uint32(0x7FC00000)
    jlane = jvec.astype(costs.dtype)
    j_left = np.empty(n_cols, costs.dtype)
    j_right = np.empty(right_pad.shape[1], costs.dtype)
    second_left = np.empty(n_cols, costs.dtype)
    second_right = np.empty(right_pad.shape[1], costs.dtype)
    # columns where the window fits for every disparity
    lo_left, hi_left = max(r, r + max_disp), min(n_cols - 1 - r, n_cols - 1 - r + min_disp)
    lo_right, hi_right = max(r, r - min_disp), min(n_cols - 1 - r, n_cols - 1 - r - max_disp)
    x0, x1 = u64(r), u64(n_cols - r)
    for y in range(r, n_rows - r):
        _column_sums(colsum, lf, rf, y, r, wu, wp, u64(off))
        key_right[:] = big
        _costs_and_winners(costs, colsum, key_left, key_right, r, u64(off), scale, jvec)
        # partial columns: their winners over the lanes whose right window fits (r <= x + k - d_max < W - r)
        # serve only the right image's consistency check
        for x in range(r, n_cols - r):
            if x < lo_left or x > hi_left:
                k0 = max(0, r - (x - max_disp))
                k1 = min(n_disp, n_cols - r - (x - max_disp))
                key_left[x] = big if k0 >= k1 else _best_in(costs, u64(x) * stride, u64(k0), u64(k1), scale, jvec)
        if track:
            for x in range(n_cols):
                j_left[x] = key_left[x] & mask
            for i in range(right_pad.shape[1]):
                j_right[i] = key_right[i] & mask
            second_right[:] = top
            _seconds(costs, j_left, j_right, second_left, second_right, x0, x1, u64(off), nd, jlane, top)
        # tests: texture, left-right consistency against the other image's winner, uniqueness. On these
        # columns x - d + 0.5 and u + d + 0.5 are >= r > 0, so int() rounds them. (Signed loop variables and
        # int() conversions: unsigned ones convert to and from floats slowly.)
        row = y * n_cols
        for x in range(lo_left, hi_left + 1):
            key = key_left[x]
            j = key & mask
            d = float(min_disp + j)
            if subpixel and 0 < j < n_disp - 1:
                c = u64(x * (n_disp + 1) + n_disp - 1 - j)
                d += _subpixel(costs[c + u64(1)], key >> shift, costs[c - u64(1)])
            other = key_right[int(x - d + 0.5) + pad_l]
            ok = tex_left[row + x] & (other != big) & (abs(d - (min_disp + (other & mask))) <= tol)
            if track:
                ok &= _unique(key >> shift, second_left[x], uniqueness, top)
            out_left[row + x] = d
            left_bits[row + x] |= np.uint32(not ok) * quiet_nan
            out_valid[row + x] = ok
        for u in range(lo_right, hi_right + 1):
            key = key_right[u + pad_l]
            j = key & mask
            x = u + min_disp + j  # the left column of the match
            d = float(min_disp + j)
            if subpixel and 0 < j < n_disp - 1 and r < x < n_cols - 1 - r:
                c = u64(x * (n_disp + 1) + n_disp - 1 - j)
                d += _subpixel(costs[c - stride + u64(1)], key >> shift, costs[c + stride - u64(1)])
            other = key_left[int(u + d + 0.5)]
            ok = tex_right[row + u] & (other != big) & (abs(d - (min_disp + (other & mask))) <= tol)
            if track:
                ok &= _unique(key >> shift, second_right[u + pad_l], uniqueness, top)
            out_right[row + u] = d
            right_bits[row + u] |= np.uint32(not ok) * quiet_nan


def _cost_dtype(config: SADConfig):
    """uint16 when every cost stays below its maximum (the "infinite" cost), int32 otherwise."""
    return np.uint16 if config.max_cost < np.iinfo(np.uint16).max else np.int32


def _padded_right(right: np.ndarray, config: SADConfig) -> tuple[np.ndarray, int]:
    pad_l, pad_r, off = _padding(config)
    return np.pad(right, ((0, 0), (pad_l, pad_r))), off


def _numba_disparity(left, right, tex_left, tex_right, config: SADConfig) -> DisparityResult:
    """Both disparity images from the prefiltered (H, W) int16 images by :func:`_sad_kernel`."""
    n_rows, n_cols = left.shape
    out_left = np.full((n_rows, n_cols), np.nan, np.float32)
    out_right = np.full((n_rows, n_cols), np.nan, np.float32)
    valid = np.zeros((n_rows, n_cols), bool)
    r = config.block_size // 2
    if n_rows > 2 * r and n_cols > 2 * r:
        right_pad, off = _padded_right(right, config)
        dtype = _cost_dtype(config)
        _sad_kernel(
            left, right_pad, tex_left, tex_right, r, config.min_disparity, off, _key_shift(config.num_disparities),
            config.uniqueness_ratio, config.subpixel, float(config.lr_tolerance),
            np.zeros(n_cols * config.num_disparities, dtype), np.zeros(n_cols * (config.num_disparities + 1), dtype),
            out_left, out_right, valid,
        )  # fmt: skip
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
    """(H, W) bool: ``|disp(u) − round(other(round(u + sign·disp(u))))| <= tol``, the other image's disparity
    rounded like the numba kernel's winner (False where either is NaN or outside the image)."""
    n_rows, n_cols = disp.shape
    u = np.arange(n_cols, dtype=np.float64)[None, :]
    with np.errstate(invalid="ignore"):
        match = np.floor(u + sign * disp + 0.5)
        inside = (match >= 0) & (match < n_cols)
    cols = np.where(inside, match, 0).astype(np.intp)
    other_at = np.rint(np.take_along_axis(other, cols, axis=1))
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
    jvec = np.arange(n_disp - 1, -1, -1).astype(np.int32)
    keys = np.empty(right_pad.shape[1], np.int32)  # the winners, not needed here
    for y in range(r, n_rows - r):
        _column_sums(colsum, lf, rf, y, r, np.uint64(n_cols), np.uint64(right_pad.shape[1]), np.uint64(off))
        _costs_and_winners(costs, colsum, keys, keys, r, np.uint64(off), np.int32(1 << 16), jvec)
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
