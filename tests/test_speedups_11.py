"""Issue 13, the per-frame pipeline faster (eleventh pass): the landmark stage against the former implementation
(kept here as the reference) on frames of several simulated scenarios, bit for bit.

:func:`~stablemarks.pipeline.select_landmarks` models a wall again without the boundaries
:func:`~stablemarks.landmarks.boundaries_apart` flags (the bench's lab frame: both walls). It now hands
:func:`~stablemarks.landmarks.landmarks_on_plane` a ``memo`` of the first model of that wall: the gate, the members,
each edge's search and checks, the features of one boundary, each line's nearer-side test and the silhouettes are
taken from it instead of computed again. The former functions below compute everything afresh; the frame's whole
model (predictions, fits, boundaries, candidates with every field, rejections, warnings) must be the same."""

from __future__ import annotations

import math
import time
from dataclasses import fields, is_dataclass, replace

import numpy as np
import pytest

from stablemarks.config import Config
from stablemarks.errors import InputError  # noqa: F401  (the former code's module namespace)
from stablemarks.geometry import StereoCamera
from stablemarks.landmarks import (
    REASON_BESIDE_NEARER,
    SLOPE_GATE_CHI2,
    LandmarkConfig,
    PlaneLandmarks,
    _at_silhouette,
    _replace,
    beside_nearer_sides,
    boundaries_apart,
    boundary_disagreement,
    boundary_window,
    edge_depth_step,
    edge_incidence,
    edge_occluded,
    fit_disagreements,
    landmarks_on_plane,
    mapped_boundaries,
    model_features,
    nearer_silhouettes,
    occluded_boundary,
    off_wall_by_lines,
    other_wall_gap,
    search_boundary,
    select,
    wall_columns,
)
from stablemarks.maps import Map
from stablemarks.pipeline import (
    FrameLandmarks,
    FrontEnd,
    _prediction_key,
    _same_key,
    edge_windows,
    plane_regions,
    prediction_regions,
    run_front_end,
    select_landmarks,
    valid_columns,
)
from stablemarks.planes import PlaneConfig, PlaneFit, fit_plane, median, plane_members, predict_planes

from .conftest import COV_PRIOR


