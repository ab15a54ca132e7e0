"""Issue 13, the per-frame pipeline faster (sixteenth pass): every rewritten function against the former
implementation (kept here as the reference, executed in a copy of its module's namespace) on frames of the simulated
scenarios ``lab``, ``corridor``, ``office`` and ``hall`` and on random inputs — the same values, bit for bit.

:func:`~stablemarks.planes.fit_plane` reweights in one numba call per iteration, takes its two starting medians, its
column directions and its bias rates in one numba call each and the camera's pose without an SE2;
:meth:`~stablemarks.planes.PlanePrediction.disparity_at` of one column interpolates in one numba call;
:func:`~stablemarks.planes.plane_members` tests each pixel's window in the undilated region;
:func:`~stablemarks.planes.predict_plane` without np.stack and an SE2; an edge's search
(:func:`~stablemarks.landmarks.landmarks_on_plane`) computes its inner columns and the camera's frame once for the
depth step, the gap, the boundary search and the boundary checks, the gap's columns inside its scan, the search's row
ends and robust column in one numba call per image and its columns on Python floats;
:func:`~stablemarks.landmarks.model_features` computes the per-candidate geometry in two numba passes and builds the
candidates from dict literals; :func:`~stablemarks.landmarks.select` looks a reference boundary up once;
:func:`~stablemarks.landmarks.mapped_boundaries` copies without ``dataclasses.replace``."""

from __future__ import annotations

import dataclasses
from contextlib import contextmanager

import numpy as np
import pytest

from stablemarks import landmarks as L
from stablemarks import pipeline as PL
from stablemarks import planes as P
from stablemarks.config import Config
from stablemarks.planes import PlaneConfig

from .conftest import COV_PRIOR
from .helpers import assert_same_candidate, boundary_model_inputs, disparity_variants

# ------------------------------------------------------------------ the former code
_PLANES_REFERENCE = r'''
from __future__ import annotations


def fit_plane(
    camera: StereoCamera,
    X,
    disparity: np.ndarray,
    prediction: PlanePrediction,
    config: PlaneConfig = PlaneConfig(),
) -> PlaneFit | FailedFit:
    plane = prediction.plane
    rows, cols = prediction.box(disparity.shape[0], config.row_margin_px)
    disp = np.ascontiguousarray(disparity[rows, cols])
    band, n, n_columns, n_half = _band_counts(disp, rows.start, prediction.d, prediction.sigma_d, prediction.v_top,
                                              prediction.v_bottom, float(prediction.gate), float(config.row_margin_px),
                                              rows.start % 2, cols.start % 2)
    if n < config.min_pixels:
        return FailedFit(plane, f"{n} disparity pixels in the predicted band (need {config.min_pixels})", n)
    if n_columns < config.min_columns:
        return FailedFit(plane, "band pixels span too few columns", n)
    X = np.asarray(X, dtype=float)
    cam = camera.camera_pose(X)
    fwd = np.array([np.cos(cam.theta), np.sin(cam.theta)])
    right = np.array([np.sin(cam.theta), -np.cos(cam.theta)])
    r = fwd + ((prediction.columns - camera.cu) / camera.f)[:, None] * right  # (K, 2)
    r_s, r_o = r @ plane.direction, r @ plane.normal
    c_s, c_o = float(plane.along(cam.translation)), float(plane.offset(cam.translation))
    fb = camera.f * camera.baseline
    frame = (r_s, r_o, c_s, c_o, fb, config.sigma_nu(camera))
    if n_half < config.min_pixels // 4:
        i0, k0, step = 0, 0, 1
    else:
        i0, k0, step = rows.start % 2, cols.start % 2, 2
    s, o, sigma_o, w_all, column = _wall_points_weights(disp, band, i0, k0, step, *frame)
    inl = np.ones(len(s), dtype=bool)
    a, b = median(o), 0.0
    s0 = median(s)
    scale = 1.0
    min_inliers = max(3, len(s) * config.min_pixels // (2 * n))
    outlier_sigma = float(config.outlier_sigma)
    for _ in range(4):
        scale, inl, wgt, s_in, o_in, sum_w = _reweight_sum(s, o, sigma_o, w_all, inl, float(a), float(b), float(s0),
                                                           outlier_sigma)
        if len(wgt) < min_inliers:
            return FailedFit(plane, "too few pixels agree on one wall line", n)
        s0 = float(wgt @ s_in) / sum_w
        ds, w_ds, sum_w_ds = _centred(wgt, s_in, s0)
        N_inv = _inverse_spd2(sum_w, sum_w_ds, w_ds @ ds)  # N = [[Σw, Σw·ds], [Σw·ds, Σw·ds²]]
        if N_inv is None:
            return FailedFit(plane, "wall seen over too short a span to fit", n)
        a, b = (float(v) for v in N_inv @ np.array([wgt @ o_in, w_ds @ o_in]))
    clustered = config.fit_covariance == "clustered"
    res, scores = _final_residuals(s, o, sigma_o, w_all, inl, a, b, s0, column,
                                   float(max(1.0, config.correlation_px)), clustered)
    chi2_dof = float(res @ res) / max(1, len(res) - 2)
    cov_R = N_inv * max(1.0, chi2_dof) * config.correlation_px * len(s) / n
    if clustered:
        cov_R = _at_least(cov_R, _sandwich(N_inv, scores))
    depth = (s_in - c_s) * (fwd @ plane.direction) + (o_in - c_o) * (fwd @ plane.normal)
    g = -(depth / fb) * ((o_in - c_o) - b * (s_in - c_s))
    J_beta = N_inv @ np.array([wgt @ g, w_ds @ g])
    if config.disparity_bias_px > 0 or config.disparity_tilt_px > 0:
        if config.disparity_bias_px > 0:
            cov_R = cov_R + config.disparity_bias_px**2 * np.outer(J_beta, J_beta)
        if config.disparity_tilt_px > 0:
            col = column[inl].astype(np.float64)
            lo, hi = float(col.min()), float(col.max())
            g_x = g * ((col - 0.5 * (lo + hi)) / max(0.5 * (hi - lo), 1.0))
            J_gamma = N_inv @ np.array([wgt @ g_x, w_ds @ g_x])
            cov_R = cov_R + config.disparity_tilt_px**2 * np.outer(J_gamma, J_gamma)
    region = np.zeros(np.shape(disparity), dtype=bool)
    n_keep = _on_line_region(region, rows.start, cols.start, disp, band, *frame, a, b, s0, config.outlier_sigma * scale)
    return PlaneFit(plane, prediction, a, b, s0, cov_R, region, n, n_keep, chi2_dof, X, (rows, cols), J_beta)


def _inverse_spd2(p, q, r, max_cond: float = 1e12) -> np.ndarray | None:
    p, q, r = np.float64(p), np.float64(q), np.float64(r)
    det = p * r - q * q
    lam_max = 0.5 * (p + r) + np.hypot(0.5 * (p - r), q)
    if not lam_max > 0 or not det / lam_max * max_cond >= lam_max:  # the smaller eigenvalue is det / lam_max
        return None
    return np.array([[r, -q], [-q, p]]) / det


def predict_plane(
    camera: StereoCamera,
    X,
    cov_X,
    plane: ReferencePlane,
    config: PlaneConfig = PlaneConfig(),
) -> PlanePrediction | None:
    X = np.asarray(X, dtype=float)
    cov_X = np.asarray(cov_X, dtype=float)
    gate = config.gate_sigma
    ends = np.stack([plane.P1, plane.P2])
    uv, J_X, _ = camera.project_columns(X, ends, jacobians=True)
    cov_I = J_X @ cov_X @ np.swapaxes(J_X, -1, -2)
    var_img = camera.sigma_img**2
    (c_1, _), (_, c_2) = cov_I[0].tolist()
    (e_1, _), (_, e_2) = cov_I[1].tolist()
    sig = np.array([[math.sqrt(c_1 + var_img), math.sqrt(c_2 + var_img)],
                    [math.sqrt(e_1 + var_img), math.sqrt(e_2 + var_img)]])
    edges = {
        w: EdgePrediction(w, ends[i], uv[i], sig[i], w in plane.free_edges) for i, w in enumerate(("p1", "p2"))
    }
    _, Zc = camera.to_camera(X, ends)
    if not any(z > 1e-3 for z in Zc.tolist()):
        return None
    W = camera.width
    u_ends, s_ends = uv[:, 0].tolist(), sig[:, 0].tolist()
    if all(math.isfinite(v) for v in u_ends):
        lo = _nan_extreme(min, [v - gate * s for v, s in zip(u_ends, s_ends, strict=True)])
        hi = _nan_extreme(max, [v + gate * s for v, s in zip(u_ends, s_ends, strict=True)])
    else:  # one end behind the camera: the wall runs out of the image on that side
        inside = np.isfinite(uv[:, 0])
        u_in = uv[inside, 0][0]
        s_in = sig[inside, 0][0]
        parts = visible_parts(Map((plane,)), camera, X, max_range=config.max_range, margin_px=-config.view_margin_px)
        if not parts:
            return None
        probe = plane.point_at(np.array([np.mean(parts[0].intervals[0])]))[0]
        u_probe = camera.project_columns(X, probe)[0]
        lo, hi = (u_in - gate * s_in, W - 0.5) if u_probe >= u_in else (-0.5, u_in + gate * s_in)
    u0 = int(min(max(float(np.ceil(lo)), 0.0), W - 1))  # np.clip of the whole number, on Python floats
    u1 = int(min(max(float(np.floor(hi)), 0.0), W - 1))
    if hi < 0 or lo > W - 1 or u1 < u0:
        return None
    found = _columns_on_wall(camera, X, plane, u0, u1, config.max_range)
    if found is None:
        return None
    columns, d, J_d_X, v_top, v_bottom = found
    var_d = camera.disparity_variance(J_d_X, cov_X, config.sigma_nu(camera))  # Eq 10
    return PlanePrediction(plane, columns, d, np.sqrt(var_d), v_top, v_bottom, edges, gate)


def _columns_on_wall(camera: StereoCamera, X: np.ndarray, plane: ReferencePlane, u0: int, u1: int, max_range: float):
    cam = camera.camera_pose(X)
    psi = cam.theta
    cos_p, sin_p = float(np.cos(psi)), float(np.sin(psi))
    r, dr_dth = _column_rays(u0, u1, float(camera.cu), float(camera.f), cos_p, sin_p)
    n = plane.normal
    c0 = float(n @ plane.P1)
    nr = r @ n
    num = float(c0 - n @ cam.translation)
    th = X[2]
    m = np.array([camera.mount_x, camera.mount_y])
    dc_dth = np.array([[-np.sin(th), -np.cos(th)], [np.cos(th), -np.sin(th)]]) @ m
    z_low, z_high = plane.z
    out = _wall_depths(u0, nr, dr_dth @ n, num, float(n[0]), float(n[1]), float(n @ dc_dth), float(max_range),
                       float(camera.f * camera.baseline), float(camera.f * (camera.mount_height - z_high)),
                       float(camera.f * (camera.mount_height - z_low)), float(camera.cv))
    return None if len(out[0]) == 0 else out


def plane_members(fit: PlaneFit, pairs, left_segments, config: PlaneConfig = PlaneConfig()) -> np.ndarray:
    out = np.zeros(len(pairs), dtype=bool)
    agree, region, v0, c0 = member_candidates(fit, pairs, config)
    if len(agree) == 0:
        return out
    seg = np.asarray(pairs.left_index)[agree].astype(np.int64)
    H, W = fit.region.shape
    frac = _member_fractions(seg, np.asarray(left_segments.pixel_offsets, np.int64), left_segments.pixel_uv,
                             np.ascontiguousarray(region), c0, v0, H, W)
    out[agree] = frac >= config.member_min_fraction
    return out
'''

