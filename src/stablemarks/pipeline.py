"""One stereo frame through the whole method (DESIGN.md §1): front end, planes, landmarks.

:func:`run_front_end` — vertical segments in both images, segment stereo matching by dynamic
programming (Sec 2.1), SAD disparity in both directions with the left-right check (Sec 2.2), and the
filter that drops pairs the disparity image contradicts (Fig 5 → Fig 6).

:func:`select_landmarks` — for every reference plane in view of the belief: prediction (Eqs 3–10),
fit (Eq 11), members (Sec 2.4), boundary (Sec 3.2), relative model (Eqs 12–17) and selection (Sec 4).

Both return plain dataclasses with per-stage timings [s]; nothing here prints or plots.

Disparity only where the method reads it. :func:`plane_regions`, from the pose prior before the frame is
processed, names the predicted windows of the reference planes in view (what the plane fit reads) and the
right-image windows where their free edges are searched; ``run_front_end(left, right, config, regions)``
computes SAD there and in bands around the segment pairs (what the disparity filter reads), with
:func:`~stablemarks.vision.area_stereo.compute_disparity_regions`: at every pixel computed, the dense value
bit for bit. :func:`select_landmarks` computes whatever its planes read that is still missing (another prior,
the localizer's widened search) and what it takes for :func:`valid_columns` to decide the edges' search
windows as with the dense images (:meth:`RegionDisparity.decide_columns`). So the kept pairs, candidates,
selection and poses are those of the dense computation, whatever regions were asked for
(``tests/test_regions_pipeline.py``). Only the disparity images differ: NaN where nothing read them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numba import njit

from .config import Config
from .errors import ImageError, expected
from .geometry import StereoCamera
from .landmarks import Candidate, PlaneLandmarks, boundaries_apart, landmarks_on_plane, off_wall_by_lines
from .maps import Map
from .planes import FailedFit, PlaneFit, PlanePrediction, fit_plane, predict_planes
from .vision.area_stereo import (
    _STEP,
    DisparityResult,
    SADConfig,
    _planning_runs,
    _region_runs,
    _run_prepared,
    _xsobel,
    compute_disparity,
    prepare_pair,
    regions_on_prepared,
)
from .vision.filter import filter_pairs
from .vision.segment_stereo import SegmentPairs, match_segments
from .vision.segments import Segments, extract_vertical_segments


# ------------------------------------------------------------------ where the disparity is read
@dataclass(frozen=True, eq=False)
class Regions:
    """Where a frame's disparity is wanted, besides the segment pairs' bands :func:`run_front_end` adds itself.

    ``left`` (N, 4) and ``right`` (M, 4) int64 rectangles ``(row0, row1, col0, col1)``: the half-open blocks
    ``[row0, row1) × [col0, col1)`` of the left image whose left-reference disparity is wanted and of the right
    image whose right-reference disparity is wanted (clipped to the image). ``predictions``: the plane
    predictions they were made from and ``key`` what those were predicted from (:func:`plane_regions`), for
    :func:`select_landmarks` to take them instead of predicting again from the same prior; ``shape`` the images'
    (H, W) the rectangles were made for (:func:`prediction_regions`) and ``windows`` the predictions'
    :func:`edge_windows`, which it then takes too.
    """

    left: np.ndarray
    right: np.ndarray
    predictions: list[PlanePrediction] | None = None
    key: tuple | None = field(default=None, repr=False)
    shape: tuple[int, int] | None = field(default=None, repr=False)
    windows: list | None = field(default=None, repr=False)

    @classmethod
    def none(cls) -> Regions:
        """No plane: only the segment pairs' bands (a method that models no plane)."""
        return cls(np.zeros((0, 4), np.int64), np.zeros((0, 4), np.int64))


