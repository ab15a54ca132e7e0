"""Issue 13, the per-frame pipeline faster (sixth pass): every replaced computation against the former
implementation (kept here as the reference) on frames of several simulated scenarios and on random inputs — the
same values, bit for bit."""

from __future__ import annotations

import numpy as np
from numba import njit

from stablemarks import landmarks as L
from stablemarks import planes as P
from stablemarks.config import Config

from .helpers import assert_same_candidate, boundary_model_inputs


# ------------------------------------------------------------------ the plane fit's reweighting steps
def reweight_numpy(s, o, sigma_o, w_all, inl, a, b, s0, outlier_sigma):
    """The NumPy expressions :func:`~stablemarks.planes._reweight` replaced in :func:`~stablemarks.planes.fit_plane`'s
    reweighting loop."""
    res = (o - a - b * (s - s0)) / sigma_o
    scale = max(1e-3, 1.4826 * P.median(np.abs(res[inl])))
    inl = np.abs(res) <= outlier_sigma * scale
    return scale, inl, w_all[inl], s[inl], o[inl]


def fit_plane_reference(camera, X, disparity, prediction, config):
    """The former :func:`~stablemarks.planes.fit_plane`: the same function with its reweighting step as the NumPy
    expressions it was (:func:`reweight_numpy`), not a copy of the rest."""
    fast = P._reweight
    P._reweight = reweight_numpy
    try:
        return P.fit_plane(camera, X, disparity, prediction, config)
    finally:
        P._reweight = fast


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
        ref_scale, ref_inl, ref_wgt, ref_s, ref_o = reweight_numpy(s, o, sigma_o, w_all, inl, a, b, s0, k)
        assert scale == ref_scale
        assert np.array_equal(new, ref_inl)
        for x, y in ((wgt, ref_wgt), (s_in, ref_s), (o_in, ref_o)):
            assert np.array_equal(x, y)


# (the relative model's slope steps: its numba pass is compared with the former NumPy code in test_speedups_8)


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
    var_G_fit = np.einsum("ki,ij,kj->k", J_G_R, fit.cov_R, J_G_R)
    var_G = np.einsum("i,kij,j->k", J_G_P, cov_f, J_G_P) + var_G_fit
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
                      sigma_wall_fit=float(np.sqrt(var_G_fit[j])), height_margin=float(margin[j]),
                      range=float(dist[j]), incidence=float(incidence[j]),
                      shared_jacobian=None if J_shared is None else J_shared[j], shared_cov=cov_shared,
                      sigma_own=np.nan if J_shared is None else float(sigma_own[j]))
        )
    return out


def test_model_features_equals_the_reference(scenario_frames, scenario_models):
    """Every plane's candidates from every boundary found, with and without contrasts, both boundary-σ variants:
    the same candidates, field by field (values and types)."""
    from dataclasses import replace as dc_replace

    config = Config()
    n = 0
    for camera, plane, b, pairs, idx, step in boundary_model_inputs(scenario_frames, scenario_models, config):
        for contrast in (step, None):
            for lc in (config.landmarks, dc_replace(config.landmarks, filter_boundary_sigma="measured")):
                got = L.model_features(camera, plane.fit, b, pairs, idx, contrast, lc)
                want = model_features_reference(camera, plane.fit, b, pairs, idx, contrast, lc)
                assert len(got) == len(want)
                for x, y in zip(got, want, strict=True):
                    assert_same_candidate(x, y)
                n += len(got)
    assert n > 50