_LANDMARKS_REFERENCE = r'''
from __future__ import annotations


def landmarks_on_plane(
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
    memo: dict | None = None,
    boundaries_only: bool = False,
    edge_pairs=None,
) -> PlaneLandmarks:
    if memo is None:
        memo = {}
    elif memo.setdefault("fit", fit) is not fit:
        raise ValueError("landmarks_on_plane: memo was made for another fit")
    if cov_X is not None:
        if "gate" not in memo:
            cov_map = world_map.accuracy_cov if world_map is not None else np.zeros((2, 2))
            memo["gate"] = fit_disagreements(camera, fit, cov_X, cov_map)
        m2, m2_slope = memo["gate"]
        if m2 > config.fit_gate_chi2:
            in_view = [e for e in fit.plane.free_edges if np.isfinite(fit.prediction.edges[e].u).all()
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
    if "members" not in memo:
        members = plane_members(fit, pairs, left_segments, plane_config)
        lo, hi = wall_columns(camera, fit, config.search_sigma)
        members = members & (pairs.u_left >= lo) & (pairs.u_left <= hi)
        idx = np.flatnonzero(members)
        members_u = np.stack([pairs.u_left[idx], pairs.u_right[idx]], axis=-1) if len(idx) else np.zeros((0, 2))
        memo["members"] = members, idx, members_u
        memo["edge_pairs"] = None if edge_pairs is None or disparity_left is None else \
            edge_pairs.subset(on_wall_pairs(camera, fit, edge_pairs, config, lo, hi))
    members, idx, members_u = memo["members"]
    boundaries, rejected, searched, hidden = [], [], [], []
    w_sad = boundary_window(config, window_px)
    for edge in fit.plane.free_edges:
        if ("edge", edge) not in memo:
            lines = members_u
            if memo["edge_pairs"] is not None and len(memo["edge_pairs"]) and \
                    np.isfinite(fit.prediction.edges[edge].u).all():
                box = fit.prediction.box(disparity_left.shape[0], plane_config.row_margin_px)
                lines = np.concatenate([members_u, edge_lines(camera, fit, edge, memo["edge_pairs"], disparity_left,
                                                              window_px, box=box)])
            memo[("edge", edge)] = _edge_search(camera, fit, edge, disparity_right, lines, config, plane_config,
                                                window_px, valid_columns, world_map, border_sigma_px,
                                                disparity_range, w_sad)
        found, rejected_before = memo[("edge", edge)]  # None: not searched; False: searched, not found
        rejected += rejected_before
        if found is None:
            continue
        searched.append(edge)
        if found is False:
            continue
        b = found
        if unusable and edge in unusable:  # found, but known not to be usable in this frame (boundaries_apart)
            rejected.append((b, unusable[edge]))
            continue
        if ("checked", edge) not in memo:
            memo[("checked", edge)] = _boundary_checks(camera, fit, b, config, window_px, cov_X, disparity_left)
        why, occluded = memo[("checked", edge)]
        if why:
            rejected.append((b, why))
            if occluded:
                hidden.append(edge)
            continue
        boundaries.append(b)
    if len(boundaries) == 2:
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
    if not boundaries or boundaries_only:
        return PlaneLandmarks(fit, boundaries, members, [], rejected, searched, hidden=hidden)
    ref = min(boundaries, key=lambda b: b.sigma_along)
    features = memo.get("features")
    if features is None or features[0] is not ref:  # the features modelled from this very boundary
        step = left_segments.contrast[pairs.left_index] / 4.0  # a Sobel_x response is 4× the step across an edge
        features = memo["features"] = ref, model_features(camera, fit, ref, pairs, idx, step, config)
    cands = features[1]
    mapped = mapped_boundaries(fit.plane, boundaries, ref)
    cands = select(cands, boundaries + mapped, config, fit.plane.z)
    if disparity_left is not None and config.nearer_fraction < 1.0:
        slope = left_segments.slope[pairs.left_index]
        chosen = [c for c in cands if c.selected]
        known = memo.setdefault("sides", {})
        keys = [(c.u_left, c.v_top, c.v_bottom, float(slope[c.pair])) for c in chosen]
        new = list(dict.fromkeys(k for k in keys if k not in known))
        if new:
            sides = beside_nearer_sides(fit, disparity_left, [k[0] for k in new], [k[1] for k in new],
                                        [k[2] for k in new], [k[3] for k in new], window_px, config.nearer_fraction)
            known.update(zip(new, sides.tolist(), strict=True))
        nearer = {id(c) for c, k in zip(chosen, keys, strict=True) if known[k]}
        if config.nearer_fit_sigma is not None:
            scored = memo.setdefault("fit_sides", {})
            rest = list(dict.fromkeys(k for c, k in zip(chosen, keys, strict=True) if id(c) not in nearer
                                      and k not in scored))
            if rest:
                z = nearer_than_fit(camera, fit, disparity_left, [k[0] for k in rest], [k[1] for k in rest],
                                    [k[2] for k in rest], [k[3] for k in rest], window_px,
                                    plane_config.sigma_nu(camera))
                scored.update(zip(rest, z.tolist(), strict=True))
            nearer |= {id(c) for c, k in zip(chosen, keys, strict=True)
                       if id(c) not in nearer and scored[k] > config.nearer_fit_sigma}
        cands = [_replace(c, selected=False, reason=REASON_BESIDE_NEARER) if id(c) in nearer else c
                 for c in cands]
    if world_map is not None and cov_X is not None and config.nearer_fraction < 1.0 and any(c.selected for c in cands):
        if "silhouettes" not in memo:
            band_px = float(fit.prediction.gate * median(fit.prediction.sigma_d)) + 1.0  # np.median, without overhead
            memo["silhouettes"] = nearer_silhouettes(camera, fit.X, cov_X, world_map, fit.plane, max_step_px=band_px)
        sil = memo["silhouettes"]
        cands = [_replace(c, selected=False, reason=REASON_BESIDE_NEARER)
                 if c.selected and _at_silhouette(camera, c, sil, config.boundary_sigma) else c
                 for c in cands]
    return PlaneLandmarks(fit, boundaries, members, cands, rejected, searched, hidden=hidden)


def _edge_search(camera: StereoCamera, fit: PlaneFit, edge: str, disparity_right, members_u, config: LandmarkConfig,
                 plane_config: PlaneConfig, window_px: float, valid_columns, world_map: Map | None, border_sigma_px,
                 disparity_range, w_sad: float) -> tuple[Boundary | bool | None, list]:
    e = fit.prediction.edges[edge]
    if not np.isfinite(e.u).all():  # the edge is behind the camera
        return None, []
    lo, hi = e.window(0, config.search_sigma)
    if hi < 0 or lo > camera.width - 1:
        return None, []
    windows = [e.window(img, config.search_sigma) for img in (0, 1)]
    if valid_columns is not None and any(
        not (vc[0] + 1 < w[0] and w[1] < vc[1] - 1) for w, vc in zip(windows, valid_columns, strict=True)
    ):
        return None, []
    if disparity_range is not None:
        d, sd = fit.prediction.disparity_at(e.u[0])
        d_lo, d_hi = float(d - config.search_sigma * sd), float(d + config.search_sigma * sd)
        if d_hi > disparity_range[1] or d_lo < disparity_range[0]:
            return None, [(None, f"plane {fit.plane.label!r}: the wall's disparity at its free edge {edge} may "
                                 f"be {d_lo:.0f}–{d_hi:.0f} px, beyond the {disparity_range[0]:g}–"
                                 f"{disparity_range[1]:g} px block matching searches (sad.min_disparity, "
                                 "sad.num_disparities): not searched")]
    incidence = edge_incidence(camera, fit.X, fit.plane, edge)
    if incidence > math.radians(config.max_incidence_deg):
        return None, [(None, f"plane {fit.plane.label!r}: its free edge {edge} is seen "
                             f"{np.degrees(incidence):.0f}° from the wall's normal (more than "
                             f"landmarks.max_incidence_deg, {config.max_incidence_deg:g}°): not searched")]
    if world_map is not None:
        if edge_occluded(camera, fit.X, world_map, fit.plane, edge):
            return None, []
        step = edge_depth_step(camera, fit.X, world_map, fit.plane, edge, window_px / 2 + 1)
        if abs(step) < config.min_edge_step_sigma * plane_config.sigma_nu(camera):
            return None, []
    bridge = None
    if world_map is not None:
        span = int(np.ceil(max(w_[1] - w_[0] for w_ in windows)))
        gap = other_wall_gap(camera, fit, world_map, edge, config.search_sigma)
        bridge = span if not np.isfinite(gap) else max(int(w_sad // 2), min(span, int(gap - w_sad)))
    b = search_boundary(camera, fit, edge, disparity_right, members_u, config, plane_config, window_px,
                        border_sigma_px, bridge)
    return (False if b is None else b), []


def _boundary_checks(camera: StereoCamera, fit: PlaneFit, b: Boundary, config: LandmarkConfig, window_px: float,
                     cov_X, disparity_left) -> tuple[str, bool]:
    edge = b.edge
    if disparity_left is not None and config.nearer_fraction < 1.0 and \
            occluded_boundary(camera, fit, disparity_left, b, window_px, config.nearer_fraction):
        return (f"plane {fit.plane.label!r}: the boundary found at {edge} is the silhouette of "
                "something nearer standing in front of the wall, not its end: not used"), True
    if cov_X is not None:
        off, sigma = boundary_disagreement(b, fit.plane, fit.X, cov_X)
        if abs(off) > config.boundary_gate_sigma * sigma:
            return (f"plane {fit.plane.label!r}: the boundary found at {edge} is {100 * off:+.1f} cm "
                    f"along the wall from the map's free edge (σ {100 * sigma:.1f} cm): not used"), False
    return "", False


def search_boundary(
    camera: StereoCamera,
    fit: PlaneFit,
    edge: str,
    disparity_right: np.ndarray | None,
    members_u: np.ndarray,
    config: LandmarkConfig = LandmarkConfig(),
    plane_config: PlaneConfig = PlaneConfig(),
    window_px: float = 15.0,
    border_sigma_px: float | tuple[float | None, float | None] | None = None,
    bridge_px: int | None = None,
) -> Boundary | None:
    w = boundary_window(config, window_px)
    pred = fit.prediction
    plane = fit.plane
    e = pred.edges[edge]
    X = fit.X
    u_inner = _inner_columns(camera, X, plane, edge)
    u_b = np.zeros(2)
    var_b = np.zeros(2)
    rows_used = 0
    snapped = False
    H, W = fit.region.shape
    v0, v1, _ = fit.box[0].indices(H)
    regions = [(fit.region[v0:max(v0, v1)], v0, 0), None]
    if disparity_right is not None and np.isfinite(e.u).all():
        lo_r, hi_r = e.window(1, config.search_sigma)
        regions[1] = _right_box(pred, disparity_right, plane_config.row_margin_px,
                                (int(np.floor(lo_r)) - 1, int(np.ceil(hi_r)) + 1))
    outwards = [-1 if e.u[img] < u_inner[img] else 1 for img in (0, 1)]
    right_found = True
    for img in (0, 1):
        outward = outwards[img]
        lo, hi = e.window(img, config.search_sigma)
        if img == 0:  # the left region exists only inside the plane's predicted window
            lo, hi = max(lo, pred.window[0]), min(hi, pred.window[1])
        if regions[img] is None:
            n_rows = 0
        else:
            block, bv0, bu0 = regions[img]
            hole = int(w // 2) if bridge_px is None else int(bridge_px)
            if img == 0:
                _, cols = _block_boundary_columns(block, bv0, bu0, W, lo, hi, outward, hole)
            else:
                _, cols = _right_boundary_columns(pred, block, bv0, bu0, disparity_right.shape[1], lo, hi, outward,
                                                  hole, plane_config.row_margin_px)
            n_rows, m, var = _robust_minimum_variance(cols, float(config.row_outlier_mad), float(lo), float(hi))
        if n_rows < config.min_boundary_rows:
            if img == 0:
                return None
            right_found = False
            continue
        if img == 0:
            rows_used = n_rows
        u_b[img] = m
        var_b[img] = var + camera.sigma_img**2
    if len(members_u):
        (ub0, ub1), (o0, o1) = u_b.tolist(), outwards
        k, farthest = -1, 0.0
        for q, (m0, m1) in enumerate(members_u.tolist()):
            b0 = (m0 - ub0) * o0
            if 0 < b0 <= w and (not right_found or abs((m1 - ub1) * o1) <= w) and (k < 0 or b0 > farthest):
                k, farthest = q, b0
        if k >= 0:
            u_b[:] = members_u[k]
            snapped = True
            var_b[:] = camera.sigma_img**2
            right_found = True
    if right_found and not snapped:
        d_here, _ = pred.disparity_at(u_b[0])
        if abs(u_b[0] - u_b[1] - float(d_here)) > w / 2.0:
            right_found = False
    if not right_found:
        d_here, _ = pred.disparity_at(u_b[0])
        u_b[1] = u_b[0] - float(d_here)
        var_b[1] = config.fallback_sigma_px**2
    border = border_sigma_px if isinstance(border_sigma_px, tuple) else (border_sigma_px, border_sigma_px)
    border = border[0] if snapped else border[1]
    var_w = w**2 / 12.0 if border is None else float(border) ** 2
    vb0, vb1 = var_b.tolist()
    cov_uv = np.array([[vb0 + var_w, var_w], [var_w, vb1 + var_w]])  # np.diag(var_b) + var_w
    sigma_u = np.sqrt(np.array([vb0 + var_w, vb1 + var_w]))
    P, cov = camera.triangulate(u_b[0], u_b[1], X, cov_uv=cov_uv)
    if not np.isfinite(P).all():
        d_here, _ = pred.disparity_at(u_b[0])
        u_b[1] = u_b[0] - float(d_here)
        P, cov = camera.triangulate(u_b[0], u_b[1], X, cov_uv=cov_uv)
    P_hat, cov_hat = fit.fuse_point(P, cov)
    t = _inward(plane, edge)
    sigma_along = float(np.sqrt(t @ cov_hat @ t))
    sigma_m = np.nan
    if config.filter_boundary_sigma == "measured":
        _, cov_m = camera.triangulate(u_b[0], u_b[1], X, cov_uv=np.diag(var_b))
        _, cov_m = fit.fuse_point(P, cov_m)
        sigma_m = float(np.sqrt(t @ cov_m @ t))
    return Boundary(plane.id, edge, u_b, sigma_u, P_hat, cov_hat, sigma_along, snapped, rows_used, t, sigma_m,
                    cov_uv, np.diag(var_b) if config.filter_boundary_sigma == "measured" else None)


def model_features(
    camera: StereoCamera,
    fit: PlaneFit,
    boundary: Boundary,
    pairs,
    member_idx: np.ndarray,
    contrast: np.ndarray | None = None,
    config: LandmarkConfig = LandmarkConfig(),
) -> list[Candidate]:
    plane = fit.plane
    X = fit.X
    edge = boundary.edge
    t = _inward(plane, edge)
    P_edge = plane.edge(edge)
    k = np.asarray(member_idx, dtype=int)
    P_f, cov_f = camera.triangulate(pairs.u_left[k], pairs.u_right[k], X)
    ok = np.isfinite(P_f).all(axis=-1)
    if not ok.any():
        return []
    k, P_f, cov_f = k[ok], P_f[ok], cov_f[ok]
    G, var_G, var_G_fit = fit.innovation(P_f, cov_f)  # is the line on the fitted wall at all?
    P_hat, cov_hat = fit.fuse_point(P_f, cov_f)
    d_p = (P_hat - boundary.P) @ t
    sigma_f = np.sqrt(np.einsum("i,kij,j->k", t, cov_hat, t))
    var_s = boundary.sigma_along**2 + sigma_f**2
    tt = np.outer(t, t)
    Xc, Zc = camera.to_camera(X, P_hat)
    z_high = camera.heights(pairs.v_top[k], Zc)
    z_low = camera.heights(pairs.v_bottom[k], Zc)
    centre = camera.optical_centres(X)[0]
    ray = P_hat - centre
    dist = np.hypot(ray[:, 0], ray[:, 1])
    view = ray / dist[:, None]
    var_Z = np.einsum("ki,kij,kj->k", view, cov_hat, view)
    sigma_row_z = Zc * config.row_sigma_px / camera.f
    h = camera.mount_height
    span = np.maximum(np.abs(h - z_low), np.abs(h - z_high))
    margin = config.off_wall_sigma * np.sqrt(sigma_row_z**2 + (span / Zc) ** 2 * var_Z)
    incidence = np.arccos(np.clip(np.abs(view @ plane.normal), 0.0, 1.0))
    J_shared, sigma_own, cov_shared = relative_error_model(camera, fit, boundary, pairs.u_left[k], pairs.u_right[k],
                                                           t, config.filter_boundary_sigma == "measured")
    d_l, sf_l, zl_l, zh_l, G_l, sG_l, sGf_l, m_l, dist_l, inc_l = (
        a.tolist() for a in (d_p, sigma_f, z_low, z_high, G, np.sqrt(var_G), np.sqrt(var_G_fit), margin, dist,
                             incidence))
    ls_l, ul_l, ur_l, vt_l, vb_l = (np.asarray(a, dtype=float)[k].tolist() for a in (
        pairs.length_similarity, pairs.u_left, pairs.u_right, pairs.v_top, pairs.v_bottom))
    c_l = [np.inf] * len(k) if contrast is None else np.asarray(contrast, dtype=float)[k].tolist()
    so_l = [np.nan] * len(k) if J_shared is None else sigma_own.tolist()
    k_l = k.tolist()
    P_model = P_edge + d_p[:, None] * t  # Eq 15, every candidate's (row j: P_edge + d_p[j] t)
    cov_model = var_s[:, None, None] * tt  # Eq 17: rank 1 along the wall
    out = []
    for rank, j in enumerate(np.argsort(d_p, kind="stable").tolist()):
        out.append(_new_candidate(dict(
            plane_id=plane.id, plane_label=plane.label, index=rank + 1, pair=k_l[j], edge=edge, s=d_l[j],
            sigma_b=boundary.sigma_along, sigma_f=sf_l[j],
            P=P_model[j], cov=cov_model[j],
            z_low=zl_l[j], z_high=zh_l[j], length_similarity=ls_l[j], u_left=ul_l[j], u_right=ur_l[j],
            v_top=vt_l[j], v_bottom=vb_l[j], selected=False, reason="",
            P_observed=P_hat[j], cov_observed=cov_hat[j], contrast=c_l[j],
            sigma_b_measured=boundary.sigma_along_measured, wall_offset=G_l[j], sigma_wall_offset=sG_l[j],
            sigma_wall_fit=sGf_l[j], height_margin=m_l[j], range=dist_l[j], incidence=inc_l[j],
            shared_jacobian=None if J_shared is None else J_shared[j], shared_cov=cov_shared, sigma_own=so_l[j])))
    return out


def select(candidates: list[Candidate], boundaries: list[Boundary], config: LandmarkConfig = LandmarkConfig(),
           z_range: tuple[float, float] | None = None):
    out = []
    for c in candidates:
        reason = on_wall_reason(c, config, z_range)
        ref = next((b for b in boundaries if b.plane_id == c.plane_id and b.edge == c.edge), None)
        P_c = ref.P + c.s * ref.inward if ref is not None else c.P_observed
        for b in boundaries:
            if reason:
                break
            if b.plane_id != c.plane_id:
                continue
            if b.edge == c.edge:
                dist = c.s
            else:  # the wall's other end, found in view or placed from the map: distance inward from it
                dist = float((P_c - b.P) @ b.inward)
            sigma_b = b.sigma_along
            if config.boundary_rule == "combined":
                margin = config.boundary_sigma * np.hypot(sigma_b, c.sigma_f)
            else:
                margin = config.boundary_sigma * (sigma_b + c.sigma_f)
            if dist < -margin:
                reason = REASON_OUTSIDE
                break
            if abs(dist) <= margin:
                reason = REASON_NEAR_BOUNDARY
                break
        if not reason and c.length_similarity < config.min_length_similarity:
            reason = REASON_LENGTH
        if not reason and c.contrast < config.min_contrast:
            reason = REASON_CONTRAST
        if not reason and c.range > config.max_range:
            reason = REASON_FAR
        if not reason and c.incidence > math.radians(config.max_incidence_deg):
            reason = REASON_OBLIQUE
        out.append(_replace(c, selected=not reason, reason=reason))
    return out


def mapped_boundaries(plane, boundaries: list[Boundary], ref: Boundary) -> list[Boundary]:
    found = {b.edge for b in boundaries}
    return [replace(ref, edge=e, P=ref.P + plane.length * ref.inward, inward=-ref.inward)
            for e in ("p1", "p2") if e not in found]


def occluded_boundary(camera: StereoCamera, fit: PlaneFit, disparity_left: np.ndarray, b: Boundary,
                      window_px: float, fraction: float) -> bool:
    pred = fit.prediction
    u = float(b.u[0])
    inner = float(_inner_columns(camera, fit.X, fit.plane, b.edge)[0])
    outward = -1 if u < inner else 1
    v_top = float(np.interp(u, pred.columns, pred.v_top))
    v_bottom = float(np.interp(u, pred.columns, pred.v_bottom))
    return int(beside_nearer_sides(fit, disparity_left, [u], [v_top], [v_bottom], [0.0], window_px, fraction,
                                   (outward,))[0]) == outward


def beside_nearer_sides(fit: PlaneFit, disparity_left: np.ndarray, u_left, v_top, v_bottom, slope,
                        window_px: float, fraction: float, sides: tuple[int, ...] = (-1, 1)) -> np.ndarray:
    pred = fit.prediction
    rows_box, cols_box = pred.box(disparity_left.shape[0])
    return _beside_nearer_sides(
        disparity_left, rows_box.start, rows_box.stop, cols_box.start, cols_box.stop,
        np.asarray(u_left, dtype=np.float64), np.asarray(v_top, dtype=np.float64),
        np.asarray(v_bottom, dtype=np.float64), np.asarray(slope, dtype=np.float64),
        int(window_px // 2) + 1, int(window_px) + 2, np.asarray(pred.columns, dtype=np.float64),
        np.asarray(pred.d, dtype=np.float64), np.asarray(pred.sigma_d, dtype=np.float64), float(pred.gate),
        float(fraction), np.asarray(sides, dtype=np.int64))


def other_wall_gap(camera: StereoCamera, fit: PlaneFit, world_map: Map, edge: str, search_sigma: float) -> float:
    e = fit.prediction.edges[edge]
    u_e = float(e.u[0])
    u_i = float(_inner_columns(camera, fit.X, fit.plane, edge)[0])
    if not np.isfinite(u_e + u_i):
        return 0.0
    lo, hi = e.window(0, search_sigma)
    outer = lo if u_e < u_i else hi
    outer = u_e + 2.0 * (outer - u_e)
    cols = np.linspace(u_e, outer, max(2, int(abs(outer - u_e)) + 1))
    walls, exclude, kept = world_map.others(fit.plane.id)
    if len(walls) == len(exclude):
        return np.inf
    cx, cy, psi, c, s = camera._frame(fit.X)
    d_edge, sigma = fit.prediction.disparity_at(u_e)
    hit = _first_wall_in_band(cols, float(camera.cu), float(camera.f), c, s, cx, cy, walls, kept,
                              float(np.cos(psi)), float(np.sin(psi)),
                              float(camera.f * camera.baseline), float(d_edge),
                              float(fit.prediction.gate * sigma + 1.0))
    return float(abs(cols[hit] - u_e)) if hit >= 0 else np.inf


def edge_depth_step(camera: StereoCamera, X, world_map: Map, plane, edge: str, offset_px: float) -> float:
    P = plane.edge(edge)
    u_e = float(camera.project_columns(X, P)[0])
    u_i = float(_inner_columns(camera, X, plane, edge)[0])
    if not np.isfinite(u_e + u_i):
        return 0.0
    u_out = u_e + float(np.sign(u_e - u_i)) * offset_px
    fb = camera.f * camera.baseline
    cx, cy, _, c, s = camera._frame(X)
    Z_e = c * (float(P[0]) - cx) + s * (float(P[1]) - cy)
    xn = (u_out - camera.cu) / camera.f
    r0, r1 = c + s * xn, s - c * xn
    norm = math.sqrt(r0 * r0 + r1 * r1)
    ray = np.array([r0 / norm, r1 / norm])
    walls, _, kept = world_map.others(plane.id)
    dist = nearest_crossing(cx, cy, float(ray[0]), float(ray[1]), walls, kept)  # ray_distances of the one ray
    cam = camera.camera_pose(X)
    Z_bg = dist * (ray @ np.array([np.cos(cam.theta), np.sin(cam.theta)]))
    return float((fb / Z_bg if np.isfinite(Z_bg) and Z_bg > 0 else 0.0) - fb / Z_e)


def edge_incidence(camera: StereoCamera, X, plane, edge: str) -> float:
    ray = plane.edge(edge) - camera.optical_centres(X)[0]
    norm = float(np.hypot(ray[0], ray[1]))
    if norm == 0.0:
        return math.pi / 2
    return math.acos(min(1.0, abs(float(ray @ plane.normal)) / norm))


def _right_box(prediction, disparity_right: np.ndarray, row_margin: float = 0.0,
               columns: tuple[int, int] | None = None) -> tuple[np.ndarray, int, int]:
    H, W = disparity_right.shape
    c0, c1 = (0, W - 1) if columns is None else (max(0, int(columns[0])), min(W - 1, int(columns[1])))
    if c1 < c0:
        return disparity_right[:0, :0], 0, 0
    v0 = max(0, int(np.floor(prediction.v_top.min() - row_margin)))
    v1 = min(H - 1, int(np.ceil(prediction.v_bottom.max() + row_margin)))
    if v1 < v0:
        return disparity_right[:0, :0], 0, 0
    return disparity_right[v0 : v1 + 1, c0 : c1 + 1], v0, c0


def boundary_disagreement(b: Boundary, plane, X, cov_X) -> tuple[float, float]:
    t = b.inward
    off = float((b.P - plane.edge(b.edge)) @ t)
    X = np.asarray(X, dtype=float)
    J = np.array([[1.0, 0.0, -(b.P[1] - X[1])], [0.0, 1.0, b.P[0] - X[0]]])  # ∂P/∂(x, y, θ)
    Jt = t @ J
    return off, float(np.sqrt(b.sigma_along**2 + Jt @ np.asarray(cov_X, dtype=float) @ Jt))


def wall_columns(camera: StereoCamera, fit: PlaneFit, search_sigma: float) -> tuple[float, float]:
    lo, hi = -np.inf, np.inf
    for name, e in fit.prediction.edges.items():
        if not np.isfinite(e.u).all():
            continue
        w_lo, w_hi = e.window(0, search_sigma)
        if _inner_columns(camera, fit.X, fit.plane, name, 0.1)[0] >= e.u[0]:  # the wall lies right of this end
            lo = w_lo if lo == -np.inf else min(lo, w_lo)
        else:
            hi = w_hi if hi == np.inf else max(hi, w_hi)
    return float(lo), float(hi)


def nearer_silhouettes(camera: StereoCamera, X, cov_X, world_map: Map, plane, min_offset: float = 0.1,
                       max_step_px: float = np.inf) -> list[tuple[int, float, float, tuple[float, float]]]:
    out = []
    fb = camera.f * camera.baseline
    centres = camera.optical_centres(X)
    offsets = [float(plane.offset(O)) for O in centres]
    walls, ends, oE_all = _wall_ends(world_map, plane)
    if not len(walls):
        return out
    a = np.abs(oE_all)
    skip = np.ones(len(a), dtype=bool)
    for oO in offsets:
        skip &= (oO * oE_all <= 0) | (a < min_offset) | (a >= abs(oO))
    todo = np.flatnonzero(~skip).tolist()
    for start in range(0, len(todo), _FEW_ENDS):
        chunk = todo[start : start + _FEW_ENDS]
        uvs, Js, _ = camera.project_columns(X, ends[chunk], jacobians=True)
        for q, i in enumerate(chunk):
            w, E, oE = walls[i // 2], ends[i], float(oE_all[i])
            uv, J = uvs[q], Js[q].copy()  # a fresh (2, 3) array, as the projection of the one end gave it
            for img in (0, 1):
                O = centres[img]
                oO = offsets[img]
                if not np.isfinite(uv[img]) or oO * oE <= 0 or abs(oE) < min_offset or abs(oE) >= abs(oO):
                    continue  # not in front of the camera, or not between the camera and the wall
                W = O + oO / (oO - oE) * (E - O)  # where the sight line past the end meets the wall
                if fb / np.hypot(*(E - O)) - fb / np.hypot(*(W - O)) > max_step_px:
                    continue
                out.append((img, float(uv[img]), float(np.sqrt(max(J[img] @ cov_X @ J[img], 0.0))), tuple(w.z)))
    return out
'''