# ------------------------------------------------------------------ the former implementation (the reference)
def former_landmarks_on_plane(
    camera: StereoCamera,
    fit: PlaneFit,
    pairs,
    left_segments,
    disparity_right: np.ndarray | None,
    config: LandmarkConfig = LandmarkConfig(),
    plane_config: PlaneConfig = PlaneConfig(),
    window_px: float = 15.0,
    valid_columns: tuple[tuple[float, float], tuple[float, float]] | None = None,
    world_map: Map | None = None,
    *,
    cov_X=None,
    border_sigma_px: float | tuple[float | None, float | None] | None = None,
    disparity_left: np.ndarray | None = None,
    disparity_range: tuple[float, float] | None = None,
    unusable: dict[str, str] | None = None,
) -> PlaneLandmarks:
    """The former :func:`~stablemarks.landmarks.landmarks_on_plane` (everything computed afresh on every call):
    members, boundary search at every free edge in the window, relative model and selection.

    ``valid_columns``: for the left and the right image, the first and last column where the disparity
    image can hold a match. An edge whose search window reaches beyond them is not searched: the region
    would end there at the image's (or the disparity range's) border, not at the plane's edge.
    ``world_map``: when given, an edge with no depth step behind it (:func:`edge_depth_step`, below
    ``min_edge_step_sigma``) is not searched either. Ends not searched (or not found) are placed from the
    edge that was found with the map's length, and features near them are rejected like near a found one.
    ``cov_X`` (3, 3): the pose covariance; with it a found boundary is checked against the map's free edge
    (:func:`boundary_disagreement`) and not used when it is farther than ``boundary_gate_sigma`` σ.
    ``border_sigma_px``: see :func:`search_boundary`. ``disparity_left``: when given, a selected candidate
    beside something nearer than its wall (:func:`beside_nearer`) is rejected. ``disparity_range``: the least and
    the largest disparity block matching searches [px]; an edge where the wall's predicted disparity may lie
    outside it (``search_sigma`` σ) is not searched: block matching finds nothing there, and the wall's region
    ends where the wall leaves the range, not at its edge (a camera with f·b = 98 px·m and 64 disparities sees
    nothing nearer than 1.5 m: a free-standing panel's end 1.2 m away was found 21 cm inside it).
    """
    if cov_X is not None:
        cov_map = world_map.accuracy_cov if world_map is not None else np.zeros((2, 2))
        m2, m2_slope = fit_disagreements(camera, fit, cov_X, cov_map)
        if m2 > config.fit_gate_chi2:
            # A wall turned from the map (a wrong pan turns every wall like this): its free edges in view were
            # expected and are not found. A wall merely shifted (a slip, a kidnap) is left to the widened search.
            in_view = [e for e in fit.plane.free_edges if np.all(np.isfinite(fit.prediction.edges[e].u))
                       and fit.prediction.edges[e].window(0, config.search_sigma)[1] >= 0
                       and fit.prediction.edges[e].window(0, config.search_sigma)[0] <= camera.width - 1]
            turned = m2_slope > SLOPE_GATE_CHI2
            if not turned:
                in_view = []
            return PlaneLandmarks(fit, [], np.zeros(len(pairs), dtype=bool), [], [
                (None, f"plane {fit.plane.label!r}: the fitted wall is {100 * fit.a:+.1f} cm off and turned "
                       f"{np.degrees(np.arctan(fit.b)):+.1f}° from the map's (Mahalanobis² {m2:.0f} > "
                       f"{config.fit_gate_chi2:g} with the pose's uncertainty): another surface in its band, "
                       "not used")],
                in_view, "turned" if turned else "shifted")
    members = plane_members(fit, pairs, left_segments, plane_config)
    # A wall in line with another (two partitions in a row) shares its plane: segments beyond the wall's ends
    # fit it too. Only those between the two ends' search windows are the wall's.
    lo, hi = wall_columns(camera, fit, config.search_sigma)
    members = members & (pairs.u_left >= lo) & (pairs.u_left <= hi)
    idx = np.flatnonzero(members)
    members_u = np.stack([pairs.u_left[idx], pairs.u_right[idx]], axis=-1) if len(idx) else np.zeros((0, 2))
    boundaries, rejected, searched, hidden = [], [], [], []
    w_sad = boundary_window(config, window_px)
    for edge in fit.plane.free_edges:
        e = fit.prediction.edges[edge]
        if not np.all(np.isfinite(e.u)):  # the edge is behind the camera
            continue
        lo, hi = e.window(0, config.search_sigma)
        if hi < 0 or lo > camera.width - 1:
            continue
        windows = [e.window(img, config.search_sigma) for img in (0, 1)]
        if valid_columns is not None and any(
            not (vc[0] + 1 < w[0] and w[1] < vc[1] - 1) for w, vc in zip(windows, valid_columns, strict=True)
        ):
            continue
        if disparity_range is not None:
            d, sd = fit.prediction.disparity_at(e.u[0])
            d_lo, d_hi = float(d - config.search_sigma * sd), float(d + config.search_sigma * sd)
            if d_hi > disparity_range[1] or d_lo < disparity_range[0]:
                rejected.append((None, f"plane {fit.plane.label!r}: the wall's disparity at its free edge {edge} may "
                                       f"be {d_lo:.0f}–{d_hi:.0f} px, beyond the {disparity_range[0]:g}–"
                                       f"{disparity_range[1]:g} px block matching searches (sad.min_disparity, "
                                       "sad.num_disparities): not searched"))
                continue
        incidence = edge_incidence(camera, fit.X, fit.plane, edge)
        if incidence > math.radians(config.max_incidence_deg):
            # the limit of the lines modelled from a boundary holds for the boundary too: its column error is
            # stretched along the wall as much, and every landmark placed from it inherits that error (a warehouse
            # aisle: an end seen at 72° placed its wall's landmarks 12–17 cm off, with σ of a few cm)
            rejected.append((None, f"plane {fit.plane.label!r}: its free edge {edge} is seen "
                                   f"{np.degrees(incidence):.0f}° from the wall's normal (more than "
                                   f"landmarks.max_incidence_deg, {config.max_incidence_deg:g}°): not searched"))
            continue
        if world_map is not None:
            if edge_occluded(camera, fit.X, world_map, fit.plane, edge):
                continue
            step = edge_depth_step(camera, fit.X, world_map, fit.plane, edge, window_px / 2 + 1)
            if abs(step) < config.min_edge_step_sigma * plane_config.sigma_nu(camera):
                continue
        bridge = None
        if world_map is not None:
            # a hole is followed across up to the whole window, but never across the gap to another wall of the
            # map that would continue the region (less one window: each side's border fattens by half of it)
            span = int(np.ceil(max(w_[1] - w_[0] for w_ in windows)))
            gap = other_wall_gap(camera, fit, world_map, edge, config.search_sigma)
            bridge = span if not np.isfinite(gap) else max(int(w_sad // 2), min(span, int(gap - w_sad)))
        searched.append(edge)
        b = search_boundary(camera, fit, edge, disparity_right, members_u, config, plane_config, window_px,
                            border_sigma_px, bridge)
        if b is None:
            continue
        if unusable and edge in unusable:  # found, but known not to be usable in this frame (boundaries_apart)
            rejected.append((b, unusable[edge]))
            continue
        if disparity_left is not None and config.nearer_fraction < 1.0 and \
                occluded_boundary(camera, fit, disparity_left, b, window_px, config.nearer_fraction):
            rejected.append((b, f"plane {fit.plane.label!r}: the boundary found at {edge} is the silhouette of "
                                "something nearer standing in front of the wall, not its end: not used"))
            hidden.append(edge)  # (since: the end hidden, not missed; landmarks.PlaneLandmarks.hidden)
            continue
        if cov_X is not None:
            off, sigma = boundary_disagreement(b, fit.plane, fit.X, cov_X)
            if abs(off) > config.boundary_gate_sigma * sigma:
                rejected.append((b, f"plane {fit.plane.label!r}: the boundary found at {edge} is {100 * off:+.1f} cm "
                                    f"along the wall from the map's free edge (σ {100 * sigma:.1f} cm): not used"))
                continue
        boundaries.append(b)
    if len(boundaries) == 2:
        # Both ends found: the map fixes their distance, whatever the pose. One end snapped onto a line beyond
        # the wall (the corridor: a poster's far edge found 6 cm out, on a line of the wall behind it, so that
        # the poster's own edge passed for a feature) or inside it makes it disagree. Which end is wrong only the
        # pose can tell: an end farther from the map's edge than its gate is not used (with the pose's
        # covariance that gate already ran above), and when both lie inside their gates the pose cannot tell
        # them apart (office, a turn: both ends within 3 σ of a heading 25 mrad uncertain, the one kept was the
        # wrong one, and the seven landmarks modelled from it pulled the pose 3 cm off with NEES 275), so
        # neither is used. Without a pose covariance the less certain end gives way, as before.
        b1, b2 = boundaries
        length = abs(float((b1.P - b2.P) @ fit.plane.direction))
        sigma = float(np.hypot(b1.sigma_along, b2.sigma_along))
        if abs(length - fit.plane.length) > config.boundary_gate_sigma * sigma:
            why = (f"plane {fit.plane.label!r}: the boundaries found at both ends are {100 * length:.1f} cm apart, "
                   f"the map's wall {100 * fit.plane.length:.1f} cm (σ {100 * sigma:.1f} cm)")
            if cov_X is None:
                worse = max(boundaries, key=lambda b: b.sigma_along)
                boundaries.remove(worse)
                rejected.append((worse, f"{why}: the one at {worse.edge} is not used"))
            else:
                z = [abs(off) / sig for off, sig in (boundary_disagreement(b, fit.plane, fit.X, cov_X)
                                                     for b in boundaries)]
                out = [b for b, zi in zip(boundaries, z, strict=True) if zi > config.boundary_gate_sigma]
                if not out:  # both fit the pose: it cannot tell which is wrong
                    out = list(boundaries)
                    why += ": the pose cannot tell which end is wrong, so both are not used"
                else:
                    why += f": the one at {out[0].edge} is off the map's edge, not used"
                for b in out:
                    boundaries.remove(b)
                    rejected.append((b, why))
    if not boundaries:
        return PlaneLandmarks(fit, [], members, [], rejected, searched, hidden=hidden)
    ref = min(boundaries, key=lambda b: b.sigma_along)
    step = left_segments.contrast[pairs.left_index] / 4.0  # a Sobel_x response is 4× the step across an edge
    cands = model_features(camera, fit, ref, pairs, idx, step, config)
    # An end of the wall not found in this frame (not free, out of the searchable part of the image, or
    # without a depth step) is still where the map puts it: the wall's length from the edge that was found.
    # Features near it are near a boundary too.
    mapped = mapped_boundaries(fit.plane, boundaries, ref)
    cands = select(cands, boundaries + mapped, config, fit.plane.z)
    if disparity_left is not None and config.nearer_fraction < 1.0:
        slope = left_segments.slope[pairs.left_index]
        chosen = [c for c in cands if c.selected]
        sides = beside_nearer_sides(fit, disparity_left, [c.u_left for c in chosen], [c.v_top for c in chosen],
                                    [c.v_bottom for c in chosen], [float(slope[c.pair]) for c in chosen],
                                    window_px, config.nearer_fraction) if chosen else []
        nearer = {id(c) for c, side in zip(chosen, sides, strict=True) if side}
        cands = [_replace(c, selected=False, reason=REASON_BESIDE_NEARER) if id(c) in nearer else c
                 for c in cands]
    if world_map is not None and cov_X is not None and config.nearer_fraction < 1.0 and any(c.selected for c in cands):
        # only the ends whose depth step the disparity test above cannot see: a step within the wall's band
        band_px = float(fit.prediction.gate * median(fit.prediction.sigma_d)) + 1.0  # np.median, without its overhead
        sil = nearer_silhouettes(camera, fit.X, cov_X, world_map, fit.plane, max_step_px=band_px)
        cands = [_replace(c, selected=False, reason=REASON_BESIDE_NEARER)
                 if c.selected and _at_silhouette(camera, c, sil, config.boundary_sigma) else c
                 for c in cands]
    return PlaneLandmarks(fit, boundaries, members, cands, rejected, searched, hidden=hidden)


def former_select_landmarks(
    front: FrontEnd,
    camera: StereoCamera,
    world_map: Map,
    X,
    cov_X,
    config: Config = Config(),
) -> FrameLandmarks:
    """The former :func:`~stablemarks.pipeline.select_landmarks` (a wall modelled again from scratch):
    planes, members, boundaries, models and selection for one frame (Sec 2.3–4).

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
    fits, models = [], []
    t_fit = t_model = 0.0
    plane_args = dict(camera=camera, pairs=pairs, left_segments=front.left_segments,
                      disparity_right=front.disparity.right, config=config.landmarks, plane_config=config.planes,
                      window_px=float(config.sad.block_size), valid_columns=columns, world_map=world_map, cov_X=cov_X,
                      border_sigma_px=(config.noise.boundary_px, config.noise.free_boundary_px),
                      disparity_left=front.disparity.left,
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
        model = former_landmarks_on_plane(**{**plane_args, "fit": fit})
        warnings += [why for _, why in model.rejected_boundaries]
        t_model += time.perf_counter() - tb
        if fit.plane.free_edges and not model.boundaries:
            warnings.append(f"plane {fit.plane.label!r}: no free edge found in view; its features are not modelled")
        models.append(model)
    # boundaries of different walls whose distance the map contradicts: neither is used (landmarks.boundaries_apart);
    # their walls are modelled again without them
    apart = boundaries_apart(models, config.landmarks)
    if apart:
        for n, m in enumerate(models):
            skip = {edge: why for (plane_id, edge), why in apart.items() if plane_id == m.fit.plane.id}
            if skip:
                models[n] = former_landmarks_on_plane(**{**plane_args, "fit": m.fit, "unusable": skip})
                warnings += [why for _, why in models[n].rejected_boundaries if why in skip.values()]
                if m.fit.plane.free_edges and not models[n].boundaries:
                    warnings.append(f"plane {m.fit.plane.label!r}: no free edge found in view; its features are not "
                                    "modelled")
    # walls whose own lines scatter about their fit give nothing; then the off-wall test once more with the line
    # noise the frame's own lines show, when below the model's (landmarks.off_wall_by_lines)
    before = [len(m.rejected_boundaries) for m in models]
    models, _ = off_wall_by_lines(models, config.landmarks, camera.sigma_img)
    warnings += [why for m, n in zip(models, before, strict=True) for _, why in m.rejected_boundaries[n:]]
    cands = [c for m in models for c in m.candidates]
    timings = {"disparity": t_disp, "planes": t_fit, "landmarks": t_model, "total": time.perf_counter() - t0}
    return FrameLandmarks(front, X, cov_X, preds, fits, models, cands, warnings, timings)


# ------------------------------------------------------------------ comparison
def _same(a, b, where: str = "") -> None:
    """``a`` and ``b`` equal bit for bit: arrays by dtype, shape and bytes, floats by their bits (NaN equal to NaN),
    dataclasses field by field, containers element by element."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape == b.shape, where
        assert a.tobytes() == b.tobytes(), where
    elif isinstance(a, float | np.floating) and isinstance(b, float | np.floating):
        assert type(a) is type(b) and np.float64(a).tobytes() == np.float64(b).tobytes(), where
    elif is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), where
        for f in fields(a):
            if isinstance(a, FrameLandmarks) and f.name == "front":  # the same front end, handed to both
                assert getattr(a, f.name) is getattr(b, f.name), where
                continue
            if f.name == "timings":
                continue
            _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, list | tuple):
        assert type(a) is type(b) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, slice | str | int | bool | type(None) | StereoCamera | Map):
        assert a == b, where
    else:
        assert a is b or a == b, where