def disparity_limits(sad: SADConfig, width: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """First and last column of the left and of the right image where a disparity can be valid at all.

    A left pixel needs its window and every candidate match ``u − d`` (``d`` over the disparity range) inside
    the image, a right pixel every ``u + d``: the numba kernel tests no other column (its ``lo_left ...
    hi_right``), so the disparity images are NaN outside these columns whatever the images hold. (The
    geometry, not :func:`valid_columns`: a border column may hold no valid pixel.)
    """
    r = sad.block_size // 2
    last = width - 1 - r
    left = (max(r, r + sad.max_disparity), min(last, last + sad.min_disparity))
    right = (max(r, r - sad.min_disparity), min(last, last - sad.max_disparity))
    return left, right


def edge_windows(predictions: list[PlanePrediction], config: Config = Config()
                 ) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The search windows (left image, right image) of every free edge in front of the camera: the windows
    :func:`landmarks_on_plane` tests against :func:`valid_columns`."""
    sigma = config.landmarks.search_sigma
    return [(e.window(0, sigma), e.window(1, sigma)) for pred in predictions for e in pred.edges.values()
            if e.free and np.isfinite(e.u).all()]


def prediction_regions(predictions: list[PlanePrediction], shape: tuple[int, int], config: Config = Config()
                       ) -> Regions:
    """The disparity :func:`select_landmarks` reads for these plane predictions, in images of ``shape`` (H, W).

    Left image: each prediction's band box (:meth:`PlanePrediction.band_box` with ``planes.row_margin_px``):
    :func:`~stablemarks.planes.fit_plane` reads nothing else, and the left boundary search reads the fit's
    region, which lies inside it. Right image: for every free edge :func:`landmarks_on_plane` may search (in
    front of the camera, both search windows inside :func:`disparity_limits` by more than a pixel: else the
    test against :func:`valid_columns` fails whatever the images), the block
    :func:`~stablemarks.landmarks.right_region` reads — the edge's right-image search window widened by one
    column either side, over the rows the plane reaches.
    """
    H, W = shape
    rm = config.planes.row_margin_px
    lim = disparity_limits(config.sad, W)
    left, right = [], []
    for pred in predictions:
        rows, cols = pred.box(H, rm)
        if rows.stop > rows.start:
            left.append((rows.start, rows.stop, cols.start, cols.stop))
        top, bottom = pred.rows_reached
        r0 = max(0, math.floor(top - rm))
        r1 = min(H - 1, math.ceil(bottom + rm))
        for windows in edge_windows([pred], config):
            if not all(lo + 1 < w[0] and w[1] < hi - 1 for w, (lo, hi) in zip(windows, lim, strict=True)):
                continue
            c0 = max(0, math.floor(windows[1][0]) - 1)
            c1 = min(W - 1, math.ceil(windows[1][1]) + 1)
            if r1 >= r0 and c1 >= c0:
                right.append((r0, r1 + 1, c0, c1 + 1))
    return Regions(np.array(left, np.int64).reshape(-1, 4), np.array(right, np.int64).reshape(-1, 4), predictions)


def _prediction_key(camera: StereoCamera, X: np.ndarray, cov_X: np.ndarray, world_map: Map, config: Config) -> tuple:
    """What :func:`~stablemarks.planes.predict_planes` depends on."""
    return camera, X.shape, X.tobytes(), cov_X.shape, cov_X.tobytes(), world_map, config


def _same_key(a: tuple, b: tuple) -> bool:
    def same(x, y) -> bool:
        try:
            return x is y or (type(x) is type(y) and bool(x == y))
        except (TypeError, ValueError):
            return False

    return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))


def plane_regions(camera: StereoCamera, X, cov_X, world_map: Map, config: Config = Config(),
                  shape: tuple[int, int] | None = None) -> Regions:
    """The disparity regions of the reference planes in view of the pose prior ``X`` (3,), ``cov_X`` (3, 3):
    :func:`prediction_regions` of :func:`~stablemarks.planes.predict_planes`, for ``run_front_end(...,
    regions=...)`` ahead of :func:`select_landmarks` with the same camera and prior (which then takes these
    predictions). ``shape`` (H, W): the images' size (default the camera's)."""
    camera = config.camera(camera)
    X = np.asarray(X, dtype=float)
    cov_X = np.asarray(cov_X, dtype=float)
    preds = predict_planes(camera, X, cov_X, world_map, config.planes)
    shape = tuple(shape or (camera.height, camera.width))
    out = prediction_regions(preds, shape, config)
    return Regions(out.left, out.right, preds, _prediction_key(camera, X, cov_X, world_map, config), shape,
                   edge_windows(preds, config))


def pair_bands(pairs: SegmentPairs, left_segments: Segments, search_radius: int) -> np.ndarray:
    """(N, 4) rectangles ``(row0, row1, col0, col1)`` covering what :func:`~stablemarks.vision.filter.filter_pairs`
    reads of the left disparity image and its mask: each edge pixel ``(u, v)`` of every pair's left segment and
    ``search_radius`` columns either side — one box per segment, its rows by its pixels' columns ±
    ``search_radius``."""
    if not len(pairs):
        return np.zeros((0, 4), np.int64)
    # one pass over the pixels of each segment in use (in the order of np.unique's sorted indices, those without a
    # pixel left out), without a Segments.subset copy of them
    return _segment_boxes(np.unique(np.asarray(pairs.left_index, np.int64)),
                          np.asarray(left_segments.pixel_offsets, np.int64), left_segments.pixel_uv, int(search_radius))


@njit(cache=True)
def _segment_boxes(seg, offsets, pixel_uv, radius):  # pragma: no cover - numba
    """:func:`pair_bands` of the segments ``seg`` (sorted, unique): per segment with pixels, its rows' extent and its
    columns' widened by ``radius``, int64."""
    out = np.empty((len(seg), 4), np.int64)
    n = 0
    for i in range(len(seg)):
        a, b = offsets[seg[i]], offsets[seg[i] + 1]
        if b <= a:
            continue
        u0 = u1 = np.int64(pixel_uv[a, 0])
        v0 = v1 = np.int64(pixel_uv[a, 1])
        for q in range(a + 1, b):
            u, v = np.int64(pixel_uv[q, 0]), np.int64(pixel_uv[q, 1])
            u0, u1, v0, v1 = min(u0, u), max(u1, u), min(v0, v), max(v1, v)
        out[n, 0] = v0
        out[n, 1] = v1 + 1
        out[n, 2] = u0 - radius
        out[n, 3] = u1 + radius + 1
        n += 1
    return out[:n].copy()