def _reference_namespaces():
    """The former functions, each defined in a copy of its module's namespace (so that they call one another and the
    modules' unchanged helpers); the landmark stage's reference takes the former plane_members."""
    p_ns = dict(vars(P))
    exec(compile(_PLANES_REFERENCE, "planes_reference", "exec"), p_ns)
    l_ns = dict(vars(L))
    l_ns["plane_members"] = p_ns["plane_members"]
    exec(compile(_LANDMARKS_REFERENCE, "landmarks_reference", "exec"), l_ns)
    return p_ns, l_ns


REF_P, REF_L = _reference_namespaces()


def _former_disparity_at(self, u):
    """The former :meth:`~stablemarks.planes.PlanePrediction.disparity_at`: np.interp for every input."""
    u = np.asarray(u, dtype=float)
    return np.interp(u, self.columns, self.d), np.interp(u, self.columns, self.sigma_d)


@contextmanager
def _former_interp():
    """The former disparity_at in place (the references call it) while the block runs."""
    current = P.PlanePrediction.disparity_at
    P.PlanePrediction.disparity_at = _former_disparity_at
    try:
        yield
    finally:
        P.PlanePrediction.disparity_at = current


def _run_former(name: str, ns: dict):
    """The former function ``name`` of the namespace ``ns``, called with the former disparity_at."""
    def run(*args, **kwargs):
        with _former_interp():
            return ns[name](*args, **kwargs)
    return run