def _priors(X):
    """The true pose with the tests' prior, and the pose a little off with a wider prior (other searches, gates)."""
    yield np.asarray(X, float), COV_PRIOR
    yield np.asarray(X, float) + np.array([0.06, -0.04, np.radians(1.5)]), np.diag([0.1, 0.1, np.radians(3.0)]) ** 2


@pytest.fixture(scope="module")
def frames(scenario_frames):
    """Every scenario frame with each prior: ``(name, k, camera, map, X, cov_X, front end in regions)``."""
    config = Config()
    out = []
    for name, k, left, right, camera, world_map, X in scenario_frames:
        cam = config.camera(camera)
        for X_, cov in _priors(X):
            reg = plane_regions(cam, X_, cov, world_map, config, left.shape)
            out.append((name, k, cam, world_map, X_, cov, run_front_end(left, right, config, reg)))
    return out


def _former(**landmarks) -> Config:
    """The defaults with ``landmarks`` overrides, without the test against the fitted wall
    (``landmarks.nearer_fit_sigma``), which the former landmark stage did not have."""
    return Config().with_overrides({"landmarks": {**landmarks, "nearer_fit_sigma": None}})


CONFIGS = {
    "default": _former(),
    "no nearer test": _former(nearer_fraction=1.0),
    "measured": _former(filter_boundary_sigma="measured"),
    "oblique": _former(max_incidence_deg=25.0),  # edges not searched, with why
}


