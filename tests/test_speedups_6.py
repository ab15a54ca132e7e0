"""Issue 13, the per-frame pipeline faster (sixth pass): every replaced computation against the former
implementation (kept here as the reference) on frames of several simulated scenarios and on random inputs — the
same values, bit for bit."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numba import njit

from stablemarks import landmarks as L
from stablemarks import planes as P
from stablemarks.config import Config
from stablemarks.landmarks import relative_error_model


# ------------------------------------------------------------------ the plane fit's reweighting steps
def fit_plane_reference(camera, X, disparity, prediction, config):
    """The former :func:`~stablemarks.planes.fit_plane`: the reweighting steps as NumPy expressions."""
    plane = prediction.plane
    rows, cols, band = prediction.band_box(disparity, config.row_margin_px)
    n = int(np.count_nonzero(band))
    if n < config.min_pixels:
        return P.FailedFit(plane, f"{n} disparity pixels in the predicted band (need {config.min_pixels})", n)
    if np.count_nonzero(band.any(axis=0)) < config.min_columns:
        return P.FailedFit(plane, "band pixels span too few columns", n)
    # Every pixel of the band's box in the wall frame, placed with the mean pose: the left pixel at column
    # u with depth Z is at c + Z r(u), r(u) = fwd + (u − cu)/f · right the world direction of unit depth.
    X = np.asarray(X, dtype=float)
    cam = camera.camera_pose(X)
    fwd = np.array([np.cos(cam.theta), np.sin(cam.theta)])
    right = np.array([np.sin(cam.theta), -np.cos(cam.theta)])
    r = fwd + ((prediction.columns - camera.cu) / camera.f)[:, None] * right  # (K, 2)
    r_s, r_o = r @ plane.direction, r @ plane.normal
    c_s, c_o = float(plane.along(cam.translation)), float(plane.offset(cam.translation))
    fb = camera.f * camera.baseline
    # Fit on every other row and column (neighbouring pixels share their SAD window anyway), then
    # classify every band pixel with the final line.
    disp = disparity[rows, cols]
    frame = (r_s, r_o, c_s, c_o, fb, config.sigma_nu(camera))
    if np.count_nonzero(band[rows.start % 2 :: 2, cols.start % 2 :: 2]) < config.min_pixels // 4:
        s, o, sigma_o = P._wall_points(disp, band, 0, 0, 1, *frame)
    else:
        s, o, sigma_o = P._wall_points(disp, band, rows.start % 2, cols.start % 2, 2, *frame)
    w_all = 1.0 / sigma_o**2
    # Robust start: the median offset, then reweighted least squares with outlier rejection.
    inl = np.ones(len(s), dtype=bool)
    a, b = P.median(o), 0.0
    s0 = P.median(s)
    scale = 1.0
    min_inliers = max(3, len(s) * config.min_pixels // (2 * n))
    for _ in range(4):
        res = (o - a - b * (s - s0)) / sigma_o
        # the data's own spread, not the model's σ: disparity noise is often below σ_ν, and clutter
        # a few tens of cm in front of a wall is then still separable
        scale = max(1e-3, 1.4826 * P.median(np.abs(res[inl])))
        inl = np.abs(res) <= config.outlier_sigma * scale
        if np.count_nonzero(inl) < min_inliers:
            return P.FailedFit(plane, "too few pixels agree on one wall line", n)
        wgt, s_in, o_in = w_all[inl], s[inl], o[inl]
        sum_w = float(wgt.sum())
        s0 = float(wgt @ s_in) / sum_w
        ds = s_in - s0
        w_ds = wgt * ds
        N = np.array([[sum_w, w_ds.sum()], [w_ds.sum(), w_ds @ ds]])
        N_inv = P._inverse_spd2(N)
        if N_inv is None:
            return P.FailedFit(plane, "wall seen over too short a span to fit", n)
        a, b = (float(v) for v in N_inv @ np.array([wgt @ o_in, w_ds @ o_in]))
    res = (o[inl] - a - b * (s[inl] - s0)) / sigma_o[inl]
    chi2_dof = float(res @ res) / max(1, int(np.count_nonzero(inl)) - 2)
    # one independent measurement per `correlation_px` pixels of the full band (the subsample carries
    # len(s)/n of its information). The residuals are correlated down the column as well (13–14 px either way
    # with 15 px windows, measured on the simulator's walls); counting one measurement per window area, with
    # the residuals' own spread, was tried (December 2026, with the snapped boundary's σ taken from its line)
    # and made the whole filter more cautious, not more consistent (room's pose NEES 3.1 → 1.5, 20 trials): the
    # landmarks it feeds are already held less certain than their errors, by the boundary's σ. Not adopted.
    cov_R = N_inv * max(1.0, chi2_dof) * config.correlation_px * len(s) / n
    if config.disparity_bias_px > 0:
        # a disparity error β shared by the wall moves each pixel along its ray: ∂(s, o)/∂β = −Z/(f b) (s − c_s,
        # o − c_o), Z the pixel's depth; the line (a, b) follows through the weighted least squares
        depth = (s_in - c_s) * (fwd @ plane.direction) + (o_in - c_o) * (fwd @ plane.normal)
        g = -(depth / fb) * ((o_in - c_o) - b * (s_in - c_s))
        J_beta = N_inv @ np.array([wgt @ g, w_ds @ g])
        cov_R = cov_R + config.disparity_bias_px**2 * np.outer(J_beta, J_beta)
    keep = P._on_line(disp, band, *frame, a, b, s0, config.outlier_sigma * scale)
    region = np.zeros(disparity.shape, dtype=bool)
    region[rows, cols] = keep
    return P.PlaneFit(plane, prediction, a, b, s0, cov_R, region, n, int(np.count_nonzero(keep)),
                    chi2_dof, X, (rows, cols))


def _same_fit(a, b) -> None:
    assert type(a) is type(b)
    if not a:
        assert (a.reason, a.n_pixels) == (b.reason, b.n_pixels)
        return
    for name in ("a", "b", "s0", "n_points", "n_inliers", "chi2_dof"):
        assert getattr(a, name) == getattr(b, name), name
    assert np.array_equal(a.cov_R, b.cov_R)
    assert np.array_equal(a.region, b.region)
    assert a.box == b.box


def test_fit_plane_equals_the_reference(scenario_frames, scenario_models):
    """Every predicted plane of every frame, on its disparity image and with the band's pixels corrupted (clutter in
    front of the wall) or thinned (too few pixels), with and without the shared disparity bias: the same fit, bit
    for bit, or the same failure."""
    rng = np.random.default_rng(13)
    config = Config()
    n_fits = n_failed = 0
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for pred in model.predictions:
            disp = np.array(front.disparity.left)
            cluttered = disp.copy()
            rows, cols = pred.box(disp.shape[0], config.planes.row_margin_px)
            box = cluttered[rows, cols]
            patch = rng.random(box.shape) < 0.2
            box[patch] += rng.uniform(0.5, 3.0, int(patch.sum())).astype(np.float32)
            sparse = disp.copy()
            sparse[rng.random(disp.shape) < 0.97] = np.nan
            for d in (disp, cluttered, sparse):
                for pc in (config.planes, P.PlaneConfig(disparity_bias_px=0.03, outlier_sigma=2.0)):
                    new = P.fit_plane(camera, model.X, d, pred, pc)
                    _same_fit(new, fit_plane_reference(camera, model.X, d, pred, pc))
                    n_fits += bool(new)
                    n_failed += not new
    assert n_fits > 20 and n_failed > 0


def test_reweight_equals_numpy_on_random_points():
    """:func:`~stablemarks.planes._reweight` against the NumPy expressions it replaced, on random lines and points
    with outliers, odd and even inlier counts, and ties in the residuals."""
    rng = np.random.default_rng(7)
    for trial in range(200):
        n = int(rng.integers(3, 400))
        s = rng.normal(0, 2, n)
        o = rng.normal(0, 0.01, n) + (rng.random(n) < 0.2) * rng.normal(0, 0.3, n)
        if trial % 10 == 0:
            o = np.round(o, 2)  # ties
        sigma_o = rng.uniform(1e-3, 0.05, n)
        w_all = 1.0 / sigma_o**2
        inl = rng.random(n) < 0.8
        inl[:2] = True
        a, b, s0 = float(rng.normal(0, 0.01)), float(rng.normal(0, 0.01)), float(rng.normal())
        k = float(rng.choice([2.0, 3.0, 3.5]))
        scale, new, wgt, s_in, o_in = P._reweight(s, o, sigma_o, w_all, inl, a, b, s0, k)
        res = (o - a - b * (s - s0)) / sigma_o
        ref_scale = max(1e-3, 1.4826 * P.median(np.abs(res[inl])))
        ref_inl = np.abs(res) <= k * ref_scale
        assert scale == ref_scale
        assert np.array_equal(new, ref_inl)
        for x, y in ((wgt, w_all[ref_inl]), (s_in, s[ref_inl]), (o_in, o[ref_inl])):
            assert np.array_equal(x, y)


# ------------------------------------------------------------------ the relative model's slope steps
def relative_error_model_reference(camera, fit, boundary, u_left, u_right, t,
                         measured: bool = False, step_px: float = 0.01, step_line: float = 1e-4):
    """The former :func:`~stablemarks.landmarks.relative_error_model`: the slope's steps through copies of the
    fit (``dataclasses.replace``) and :meth:`PlaneFit.fuse_point`."""
    cov_ub = boundary.cov_uv_measured if measured and boundary.cov_uv_measured is not None else boundary.cov_uv
    if cov_ub is None:
        return None, None, None
    X = fit.X
    n_f = len(np.atleast_1d(u_left))
    u_f = np.stack([np.asarray(u_left, dtype=float).ravel(), np.asarray(u_right, dtype=float).ravel()], axis=-1)
    steps = np.array([[0.0, 0.0], [step_px, 0.0], [-step_px, 0.0], [0.0, step_px], [0.0, -step_px]])  # (5, 2)
    uf = u_f[None, :, :] + steps[:, None, :]  # (5, n, 2): base, ±u_l, ±u_r
    ub = np.asarray(boundary.u, dtype=float)[None, :] + steps  # (5, 2)
    P_f, cov_f = camera.triangulate(uf[..., 0], uf[..., 1], X)  # (5, n, 2)
    P_b, cov_b = camera.triangulate(ub[:, 0], ub[:, 1], X, cov_uv=cov_ub)  # (5, 2)
    nrm = fit.plane.normal
    # the base line on: every column variant, and the base columns moved ∓h along the normal (a ± h)
    hf = np.stack([P_f[0] - step_line * nrm, P_f[0] + step_line * nrm])  # (2, n, 2)
    hb = np.stack([P_b[0] - step_line * nrm, P_b[0] + step_line * nrm])  # (2, 2)
    cov_hf = np.broadcast_to(cov_f[0], hf.shape + (2,))
    cov_hb = np.broadcast_to(cov_b[0], hb.shape + (2,))
    F, _ = fit.fuse_point(np.concatenate([P_f, hf]), np.concatenate([cov_f, cov_hf]))
    B, _ = fit.fuse_point(np.concatenate([P_b, hb]), np.concatenate([cov_b, cov_hb]))
    F[5] += step_line * nrm
    F[6] -= step_line * nrm
    B[5] += step_line * nrm
    B[6] -= step_line * nrm
    slope = []
    for h in (step_line, -step_line):
        line = replace(fit, b=fit.b + h)
        slope.append((line.fuse_point(P_f[0], cov_f[0])[0] - line.fuse_point(P_b[0], cov_b[0])[0]) @ t)
    base_b = B[0]
    J = np.empty((n_f, 4))
    J[:, 0] = ((F[5] - B[5]) @ t - (F[6] - B[6]) @ t) / (2 * step_line)
    J[:, 1] = (slope[0] - slope[1]) / (2 * step_line)
    J[:, 2] = ((F[0] - B[1]) @ t - (F[0] - B[2]) @ t) / (2 * step_px)
    J[:, 3] = ((F[0] - B[3]) @ t - (F[0] - B[4]) @ t) / (2 * step_px)
    own = (((F[1] - base_b) @ t - (F[2] - base_b) @ t) / (2 * step_px) * camera.sigma_img) ** 2
    own += (((F[3] - base_b) @ t - (F[4] - base_b) @ t) / (2 * step_px) * camera.sigma_img) ** 2
    cov_shared = np.zeros((4, 4))
    cov_shared[:2, :2] = fit.cov_R
    cov_shared[2:, 2:] = cov_ub
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(own))):
        return None, None, None
    return J, np.sqrt(own), cov_shared


def test_relative_error_model_equals_the_reference(scenario_frames, scenario_models):
    """The error model of every plane's candidates, from every boundary found, both variants (``measured``): the
    same Jacobians, own σ and shared covariance, bit for bit."""
    config = Config()
    n = 0
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        pairs = front.kept_pairs
        for plane in model.planes:
            for b in plane.boundaries:
                t = plane.fit.plane.direction if b.edge == "p1" else -plane.fit.plane.direction
                idx = np.flatnonzero(plane.members)
                for measured in (False, True):
                    got = relative_error_model(camera, plane.fit, b, pairs.u_left[idx], pairs.u_right[idx], t, measured)
                    want = relative_error_model_reference(camera, plane.fit, b, pairs.u_left[idx], pairs.u_right[idx],
                                                          t, measured)
                    for x, y in zip(got, want, strict=True):
                        assert (x is None and y is None) or np.array_equal(x, y)
                    n += got[0] is not None
    assert n > 5


# ------------------------------------------------------------------ the segments' edge pixels
@njit(cache=False)
def detect_and_link_reference(gx, threshold, max_drift, max_gap):
    """The former :func:`~stablemarks.vision.segments._detect_and_link`: the compaction of each row's maxima
    branch-free over every column."""
    H, W = gx.shape
    cap = H * W
    ev = np.empty(cap, np.int32)
    ecol = np.empty(cap, np.int32)
    nxt = np.empty(cap, np.int32)
    head = np.empty(cap, np.int32)
    tail = np.empty(cap, np.int32)
    first_row = np.empty(cap, np.int32)
    last_row = np.empty(cap, np.int32)
    # Candidate predecessors other than the one directly above, cheapest first:
    # (rows up, column offset) by growing drift, then bridged gaps.
    n_off = 0
    off_k = np.empty((max_gap + 1) * (2 * max_drift * (max_gap + 1) + 1), np.int64)
    off_dc = np.empty_like(off_k)
    for k in range(1, max_gap + 2):
        for a in range(0, k * max_drift + 1):
            for sgn in (-1, 1):
                if (a == 0 and sgn == 1) or (k == 1 and a == 0):
                    continue
                off_k[n_off] = k
                off_dc[n_off] = sgn * a
                n_off += 1
    # ring[v % n_ring, margin + col] = 2 run + (sign > 0) of the edge pixel at (v, col) of a recent
    # row, or -1; the margin spares bound checks.
    n_ring = max_gap + 2
    margin = (max_gap + 1) * max_drift
    ring = np.full((n_ring, W + 2 * margin), -1, np.int32)
    slot_up = np.empty(max_gap + 2, np.int64)  # ring row of row v - k
    is_max = np.zeros(W, np.bool_)
    run_of = np.empty(W, np.int32)  # run of each edge pixel of the current row
    n_e = 0
    n_ch = 0
    for v in range(H):
        row = gx[v]
        # Branch-free NMS (vectorizes) and compaction; ties go to the left pixel of a plateau.
        for c in range(1, W - 1):
            g, gl, gr = row[c], row[c - 1], row[c + 1]
            is_max[c] = ((g >= threshold) & (g > gl) & (g >= gr)) | ((g <= -threshold) & (g < gl) & (g <= gr))
        row_start = n_e
        for c in range(1, W - 1):
            ecol[n_e] = c
            n_e += is_max[c]
        n_row = n_e - row_start
        for k in range(max_gap + 2):
            slot_up[k] = (v - k) % n_ring
        for e in range(n_row):
            run_of[e] = -1
        if v >= 1:  # first every direct continuation, so that a drifting pixel cannot steal it
            above = slot_up[1]
            for e in range(n_row):
                c = ecol[row_start + e]
                code = ring[above, margin + c]
                if code >= 0 and (code & 1) == (row[c] > 0) and last_row[code >> 1] == v - 1:
                    run_of[e] = code >> 1
        for e in range(n_row):
            c = ecol[row_start + e]
            ch = run_of[e]
            if ch < 0:
                positive = row[c] > 0
                for o in range(n_off):
                    vv = v - off_k[o]
                    if vv < 0:
                        break
                    code = ring[slot_up[off_k[o]], margin + c + off_dc[o]]
                    if code >= 0 and (code & 1) == positive and last_row[code >> 1] == vv:
                        ch = code >> 1
                        break
            if ch < 0:
                ch = n_ch
                n_ch += 1
                head[ch] = row_start + e
                first_row[ch] = v
            else:
                nxt[tail[ch]] = row_start + e
            run_of[e] = ch
            tail[ch] = row_start + e
            last_row[ch] = v
            ev[row_start + e] = v
            nxt[row_start + e] = -1
        slot = slot_up[0]
        ring[slot, :] = -1
        for e in range(n_row):
            c = ecol[row_start + e]
            ring[slot, margin + c] = 2 * run_of[e] + (row[c] > 0)
    return ev[:n_e], ecol[:n_e], nxt[:n_e], head[:n_ch], first_row[:n_ch], last_row[:n_ch]


def test_detect_and_link_equals_the_reference(scenario_frames):
    """The edge pixels, their links and the runs of every scenario frame's images (their x-Sobel, int16) and of
    random images (uint8 and float gradients, widths not a multiple of 8, down to 3 columns, flat and noisy), with
    several drifts and gaps: the same arrays."""
    import cv2

    from stablemarks.vision.segments import _detect_and_link

    cases = []
    for _, _, left, right, *_ in scenario_frames:
        for img in (left, right):
            cases.append((cv2.Sobel(img, cv2.CV_16S, 1, 0, ksize=3), np.int16(20)))
    rng = np.random.default_rng(3)
    for h, w in ((3, 3), (5, 9), (40, 17), (64, 64), (120, 161)):
        img = (rng.random((h, w)) * 255).astype(np.uint8)
        cases.append((cv2.Sobel(img, cv2.CV_16S, 1, 0, ksize=3), np.int16(40)))
        cases.append((cv2.Sobel(np.zeros((h, w), np.uint8), cv2.CV_16S, 1, 0, ksize=3), np.int16(1)))
        cases.append((cv2.Sobel(rng.random((h, w)).astype(np.float32), cv2.CV_32F, 1, 0, ksize=3), np.float32(0.3)))
    for gx, threshold in cases:
        for drift, gap in ((1, 1), (0, 0), (2, 3)):
            got = _detect_and_link(gx, threshold, drift, gap)
            want = detect_and_link_reference(gx, threshold, drift, gap)
            assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))


# ------------------------------------------------------------------ the planes' regions taken from plane_regions
def test_plane_regions_keep_what_select_landmarks_would_compute(scenario_frames):
    """The rectangles and edge windows :func:`plane_regions` keeps are those :func:`select_landmarks` computed from
    the same predictions; and a frame's model with them taken from the regions equals the one with them computed
    again (regions without ``shape`` / ``windows``): the same disparity pixels, fits, candidates and selection."""
    from dataclasses import replace as dc_replace

    from stablemarks.pipeline import edge_windows, plane_regions, prediction_regions, run_front_end, select_landmarks

    config = Config()
    cov = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
    for _, _, left, right, camera, world_map, X in scenario_frames:
        reg = plane_regions(camera, X, cov, world_map, config, left.shape)
        again = prediction_regions(reg.predictions, left.shape, config)
        assert reg.shape == left.shape
        assert np.array_equal(reg.left, again.left) and np.array_equal(reg.right, again.right)
        assert reg.windows == edge_windows(reg.predictions, config)
        models = []
        for regions in (reg, dc_replace(reg, shape=None, windows=None)):
            front = run_front_end(left, right, config, regions)
            models.append(select_landmarks(front, camera, world_map, X, cov, config))
        a, b = models
        for x, y in zip(a.front.disparity.__dict__.values(), b.front.disparity.__dict__.values(), strict=True):
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f")
        assert [bool(f) and (f.a, f.b) for f in a.fits] == [bool(f) and (f.a, f.b) for f in b.fits]
        assert [(c.pair, c.s, c.selected, c.reason) for c in a.candidates] == \
            [(c.pair, c.s, c.selected, c.reason) for c in b.candidates]
        assert a.warnings == b.warnings


# ------------------------------------------------------------------ the candidates' numbers
def model_features_reference(
    camera,
    fit,
    boundary,
    pairs,
    member_idx,
    contrast=None,
    config=None,
):
    """The former :func:`~stablemarks.landmarks.model_features`: each candidate's numbers taken one by one with
    ``float(a[j])``."""
    config = config or L.LandmarkConfig()
    plane = fit.plane
    X = fit.X
    edge = boundary.edge
    t = L._inward(plane, edge)
    P_edge = plane.edge(edge)
    k = np.asarray(member_idx, dtype=int)
    P_f, cov_f = camera.triangulate(pairs.u_left[k], pairs.u_right[k], X)
    ok = np.all(np.isfinite(P_f), axis=-1)
    if not ok.any():
        return []
    k, P_f, cov_f = k[ok], P_f[ok], cov_f[ok]
    # Eq 12's innovation before the fusion: is the line on the fitted wall at all?
    G, J_G_P, J_G_R = fit.constraint(P_f)
    var_G = np.einsum("i,kij,j->k", J_G_P, cov_f, J_G_P) + np.einsum("ki,ij,kj->k", J_G_R, fit.cov_R, J_G_R)
    P_hat, cov_hat = fit.fuse_point(P_f, cov_f)
    d_p = (P_hat - boundary.P) @ t
    sigma_f = np.sqrt(np.einsum("i,kij,j->k", t, cov_hat, t))
    var_s = boundary.sigma_along**2 + sigma_f**2
    tt = np.outer(t, t)
    Xc, Zc = camera.to_camera(X, P_hat)
    z_high = camera.heights(pairs.v_top[k], Zc)
    z_low = camera.heights(pairs.v_bottom[k], Zc)
    # heights: z = h − (v − c_v) Z / f; σ_z² = (Z σ_v / f)² + ((h − z) σ_Z / Z)²
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
    J_shared, sigma_own, cov_shared = L.relative_error_model(camera, fit, boundary, pairs.u_left[k], pairs.u_right[k],
                                                           t, config.filter_boundary_sigma == "measured")
    out = []
    for rank, j in enumerate(np.argsort(d_p, kind="stable")):
        i = int(k[j])
        out.append(
            L.Candidate(plane.id, plane.label, rank + 1, i, edge, float(d_p[j]), boundary.sigma_along,
                        float(sigma_f[j]),
                      P_edge + d_p[j] * t,  # Eq 15
                      var_s[j] * tt,  # Eq 17: rank 1 along the wall
                      float(z_low[j]), float(z_high[j]), float(pairs.length_similarity[i]), float(pairs.u_left[i]),
                      float(pairs.u_right[i]), float(pairs.v_top[i]), float(pairs.v_bottom[i]),
                      P_observed=P_hat[j], cov_observed=cov_hat[j], sigma_b_measured=boundary.sigma_along_measured,
                      contrast=np.inf if contrast is None else float(contrast[i]),
                      wall_offset=float(G[j]), sigma_wall_offset=float(np.sqrt(var_G[j])),
                      height_margin=float(margin[j]), range=float(dist[j]), incidence=float(incidence[j]),
                      shared_jacobian=None if J_shared is None else J_shared[j], shared_cov=cov_shared,
                      sigma_own=np.nan if J_shared is None else float(sigma_own[j]))
        )
    return out


def _same_candidate(a, b) -> None:
    assert a.__dict__.keys() == b.__dict__.keys()
    for key, x in a.__dict__.items():
        y = b.__dict__[key]
        assert type(x) is type(y), key
        if isinstance(x, np.ndarray):
            assert np.array_equal(x, y, equal_nan=True), key
        elif isinstance(x, float):
            assert x == y or (np.isnan(x) and np.isnan(y)), key
        else:
            assert x == y, key


def test_model_features_equals_the_reference(scenario_frames, scenario_models):
    """Every plane's candidates from every boundary found, with and without contrasts, both boundary-σ variants:
    the same candidates, field by field (values and types)."""
    from dataclasses import replace as dc_replace

    config = Config()
    n = 0
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        pairs = front.kept_pairs
        step = front.left_segments.contrast[pairs.left_index] / 4.0
        for plane in model.planes:
            idx = np.flatnonzero(plane.members)
            for b in plane.boundaries:
                for contrast in (step, None):
                    for lc in (config.landmarks, dc_replace(config.landmarks, filter_boundary_sigma="measured")):
                        got = L.model_features(camera, plane.fit, b, pairs, idx, contrast, lc)
                        want = model_features_reference(camera, plane.fit, b, pairs, idx, contrast, lc)
                        assert len(got) == len(want)
                        for x, y in zip(got, want, strict=True):
                            _same_candidate(x, y)
                        n += len(got)
    assert n > 50