class _Former(dict):
    """``former[name]``: the former function, run with the former disparity_at."""

    def __init__(self, ns):
        super().__init__()
        self.ns = ns

    def __getitem__(self, name):
        return _run_former(name, self.ns)


@pytest.fixture
def former():
    """The reference namespaces' functions, each run with the former disparity_at; the current code runs with the
    current one."""
    return _Former(REF_P), _Former(REF_L)


def assert_same(a, b, where="result"):
    """``a`` and ``b`` the same bit for bit: the same types, dataclass fields, containers, arrays (NaN equal to
    NaN) and numbers."""
    assert type(a) is type(b), f"{where}: {type(a)} vs {type(b)}"
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"), where
    elif dataclasses.is_dataclass(a) and type(a).__name__ == "FrontEnd":
        assert a is b, where
    elif dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for k in a:
            assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, list | tuple):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, float | np.floating):
        assert a == b or (a != a and b != b), f"{where}: {a!r} vs {b!r}"
    else:
        assert a == b, f"{where}: {a!r} vs {b!r}"


def _fits(scenario_models):
    """Every fitted wall of the scenario models: ``(front end, model, fit)``."""
    for _, _, front, model in scenario_models:
        for fit in model.fits:
            if fit:
                yield front, model, fit


def _cameras(scenario_frames, config):
    return [config.camera(f[4]) for f in scenario_frames]