@pytest.mark.parametrize("variant", list(CONFIGS))
def test_select_landmarks_same_as_former(frames, variant):
    """The frame's whole model is the former's, bit for bit, on every scenario frame and prior; some frames model
    walls again (:func:`boundaries_apart`), which is what the memo is for."""
    config = CONFIGS[variant]
    again = 0
    for name, k, cam, world_map, X, cov, front in frames:
        new = select_landmarks(front, cam, world_map, X, cov, config)
        old = former_select_landmarks(front, cam, world_map, X, cov, config)
        _same(new, old, f"{name}[{k}]")
        again += any("the map's free edges" in why for why in old.warnings)  # boundaries_apart fired
    if variant == "default":
        assert again >= 2  # the lab's first frame with both priors at least


def test_landmarks_on_plane_memo_same_as_former(frames):
    """Each wall modelled with a memo, then again with the same memo and every subset of its free edges unusable (and
    an edge named that it does not have), without a pose covariance, a map or a left disparity, with edges not searched
    (the disparity range, the incidence; their reasons are kept in the memo): each result the
    former function's with the same arguments, also when the memo was filled by a call with other ``unusable``."""
    config = _former()
    checked = 0
    for name, k, cam, world_map, X, cov, front in frames:
        model = select_landmarks(front, cam, world_map, X, cov, config)
        columns = valid_columns(front.disparity)
        base = dict(camera=cam, pairs=front.kept_pairs, left_segments=front.left_segments,
                    disparity_right=front.disparity.right, config=config.landmarks, plane_config=config.planes,
                    window_px=float(config.sad.block_size), valid_columns=columns, world_map=world_map, cov_X=cov,
                    border_sigma_px=(config.noise.boundary_px, config.noise.free_boundary_px),
                    disparity_left=front.disparity.left,
                    disparity_range=(float(config.sad.min_disparity),
                                     float(config.sad.min_disparity + config.sad.num_disparities - 1)))
        oblique = replace(config.landmarks, max_incidence_deg=25.0)
        for variant in ({}, {"cov_X": None}, {"world_map": None}, {"disparity_left": None},
                        {"disparity_range": (0.0, 16.0)}, {"config": oblique}):
            args = {**base, **variant}
            for fit in model.fits:
                if not fit:
                    continue
                edges = list(fit.plane.free_edges)
                subsets = [{}] + [{e: f"{e} unusable"} for e in edges] + [{e: "both" for e in edges}, {"p9": "?"}]
                memo: dict = {}
                for unusable in subsets + subsets[::-1]:
                    new = landmarks_on_plane(**args, fit=fit, unusable=unusable or None, memo=memo)
                    old = former_landmarks_on_plane(**args, fit=fit, unusable=unusable or None)
                    _same(new, old, f"{name}[{k}] {fit.plane.id} {unusable}")
                    _same(landmarks_on_plane(**args, fit=fit, unusable=unusable or None), old)
                    checked += 1
    assert checked > 100