def _rect_mask(rects: np.ndarray, shape: tuple[int, int], mask: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool union of rectangles (N, 4) ``(row0, row1, col0, col1)``, clipped to the image (into ``mask``)."""
    mask = np.zeros(shape, bool) if mask is None else mask
    H, W = shape
    for v0, v1, u0, u1 in np.asarray(rects, np.int64).reshape(-1, 4).tolist():
        mask[max(0, v0) : max(0, min(H, v1)), max(0, u0) : max(0, min(W, u1))] = True
    return mask


def _rects_box(rects, shape: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """Bounding box ``(row0, row1, col0, col1)`` (half-open) of :func:`_rect_mask` of ``rects``; None when empty."""
    H, W = shape
    box = None
    for v0, v1, u0, u1 in np.asarray(rects, np.int64).reshape(-1, 4).tolist():
        v0, v1, u0, u1 = max(0, v0), max(0, min(H, v1)), max(0, u0), max(0, min(W, u1))
        if v1 > v0 and u1 > u0:
            box = _union_box(box, (v0, v1, u0, u1))
    return box


@njit(cache=True)
def _runs_mask(ptr, runs, H, W):  # pragma: no cover - numba
    """(H, W) bool mask of the runs ``(ptr, runs)`` of :func:`~stablemarks.vision.area_stereo._region_runs` and its
    bounding box ``(row0, row1, col0, col1)`` (half-open; row1 <= row0 when empty)."""
    mask = np.zeros((H, W), np.bool_)
    r0, r1, c0, c1 = H, 0, W, 0
    for y in range(H):
        for t in range(ptr[y], ptr[y + 1]):
            a, b = runs[t, 0], runs[t, 1]
            if b > a:
                mask[y, a:b] = True
                r0, r1, c0, c1 = min(r0, y), max(r1, y + 1), min(c0, a), max(c1, b)
    return mask, (r0, r1, c0, c1)


@njit(cache=True)
def _valid_columns_valid(valid, r0, r1, c0, c1):  # pragma: no cover - numba
    """First and last column of ``valid[r0:r1, c0:c1]`` (bool) holding a True pixel, in image columns (``first >
    last``: none). Row by row, each row read from either side only up to the columns found so far: what
    ``np.flatnonzero(sub.any(axis=0))``'s ends are, reading a fraction of the box."""
    first, last = c1, c0 - 1
    for r in range(r0, r1):
        for c in range(c0, first):
            if valid[r, c]:
                first = c
                break
        for c in range(c1 - 1, max(first - 1, last), -1):
            if valid[r, c]:
                last = c
                break
    return first, last


@njit(cache=True)
def _valid_columns_finite(image, r0, r1, c0, c1):  # pragma: no cover - numba
    """:func:`_valid_columns_valid` of the finite pixels of ``image`` (a disparity image, NaN where none)."""
    first, last = c1, c0 - 1
    for r in range(r0, r1):
        for c in range(c0, first):
            if np.isfinite(image[r, c]):
                first = c
                break
        for c in range(c1 - 1, max(first - 1, last), -1):
            if np.isfinite(image[r, c]):
                last = c
                break
    return first, last


def _mask_box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """Bounding box ``(row0, row1, col0, col1)`` (half-open) of the True pixels of an (H, W) bool mask; None: none."""
    rows = np.flatnonzero(np.asarray(mask).any(axis=1))
    if not len(rows):
        return None
    cols = np.flatnonzero(mask[rows[0] : rows[-1] + 1].any(axis=0))
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _union_box(a, b):
    """The bounding box of two boxes (None: empty)."""
    if a is None or b is None:
        return b if a is None else a
    return min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3])


DENSE_ABOVE = 0.8
"""Above this :func:`region_work` the front end computes the dense disparity images instead: the kernel's cost
is about proportional to the work, the region bookkeeping (and any pixel computed later) comes on top."""


def region_work(left: np.ndarray, right: np.ndarray, sad: SADConfig, shape: tuple[int, int]) -> float:
    """The SAD kernel's work for the requested ``left`` and ``right`` pixels ((N, 4) rectangles or (H, W) bool masks,
    as :func:`~stablemarks.vision.area_stereo.compute_disparity_regions` takes them) in images of ``shape``, as
    a fraction of the dense images': per row, each run of requested pixels (runs closer than the disparity range
    planned as one) needs the costs of its columns and of ``num_disparities − 1`` more for the winners its
    left-right check reads; a row never needs more than the dense row (the kernel takes the dense plan from
    three quarters on)."""
    H, W = shape
    plans = [_planning_runs(*_region_runs(mask, (H, W), "regions"), sad.num_disparities, _STEP, W)
             for mask in (left, right)]
    return _plans_work(plans, sad, shape)


def _plans_work(plans, sad: SADConfig, shape: tuple[int, int]) -> float:
    """:func:`region_work` of the planning runs ``plans`` ((ptr, runs) of the left and of the right pixels,
    :func:`~stablemarks.vision.area_stereo._planning_runs`)."""
    H, W = shape
    r = sad.block_size // 2
    dense_row = W - 2 * r
    if H <= 2 * r or dense_row <= 0:
        return 0.0
    (ptr_l, runs_l), (ptr_r, runs_r) = plans
    return float(_rows_work(ptr_l, runs_l, ptr_r, runs_r, sad.num_disparities, r, H, dense_row))