# ------------------------------------------------------------------ planes
def test_fit_plane_is_the_former(scenario_frames, scenario_models, former):
    """Every prediction of every scenario frame, on its disparity image as it is, cluttered and thinned, with the
    default configuration and with the independent covariance, a shared bias and tilt."""
    ref_p, _ = former
    rng = np.random.default_rng(16)
    configs = [PlaneConfig(), PlaneConfig(fit_covariance="independent"),
               PlaneConfig(disparity_bias_px=0.03, disparity_tilt_px=0.05)]
    n = 0
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = Config().camera(frame[4])
        for disp in disparity_variants(front.disparity.left, rng):
            for pred in model.predictions:
                for config in configs:
                    got = P.fit_plane(camera, frame[6], disp, pred, config)
                    want = ref_p["fit_plane"](camera, frame[6], disp, pred, config)
                    assert_same(got, want)
                    n += bool(got)
    assert n > 40


def test_reweight_step_is_reweight_sum():
    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 100, 1001, 8529):
        s, o = rng.normal(size=n) * 3, rng.standard_t(2, n) * 0.1
        sigma = np.abs(rng.normal(size=n)) + 0.01
        w = 1.0 / (sigma * sigma)
        for inl in (np.ones(n, bool), rng.random(n) < 0.7):
            if not inl.any():
                continue
            for a, b, s0, k in ((0.0, 0.0, 0.0, 3.0), (0.01, -0.2, 1.5, 2.0), (5.0, 1.0, -3.0, 3.0)):
                got = P._reweight_step(s, o, sigma, w, inl, a, b, s0, k)
                want = P._reweight_sum(s, o, sigma, w, inl, a, b, s0, k)
                assert_same(tuple(map(np.asarray, got)), tuple(map(np.asarray, want)))