def test_memo_of_another_fit_is_refused(frames):
    """A memo holds one wall's model: handed another fit, the call refuses it rather than mix the two."""
    config = Config()
    name, k, cam, world_map, X, cov, front = frames[0]
    model = select_landmarks(front, cam, world_map, X, cov, config)
    fits = [f for f in model.fits if f]
    assert len(fits) >= 2
    args = dict(camera=cam, pairs=front.kept_pairs, left_segments=front.left_segments,
                disparity_right=front.disparity.right, config=config.landmarks, plane_config=config.planes,
                world_map=world_map, cov_X=cov)
    memo: dict = {}
    landmarks_on_plane(**args, fit=fits[0], memo=memo)
    with pytest.raises(ValueError, match="another fit"):
        landmarks_on_plane(**args, fit=fits[1], memo=memo)


# ------------------------------------------------------------------ the right region's row ends, without its block
def test_right_row_ends_same_as_the_block_walk(frames):
    """:func:`~stablemarks.landmarks._right_boundary_columns` (the band tested where the walk reads it) against the
    former search's two steps, :func:`~stablemarks.landmarks._right_block` then
    :func:`~stablemarks.landmarks._block_boundary_columns`: the same rows and columns, for every fitted wall's edge
    windows, windows shifted and widened about them, the whole image, both walking directions, several holes and
    row margins (the boxes also empty, and clipped at the image's sides)."""
    from stablemarks import landmarks as L

    rng = np.random.default_rng(11)
    config = Config()
    rows_seen = 0
    for _name, _k, cam, world_map, X, cov, front in frames:
        model = select_landmarks(front, cam, world_map, X, cov, config)
        disp_r = front.disparity.right
        H, W = disp_r.shape
        for fit in (f for f in model.fits if f):
            pred = fit.prediction
            windows = [e.window(1, 3.0) for e in pred.edges.values() if np.all(np.isfinite(e.u))]
            windows += [(lo + d, hi + d + g) for lo, hi in list(windows)
                        for d, g in zip(rng.uniform(-40, 40, 4), rng.uniform(-10, 60, 4), strict=True)]
            windows += [(-5.0, W + 5.0), (W + 3.0, W + 9.0), (-20.0, -3.0), (10.0, 5.0)]
            for lo, hi in windows:
                cols = (int(np.floor(lo)) - 1, int(np.ceil(hi)) + 1)
                for margin in (0.0, 4.0, 30.0):
                    v0, c0, block = L._right_block(pred, disp_r, margin, cols)
                    sub, sv0, sc0 = L._right_box(pred, disp_r, margin, cols)
                    for outward in (-1, 1):
                        for hole in (0, 2, 7, 40):
                            want = L._block_boundary_columns(block, v0, c0, W, lo, hi, outward, hole)
                            got = L._right_boundary_columns(pred, sub, sv0, sc0, W, lo, hi, outward, hole, margin)
                            for g, wnt in zip(got, want, strict=True):
                                assert g.dtype == wnt.dtype and g.tobytes() == wnt.tobytes(), (lo, hi, margin)
                            rows_seen += len(want[0])
    assert rows_seen > 10000
