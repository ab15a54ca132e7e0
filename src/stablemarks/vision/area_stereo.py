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

:func:`compute_disparity_regions` does the same only where it is asked to (the predicted windows of
the reference planes, bands around candidate segment pairs): for the requested pixels and the
winners their left-right check reads, with results equal to the dense ones bit for bit.

Image convention (DESIGN §3): ``u`` column to the right, ``v`` row down, rectified pair with the left
camera as reference, disparity ``d = u_left − u_right``. Pixels whose window or disparity range
leaves the image are invalid (NaN).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from numbers import Real

import cv2
import numpy as np
from numba import njit

from ..errors import ConfigError, ImageError, InputError, expected
from .gray import to_gray8

__all__ = [
    "DisparityResult",
    "SADConfig",
    "compute_disparity",
    "compute_disparity_regions",
    "PreparedPair",
    "prepare_pair",
    "regions_on_prepared",
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


def compute_disparity(left: np.ndarray, right: np.ndarray, config: SADConfig = SADConfig(), *,
                      sobel: tuple[np.ndarray, np.ndarray] | None = None) -> DisparityResult:
    """Left- and right-reference disparity images of a rectified pair by SAD matching (Eq 2).

    Parameters
    ----------
    left, right : (H, W) grayscale images, ``uint8`` or float in [0, 1] (quantized to 8 bits).
    config : matching parameters; ``config.backend`` selects our numba kernel or OpenCV's StereoBM.

    Returns
    -------
    DisparityResult with NaN wherever a test failed or the window or disparity range does not fit.
    Raises :class:`ImageError` for images that are not 2-D, of different shapes, or of another type.
    ``sobel``: the images' x-Sobel derivatives if already computed (``cv2.Sobel(img, cv2.CV_16S, 1, 0,
    ksize=3)`` of the 8-bit images), else computed here.
    """
    left8, right8 = _pair(left, right)
    sobel_left, sobel_right = (_xsobel(left8), _xsobel(right8)) if sobel is None else sobel
    if config.backend == "opencv":
        return _opencv_disparity(left8, right8, _textured(sobel_left, config), _textured(sobel_right, config), config)
    every = _all_runs(*left8.shape)
    return _run_kernel(left8, right8, sobel_left, sobel_right, config, every, every)


def compute_disparity_regions(
    left: np.ndarray,
    right: np.ndarray,
    config: SADConfig = SADConfig(),
    regions: np.ndarray | None = None,
    right_regions: np.ndarray | None = None,
) -> DisparityResult:
    """:func:`compute_disparity` restricted to the pixels asked for: the same values there, NaN elsewhere.

    SAD in both directions, the left-right check, the uniqueness and texture tests and the sub-pixel
    refinement are computed only for the requested pixels and for what their tests read: a requested
    left pixel ``u`` needs the right image's winners at its candidate matches ``u − d`` (``d`` over the
    disparity range), a requested right pixel ``u`` the left image's winners at ``u + d``. The work is
    proportional to the requested area plus, per run of requested pixels in a row, a band of
    ``num_disparities − 1`` columns for those winners (the right pixels' costs lie along diagonals of
    the cost volume), and a few fixed passes over the image (Sobel, prefilter, run extraction). Measured
    on 640×480 with 64 disparities, as a fraction of the dense time: full-width blocks of rows covering
    10 / 30 / 50 % of the image 0.14 / 0.29 / 0.47; one full-height band of columns 0.35 / 0.49 / 0.64;
    two plane windows of 80 % of the height 0.50 / 0.64 / 0.75; bands of ±20 px around segments 0.53 /
    0.79 / 0.87 (``benchmarks/bench_area_stereo.py --regions``). Runs closer than the disparity range
    are planned as one, and rows whose runs need most of the row (scattered masks) take the dense plan.

    Parameters
    ----------
    left, right : (H, W) grayscale images, as for :func:`compute_disparity`.
    config : matching parameters (the ``"opencv"`` backend computes the whole images and masks them).
    regions : left-image pixels whose left disparity (``.left``, ``.valid``) is wanted, either an (H, W)
        bool mask or rectangles: an (N, 4) integer array-like of ``(row0, row1, col0, col1)`` [px], each the
        half-open block ``[row0, row1) × [col0, col1)`` of rows ``v`` and columns ``u``, clipped to the image
        (rectangles may overlap or be empty). None: every pixel.
    right_regions : right-image pixels whose right disparity (``.right``) is wanted, in the same forms.
        None (the default): none, ``.right`` is all NaN.

    Returns
    -------
    DisparityResult equal to ``compute_disparity(left, right, config)`` at the requested pixels (bit for bit:
    the same costs, winners, tests and refinement), NaN in ``.left`` / ``.right`` and False in ``.valid``
    elsewhere. Raises :class:`ImageError` for bad images and :class:`InputError` for bad regions.
    """
    left8, right8 = _pair(left, right)
    shape = left8.shape
    left_runs = _all_runs(*shape) if regions is None else _region_runs(regions, shape, "regions")
    right_runs = _no_runs(shape[0]) if right_regions is None else _region_runs(right_regions, shape, "right_regions")
    sobel_left = _xsobel(left8)
    sobel_right = _xsobel(right8)
    if config.backend == "opencv":
        res = _opencv_disparity(left8, right8, _textured(sobel_left, config), _textured(sobel_right, config), config)
        valid = res.valid & _runs_mask(*left_runs, shape)
        right_out = np.where(_runs_mask(*right_runs, shape), res.right, np.float32(np.nan))
        return _frozen(np.where(valid, res.left, np.float32(np.nan)), right_out, valid)
    return _run_kernel(left8, right8, sobel_left, sobel_right, config, left_runs, right_runs)


def regions_on_prepared(prepared: PreparedPair, regions, right_regions=None, out=None) -> DisparityResult:
    """:func:`compute_disparity_regions` on a pair prepared once (:func:`prepare_pair`, numba backend): the same
    values at the requested pixels. ``out``: None (fresh frozen outputs, NaN / False elsewhere) or the
    writable (left, right, valid) (H, W) arrays to write the requested pixels into, leaving the others as they
    are."""
    shape = prepared.shape
    if prepared.config.backend != "numba":  # the whole images, masked (prepared holds the 8-bit pair)
        res = compute_disparity_regions(prepared.left, prepared.right_pad, prepared.config, regions, right_regions)
        if out is None:
            return res
        want = [np.ones(shape, bool) if regions is None else
                _runs_mask(*_region_runs(regions, shape, "regions"), shape),
                np.zeros(shape, bool) if right_regions is None else
                _runs_mask(*_region_runs(right_regions, shape, "right_regions"), shape)]
        np.copyto(out[0], res.left, where=want[0])
        np.copyto(out[2], res.valid, where=want[0])
        np.copyto(out[1], res.right, where=want[1])
        return DisparityResult(*out)
    left_runs = _all_runs(*shape) if regions is None else _region_runs(regions, shape, "regions")
    right_runs = _no_runs(shape[0]) if right_regions is None else _region_runs(right_regions, shape, "right_regions")
    return _run_prepared(prepared, left_runs, right_runs, out=out)


def _pair(left, right) -> tuple[np.ndarray, np.ndarray]:
    left8 = _gray8(left, "left")
    right8 = _gray8(right, "right")
    if left8.shape != right8.shape:
        raise ImageError(expected(f"right image of the left's shape {left8.shape}", right8.shape, where="right"))
    return left8, right8


def _region_runs(regions, shape: tuple[int, int], name: str) -> tuple[np.ndarray, np.ndarray]:
    """(ptr, runs) (:func:`_mask_runs`) of ``regions``: an (H, W) bool mask, or (N, 4) rectangles ``(row0, row1,
    col0, col1)``, clipped to the image."""
    arr = np.asarray(regions)
    if arr.dtype == bool:
        if arr.shape != shape:
            raise InputError(expected(f"a bool mask of the images' shape {shape}", arr.shape, where=name))
        return _mask_runs(np.ascontiguousarray(arr))
    if arr.size == 0:
        return _no_runs(shape[0])
    if arr.ndim != 2 or arr.shape[1] != 4 or arr.dtype.kind not in "iu":
        raise InputError(
            expected("an (H, W) bool mask or (N, 4) integer rectangles (row0, row1, col0, col1)",
                     f"{arr.dtype} array of shape {arr.shape}", where=name)
        )  # fmt: skip
    rects = np.clip(arr.astype(np.int64), 0, np.array([shape[0], shape[0], shape[1], shape[1]]))
    rects = rects[(rects[:, 0] < rects[:, 1]) & (rects[:, 2] < rects[:, 3])]
    return _rect_runs(rects[np.argsort(rects[:, 2], kind="stable")], shape[0])


def _no_runs(n_rows: int) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(n_rows + 1, np.int64), np.zeros((0, 2), np.int64)


def _runs_mask(ptr: np.ndarray, runs: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool mask of (ptr, runs)."""
    mask = np.zeros(shape, bool)
    for y in range(shape[0]):
        for a, b in runs[ptr[y] : ptr[y + 1]]:
            mask[y, a:b] = True
    return mask


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
    ``config.texture_threshold``; ``sobel`` is :func:`_xsobel` of the image. (The OpenCV backend's; the numba
    kernel computes the same sums itself, for the pixels it is asked for.)"""
    if config.texture_threshold <= 0:
        return np.ones(sobel.shape, dtype=bool)
    b = config.block_size
    depth = cv2.CV_16U if 255 * b * b <= np.iinfo(np.uint16).max else cv2.CV_32S
    sums = cv2.boxFilter(cv2.convertScaleAbs(sobel), depth, (b, b), normalize=False, borderType=cv2.BORDER_CONSTANT)
    return sums >= int(np.ceil(8.0 * config.texture_threshold * b * b))  # integer sums: the same test


# ---------------------------------------------------------------------------------------------
# numba backend
#
# Costs are kept per image row in "lanes" k = 0 ... D-1 for the disparity index j = D-1-k
# (d = min_disparity + j), so that the right-image pixels a left column x meets, x - d, are
# contiguous and increasing in k. The right image is padded on the left by pad_l columns so the
# right pixel u sits at column u + pad_l; lane k of left column x reads right column x + off + k
# with off = pad_l - min_disparity - (D - 1) >= 0. The row's costs sit at costs[x·S + k], S the
# lane count rounded up to 16 with at least one lane more (held at the dtype's maximum), so that
# every column starts on a 32-byte boundary; its column sums at colsum[x·D + k], in uint8 when a column of
# the window cannot sum beyond 255 (block_size · max_pixel <= 255: 150 with StereoBM's prefilter at cap 5 and
# 15 × 15 windows; modular arithmetic, exact since every true sum fits), else in the cost dtype.
#
# Work is planned per row (_plan_row) from the runs of requested pixels: the right pixels whose
# winners are needed are the requested right pixels and the matches x − d of the requested left
# pixels; the left columns whose winners are needed over every disparity are the requested left
# pixels and the matches u + d of the requested right pixels. Column x offers lane k to right
# pixel x + k − d_max, so a column needs either all lanes or a contiguous range of them. Lane
# ranges are rounded to multiples of _STEP and cut into segments of columns with one lane range:
# within a segment every loop has the same bounds, which keeps the loops tight. The dense image
# is one plan, made once: columns [r, W − r), every lane (lanes whose right window leaves the
# image read the padding; what they produce reaches no pixel that is output).
#
# Per row, in passes over the row:
# 1. the column sums are slid down by one row (or summed afresh over 2r + 1 rows for lanes a
#    column did not have in the row above), and so are the texture test's column sums;
# 2. the costs: box sums along the row kept running from column to column, and each column's best;
# 3. the winners, from the same costs: the left pixel's (the smallest j with the best cost) and the
#    right pixel's as a running minimum along the diagonals SAD_RL(u, d) = SAD_LR(u + d, d);
# 4. for the uniqueness test, both images' smallest cost outside the winner's j ± 1 (the right image's only in
#    the columns whose diagonals reach a requested right pixel);
# 5. the tests and the sub-pixel refinement, on the requested pixels only, in branch-free loops.
# Passes 3 and 4 visit the columns _PHASES apart, so that their read-modify-writes of the right
# pixels' minima never read back a store still in flight (store-to-load forwarding needs equal
# addresses; a load overlapping a pending store at another offset stalls until it completes).
#
# Measured on 640×480 with 64 disparities (single thread, lab frame, `stablemarks bench`, December 2026, numba
# 0.68, 2-core AVX2 machine, StereoBM 14-20 ms there): dense 15.6-17.1 ms, the pipeline's regions 7.1-7.8 ms.
# Before the winners pass was rewritten: dense 46 ms, of it (the row loop cut after each pass) column sums 2.6,
# costs 1.5 and winners 32-35: with the left winner's lane search and the right minima in one loop, numba 0.68
# vectorized neither; split, the search ran in 64-bit lanes (6-9 ms). Now the left winner is an int32 key minimum
# and the right minima have their own loop. Check the hot loops' assembly (``inspect_asm``) after a numba
# upgrade: it changes no output, only the time (tests/test_sad_vectorized.py checks the winners pass).
#
# The hot loops index flat arrays with unsigned integers (no negative-index wraparound, no array
# views per column), compute in the narrowest dtype (uint16 costs: 16 lanes per AVX2 operation)
# and compile with error_model="numpy" (no zero-division branch), so that LLVM vectorizes them.
#
# Tried without gain (issue 13, measured against the kernel above in the same process, outputs identical on
# the scenario frames and Middlebury): the left winner, its neighbours and its second-best cost taken in the
# costs pass while the column is in the cache (0.96-1.00x: the costs pass grew by about what the
# uniqueness pass lost, the winners pass did not shrink; probably the three dependent horizontal reductions
# per column); the left second-best taken in the winners pass after the winner (1.03x); uint8 instead of
# int16 prefiltered images for the column sums (1.00-1.04x; with uint8 column sums on int16 images: 0.975x
# dense, 0.96x with the right second-best costs limited as above in the lab frame's regions); 512-bit
# vectors (numba compiled with -prefer-256-bit: 1.2-1.25x slower); _PHASES 8 or 32 (1.25x / 1.07x slower).
# The right image's passes (running minima along the diagonals) are what is left to gain from; computing
# the right image's costs in their own layout (the same column sums, skewed) would double the column-sum
# and costs passes.
# ---------------------------------------------------------------------------------------------

_STEP = 32  # lane ranges are rounded to multiples of this (two AVX2 registers of uint16 costs)
_PHASES = 16  # the winner and uniqueness passes visit columns this far apart
_NJ = dict(cache=True, boundscheck=False, error_model="numpy")
_u64 = np.uint64


def _padding(config: SADConfig) -> tuple[int, int, int]:
    """(pad_l, pad_r, off) of the padded right image for the lane layout above."""
    pad_l = max(0, config.max_disparity)
    pad_r = max(0, -config.min_disparity)
    return pad_l, pad_r, pad_l - config.max_disparity


@njit(**_NJ)
def _plan_row(lruns, rruns, r, min_disp, n_disp, n_cols, need_lo, need_hi, full, segs, cs_lo, cs_hi, csegs):
    """Plan one row from its runs of requested pixels; returns (number of cost segments, of colsum segments).

    lruns (K, 2), rruns (M, 2): runs [a, b) of requested left / right pixels. Fills need_lo, need_hi (W,):
    each column's lane range (empty: lo >= hi), full (W,): columns whose winners are needed over every
    disparity, segs (n, 4): cost segments (x0, x1, k0, k1) of columns [x0, x1) with lanes [k0, k1), and
    csegs (m, 4): the column-sum segments those need (each segment widened by r columns).
    """
    max_disp = min_disp + n_disp - 1
    n_l = lruns.shape[0]
    need_lo[:] = n_disp
    need_hi[:] = 0
    full[:] = False
    for t in range(n_l + rruns.shape[0]):
        # right pixels [p0, p1) whose winners are needed; column x offers them lanes p0 - x + d_max ...
        if t < n_l:
            p0, p1 = lruns[t, 0] - max_disp, lruns[t, 1] - min_disp
        else:
            p0, p1 = rruns[t - n_l, 0], rruns[t - n_l, 1]
        for x in range(max(r, p0 + min_disp), min(n_cols - r, p1 + max_disp)):
            need_lo[x] = min(need_lo[x], max(0, p0 - x + max_disp))
            need_hi[x] = max(need_hi[x], min(n_disp, p1 - x + max_disp))
    for t in range(n_l + rruns.shape[0]):
        # left columns whose winners are needed over every disparity
        if t < n_l:
            a, b = lruns[t, 0], lruns[t, 1]
        else:
            a, b = rruns[t - n_l, 0] + min_disp, rruns[t - n_l, 1] + max_disp
        for x in range(max(r, a), min(n_cols - r, b)):
            need_lo[x] = 0
            need_hi[x] = n_disp
            full[x] = True
    n_seg = 0
    x = r
    while x < n_cols - r:
        # rounded outward to _STEP. Lanes whose right window leaves the image are kept too (they read the padding):
        # their costs reach only right pixels outside [r, W - r), and the winners of the left columns they belong
        # to are taken again over the lanes that fit (_best_in); fewer, longer segments keep the loops long.
        lo = need_lo[x]
        hi = need_hi[x]
        if lo >= hi:
            need_lo[x] = n_disp
            need_hi[x] = 0
            x += 1
            continue
        lo = lo // _STEP * _STEP
        hi = min(n_disp, (hi + _STEP - 1) // _STEP * _STEP)
        need_lo[x] = lo
        need_hi[x] = hi
        if n_seg > 0 and segs[n_seg - 1, 1] == x and segs[n_seg - 1, 2] == lo and segs[n_seg - 1, 3] == hi:
            segs[n_seg - 1, 1] = x + 1
        else:
            segs[n_seg, 0] = x
            segs[n_seg, 1] = x + 1
            segs[n_seg, 2] = lo
            segs[n_seg, 3] = hi
            n_seg += 1
        x += 1
    cs_lo[:] = n_disp
    cs_hi[:] = 0
    for s in range(n_seg):
        for x in range(segs[s, 0] - r, segs[s, 1] + r):
            cs_lo[x] = min(cs_lo[x], segs[s, 2])
            cs_hi[x] = max(cs_hi[x], segs[s, 3])
    n_cs = 0
    for x in range(n_cols):
        if cs_lo[x] >= cs_hi[x]:
            continue
        if n_cs > 0 and csegs[n_cs - 1, 1] == x and csegs[n_cs - 1, 2] == cs_lo[x] and csegs[n_cs - 1, 3] == cs_hi[x]:
            csegs[n_cs - 1, 1] = x + 1
        else:
            csegs[n_cs, 0] = x
            csegs[n_cs, 1] = x + 1
            csegs[n_cs, 2] = cs_lo[x]
            csegs[n_cs, 3] = cs_hi[x]
            n_cs += 1
    return n_seg, n_cs


@njit(**_NJ)
def _slide_columns(colsum, lf, rf, ladd, lsub, radd, rsub, n_disp, x0, x1, k0, k1):  # pragma: no cover - numba
    """Slide the column sums of columns [x0, x1), lanes [k0, k1) down one row: add the image row at offsets
    ``ladd`` (left, flat) / ``radd`` (padded right, flat), subtract the one at ``lsub`` / ``rsub``."""
    for x in range(x0, x1):
        cb = x * n_disp
        la = lf[ladd + x]
        ls = lf[lsub + x]
        ra = radd + x
        rs = rsub + x
        for k in range(k0, k1):
            colsum[cb + k] += abs(np.int16(la - rf[ra + k])) - abs(np.int16(ls - rf[rs + k]))


@njit(**_NJ)
def _fresh_column(colsum, lf, rf, y, r, n_cols, n_padded, off, n_disp, x, k0, k1):  # pragma: no cover - numba
    """Column sums of column x, lanes [k0, k1), summed afresh over rows y − r ... y + r."""
    cb = _u64(x) * n_disp
    for k in range(k0, k1):
        colsum[cb + k] = 0
    for yy in range(y - r, y + r + 1):
        la = lf[_u64(yy * n_cols + x)]
        ra = _u64(yy * n_padded + x + off)
        for k in range(k0, k1):
            colsum[cb + k] += abs(np.int16(la - rf[ra + k]))


@njit(**_NJ)
def _column_sums(colsum, lf, rf, y, r, n_cols, n_padded, off, n_disp, csegs, n_cs, v_lo, v_hi, same):
    """The column sums of row y for the column-sum segments; ``v_lo, v_hi`` (W,): lanes each column has from
    row y − 1 (updated). ``same``: every column has exactly its segment's lanes from row y − 1."""
    nd = _u64(n_disp)
    if same:
        ladd = _u64((y + r) * n_cols)
        lsub = _u64((y - r - 1) * n_cols)
        radd = _u64((y + r) * n_padded + off)
        rsub = _u64((y - r - 1) * n_padded + off)
        for s in range(n_cs):
            _slide_columns(colsum, lf, rf, ladd, lsub, radd, rsub, nd, _u64(csegs[s, 0]), _u64(csegs[s, 1]),
                           _u64(csegs[s, 2]), _u64(csegs[s, 3]))  # fmt: skip
        return
    x = 0
    for s in range(n_cs + 1):
        end = csegs[s, 0] if s < n_cs else n_cols
        while x < end:  # columns no segment needs: nothing kept
            v_lo[x] = n_disp
            v_hi[x] = 0
            x += 1
        if s == n_cs:
            break
        k0, k1 = csegs[s, 2], csegs[s, 3]
        x = csegs[s, 0]
        while x < csegs[s, 1]:
            if y > r and v_lo[x] == k0 and v_hi[x] == k1:  # a stretch of columns that keep their lanes
                xb = x + 1
                while xb < csegs[s, 1] and v_lo[xb] == k0 and v_hi[xb] == k1:
                    xb += 1
                _slide_columns(colsum, lf, rf, _u64((y + r) * n_cols), _u64((y - r - 1) * n_cols),
                               _u64((y + r) * n_padded + off), _u64((y - r - 1) * n_padded + off), nd,
                               _u64(x), _u64(xb), _u64(k0), _u64(k1))  # fmt: skip
                x = xb
                continue
            a, b = max(k0, v_lo[x]), min(k1, v_hi[x])
            if y > r and a < b:
                _slide_columns(colsum, lf, rf, _u64((y + r) * n_cols), _u64((y - r - 1) * n_cols),
                               _u64((y + r) * n_padded + off), _u64((y - r - 1) * n_padded + off), nd,
                               _u64(x), _u64(x + 1), _u64(a), _u64(b))  # fmt: skip
                if k0 < a:
                    _fresh_column(colsum, lf, rf, y, r, n_cols, n_padded, off, nd, x, _u64(k0), _u64(a))
                if b < k1:
                    _fresh_column(colsum, lf, rf, y, r, n_cols, n_padded, off, nd, x, _u64(b), _u64(k1))
            else:
                _fresh_column(colsum, lf, rf, y, r, n_cols, n_padded, off, nd, x, _u64(k0), _u64(k1))
            v_lo[x] = k0
            v_hi[x] = k1
            x += 1


# Winner-take-all keys pack a cost and its disparity index j into one int32, cost · scale + j with
# scale = 2^shift > j, so that one min() finds the best cost and, among equal costs, the smallest
# disparity. The costs pass only stores the costs; the left winner's key is their minimum, taken in the pass
# over the row's costs that follows (the second-best costs need it).


@njit(**_NJ)
def _running_costs(costs, colsum, window, x0, x1, r, n_disp, stride, k0, k1, advance):
    """Costs of columns [x0, x1), lanes [k0, k1), as box sums along the row kept running in ``window`` (which
    holds column x0 − 1's; with ``advance`` False it holds column x0's and x1 = x0 + 1). All indices unsigned.
    (The running sums live in the small ``window`` rather than in ``costs``, whose columns straddle cache lines:
    reading back a column just stored there would stall on store-to-load forwarding.)"""
    for x in range(x0, x1):
        ab = (x + r) * n_disp
        sb = (x - r - _u64(1)) * n_disp
        cb = x * stride
        if advance:
            for k in range(k0, k1):
                c = window.dtype.type(window[k] + window.dtype.type(colsum[ab + k]) - window.dtype.type(colsum[sb + k]))
                window[k] = c
                costs[cb + k] = c
        else:
            for k in range(k0, k1):
                costs[cb + k] = window[k]


@njit(**_NJ)
def _row_costs(costs, colsum, window, segs, n_seg, r, n_disp, stride):
    """The costs of one row, segment by segment. A segment's first column continues the
    running sums of the lanes it shares with the column before it and sums the others afresh over 2r + 1
    columns."""
    nd = _u64(n_disp)
    ur = _u64(r)
    p1, pk0, pk1 = -1, 0, 0  # the previous segment's end column and lanes
    for s in range(n_seg):
        x0, x1, k0, k1 = segs[s, 0], segs[s, 1], segs[s, 2], segs[s, 3]
        a, b = (max(k0, pk0), min(k1, pk1)) if p1 == x0 else (k0, k0)
        if a >= b:
            a, b = k0, k0
        ab, sb = _u64(x0 + r) * nd, _u64(x0 - r - 1) * nd
        for k in range(_u64(a), _u64(b)):  # lanes that continue: advance to column x0
            window[k] = window.dtype.type(window[k] + window.dtype.type(colsum[ab + k])
                                          - window.dtype.type(colsum[sb + k]))
        for lo, hi in ((k0, a), (b, k1)):  # the others: column x0 from scratch
            for k in range(_u64(lo), _u64(hi)):
                window[k] = 0
            for xx in range(_u64(x0 - r), _u64(x0 + r + 1)):
                for k in range(_u64(lo), _u64(hi)):
                    window[k] = window.dtype.type(window[k] + window.dtype.type(colsum[xx * nd + k]))
        _running_costs(costs, colsum, window, _u64(x0), _u64(x0 + 1), ur, nd, _u64(stride), _u64(k0), _u64(k1), False)
        _running_costs(costs, colsum, window, _u64(x0 + 1), _u64(x1), ur, nd, _u64(stride), _u64(k0), _u64(k1), True)
        p1, pk0, pk1 = x1, k0, k1


@njit(**_NJ)
def _winners(costs, key_left, near_left, best_right, j_right, segs, n_seg, off, n_disp, stride, jlane, jvec, scale):
    """The winners of the row's cost segments (columns [x0, x1), lanes [k0, k1) each). Left: ``key_left[x]``, the
    smallest key ``cost · scale + j`` over the segment's lanes (:func:`_best_in`, ``jvec[k]`` lane k's disparity
    index as int32: the best cost, and among equal costs the smallest j; the border columns' are taken again over
    the lanes that fit, after this pass). Right: the costs are offered
    to the right pixels' running minima along the diagonals, ``best_right[x + off + k]`` (cost) and ``j_right`` (its
    disparity index; among equal costs the smallest). Columns are visited _PHASES apart (see above), so ties
    are broken explicitly. ``jlane[k]``: lane k's disparity index. ``near_left`` (2, W): the left winner's
    neighbouring costs, at j − 1 and j + 1 (for the sub-pixel refinement; read for the columns whose left tests
    run, never for the border columns)."""
    for s in range(n_seg):
        x0, x1, k0, k1 = _u64(segs[s, 0]), _u64(segs[s, 1]), _u64(segs[s, 2]), _u64(segs[s, 3])
        for phase in range(_u64(_PHASES)):
            for x in range(x0 + phase, x1, _u64(_PHASES)):
                cb = x * stride
                rb = x + off
                # the left winner's key as an int32 minimum, which LLVM vectorizes (a search for the last lane
                # holding the column's best cost it kept in 64-bit lanes: 6-9 ms a 640x480 frame); then the right
                # minima in a loop of their own (in one loop with the left reduction, numba 0.68 vectorized
                # neither: 35 ms for this pass)
                key = _best_in(costs, cb, k0, k1, scale, jvec)
                kk = costs.dtype.type(n_disp - _u64(key & (scale - np.int32(1))))  # 1 + the winner's lane
                for k in range(k0, k1):
                    c = costs[cb + k]
                    jj = jlane[k]
                    b = best_right[rb + k]
                    jb = j_right[rb + k]
                    better = (c < b) | ((c == b) & (jj < jb))
                    best_right[rb + k] = min(b, c)
                    j_right[rb + k] = jj if better else jb
                key_left[x] = key
                near_left[0, x] = costs[cb + _u64(kk)]  # lane kb + 1: j - 1 (lane D: the maximum)
                near_left[1, x] = costs[cb + _u64(kk) - _u64(2)]  # lane kb - 1: j + 1


@njit(**_NJ)
def _best_in(costs, cb, k0, k1, scale, jvec):  # pragma: no cover - numba
    """Best key among lanes ``k0 ... k1 − 1`` of the column costs at ``cb``."""
    best = np.int32(2**31 - 1)
    for k in range(k0, k1):
        best = min(best, np.int32(np.int32(costs[cb + k]) * scale + jvec[k]))
    return best


@njit(**_NJ)
def _seconds(costs, key_left, j_right, second_left, second_right, segs, n_seg, off, stride, jlane, mask, top, rneed,
             n_rneed, lneed, n_lneed):  # fmt: skip
    """The smallest cost outside the winner's j ± 1 (``top``: none) over the row's cost segments (columns [x0, x1),
    lanes [k0, k1) each), for the left pixels (``second_left[x]``, winners' keys ``key_left``) and along the
    diagonals for the right pixels (``second_right``, a running minimum, winners ``j_right``, both at
    ``x + off + k``). Each only where a test reads it: the left pixels' in the columns of ``lneed[:n_lneed]`` (the
    requested left pixels whose tests run, :func:`_left_tests`), the right pixels' in those of ``rneed[:n_rneed]``
    (those whose diagonals reach a requested right pixel, :func:`_right_needs`); both sorted disjoint column ranges
    [c0, c1). Arrays in the cost dtype; ``jlane[k]`` is lane k's disparity index; "outside j ± 1" is
    ``(jlane − j + 1) mod 2^16 > 2``."""
    for s in range(n_seg):
        x0, x1, k0, k1 = segs[s, 0], segs[s, 1], segs[s, 2], segs[s, 3]
        pos = x0
        il = 0
        ir = 0
        while pos < x1:
            # the stretch [pos, end) over which it is the same whether a left and whether a right pixel needs it
            while il < n_lneed and lneed[il, 1] <= pos:
                il += 1
            while ir < n_rneed and rneed[ir, 1] <= pos:
                ir += 1
            in_l = il < n_lneed and lneed[il, 0] <= pos
            in_r = ir < n_rneed and rneed[ir, 0] <= pos
            end = x1
            if il < n_lneed:
                end = min(end, lneed[il, 1] if in_l else lneed[il, 0])
            if ir < n_rneed:
                end = min(end, rneed[ir, 1] if in_r else rneed[ir, 0])
            a, b = _u64(pos), _u64(end)
            if in_l and in_r:
                _second_both(costs, key_left, j_right, second_left, second_right, a, b, _u64(k0), _u64(k1), off,
                             stride, jlane, mask, top)  # fmt: skip
            elif in_l:
                _second_left(costs, key_left, second_left, a, b, _u64(k0), _u64(k1), stride, jlane, mask, top)
            elif in_r:
                _second_right(costs, j_right, second_right, a, b, _u64(k0), _u64(k1), off, stride, jlane, top)
            pos = end


@njit(**_NJ)
def _second_left(costs, key_left, second_left, x0, x1, k0, k1, stride, jlane, mask, top):  # pragma: no cover - numba
    """:func:`_seconds` of the left pixels of columns [x0, x1), lanes [k0, k1). (Casts keep the arithmetic in the
    cost dtype: 16 lanes per AVX2 operation for uint16 costs.)"""
    for x in range(x0, x1):
        cb = x * stride
        jb = costs.dtype.type(key_left[x] & mask)
        second = top
        for k in range(k0, k1):
            near_left = np.uint16(jlane[k] - jb + 1) <= 2
            second = min(second, max(costs[cb + k], costs.dtype.type(near_left * top)))
        second_left[x] = second


@njit(**_NJ)
def _second_both(costs, key_left, j_right, second_left, second_right, x0, x1, k0, k1, off, stride, jlane, mask,
                 top):  # fmt: skip
    """:func:`_seconds` of both images over columns [x0, x1), lanes [k0, k1); columns visited _PHASES apart (see
    above)."""
    for phase in range(_u64(_PHASES)):
        for x in range(x0 + phase, x1, _u64(_PHASES)):
            cb = x * stride
            rb = x + off
            jb = costs.dtype.type(key_left[x] & mask)
            second = top
            for k in range(k0, k1):
                c = costs[cb + k]
                near_left = np.uint16(jlane[k] - jb + 1) <= 2
                second = min(second, max(c, costs.dtype.type(near_left * top)))
                near_right = np.uint16(jlane[k] - j_right[rb + k] + 1) <= 2
                second_right[rb + k] = min(second_right[rb + k], max(c, costs.dtype.type(near_right * top)))
            second_left[x] = second


@njit(**_NJ)
def _second_right(costs, j_right, second_right, x0, x1, k0, k1, off, stride, jlane, top):  # pragma: no cover - numba
    """:func:`_seconds` of the right pixels over columns [x0, x1), lanes [k0, k1): :func:`_second_both` without the
    left pixels' part."""
    for phase in range(_u64(_PHASES)):
        for x in range(x0 + phase, x1, _u64(_PHASES)):
            cb = x * stride
            rb = x + off
            for k in range(k0, k1):
                c = costs[cb + k]
                near_right = np.uint16(jlane[k] - j_right[rb + k] + 1) <= 2
                second_right[rb + k] = min(second_right[rb + k], max(c, costs.dtype.type(near_right * top)))


@njit(**_NJ)
def _right_needs(rrun, min_disp, max_disp, out):  # pragma: no cover - numba
    """The left columns whose costs reach the requested right pixels ``rrun`` (M, 2) (runs [a, b), sorted) along
    their diagonals, u + min_disp ... u + max_disp, as sorted disjoint ranges [c0, c1) in ``out``; their count."""
    n = 0
    for t in range(rrun.shape[0]):
        c0, c1 = rrun[t, 0] + min_disp, rrun[t, 1] + max_disp
        if n > 0 and c0 <= out[n - 1, 1]:
            out[n - 1, 1] = max(out[n - 1, 1], c1)
        else:
            out[n, 0] = c0
            out[n, 1] = c1
            n += 1
    return n


@njit(**_NJ)
def _left_tests(key_left, near_left, best_right, j_right, texsum, tex_min, second, out, valid, row, x0, x1, n_disp,
                min_disp, shift, pad_l, uniqueness, subpixel, tol, top, scratch_i, scratch_f):  # fmt: skip
    """Left pixels [x0, x1) of one row (flat offset ``row``): winner, sub-pixel refinement, texture (window sums
    ``texsum`` (W,) at least ``tex_min``; <= 0: no test), left-right and uniqueness tests; writes ``out``
    (float32, NaN where a test fails) and ``valid``. Branch-free passes:
    the gathers (the neighbouring costs, the right winner at the match) apart from the arithmetic."""
    mask = np.int32((1 << shift) - 1)
    other_ = scratch_i[2]
    d_ = scratch_f[0]
    n = _u64(x1 - x0)
    cms, cps = near_left[0], near_left[1]
    for i in range(n):
        x = _u64(x0) + i
        key = key_left[x]
        j = np.int64(key & mask)
        c0 = np.int64(key >> shift)
        cm = np.int64(cms[x])
        cp = np.int64(cps[x])
        rise = max(cm, cp) - c0
        frac = np.float64(cm - cp) / (2.0 * np.float64(max(rise, 1)))
        use = subpixel & (j > 0) & (j < n_disp - 1) & (rise > 0)
        d = np.float64(min_disp + j) + (frac if use else 0.0)
        d_[i] = d
        other_[i] = np.int64(np.float64(np.int64(x)) - d + 0.5) + pad_l  # the right pixel it matches
    for i in range(n):
        m = _u64(other_[i])
        other_[i] = np.int64(j_right[m]) if best_right[m] < top else -(2**40)  # its winner (none: far off)
    uniq = np.int64(uniqueness)
    for i in range(n):
        x = _u64(x0) + i
        c0 = np.int64(key_left[x] >> shift)
        d = d_[i]
        sec = np.int64(second[x])
        ok = ((tex_min <= 0) | (texsum[x] >= tex_min)) & (abs(d - np.float64(min_disp + other_[i])) <= tol)
        ok &= (uniq <= 0) | (sec >= top) | (sec * 100 > c0 * (100 + uniq))
        out[_u64(row) + x] = np.float32(d) if ok else np.float32(np.nan)
        valid[_u64(row) + x] = ok


@njit(**_NJ)
def _right_tests(key_left, best_right, j_right, costs, stride, texsum, tex_min, second, out, row, u0, u1, n_disp,
                 min_disp, shift, pad_l, r, n_cols, uniqueness, subpixel, tol, top, scratch_i, scratch_f):  # fmt: skip
    """Right pixels [u0, u1) of one row, as :func:`_left_tests` with the right image as reference; the costs
    next to the winner lie on its diagonal (left columns x ∓ 1 at j ∓ 1)."""
    mask = np.int32((1 << shift) - 1)
    big = np.int32(2**31 - 1)
    cm_, cp_, other_ = scratch_i[0], scratch_i[1], scratch_i[2]
    d_ = scratch_f[0]
    n = _u64(u1 - u0)
    ub = _u64(u0 + pad_l)
    for i in range(n):
        j = np.int64(j_right[ub + i])
        c = _u64((u0 + np.int64(i) + min_disp + j) * stride + n_disp - 1 - j)
        cm_[i] = costs[c - _u64(stride - 1)]  # column x - 1, j - 1
        cp_[i] = costs[c + _u64(stride - 1)]  # column x + 1, j + 1
    for i in range(n):
        u = u0 + np.int64(i)
        j = np.int64(j_right[ub + i])
        c0 = np.int64(best_right[ub + i])
        x = u + min_disp + j
        cm = np.int64(cm_[i])
        cp = np.int64(cp_[i])
        rise = max(cm, cp) - c0
        frac = np.float64(cm - cp) / (2.0 * np.float64(max(rise, 1)))
        use = subpixel & (j > 0) & (j < n_disp - 1) & (rise > 0) & (x > r) & (x < n_cols - 1 - r)
        d = np.float64(min_disp + j) + (frac if use else 0.0)
        d_[i] = d
        other_[i] = np.int64(np.float64(u) + d + 0.5)  # the left pixel it matches
    for i in range(n):
        other_[i] = key_left[_u64(other_[i])]
    uniq = np.int64(uniqueness)
    for i in range(n):
        c0 = np.int64(best_right[ub + i])
        d = d_[i]
        other = np.int32(other_[i])
        sec = np.int64(second[ub + i])
        ok = ((tex_min <= 0) | (texsum[_u64(u0) + i] >= tex_min)) & (other != big)
        ok &= abs(d - np.float64(min_disp + (other & mask))) <= tol
        ok &= (c0 < top) & ((uniq <= 0) | (sec >= top) | (sec * 100 > c0 * (100 + uniq)))
        out[_u64(row + u0) + i] = np.float32(d) if ok else np.float32(np.nan)


@njit(**_NJ)
def _texture_columns(tsum, asat, y, r, n_cols, slide):  # pragma: no cover - numba
    """Column sums ``tsum`` (W,) of the texture image ``asat`` ((H·W,) flat, ``|Sobel_x|`` saturated at
    255) over rows y − r ... y + r: slid down from row y − 1's when ``slide``, else summed afresh."""
    w = _u64(n_cols)
    if slide:
        add, sub = _u64(y + r) * w, _u64(y - r - 1) * w
        for x in range(w):
            tsum[x] += tsum.dtype.type(asat[add + x]) - tsum.dtype.type(asat[sub + x])
        return
    tsum[:] = 0
    for yy in range(y - r, y + r + 1):
        base = _u64(yy) * w
        for x in range(w):
            tsum[x] += tsum.dtype.type(asat[base + x])


@njit(**_NJ)
def _window_sums(src, a, b, r, levels, out):  # pragma: no cover - numba
    """``out[x] = Σ_{i=−r}^{r} src[x + i]`` for x in [a, b) (r <= a, b + r <= W), by doubling: level l of
    ``levels`` (L, W) holds the sums of 2^(l+1) consecutive values; the window of 2r + 1 is their sum along
    its binary digits. Every pass is one vectorized loop."""
    width = 2 * r + 1
    lo = _u64(a - r)
    n_lev = 0
    w = 1
    while 2 * w <= width:  # level n_lev: sums of 2w values from lo, for x in [lo, b + r - 2w + 1)
        n = _u64(b + r - 2 * w + 1) - lo
        dst = levels[n_lev]
        if n_lev == 0:
            for i in range(n):
                dst[lo + i] = src[lo + i] + src[lo + i + _u64(w)]
        else:
            prev = levels[n_lev - 1]
            for i in range(n):
                dst[lo + i] = prev[lo + i] + prev[lo + i + _u64(w)]
        n_lev += 1
        w *= 2
    n = _u64(b - a)
    out[_u64(a) : _u64(b)] = 0
    off = lo
    for lev in range(n_lev, -1, -1):  # from the widest sums down: 2^lev values each
        if width & (1 << lev):
            part = src if lev == 0 else levels[lev - 1]
            for i in range(n):
                out[_u64(a) + i] += part[off + i]
            off += _u64(1 << lev)


@njit(**_NJ)
def _same_runs(a, b):  # pragma: no cover - numba
    if a.shape[0] != b.shape[0]:
        return False
    for i in range(a.shape[0]):
        if a[i, 0] != b[i, 0] or a[i, 1] != b[i, 1]:
            return False
    return True


@njit(**_NJ)
def _sad_kernel(  # pragma: no cover - numba
    left,
    right_pad,
    asat_left,
    asat_right,
    tex_min,
    tex_probe,
    r,
    min_disp,
    off,
    shift,
    uniqueness,
    subpixel,
    tol,
    lptr,
    lruns,
    rptr,
    rruns,
    plan_l,
    plan_r,
    probe,
    cs_probe,
    out_left,
    out_right,
    out_valid,
    volume,
):
    """Both disparity images from one pass of Eq 2 costs per row, for the requested pixels; see above.

    left (H, W) and right_pad (H, W + pads) int16 prefiltered images; asat_* (H, W) uint8 ``|Sobel_x|`` saturated
    at 255, tex_min the texture test's least window sum (<= 0: no test) and tex_probe an array of the dtype its
    sums are kept in;
    lptr (H + 1,), lruns (K, 2): the runs [a, b) of requested left pixels of row y are lruns[lptr[y]:lptr[y+1]]
    (rptr, rruns: right pixels); plan_l, plan_r: (ptr, runs) of the coarser runs the rows are planned on
    (:func:`_planning_runs`); probe (D,) array of the cost dtype; outputs (H, W) float32 / bool, written at
    the requested pixels of rows r ... H − r − 1 only. ``volume``: (H, W, D) int64 to receive the costs
    (lane order reversed to j), or a (0, 0, 0) array.
    """
    n_rows, n_cols = left.shape
    n_padded = right_pad.shape[1]
    n_disp = probe.shape[0]
    nd = _u64(n_disp)
    lf = left.reshape(left.size)
    rf = right_pad.reshape(right_pad.size)
    asat_left = asat_left.reshape(asat_left.size)
    asat_right = asat_right.reshape(asat_right.size)
    out_left = out_left.reshape(out_left.size)
    out_right = out_right.reshape(out_right.size)
    out_valid = out_valid.reshape(out_valid.size)
    big = np.int32(2**31 - 1)
    top = probe.dtype.type(np.iinfo(probe.dtype).max)
    scale = np.int32(2**shift)
    jvec = np.arange(n_disp - 1, -1, -1).astype(np.int32)
    jlane = jvec.astype(probe.dtype)
    max_disp = min_disp + n_disp - 1
    pad_l = off + max_disp
    track = uniqueness > 0
    colsum = np.zeros(n_cols * n_disp, cs_probe.dtype)
    # a column's costs: lanes 0 ... D - 1, then at least one at the dtype's maximum (the cost of "j = -1" or "D"),
    # to a multiple of 16 lanes so that columns start on 32-byte boundaries (no vector straddles a cache line)
    stride = (n_disp // 16 + 1) * 16
    costs = np.full(n_cols * stride, top, probe.dtype)
    window = np.zeros(n_disp, probe.dtype)
    key_left = np.empty(n_cols, np.int32)
    near_left = np.zeros((2, n_cols), probe.dtype)
    best_right = np.full(n_padded, top, probe.dtype)
    j_right = np.zeros(n_padded, probe.dtype)
    second_left = np.full(n_cols, top, probe.dtype)
    second_right = np.full(n_padded, top, probe.dtype)
    need_lo = np.empty(n_cols, np.int64)
    need_hi = np.empty(n_cols, np.int64)
    cs_lo = np.empty(n_cols, np.int64)
    cs_hi = np.empty(n_cols, np.int64)
    full = np.zeros(n_cols, np.bool_)
    segs = np.zeros((n_cols, 4), np.int64)
    csegs = np.zeros((n_cols, 4), np.int64)
    v_lo = np.full(n_cols, n_disp, np.int64)
    v_hi = np.zeros(n_cols, np.int64)
    tsum_left = np.zeros(n_cols, tex_probe.dtype)  # uint16 when a window's sum fits
    tsum_right = np.zeros(n_cols, tex_probe.dtype)
    texsum_left = np.zeros(n_cols, tex_probe.dtype)
    texsum_right = np.zeros(n_cols, tex_probe.dtype)
    n_levels = 1
    while 2 ** (n_levels + 1) <= 2 * r + 1:
        n_levels += 1
    levels = np.zeros((n_levels, n_cols), tex_probe.dtype)  # for _window_sums
    scratch_i = np.empty((3, n_cols), np.int64)
    rneed = np.empty((n_cols + 1, 2), np.int64)  # for _right_needs
    lneed = np.empty((n_cols + 1, 2), np.int64)  # for _seconds
    scratch_f = np.empty((1, n_cols), np.float64)
    # left columns with every lane's window inside, right pixels likewise
    lo_left, hi_left = max(r, r + max_disp), min(n_cols - 1 - r, n_cols - 1 - r + min_disp)
    lo_right, hi_right = max(r, r - min_disp), min(n_cols - 1 - r, n_cols - 1 - r - max_disp)
    planned = False  # a plan for the runs prev_l, prev_r exists
    dense_plan = False  # it is the dense image's
    every = np.array([[0, n_cols]], np.int64)
    prev_l = plan_l[1][0:0]
    prev_r = plan_r[1][0:0]
    n_seg = n_cs = 0
    last = -1  # the last row processed
    for y in range(r, n_rows - r):
        lrun = lruns[lptr[y] : lptr[y + 1]]
        rrun = rruns[rptr[y] : rptr[y + 1]]
        if lrun.shape[0] + rrun.shape[0] == 0:
            continue
        plrun = plan_l[1][plan_l[0][y] : plan_l[0][y + 1]]
        prrun = plan_r[1][plan_r[0][y] : plan_r[0][y + 1]]
        same = planned and _same_runs(plrun, prev_l) and _same_runs(prrun, prev_r)
        if not same:
            # the row's plan; from three quarters of the dense row's costs on (the lanes of its segments, the runs'
            # needs overlapping counted once), the dense plan, whose loops are the longest and which the next rows
            # keep
            n_seg, n_cs = _plan_row(plrun, prrun, r, min_disp, n_disp, n_cols, need_lo, need_hi, full, segs,
                                    cs_lo, cs_hi, csegs)  # fmt: skip
            work = 0
            for s in range(n_seg):
                work += (segs[s, 1] - segs[s, 0]) * (segs[s, 3] - segs[s, 2])
            if 4 * work >= 3 * (n_cols - 2 * r) * n_disp:
                n_seg, n_cs = _plan_row(every, every, r, min_disp, n_disp, n_cols, need_lo, need_hi, full, segs,
                                        cs_lo, cs_hi, csegs)  # fmt: skip
                same = planned and dense_plan
                dense_plan = True
            else:
                dense_plan = False
            planned = True
            prev_l, prev_r = plrun, prrun
        if last != y - 1:
            v_lo[:] = n_disp
            v_hi[:] = 0
        _column_sums(colsum, lf, rf, y, r, n_cols, n_padded, off, n_disp, csegs, n_cs, v_lo, v_hi,
                     same and last == y - 1)  # fmt: skip
        if tex_min > 0:
            _texture_columns(tsum_left, asat_left, y, r, n_cols, last == y - 1)
            _texture_columns(tsum_right, asat_right, y, r, n_cols, last == y - 1)
        last = y
        _row_costs(costs, colsum, window, segs, n_seg, r, n_disp, stride)
        if volume.shape[0]:
            for x in range(r, n_cols - r):
                for k in range(n_disp):
                    volume[y, x, n_disp - 1 - k] = costs[x * stride + k]
        # the winners of both images and, for the uniqueness test, their second-best costs
        i0, i1 = n_padded, 0
        for s in range(n_seg):
            i0, i1 = min(i0, segs[s, 0] + off + segs[s, 2]), max(i1, segs[s, 1] + off + segs[s, 3] - 1)
        best_right[i0:i1] = top
        second_right[i0:i1] = top
        _winners(costs, key_left, near_left, best_right, j_right, segs, n_seg, _u64(off), nd, _u64(stride), jlane,
                 jvec, scale)  # fmt: skip
        # left columns whose winner is needed but not every lane fits (the lanes whose right window leaves the
        # image read the padding): the key over the lanes that fit, the last ones on the left border, the first ones
        # on the right border (negative disparities only), none (an invalid key) when no lane fits
        for xa, xb in ((r, min(lo_left, n_cols - r)), (max(hi_left + 1, lo_left, r), n_cols - r)):
            for x in range(xa, xb):
                if full[x]:
                    k0, k1 = max(0, r - (x - max_disp)), min(n_disp, n_cols - r - (x - max_disp))
                    if k0 >= k1:
                        key_left[x] = big
                    else:
                        key_left[x] = _best_in(costs, _u64(x * stride), _u64(k0), _u64(k1), scale, jvec)
        if track:
            n_rneed = _right_needs(rrun, min_disp, max_disp, rneed)
            n_lneed = 0  # the requested left pixels whose tests run (below)
            for t in range(lrun.shape[0]):
                a, b = max(lrun[t, 0], lo_left), min(lrun[t, 1], hi_left + 1)
                if a < b:
                    lneed[n_lneed, 0] = a
                    lneed[n_lneed, 1] = b
                    n_lneed += 1
            _seconds(costs, key_left, j_right, second_left, second_right, segs, n_seg, _u64(off), _u64(stride), jlane,
                     scale - 1, top, rneed, n_rneed, lneed, n_lneed)  # fmt: skip
        row = y * n_cols
        for t in range(lrun.shape[0]):
            a, b = max(lrun[t, 0], lo_left), min(lrun[t, 1], hi_left + 1)
            if a < b:
                if tex_min > 0:
                    _window_sums(tsum_left, a, b, r, levels, texsum_left)
                _left_tests(key_left, near_left, best_right, j_right, texsum_left, tex_min, second_left, out_left,
                            out_valid, row, a, b, n_disp, min_disp, shift, pad_l, uniqueness, subpixel, tol, top,
                            scratch_i, scratch_f)  # fmt: skip
        for t in range(rrun.shape[0]):
            a, b = max(rrun[t, 0], lo_right), min(rrun[t, 1], hi_right + 1)
            if a < b:
                if tex_min > 0:
                    _window_sums(tsum_right, a, b, r, levels, texsum_right)
                _right_tests(key_left, best_right, j_right, costs, stride, texsum_right, tex_min, second_right,
                             out_right, row, a, b, n_disp, min_disp, shift, pad_l, r, n_cols, uniqueness, subpixel,
                             tol, top, scratch_i, scratch_f)  # fmt: skip


def _colsum_dtype(config: SADConfig):
    """uint8 when a column of the window (block_size pixels) sums to at most 255, else the cost dtype."""
    return np.uint8 if config.max_pixel * config.block_size <= 255 else _cost_dtype(config)


def _cost_dtype(config: SADConfig):
    """uint16 when every cost stays below its maximum (the "infinite" cost), int32 otherwise."""
    return np.uint16 if config.max_cost < np.iinfo(np.uint16).max else np.int32


@njit(**_NJ)
def _prepare(image8, sobel, cap, pad_l, pad_r, texture):  # pragma: no cover - numba
    """One pass over an image: the (H, pad_l + W + pad_r) int16 image SAD runs on, with zero padding: the 8-bit
    image if ``cap`` <= 0, else its x-Sobel derivative ``sobel`` clipped to ``±cap`` and shifted by ``cap``
    (StereoBM's prefilter, values ``0 ... 2 cap``); and with ``texture`` the (H, W) uint8 ``|sobel|`` saturated at
    255 that the texture test sums (else (1, 1))."""
    n_rows, n_cols = image8.shape
    width = pad_l + n_cols + pad_r
    out = np.empty((n_rows, width), np.int16)  # every element written below (the padding zeroed): no second pass
    asat = np.empty((n_rows, n_cols), np.uint8) if texture else np.zeros((1, 1), np.uint8)
    flat_out = out.reshape(out.size)
    flat_img = image8.reshape(image8.size)
    flat_sob = sobel.reshape(sobel.size)
    flat_sat = asat.reshape(asat.size)
    lo, hi = np.int16(-cap), np.int16(cap)
    w = _u64(n_cols)
    for y in range(_u64(n_rows)):
        src = y * w
        dst = y * _u64(width) + _u64(pad_l)
        for x in range(_u64(pad_l)):
            flat_out[dst - _u64(pad_l) + x] = 0
        for x in range(_u64(pad_r)):
            flat_out[dst + w + x] = 0
        if cap > 0:
            for x in range(w):
                flat_out[dst + x] = min(max(flat_sob[src + x], lo), hi) + hi
        else:
            for x in range(w):
                flat_out[dst + x] = flat_img[src + x]
        if texture:
            for x in range(w):
                flat_sat[src + x] = min(abs(np.int32(flat_sob[src + x])), 255)
    return out, asat


@dataclass(frozen=True, eq=False)
class PreparedPair:
    """A pair as the numba kernel reads it (:func:`prepare_pair`), to be matched in several calls
    (:func:`regions_on_prepared`) without preparing it again.

    ``left`` (H, W) and ``right_pad`` (H, pad_l + W + pad_r) int16: the prefiltered images (the right one
    zero-padded); ``asat_left``, ``asat_right`` (H, W) uint8: ``min(|Sobel_x|, 255)`` of the images, which
    the texture test sums ((1, 1) when there is no texture test); ``shape`` (H, W); ``config`` the
    matching parameters it was prepared for. Empty images when the window does not fit (no pixel is
    ever valid then). With the ``opencv`` backend ``left``, ``right_pad`` are copies of the 8-bit pair.
    """

    left: np.ndarray
    right_pad: np.ndarray
    asat_left: np.ndarray
    asat_right: np.ndarray
    shape: tuple[int, int]
    config: SADConfig


def prepare_pair(left, right, config: SADConfig = SADConfig(), sobel_left=None, sobel_right=None) -> PreparedPair:
    """The pair (as :func:`compute_disparity` takes it) prefiltered once for any number of
    :func:`regions_on_prepared` calls with the same ``config``; ``sobel_left``, ``sobel_right``: the
    images' x-Sobel derivatives (int16, 3×3, borders reflected: ``cv2.Sobel(img, cv2.CV_16S, 1, 0, ksize=3)``)
    if already computed (None: computed here)."""
    left8, right8 = _pair(left, right)
    return _prepared(left8, right8, sobel_left, sobel_right, config)


def _prepared(left8, right8, sobel_left, sobel_right, config: SADConfig) -> PreparedPair:
    n_rows, n_cols = left8.shape
    if config.backend != "numba":  # the 8-bit pair itself, and the texture images (RegionDisparity.possible)
        asat = [np.minimum(np.abs((_xsobel(img) if sob is None else sob).astype(np.int32)), 255).astype(np.uint8)
                for img, sob in ((left8, sobel_left), (right8, sobel_right))]
        return PreparedPair(np.array(left8), np.array(right8), *asat, (n_rows, n_cols), config)
    r = config.block_size // 2
    if not (n_rows > 2 * r and n_cols > 2 * r):
        none = np.zeros((0, 0), np.int16)
        return PreparedPair(none, none, none.astype(np.uint8), none.astype(np.uint8), (n_rows, n_cols), config)
    pad_l, pad_r, _ = _padding(config)
    b = config.block_size
    tex_min = int(np.ceil(8.0 * config.texture_threshold * b * b))
    cap = config.prefilter_cap if config.prefilter == "xsobel" else 0
    need_sobel = cap > 0 or tex_min > 0
    if need_sobel and sobel_left is None:
        sobel_left = _xsobel(left8)
    if need_sobel and sobel_right is None:
        sobel_right = _xsobel(right8)
    if not need_sobel:
        sobel_left = sobel_right = np.zeros((1, 1), np.int16)  # not read
    left, asat_left = _prepare(left8, sobel_left, cap, 0, 0, tex_min > 0)
    right_pad, asat_right = _prepare(right8, sobel_right, cap, pad_l, pad_r, tex_min > 0)
    return PreparedPair(left, right_pad, asat_left, asat_right, (n_rows, n_cols), config)


def _run_kernel(left8, right8, sobel_left, sobel_right, config: SADConfig, left_runs, right_runs, volume=None):
    """:func:`_sad_kernel` on a pair of (H, W) uint8 images and their x-Sobel derivatives; ``*_runs``: (ptr, runs)
    of requested pixels (:func:`_mask_runs`); ``volume``: see :func:`_sad_kernel`. Returns the frozen
    :class:`DisparityResult` (NaN / False outside the requested pixels)."""
    prep = _prepared(left8, right8, sobel_left, sobel_right, config)
    return _run_prepared(prep, left_runs, right_runs, volume)


def _run_prepared(prep: PreparedPair, left_runs, right_runs, volume=None, out=None, plans=None) -> DisparityResult:
    """:func:`_sad_kernel` on a prepared pair. ``out``: None (fresh outputs, frozen on the way out) or the
    (left, right, valid) arrays to write the requested pixels into (left unchanged elsewhere; returned as
    they are). ``plans``: the :func:`_planning_runs` of ``left_runs`` and ``right_runs`` if already made."""
    config = prep.config
    n_rows, n_cols = prep.shape
    if out is None:
        out_left = np.full((n_rows, n_cols), np.nan, np.float32)
        out_right = np.full((n_rows, n_cols), np.nan, np.float32)
        valid = np.zeros((n_rows, n_cols), bool)
    else:
        out_left, out_right, valid = out
    r = config.block_size // 2
    if n_rows > 2 * r and n_cols > 2 * r:
        _, _, off = _padding(config)
        b = config.block_size
        tex_min = int(np.ceil(8.0 * config.texture_threshold * b * b))  # integer window sums: the same test
        left, right_pad, asat_left, asat_right = prep.left, prep.right_pad, prep.asat_left, prep.asat_right
        _sad_kernel(
            left, right_pad, asat_left, asat_right, tex_min,
            np.zeros(0, np.uint16 if 255 * b * b <= np.iinfo(np.uint16).max else np.int32), r, config.min_disparity,
            off,
            _key_shift(config.num_disparities), config.uniqueness_ratio, config.subpixel, float(config.lr_tolerance),
            left_runs[0], left_runs[1], right_runs[0], right_runs[1],
            *(plans if plans is not None else
              [_planning_runs(*runs, config.num_disparities, _STEP, n_cols) for runs in (left_runs, right_runs)]),
            np.zeros(config.num_disparities, _cost_dtype(config)), np.zeros(0, _colsum_dtype(config)),
            out_left, out_right, valid,
            np.zeros((0, 0, 0), np.int64) if volume is None else volume,
        )  # fmt: skip
    if out is not None:
        return DisparityResult(out_left, out_right, valid)
    return _frozen(out_left, out_right, valid)


def _all_runs(n_rows: int, n_cols: int) -> tuple[np.ndarray, np.ndarray]:
    """(ptr, runs) of every pixel: one run [0, W) per row."""
    return np.arange(n_rows + 1, dtype=np.int64), np.tile(np.array([[0, n_cols]], np.int64), (n_rows, 1))


@njit(cache=True)
def _mask_runs(mask):  # pragma: no cover - numba
    """(ptr (H + 1,), runs (N, 2)) of the runs [a, b) of True in each row of the (H, W) bool ``mask``."""
    n_rows, n_cols = mask.shape
    count = 0
    for y in range(n_rows):
        prev = False
        for x in range(n_cols):
            count += mask[y, x] and not prev
            prev = mask[y, x]
    ptr = np.zeros(n_rows + 1, np.int64)
    runs = np.empty((count, 2), np.int64)
    n = 0
    for y in range(n_rows):
        x = 0
        while x < n_cols:
            if mask[y, x]:
                a = x
                while x < n_cols and mask[y, x]:
                    x += 1
                runs[n, 0] = a
                runs[n, 1] = x
                n += 1
            else:
                x += 1
        ptr[y + 1] = n
    return ptr, runs


@njit(cache=True)
def _rect_runs(rects, n_rows):  # pragma: no cover - numba
    """(ptr, runs) of the union of rectangles (N, 4) ``(row0, row1, col0, col1)``, clipped and sorted by col0."""
    ptr = np.zeros(n_rows + 1, np.int64)
    runs = np.empty((n_rows * max(1, rects.shape[0]), 2), np.int64)
    n = 0
    for y in range(n_rows):
        start = n
        for t in range(rects.shape[0]):
            if rects[t, 0] <= y < rects[t, 1]:
                if n > start and rects[t, 2] <= runs[n - 1, 1]:
                    runs[n - 1, 1] = max(runs[n - 1, 1], rects[t, 3])
                else:
                    runs[n, 0] = rects[t, 2]
                    runs[n, 1] = rects[t, 3]
                    n += 1
        ptr[y + 1] = n
    return ptr, runs[:n].copy()


@njit(cache=True)
def _planning_runs(ptr, runs, gap, step, n_cols):  # pragma: no cover - numba
    """The runs of (ptr, runs) widened outward to multiples of ``step`` columns and merged across gaps shorter
    than ``gap``: what a row plans its work on. Neighbouring runs closer than the disparity range need the full
    lane range between them anyway, and coarse runs change less often from row to row, so that the plan (and
    the column sums' lanes) can be kept."""
    n_rows = ptr.shape[0] - 1
    out_ptr = np.zeros(n_rows + 1, np.int64)
    out = np.empty_like(runs)
    n = 0
    for y in range(n_rows):
        for t in range(ptr[y], ptr[y + 1]):
            a = runs[t, 0] // step * step
            b = min(n_cols, (runs[t, 1] + step - 1) // step * step)
            if n > out_ptr[y] and a - out[n - 1, 1] < gap:
                out[n - 1, 1] = max(out[n - 1, 1], b)
            else:
                out[n, 0] = a
                out[n, 1] = b
                n += 1
        out_ptr[y + 1] = n
    return out_ptr, out[:n]


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
        # the kernel's own costs of the dense image, copied out row by row
        every = _all_runs(n_rows, n_cols)
        sobel = np.zeros((1, 1), np.int16)  # not read: no prefilter, no texture test
        _run_kernel(left8, right8, sobel, sobel, replace(config, texture_threshold=0.0), every, every, volume=costs)
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