def test_two_medians_and_column_directions():
    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 8, 101, 8001):
        x, y = rng.standard_t(3, n), np.round(rng.normal(size=n), 1)
        assert P._two_medians(x, y) == (P.median(x), P.median(y))
    for columns in (np.arange(100, 324), np.array([3]), np.array([0, 1, 5, 639])):
        for psi in (0.0, 0.3, -2.9, np.pi / 2):
            cos_p, sin_p = np.cos(psi), np.sin(psi)
            fwd, right = np.array([cos_p, sin_p]), np.array([sin_p, -cos_p])
            want = fwd + ((columns - 319.5) / 500.0)[:, None] * right
            assert np.array_equal(P._column_directions(columns, 319.5, 500.0, float(cos_p), float(sin_p)), want)


def test_interp_two_and_disparity_at_are_numpys(scenario_models):
    """np.interp of one number, NaN, infinities, nodes and the ends included; and every prediction's disparity_at
    and interp_two at columns across its window."""
    rng = np.random.default_rng(5)
    for trial in range(600):
        K = int(rng.integers(1, 40))
        xp = np.arange(K, dtype=float) + float(rng.integers(-50, 600))
        f1, f2 = rng.normal(size=K) * 10 ** rng.uniform(-3, 3), np.abs(rng.normal(size=K))
        if trial % 7 == 0:
            f1[rng.integers(0, K)] = np.nan
        if trial % 11 == 0:
            f2[rng.integers(0, K)] = np.inf
        xs = [*rng.uniform(xp[0] - 3, xp[-1] + 3, 10), *xp, xp[0] - 1e-12, xp[-1] + 1e-9, np.nan, np.inf, -np.inf]
        for x in xs:
            got = P._interp_two(float(x), xp, f1, f2)
            assert_same(tuple(map(float, got)), (float(np.interp(x, xp, f1)), float(np.interp(x, xp, f2))))
    for _, _, _, model in scenario_models:
        for pred in model.predictions:
            u0, u1 = pred.window
            for u in [*rng.uniform(u0 - 5, u1 + 5, 30), float(u0), float(u1), np.float64(u0 + 0.5)]:
                got = pred.disparity_at(u)
                want = _former_disparity_at(pred, u)
                assert_same(got, want)
                for a, b in (("v_top", "v_bottom"), ("d", "sigma_d")):
                    got = pred.interp_two(float(u), a, b)
                    want = tuple(np.interp(float(u), pred.columns, getattr(pred, name)) for name in (a, b))
                    assert_same(got, want)