@njit(cache=True)
def _rows_work(ptr_l, runs_l, ptr_r, runs_r, n_disp, r, H, dense_row):  # pragma: no cover - numba
    """:func:`_plans_work` of rows ``r … H − r − 1``: per row the columns of its runs, each widened by ``n_disp − 1``
    (left and right), the dense row's from three quarters of it on and never more, summed over the rows, over the
    dense images'. Whole numbers all along (exact in float64, whatever the order they are added in): the same value
    as the array expressions it replaced."""
    total = 0
    for y in range(r, H - r):
        row = 0
        for ptr, runs in ((ptr_l, runs_l), (ptr_r, runs_r)):
            for q in range(ptr[y], ptr[y + 1]):
                row += runs[q, 1] - runs[q, 0] + n_disp - 1
        if 4 * row >= 3 * dense_row:
            row = dense_row
        total += min(row, dense_row)
    return total / (dense_row * (H - 2 * r))


_SAMPLE_BLOCKS, _SAMPLE_ROWS = 4, 8
"""Blocks of rows :meth:`RegionDisparity._decide` looks at first, evenly spread, and rows per block."""


class RegionDisparity:
    """Disparity images filled in region by region: NaN (and not valid) where not computed.

    ``result`` is a :class:`DisparityResult` of read-only views of the images being filled; ``done`` (left,
    right) the (H, W) masks of the pixels computed; ``calls`` the SAD passes it took. Every computed pixel
    holds the dense value bit for bit (:func:`~stablemarks.vision.area_stereo.compute_disparity_regions`);
    pixels are only ever added.

    :func:`valid_columns` of ``result`` is that of the pixels computed so far; :meth:`decide_columns` computes
    just enough for it to decide given search windows as the dense images' answer does, and
    :meth:`valid_columns` enough to give that answer itself.
    """

    def __init__(self, left8: np.ndarray, right8: np.ndarray, sad: SADConfig, left=None, right=None, *,
                 sobel: tuple[np.ndarray, np.ndarray] | None = None, _runs=None):
        """``left8``, ``right8``: the (H, W) uint8 pair; ``left``, ``right``: the pixels to compute first, (N, 4)
        rectangles ``(row0, row1, col0, col1)`` or (H, W) bool masks (None: none); ``sobel``: the pair's x-Sobel
        derivatives if already computed (``cv2.Sobel(img, cv2.CV_16S, 1, 0, ksize=3)``). The pair is prefiltered
        once (:func:`~stablemarks.vision.area_stereo.prepare_pair`): later computations read only that, not
        ``left8``, ``right8``."""
        H, W = np.shape(left8)
        self.sad = sad
        self._prep = prepare_pair(left8, right8, sad, *(sobel or (None, None)))
        empty = np.zeros((0, 4), np.int64)
        if _runs is not None and sad.backend == "numba":  # front_disparity's runs and planning runs of left, right
            res = _run_prepared(self._prep, _runs[0], _runs[1], plans=_runs[2:])
        else:
            res = regions_on_prepared(self._prep, empty if left is None else left, empty if right is None else right)
        self.calls = 1
        self._images = (res.left, res.right)
        self._valid = res.valid
        views = []
        for a in (*self._images, self._valid):
            a.setflags(write=True)  # the kernel's fresh arrays, frozen on the way out: ours now
            v = a.view()
            v.setflags(write=False)
            views.append(v)
        self.result = DisparityResult(*views)
        # per image, the pixels computed and their bounding box (row0, row1, col0, col1) (None: none): no pixel outside
        # it is ever valid, so found() reads only it
        if _runs is not None:  # the runs of the pixels asked for: the same pixels as the rectangles'
            made = [_runs_mask(ptr, runs, H, W) for ptr, runs in _runs[:2]]
            self.done = tuple(mask for mask, _ in made)
            self._box = [box if box[1] > box[0] else None for _, box in made]
        else:
            self.done = tuple(np.zeros((H, W), bool) if m is None else np.array(m) if np.asarray(m).dtype == bool
                              else _rect_mask(m, (H, W)) for m in (left, right))
            self._box = [None if m is None else _mask_box(m) if np.asarray(m).dtype == bool else
                         _rects_box(m, (H, W)) for m in (left, right)]
        self.limits = disparity_limits(sad, W)
        # per image: the first and the last column not proven to hold no valid pixel (_advance), and the first
        # and last column holding a computed valid pixel (None: to be found again)
        self._open = [list(lim) for lim in self.limits]
        self._found: list[tuple[float, float] | None] = [None, None]
        self._possible: dict[tuple[int, int], np.ndarray] = {}

    @property
    def shape(self) -> tuple[int, int]:
        return self._valid.shape

    def compute(self, left: np.ndarray | None = None, right: np.ndarray | None = None) -> bool:
        """Compute the pixels of the (H, W) bool masks ``left`` / ``right`` not computed yet; whether any was."""
        need = [np.zeros(self.shape, bool) if m is None else m & ~done
                for m, done in zip((left, right), self.done, strict=True)]
        if not (need[0].any() or need[1].any()):
            return False
        # written in place: the kernel writes exactly the requested pixels, the others stay NaN / False
        regions_on_prepared(self._prep, need[0], need[1], out=(self._images[0], self._images[1], self._valid))
        self.calls += 1
        for image in (0, 1):
            self.done[image][need[image]] = True
            self._box[image] = _union_box(self._box[image], _mask_box(need[image]))
        self._found = [None, None]
        return True

    def compute_regions(self, regions: Regions) -> bool:
        """Compute the rectangles of ``regions`` not computed yet; whether any pixel was."""
        H, W = self.shape
        if all(self.done[image][max(0, v0) : max(0, min(H, v1)), max(0, u0) : max(0, min(W, u1))].all()
               for image, rects in enumerate((regions.left, regions.right))
               for v0, v1, u0, u1 in np.asarray(rects, np.int64).reshape(-1, 4).tolist()):
            return False
        return self.compute(_rect_mask(regions.left, self.shape), _rect_mask(regions.right, self.shape))

    def found(self, image: int) -> tuple[float, float]:
        """First and last column of ``image`` holding a computed valid pixel (±inf: none)."""
        if self._found[image] is None:
            box = self._box[image]
            if box is None:
                self._found[image] = (np.inf, -np.inf)
            else:  # inside the box of the computed pixels: outside it every pixel is NaN / not valid
                r0, r1, c0, c1 = box
                if image == 0:
                    first, last = _valid_columns_valid(self._valid, r0, r1, c0, c1)
                else:
                    first, last = _valid_columns_finite(self._images[1], r0, r1, c0, c1)
                self._found[image] = (float(first), float(last)) if first <= last else (np.inf, -np.inf)
        return self._found[image]

    # ------------------------------------------------------------- the columns valid_columns returns
    def possible(self, image: int, c: int) -> np.ndarray:
        """(H,) bool: the pixels of column ``c`` (inside :func:`disparity_limits`) of the left (0) or right (1)
        image that can hold a disparity at all: rows where the SAD window fits, whose window passes the texture
        test — the kernel's test exactly, ``Σ_W min(|Sobel_x|, 255) >= ceil(8 · texture_threshold · b²)`` with
        the x-Sobel of the whole image (a strip one column wider than the window has the same values inside)."""
        key = (image, c)
        if key in self._possible:
            return self._possible[key]
        H, W = self.shape
        b = self.sad.block_size
        r = b // 2
        out = np.zeros(H, bool)
        tex_min = int(np.ceil(8.0 * self.sad.texture_threshold * b * b))
        if H > 2 * r and tex_min <= 0:
            out[r : H - r] = True
        elif H > 2 * r:
            asat = self._prep.asat_left if image == 0 else self._prep.asat_right  # min(|Sobel_x|, 255)
            window = asat[:, c - r : c + r + 1].sum(axis=1, dtype=np.int64)
            sums = np.concatenate([[0], np.cumsum(window)])
            rows = np.arange(r, H - r)
            out[r : H - r] = (sums[rows + r + 1] - sums[rows - r]) >= tex_min
        self._possible[key] = out
        return out

    def _advance(self, image: int, lower: bool) -> float:
        """The first (``lower``) or last column of ``image`` not proven to hold no valid pixel, moving past the
        columns whose possible pixels (:meth:`possible`) are all computed and invalid; ±inf past the last."""
        lo, hi = self.limits[image]
        arr, done = self._images[image], self.done[image]
        side = 0 if lower else 1
        c = self._open[image][side]
        step = 1 if lower else -1
        while lo <= c <= hi and not np.isfinite(arr[:, c]).any() and not (self.possible(image, c) & ~done[:, c]).any():
            c += step
        self._open[image][side] = c
        if lo <= c <= hi:
            return float(c)
        return np.inf if lower else -np.inf

    def _known(self, image: int, lower: bool, t: float) -> bool | None:
        """Whether the dense image's first valid column is below ``t`` (``lower``), or its last one above ``t``,
        if what is computed tells; None if it does not."""
        lo, hi = self.limits[image]
        found = self.found(image)[0 if lower else 1]
        if (found < t) if lower else (found > t):
            return True  # a computed valid pixel beyond t: the dense image's first (last) one is too
        if (t <= lo) if lower else (t >= hi):
            return False  # no column on this side of t can hold a disparity
        a = self._advance(image, lower)
        if (a >= t) if lower else (a <= t):
            return False  # every column on this side of t is proven to hold no valid pixel
        return None

    def _decide(self, image: int, lower: bool, t: float) -> bool:
        """:meth:`_known`, computing what it takes to know: first a few blocks of rows across all the columns
        between the border and ``t`` (a valid pixel there is the usual answer), then the possible pixels
        (:meth:`possible`) of those columns from the border inward, 1, 2, 4, ... columns at a time, until one
        holds a valid pixel or all are proven to hold none."""
        H, W = self.shape
        lo, hi = self.limits[image]
        r = self.sad.block_size // 2
        chunk, sampled = 1, False
        while (known := self._known(image, lower, t)) is None:
            a = int(self._advance(image, lower))
            last = min(hi, math.ceil(t) - 1) if lower else max(lo, math.floor(t) + 1)
            c0, c1 = min(a, last), max(a, last)
            mask = np.zeros((H, W), bool)
            if not sampled:
                for i in range(_SAMPLE_BLOCKS):
                    y = r + (H - 2 * r) * (2 * i + 1) // (2 * _SAMPLE_BLOCKS) - _SAMPLE_ROWS // 2
                    mask[max(0, y) : max(0, y + _SAMPLE_ROWS), c0 : c1 + 1] = True
                sampled = True
            else:
                cols = range(a, min(last, a + chunk - 1) + 1) if lower else range(max(last, a - chunk + 1), a + 1)
                for c in cols:
                    mask[:, c] = self.possible(image, c)
                chunk *= 2
            self.compute(*((mask, None) if image == 0 else (None, mask)))
        return known

    def decide_columns(self, windows: list[tuple[tuple[float, float], tuple[float, float]]]) -> None:
        """Compute what it takes for :func:`valid_columns` of ``result``, ``vc``, to pass or fail every search
        window ``w`` (left-image window, right-image window) as the dense images' answer does in
        :func:`landmarks_on_plane`'s test: ``vc[i][0] + 1 < w[i][0] and w[i][1] < vc[i][1] - 1`` for both images.

        Why: ``result``'s valid pixels are some of the dense image's, so its first valid column ``b`` is at or
        after the dense one ``v``, and ``v`` at or after the first column ``a`` not proven empty (its possible
        pixels all computed, none valid). With ``t = w[0] − 1`` the dense condition is ``v < t``: it holds for
        both if ``b < t`` (``v <= b``) and fails for both if ``a >= t`` (``b >= v >= a``); :meth:`_decide`
        computes until one of the two is so. The same on the right side. A window with one condition failing
        for both fails for both whatever the others; one with all four holding for both passes for both.
        Deciding one window keeps the others decided: pixels are only added, so ``b`` only moves towards ``v``
        and ``a`` towards it from the other side.
        """
        for pair in windows:
            tests = [(image, lower, float(w[0]) - 1.0 if lower else float(w[1]) + 1.0)
                     for image, w in enumerate(pair) for lower in (True, False)]
            if any(np.isnan(t) for *_, t in tests):
                continue  # a comparison with NaN fails for any vc
            # beyond the limits every threshold decides alike: v < t for t > hi + 1 iff v < hi + 1
            tests = [(image, lower, min(t, self.limits[image][1] + 1.0) if lower else
                      max(t, self.limits[image][0] - 1.0)) for image, lower, t in tests]
            known = [self._known(*test) for test in tests]
            if False in known:
                continue
            for test, k in zip(tests, known, strict=True):
                if k is None and not self._decide(*test):
                    break

    def valid_columns(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """:func:`valid_columns` of the dense images, computing what it takes (the border columns inward, until
        one holds a valid pixel)."""
        out = []
        for image in (0, 1):
            ends = []
            for lower in (True, False):
                while True:
                    a = self._advance(image, lower)
                    if not np.isfinite(a) or self._decide(image, lower, a + 1.0 if lower else a - 1.0):
                        ends.append(a)
                        break
            out.append((ends[0], ends[1]) if np.isfinite(ends[0]) else (np.inf, -np.inf))
        return out[0], out[1]


@dataclass(frozen=True)
class FrontEnd:
    """The stereo front end's output for one frame.

    ``pairs`` are all segment pairs matched by dynamic programming (paper Fig 5); ``kept`` (M,) marks the
    ones the disparity image agrees with (Fig 6); ``disparity`` holds both disparity images: dense, or — when
    the front end was run with ``regions`` (kept here) — NaN where not computed: ``lazy`` holds what was
    computed and computes more on request (:meth:`require`; :func:`select_landmarks` asks for what its planes
    read, so the pixels filled in grow as the frame is processed).
    """

    left_segments: Segments
    right_segments: Segments
    pairs: SegmentPairs
    kept: np.ndarray
    disparity: DisparityResult
    timings: dict[str, float] = field(default_factory=dict)
    lazy: RegionDisparity | None = field(default=None, repr=False, compare=False)
    regions: Regions | None = field(default=None, repr=False, compare=False)

    @cached_property
    def kept_pairs(self) -> SegmentPairs:
        """The pairs the disparity check keeps (made once: the planes, the association and the log all ask)."""
        return self.pairs.subset(self.kept)

    def require(self, regions: Regions, windows=()) -> float:
        """Make sure the disparity of ``regions`` is computed and that :func:`valid_columns` of ``disparity``
        decides the search ``windows`` (:meth:`RegionDisparity.decide_columns`) as the dense images' would
        (nothing to do for a dense front end); returns the time it took [s]."""
        if self.lazy is None:
            return 0.0
        t0 = time.perf_counter()
        self.lazy.compute_regions(regions)
        self.lazy.decide_columns(windows)
        return time.perf_counter() - t0


def check_pair(left: np.ndarray, right: np.ndarray) -> None:
    """A stereo pair must be two 2-D grayscale images of the same size."""
    for name, img in (("left", left), ("right", right)):
        if np.ndim(img) != 2:
            raise ImageError(expected("a 2-D grayscale image", f"shape {np.shape(img)}", where=f"{name} image"))
    if left.shape != right.shape:
        raise ImageError(
            f"stereo pair: left image is {left.shape[1]}×{left.shape[0]} but right image is "
            f"{right.shape[1]}×{right.shape[0]}; expected equal sizes"
        )


def run_front_end(left: np.ndarray, right: np.ndarray, config: Config = Config(), regions: Regions | None = None
                  ) -> FrontEnd:
    """Segments, segment matching, SAD disparity and the disparity filter on a rectified pair.

    ``regions`` None: the dense disparity images. Otherwise SAD is computed only in ``regions``
    (:func:`plane_regions`) and in the bands the disparity filter reads around the segment pairs
    (:func:`pair_bands`), with the dense values bit for bit there: the kept pairs are the dense computation's;
    :func:`select_landmarks` computes what else it reads. When that would take about as long as the dense
    images (:func:`region_work` at least :data:`DENSE_ABOVE`), and with the ``opencv`` SAD backend, the dense
    images are computed.
    """
    check_pair(left, right)
    t = {}
    t0 = time.perf_counter()
    sobel = _pair_sobel(left, right)  # the segments' gradient and the SAD prefilter's: computed once
    seg_l = extract_vertical_segments(left, config.segments, sobel=None if sobel is None else sobel[0])
    seg_r = extract_vertical_segments(right, config.segments, sobel=None if sobel is None else sobel[1])
    t1 = time.perf_counter()
    pairs = match_segments(seg_l, seg_r, config.matching)
    t2 = time.perf_counter()
    f = config.filter
    disp, lazy = front_disparity(left, right, config, regions, pairs, seg_l, sobel=sobel)
    t3 = time.perf_counter()
    kept = filter_pairs(pairs, seg_l, disp.left, disp.valid, tolerance=f.tolerance, min_support=f.min_support,
                        search_radius=f.search_radius)
    t4 = time.perf_counter()
    t.update(segments=t1 - t0, matching=t2 - t1, disparity=t3 - t2, filter=t4 - t3)
    return FrontEnd(seg_l, seg_r, pairs, np.asarray(kept, dtype=bool), disp, t, lazy, regions)


def _pair_sobel(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The x-Sobel derivatives of a uint8 pair (what :func:`extract_vertical_segments` and the SAD prefilter both
    compute, the same 3×3 kernel and reflected borders), None for other images (each computes its own)."""
    if left.dtype != np.uint8 or right.dtype != np.uint8 or min(left.shape) < 3:
        return None
    return _xsobel(np.ascontiguousarray(left)), _xsobel(np.ascontiguousarray(right))


def front_disparity(left: np.ndarray, right: np.ndarray, config: Config, regions: Regions | None, pairs: SegmentPairs,
                    left_segments: Segments, sobel: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[DisparityResult, RegionDisparity | None]:
    """The front end's SAD (:func:`run_front_end`): the disparity images and, when computed in regions, the
    :class:`RegionDisparity` holding them (None when dense). ``sobel``: the pair's x-Sobel derivatives if
    already computed (:func:`_pair_sobel`)."""
    if regions is None or config.sad.backend != "numba":
        return compute_disparity(left, right, config.sad, sobel=sobel), None
    want_l = np.concatenate([np.asarray(regions.left, np.int64).reshape(-1, 4),
                             pair_bands(pairs, left_segments, config.filter.search_radius)])
    want_r = np.asarray(regions.right, np.int64).reshape(-1, 4)
    # the runs of requested pixels and the kernel's planning runs, made once for the decision and the kernel
    shape = np.shape(left)
    runs = [_region_runs(want_l, shape, "regions"), _region_runs(want_r, shape, "right_regions")]
    plans = [_planning_runs(*rr, config.sad.num_disparities, _STEP, shape[1]) for rr in runs]
    if _plans_work(plans, config.sad, shape) >= DENSE_ABOVE:
        return compute_disparity(left, right, config.sad, sobel=sobel), None
    lazy = RegionDisparity(left, right, config.sad, want_l, want_r, sobel=sobel, _runs=(*runs, *plans))
    return lazy.result, lazy


def valid_columns(disparity: DisparityResult | FrontEnd) -> tuple[tuple[float, float], tuple[float, float]]:
    """First and last column holding any valid disparity, in the left and in the right image.

    Of a :class:`FrontEnd`: the dense images' answer, also when it was run with regions (computing the border
    columns it takes, :meth:`RegionDisparity.valid_columns`). Of its ``disparity`` images: the answer of the
    pixels computed so far — after :func:`select_landmarks`, one that decides its planes' edge windows as the
    dense answer does (:meth:`RegionDisparity.decide_columns`), not necessarily equal to it."""
    if isinstance(disparity, FrontEnd):
        if disparity.lazy is not None:
            return disparity.lazy.valid_columns()
        disparity = disparity.disparity
    out = []
    for img in (disparity.left, disparity.right):
        cols = np.flatnonzero(np.isfinite(img).any(axis=0))
        out.append((float(cols[0]), float(cols[-1])) if len(cols) else (np.inf, -np.inf))
    return out[0], out[1]


@dataclass(frozen=True)
class FrameLandmarks:
    """Planes and landmark candidates of one frame.

    ``predictions`` for every reference plane in view of the belief; ``fits`` (a :class:`PlaneFit` or a
    falsy :class:`FailedFit` each); ``planes`` the per-plane models; ``candidates`` all candidate
    features of all planes (Table 1's rows); ``warnings`` plain sentences for the user.
    """

    front: FrontEnd
    X: np.ndarray
    cov_X: np.ndarray
    predictions: list[PlanePrediction]
    fits: list[PlaneFit | FailedFit]
    planes: list[PlaneLandmarks]
    candidates: list[Candidate]
    warnings: list[str]
    timings: dict[str, float]

    @property
    def selected(self) -> list[Candidate]:
        return [c for c in self.candidates if c.selected]


def select_landmarks(
    front: FrontEnd,
    camera: StereoCamera,
    world_map: Map,
    X,
    cov_X,
    config: Config = Config(),
) -> FrameLandmarks:
    """Planes, members, boundaries, models and selection for one frame (Sec 2.3–4).

    ``camera`` is the head panned as the frame was taken; its line-column noise is the configuration's
    ``noise.sigma_img`` (:meth:`Config.camera`). ``X`` (3,) and ``cov_X`` (3, 3) are the pose prior in the map.
    """
    camera = config.camera(camera)
    X = np.asarray(X, dtype=float)
    cov_X = np.asarray(cov_X, dtype=float)
    t0 = time.perf_counter()
    regions = getattr(front, "regions", None)
    same = regions is not None and regions.key is not None and \
        _same_key(regions.key, _prediction_key(camera, X, cov_X, world_map, config))
    if same:
        preds = regions.predictions  # predicted from this very prior ahead of the front end (plane_regions)
    else:
        preds = predict_planes(camera, X, cov_X, world_map, config.planes)
    t_disp = 0.0
    if getattr(front, "lazy", None) is not None:  # disparity in regions: compute what the planes read
        if same and regions.shape == front.disparity.left.shape and regions.windows is not None:
            # what plane_regions made of these predictions for images of this shape: the same rectangles and windows
            wanted, windows = regions, regions.windows
        else:
            wanted, windows = prediction_regions(preds, front.disparity.left.shape, config), edge_windows(preds, config)
        t_disp = front.require(wanted, windows)
    warnings = []
    if not preds:
        warnings.append("no reference plane of the map is in view of the pose prior")
    pairs = front.kept_pairs
    lazy = getattr(front, "lazy", None)
    # valid_columns of the images as computed so far (the lazy images keep that answer up to date)
    columns = (lazy.found(0), lazy.found(1)) if lazy is not None else valid_columns(front.disparity)
    fits, models, memos = [], [], []
    t_fit = t_model = 0.0
    plane_args = dict(camera=camera, pairs=pairs, left_segments=front.left_segments,
                      disparity_right=front.disparity.right, config=config.landmarks, plane_config=config.planes,
                      window_px=float(config.sad.block_size), valid_columns=columns, world_map=world_map, cov_X=cov_X,
                      border_sigma_px=(config.noise.boundary_px, config.noise.free_boundary_px),
                      disparity_left=front.disparity.left,
                      edge_pairs=front.pairs.subset(~np.asarray(front.kept)) if preds else None,
                      disparity_range=(float(config.sad.min_disparity),
                                       float(config.sad.min_disparity + config.sad.num_disparities - 1)))
    for pred in preds:
        ta = time.perf_counter()
        fit = fit_plane(camera, X, front.disparity.left, pred, config.planes)
        tb = time.perf_counter()
        t_fit += tb - ta
        fits.append(fit)
        if not fit:
            warnings.append(
                f"plane {pred.plane.label!r}: not found in its predicted window "
                f"(columns {pred.window[0]}–{pred.window[1]}): {fit.reason}"
            )
            continue
        memos.append({})  # what the wall's search computed, for modelling it below without reading it anew
        model = landmarks_on_plane(**{**plane_args, "fit": fit, "memo": memos[-1], "boundaries_only": True})
        warnings += [why for _, why in model.rejected_boundaries]
        t_model += time.perf_counter() - tb
        if fit.plane.free_edges and not model.boundaries:
            warnings.append(f"plane {fit.plane.label!r}: no free edge found in view; its features are not modelled")
        models.append(model)
    # boundaries of different walls whose distance the map contradicts: neither is used (landmarks.boundaries_apart);
    # each wall is then modelled once, from the boundaries that are left
    tb = time.perf_counter()
    apart = boundaries_apart(models, config.landmarks)
    for n, m in enumerate(models):
        skip = {edge: why for (plane_id, edge), why in apart.items() if plane_id == m.fit.plane.id}
        models[n] = landmarks_on_plane(**{**plane_args, "fit": m.fit, "unusable": skip or None, "memo": memos[n]})
        if skip:
            warnings += [why for _, why in models[n].rejected_boundaries if why in skip.values()]
            if m.fit.plane.free_edges and not models[n].boundaries:
                warnings.append(f"plane {m.fit.plane.label!r}: no free edge found in view; its features are not "
                                "modelled")
    t_model += time.perf_counter() - tb
    # walls whose own lines scatter about their fit give nothing; then the off-wall test once more with the line
    # noise the frame's own lines show, when below the model's (landmarks.off_wall_by_lines)
    before = [len(m.rejected_boundaries) for m in models]
    models, _ = off_wall_by_lines(models, config.landmarks, camera.sigma_img)
    warnings += [why for m, n in zip(models, before, strict=True) for _, why in m.rejected_boundaries[n:]]
    cands = [c for m in models for c in m.candidates]
    timings = {"disparity": t_disp, "planes": t_fit, "landmarks": t_model, "total": time.perf_counter() - t0}
    return FrameLandmarks(front, X, cov_X, preds, fits, models, cands, warnings, timings)


def process_frame(left, right, camera: StereoCamera, world_map: Map, X, cov_X, config: Config = Config(), *,
                  dense: bool = False):
    """Front end and landmark selection on one rectified grayscale pair.

    SAD is computed only where the method reads it (:func:`plane_regions` of the prior ``X``, ``cov_X``); the
    result is the dense computation's. ``dense``: compute the whole disparity images (e.g. to draw them)."""
    left, right = np.asarray(left), np.asarray(right)
    check_pair(left, right)
    regions = None if dense else plane_regions(camera, X, cov_X, world_map, config, left.shape)
    front = run_front_end(left, right, config, regions)
    return select_landmarks(front, camera, world_map, X, cov_X, config)
