"""One stereo frame through the whole method (DESIGN.md §1): front end, planes, landmarks.

:func:`run_front_end` — vertical segments in both images, segment stereo matching by dynamic
programming (Sec 2.1), SAD disparity in both directions with the left-right check (Sec 2.2), and the
filter that drops pairs the disparity image contradicts (Fig 5 → Fig 6).

:func:`select_landmarks` — for every reference plane in view of the belief: prediction (Eqs 3–10),
fit (Eq 11), members (Sec 2.4), boundary (Sec 3.2), relative model (Eqs 12–17) and selection (Sec 4).

Both return plain dataclasses with per-stage timings [s]; nothing here prints or plots.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .config import Config
from .errors import ImageError, expected
from .geometry import StereoCamera
from .landmarks import Candidate, PlaneLandmarks, landmarks_on_plane
from .maps import Map
from .planes import FailedFit, PlaneFit, PlanePrediction, fit_plane, predict_planes
from .vision.area_stereo import DisparityResult, compute_disparity
from .vision.filter import filter_pairs
from .vision.segment_stereo import SegmentPairs, match_segments
from .vision.segments import Segments, extract_vertical_segments


@dataclass(frozen=True)
class FrontEnd:
    """The stereo front end's output for one frame.

    ``pairs`` are all segment pairs matched by dynamic programming (paper Fig 5); ``kept`` (M,) marks the
    ones the disparity image agrees with (Fig 6); ``disparity`` holds both disparity images.
    """

    left_segments: Segments
    right_segments: Segments
    pairs: SegmentPairs
    kept: np.ndarray
    disparity: DisparityResult
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def kept_pairs(self) -> SegmentPairs:
        return self.pairs.subset(self.kept)


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


def run_front_end(left: np.ndarray, right: np.ndarray, config: Config = Config()) -> FrontEnd:
    """Segments, segment matching, SAD disparity and the disparity filter on a rectified pair."""
    check_pair(left, right)
    t = {}
    t0 = time.perf_counter()
    seg_l = extract_vertical_segments(left, config.segments)
    seg_r = extract_vertical_segments(right, config.segments)
    t1 = time.perf_counter()
    pairs = match_segments(seg_l, seg_r, config.matching)
    t2 = time.perf_counter()
    disp = compute_disparity(left, right, config.sad)
    t3 = time.perf_counter()
    f = config.filter
    kept = filter_pairs(pairs, seg_l, disp.left, disp.valid, tolerance=f.tolerance, min_support=f.min_support,
                        search_radius=f.search_radius)
    t4 = time.perf_counter()
    t.update(segments=t1 - t0, matching=t2 - t1, disparity=t3 - t2, filter=t4 - t3)
    return FrontEnd(seg_l, seg_r, pairs, np.asarray(kept, dtype=bool), disp, t)


def valid_columns(disparity: DisparityResult) -> tuple[tuple[float, float], tuple[float, float]]:
    """First and last column holding any valid disparity, in the left and in the right image."""
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
    preds = predict_planes(camera, X, cov_X, world_map, config.planes)
    warnings = []
    if not preds:
        warnings.append("no reference plane of the map is in view of the pose prior")
    pairs = front.kept_pairs
    columns = valid_columns(front.disparity)
    fits, models = [], []
    t_fit = t_model = 0.0
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
        model = landmarks_on_plane(camera, fit, pairs, front.left_segments, front.disparity.right,
                                   config.landmarks, config.planes, float(config.sad.block_size),
                                   columns, world_map, cov_X=cov_X,
                                   border_sigma_px=(config.noise.boundary_px, config.noise.free_boundary_px))
        warnings += [why for _, why in model.rejected_boundaries]
        t_model += time.perf_counter() - tb
        if fit.plane.free_edges and not model.boundaries:
            warnings.append(f"plane {fit.plane.label!r}: no free edge found in view; its features are not modelled")
        models.append(model)
    cands = [c for m in models for c in m.candidates]
    timings = {"planes": t_fit, "landmarks": t_model, "total": time.perf_counter() - t0}
    return FrameLandmarks(front, X, cov_X, preds, fits, models, cands, warnings, timings)


def process_frame(left, right, camera: StereoCamera, world_map: Map, X, cov_X, config: Config = Config()):
    """Front end and landmark selection on one rectified grayscale pair."""
    front = run_front_end(left, right, config)
    return select_landmarks(front, camera, world_map, X, cov_X, config)