def test_member_fractions_near_is_the_dilated_region():
    """Random regions inside random boxes (and a few pixels outside them), segments with pixels beyond the image."""
    rng = np.random.default_rng(6)
    for _ in range(300):
        H, W = int(rng.integers(5, 60)), int(rng.integers(5, 80))
        region = np.zeros((H, W), bool)
        bv0, bv1 = sorted(rng.integers(0, H + 1, 2))
        bc0, bc1 = sorted(rng.integers(0, W + 1, 2))
        region[bv0:bv1, bc0:bc1] = rng.random((bv1 - bv0, bc1 - bc0)) < rng.uniform(0.05, 0.9)
        region[rng.integers(0, H, 3), rng.integers(0, W, 3)] = True
        px = int(rng.integers(0, 4))
        v0, v1, c0, c1 = max(0, bv0 - px), min(H, bv1 + px), max(0, bc0 - px), min(W, bc1 + px)
        lens = rng.integers(0, 30, int(rng.integers(1, 20)))
        offsets = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        pix = np.stack([rng.integers(-5, W + 5, offsets[-1]), rng.integers(-5, H + 5, offsets[-1])], -1)
        pix = pix.astype(np.int32)
        seg = rng.integers(0, len(lens), int(rng.integers(1, 15))).astype(np.int64)
        dilated = np.ascontiguousarray(P.dilate(region[v0:v1, c0:c1], px))
        want = P._member_fractions(seg, offsets, pix, dilated, c0, v0, H, W)
        got = P._member_fractions_near(seg, offsets, pix, region, v0, v1, c0, c1, px, H, W)
        assert np.array_equal(got, want)


def test_plane_members_is_the_former(scenario_models, former):
    ref_p, _ = former
    n = 0
    for front, _, fit in _fits(scenario_models):
        for config in (PlaneConfig(), PlaneConfig(member_dilate_px=0), PlaneConfig(member_dilate_px=6)):
            got = P.plane_members(fit, front.kept_pairs, front.left_segments, config)
            assert_same(got, ref_p["plane_members"](fit, front.kept_pairs, front.left_segments, config))
            n += int(got.sum())
    assert n > 50


def test_predict_plane_is_the_former(scenario_frames, former):
    ref_p, _ = former
    rng = np.random.default_rng(7)
    config = Config()
    n = 0
    for frame in scenario_frames:
        camera = config.camera(frame[4])
        for X in [frame[6]] + [frame[6] + rng.normal(0, [0.3, 0.3, 0.2]) for _ in range(3)]:
            for cov in (COV_PRIOR, COV_PRIOR * 25):
                for plane in frame[5].reference_planes:
                    got = P.predict_plane(camera, X, cov, plane, config.planes)
                    assert_same(got, ref_p["predict_plane"](camera, X, cov, plane, config.planes))
                    n += got is not None
    assert n > 40


# ------------------------------------------------------------------ landmarks
def _free_edges(scenario_frames, scenario_models):
    config = Config()
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for plane in model.planes:
            for edge in plane.fit.plane.free_edges:
                yield camera, frame[5], front, plane, edge


def test_edge_helpers_are_the_former(scenario_frames, scenario_models, former):
    """The gap, the depth step, the incidence of every free edge of every fitted wall, from the fit's pose and from
    poses off it; the occlusion test of every boundary found."""
    _, ref_l = former
    rng = np.random.default_rng(8)
    sigma = Config().landmarks.search_sigma
    n = 0
    for camera, world_map, front, plane, edge in _free_edges(scenario_frames, scenario_models):
        fit = plane.fit
        for X in [fit.X] + [fit.X + rng.normal(0, [0.2, 0.2, 0.05]) for _ in range(2)]:
            f = dataclasses.replace(fit, X=X)
            assert_same(L.other_wall_gap(camera, f, world_map, edge, sigma),
                        ref_l["other_wall_gap"](camera, f, world_map, edge, sigma))
            for offset in (1.0, 8.5):
                assert_same(L.edge_depth_step(camera, X, world_map, fit.plane, edge, offset),
                            ref_l["edge_depth_step"](camera, X, world_map, fit.plane, edge, offset))
            assert_same(L.edge_incidence(camera, X, fit.plane, edge),
                        ref_l["edge_incidence"](camera, X, fit.plane, edge))
            assert_same(L.wall_columns(camera, f, sigma), ref_l["wall_columns"](camera, f, sigma))
            for step in (np.inf, 0.6):
                assert_same(L.nearer_silhouettes(camera, X, COV_PRIOR, world_map, fit.plane, max_step_px=step),
                            ref_l["nearer_silhouettes"](camera, X, COV_PRIOR, world_map, fit.plane, max_step_px=step))
            for b in plane.boundaries:
                for cov in (COV_PRIOR, COV_PRIOR * 9):
                    assert_same(L.boundary_disagreement(b, fit.plane, X, cov),
                                ref_l["boundary_disagreement"](b, fit.plane, X, cov))
            n += 1
        for b in plane.boundaries + [b for b, _ in plane.rejected_boundaries if b is not None]:
            for fraction in (0.3, 0.6):
                assert_same(L.occluded_boundary(camera, fit, front.disparity.left, b, 15.0, fraction),
                            ref_l["occluded_boundary"](camera, fit, front.disparity.left, b, 15.0, fraction))
    assert n > 20


def test_search_boundary_is_the_former(scenario_frames, scenario_models, former):
    """Every free edge of every fitted wall, with the wall's members, holes bridged as by default, narrow and wide,
    the border's σ as the pipeline gives it and as a uniform allowance."""
    _, ref_l = former
    config = Config()
    n = 0
    for camera, _, front, plane, edge in _free_edges(scenario_frames, scenario_models):
        fit = plane.fit
        idx = np.flatnonzero(plane.members)
        pairs = front.kept_pairs
        members_u = np.stack([pairs.u_left[idx], pairs.u_right[idx]], axis=-1) if len(idx) else np.zeros((0, 2))
        for lines in (members_u, np.zeros((0, 2))):
            for bridge in (None, 2, 40):
                for border in ((config.noise.boundary_px, config.noise.free_boundary_px), None):
                    args = (camera, fit, edge, front.disparity.right, lines, config.landmarks, config.planes, 15.0,
                            border, bridge)
                    got = L.search_boundary(*args)
                    assert_same(got, ref_l["search_boundary"](*args))
                    n += got is not None
    assert n > 20


def test_model_features_select_and_mapped_boundaries_are_the_former(scenario_frames, scenario_models, former):
    _, ref_l = former
    config = Config()
    n = 0
    for camera, plane, b, pairs, idx, step in boundary_model_inputs(scenario_frames, scenario_models, config):
        got = L.model_features(camera, plane.fit, b, pairs, idx, step, config.landmarks)
        want = ref_l["model_features"](camera, plane.fit, b, pairs, idx, step, config.landmarks)
        assert len(got) == len(want)
        for a, c in zip(got, want, strict=True):
            assert_same_candidate(a, c)
        mapped = L.mapped_boundaries(plane.fit.plane, plane.boundaries, b)
        assert_same(mapped, ref_l["mapped_boundaries"](plane.fit.plane, plane.boundaries, b))
        for bounds in (plane.boundaries + mapped, mapped, []):
            for a, c in zip(L.select(got, bounds, config.landmarks, plane.fit.plane.z),
                            ref_l["select"](want, bounds, config.landmarks, plane.fit.plane.z), strict=True):
                assert_same_candidate(a, c)
        n += len(got)
    assert n > 20
    with pytest.raises(TypeError):
        L._replace_boundary(b, edges="p1")


def test_select_landmarks_is_the_former(scenario_frames, scenario_models, monkeypatch):
    """The whole landmark stage of every scenario frame, from its true pose and from one off it, with the former fit
    and landmark model in the pipeline against the current ones: the same fits, boundaries, candidates and
    warnings."""
    config = Config()
    rng = np.random.default_rng(9)
    runs = []
    for frame, (_, _, front, _) in zip(scenario_frames, scenario_models, strict=True):
        for X in (frame[6], frame[6] + rng.normal(0, [0.05, 0.05, 0.01])):
            runs.append((front, frame[4], frame[5], X))
    got = [PL.select_landmarks(front, camera, world_map, X, COV_PRIOR, config)
           for front, camera, world_map, X in runs]
    monkeypatch.setattr(PL, "fit_plane", REF_P["fit_plane"])
    monkeypatch.setattr(PL, "landmarks_on_plane", REF_L["landmarks_on_plane"])
    with _former_interp():
        want = [PL.select_landmarks(front, camera, world_map, X, COV_PRIOR, config)
                for front, camera, world_map, X in runs]
    n = 0
    for a, b in zip(got, want, strict=True):
        assert_same(a.fits, b.fits)
        assert_same([(m.boundaries, m.members, m.rejected_boundaries, m.searched, m.gated, m.hidden) for m in a.planes],
                    [(m.boundaries, m.members, m.rejected_boundaries, m.searched, m.gated, m.hidden) for m in b.planes])
        assert len(a.candidates) == len(b.candidates)
        for x, y in zip(a.candidates, b.candidates, strict=True):
            assert_same_candidate(x, y)
        assert a.warnings == b.warnings
        n += len(a.candidates)
    assert n > 50


def test_right_rows_tested_on_their_disparity_only_walk_the_same():
    """:func:`~stablemarks.landmarks._right_end_column` (rows inside every column's band rows tested on the disparity
    only) against :func:`~stablemarks.landmarks._right_row_ends` and the robust column of its rows, on random boxes of
    disparities around random bands: flat and slanted rows, NaN holes, both directions, narrow and wide holes."""
    rng = np.random.default_rng(10)
    n = 0
    for trial in range(300):
        K = int(rng.integers(2, 80))
        u0 = int(rng.integers(0, 200))
        d = rng.uniform(5, 40) + rng.uniform(-0.2, 0.2) * np.arange(K)
        sigma_d = np.abs(rng.normal(0.5, 0.3, K)) + 0.05
        top = rng.uniform(0, 60) + (rng.uniform(-0.3, 0.3) * np.arange(K) if trial % 2 else 0.0)
        bottom = top + rng.uniform(20, 120)
        table = np.zeros((K, 8))
        for q, a in enumerate((d, sigma_d, np.asarray(top + 0.0 * d), np.asarray(bottom + 0.0 * d))):
            table[:, 2 * q] = a
            table[:-1, 2 * q + 1] = a[1:] - a[:-1]
        h, w = int(rng.integers(1, 150)), int(rng.integers(1, 90))
        c0, v0 = int(rng.integers(max(0, u0 - 60), u0 + K)), int(rng.integers(0, 40))
        sub = (np.interp(np.arange(c0, c0 + w) + 20.0, np.arange(u0, u0 + K), d)[None, :]
               + rng.normal(0, rng.uniform(0.1, 3.0), (h, w))).astype(np.float32)
        sub[rng.random((h, w)) < rng.uniform(0, 0.4)] = np.nan
        sub = np.asfortranarray(sub)[:, ::-1][:, ::-1] if trial % 3 == 0 else sub  # a strided box too
        w0, w1 = sorted(rng.integers(c0 - 5, c0 + w + 5, 2))
        w0 = max(w0, 0)
        if w1 < w0:
            continue
        for outward in (-1, 1):
            for hole in (0, 3, 60):
                rows, cols = L._right_row_ends(sub, c0, v0, u0, table, 3.0, 4.0, int(w0), int(w1), outward, hole)
                want = L._robust_minimum_variance(cols, 3.0, float(w0), float(w1))
                got = L._right_end_column(sub, c0, v0, u0, table, 3.0, 4.0, int(w0), int(w1), outward, hole, 3.0,
                                          float(w0), float(w1))
                assert_same(tuple(map(float, got)), tuple(map(float, want)))
                n += len(rows)
    assert n > 1000


def test_row_ends_looked_for_from_the_outer_side_are_the_walks():
    """When every hole is bridged, :func:`~stablemarks.landmarks._left_end_column`'s row ends (from the window's
    outer side, :func:`~stablemarks.landmarks._block_row_ends_back`) are :func:`~stablemarks.landmarks._block_row_ends`'
    walk's: random regions with holes, runs that reach the outer side, rows without a pixel, windows beyond the block,
    both directions, holes just wide enough and wider."""
    rng = np.random.default_rng(11)
    n_rows = 0
    for _ in range(400):
        h, w = int(rng.integers(1, 40)), int(rng.integers(1, 60))
        block = rng.random((h, w)) < rng.uniform(0.1, 0.95)
        block[rng.random(h) < 0.2] = False
        u0, v0 = int(rng.integers(0, 30)), int(rng.integers(0, 30))
        c0, c1 = sorted(rng.integers(u0 - 5, u0 + w + 5, 2))
        c0 = max(c0, 0)
        if c1 < c0:
            continue
        for outward in (-1, 1):
            for extra in (0, 1, 50):
                hole = c1 - c0 - 1 + extra
                want = L._block_row_ends(block, v0, u0, int(c0), int(c1), outward, hole)
                got = L._block_row_ends_back(block, v0, u0, int(c0), int(c1), outward)
                assert_same(got, want)
                n_rows += len(want[0])
    assert n_rows > 1000
