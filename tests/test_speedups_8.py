"""Issue 13, the per-frame pipeline faster (eighth pass): every replaced computation against the former
implementation (kept here as the reference) on frames of several simulated scenarios and on random inputs — the
same values, bit for bit (or where only the order of floating-point operations changed, to 1e-9, with the same
decisions)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from stablemarks import landmarks as L
from stablemarks import planes as P
from stablemarks.config import Config
from stablemarks.maps import Map, ray_distances, visible_parts

from .helpers import disparity_variants


# ------------------------------------------------------------------ the gap to another wall beyond an edge
def other_wall_gap_reference(camera, fit, world_map, edge, search_sigma):
    """The former :func:`~stablemarks.landmarks.other_wall_gap`: a ray cast through every column out to twice the
    window's outer half, all at once."""
    e = fit.prediction.edges[edge]
    u_e = float(e.u[0])
    u_i = float(L._inner_columns(camera, fit.X, fit.plane, edge)[0])
    if not np.isfinite(u_e + u_i):
        return 0.0
    lo, hi = e.window(0, search_sigma)
    outer = lo if u_e < u_i else hi
    outer = u_e + 2.0 * (outer - u_e)
    cols = np.linspace(u_e, outer, max(2, int(abs(outer - u_e)) + 1))
    walls, exclude = L._other_walls(world_map, fit.plane)
    if len(walls) == len(exclude):
        return np.inf
    X = fit.X
    rays = camera.column_ray(X, cols)
    dist = ray_distances(camera.optical_centres(X)[0], rays, walls, exclude=exclude)
    cam = camera.camera_pose(X)
    Z = dist * (rays @ np.array([np.cos(cam.theta), np.sin(cam.theta)]))
    d = np.where(np.isfinite(Z) & (Z > 0), camera.f * camera.baseline / np.where(Z > 0, Z, 1.0), 0.0)
    d_edge, sigma = fit.prediction.disparity_at(u_e)
    hit = np.flatnonzero(np.abs(d - d_edge) <= fit.prediction.gate * sigma + 1.0)
    return float(abs(cols[hit[0]] - u_e)) if len(hit) else np.inf


def test_other_wall_gap_equals_the_reference(scenario_frames, scenario_models):
    """Both ends of every fitted wall of every scenario frame, seen from the fit's pose and from perturbed ones,
    windows of 1 to 12 σ: the same gap (another wall found at the same column, or none)."""
    config = Config()
    rng = np.random.default_rng(47)
    n = n_found = 0
    for frame, (_, _, _, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for fit in model.fits:
            if not fit:
                continue
            for X in [fit.X] + [fit.X + rng.normal(0, [0.3, 0.3, 0.1]) for _ in range(4)]:
                f = L.replace(fit, X=X)
                for edge in ("p1", "p2"):
                    for sigma in (1.0, 3.0, 12.0):
                        got = L.other_wall_gap(camera, f, frame[5], edge, sigma)
                        want = other_wall_gap_reference(camera, f, frame[5], edge, sigma)
                        assert type(got) is type(want) is float and got == want
                        n += 1
                        n_found += bool(np.isfinite(got)) and got > 0
    assert n > 300 and n_found > 20


# ------------------------------------------------------------------ the boundary's rows and column in one call
def robust_minimum_variance_reference(cols, k, lo, hi):
    """What :func:`~stablemarks.landmarks.search_boundary` did with an image's boundary columns: the rows kept by
    :func:`~stablemarks.landmarks.robust_rows`, then :func:`~stablemarks.landmarks.minimum_variance_column`."""
    cols = cols[L.robust_rows(cols, k)]
    if len(cols) == 0:
        return (0,)
    return (len(cols), *L.minimum_variance_column(cols, lo, hi))


def test_pairwise_sum_equals_numpy():
    """:func:`~stablemarks.landmarks._pairwise_sum` against ``np.add.reduce`` on 1 to 1000 numbers of mixed scales
    (all three branches of the pairwise summation) and a few longer arrays: bit for bit."""
    rng = np.random.default_rng(53)
    for n in [*range(0, 300), 511, 1000, 4097]:
        a = rng.normal(size=n) * rng.uniform(1, 1e6) + rng.uniform(-1e3, 1e3)
        assert L._pairwise_sum(a, 0, n) == np.add.reduce(a)
        if n > 3:
            assert L._pairwise_sum(a, 3, n - 3) == np.add.reduce(a[3:])


def test_robust_minimum_variance_equals_the_reference(scenario_frames, scenario_models):
    """Every scenario frame's boundary columns (both edges of every fitted wall, left image) and random columns
    with outliers and whole-pixel ties, through windows around them, beside them and empty: the same number of rows
    kept, the same column and variance, bit for bit."""
    config = Config()
    rng = np.random.default_rng(59)
    cases = []
    for frame, (_, _, _, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for fit in model.fits:
            if not fit:
                continue
            H, W = fit.region.shape
            v0, v1, _ = fit.box[0].indices(H)
            for edge in ("p1", "p2"):
                e = fit.prediction.edges[edge]
                if not np.all(np.isfinite(e.u)):
                    continue
                lo, hi = e.window(0, 3.0)
                outward = -1 if e.u[0] < L._inner_columns(camera, fit.X, fit.plane, edge)[0] else 1
                _, cols = L._block_boundary_columns(fit.region[v0:v1], v0, 0, W, lo, hi, outward, 7)
                cases.append((cols, lo, hi))
    for _ in range(300):
        n = int(rng.integers(0, 200))
        cols = np.round(rng.normal(300, rng.uniform(0.5, 5), n) * rng.choice([1, 2])) / rng.choice([1, 2])
        cols[rng.random(n) < 0.1] = rng.uniform(200, 400)  # rows off the edge (floor pixels at the wall's foot)
        centre = float(rng.normal(300, 20))
        cases.append((cols, centre - rng.uniform(0, 30), centre + rng.uniform(-5, 30)))
    n_out = 0
    for cols, lo, hi in cases:
        for k in (1.0, 3.0):
            got = L._robust_minimum_variance(np.asarray(cols, float), k, float(lo), float(hi))
            want = robust_minimum_variance_reference(np.asarray(cols, float), k, lo, hi)
            assert got[0] == want[0]
            if want[0]:
                assert got[1:] == want[1:]
                n_out += not lo <= float(np.mean(cols[L.robust_rows(cols, k)])) <= hi
    assert len(cases) > 300 and n_out > 20


# ------------------------------------------------------------------ the plane prediction's ends
def predict_plane_reference(camera, X, cov_X, plane, config):
    """The former :func:`~stablemarks.planes.predict_plane`: the ends' columns projected twice (the columns, then
    :meth:`~stablemarks.geometry.StereoCamera.cov_columns`), the window by ``np.nanmin`` / ``np.nanmax`` and
    ``np.clip``."""
    X = np.asarray(X, dtype=float)
    cov_X = np.asarray(cov_X, dtype=float)
    gate = config.gate_sigma
    ends = np.stack([plane.P1, plane.P2])
    uv = camera.project_columns(X, ends)
    cov_I = camera.cov_columns(X, cov_X, ends)  # Eq 5: known wall ends
    sig = np.sqrt(np.stack([cov_I[:, 0, 0], cov_I[:, 1, 1]], axis=-1) + camera.sigma_img**2)
    edges = {
        w: P.EdgePrediction(w, ends[i], uv[i], sig[i], w in plane.free_edges) for i, w in enumerate(("p1", "p2"))
    }
    _, Zc = camera.to_camera(X, ends)
    if np.all(~(Zc > 1e-3)):
        return None
    W = camera.width
    if np.all(np.isfinite(uv[:, 0])):
        lo = np.nanmin(uv[:, 0] - gate * sig[:, 0])
        hi = np.nanmax(uv[:, 0] + gate * sig[:, 0])
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
    u0 = int(np.clip(np.ceil(lo), 0, W - 1))
    u1 = int(np.clip(np.floor(hi), 0, W - 1))
    if hi < 0 or lo > W - 1 or u1 < u0:
        return None
    columns = np.arange(u0, u1 + 1)
    Z, J_Z_X = P.column_depth_on_wall(camera, X, plane, columns, jacobian=True)
    ok = np.isfinite(Z) & (Z <= config.max_range)
    if not ok.any():
        return None
    columns, Z, J_Z_X = columns[ok], Z[ok], J_Z_X[ok]
    d, J_d_X = camera.disparity_at_depth(Z, J_Z_X)
    var_d = camera.disparity_variance(J_d_X, cov_X, config.sigma_nu(camera))
    z_low, z_high = plane.z
    v_top = camera.cv + camera.f * (camera.mount_height - z_high) / Z
    v_bottom = camera.cv + camera.f * (camera.mount_height - z_low) / Z
    return P.PlanePrediction(plane, columns, d, np.sqrt(var_d), v_top, v_bottom, edges, gate)


def assert_same_prediction(a, b) -> None:
    """Two plane predictions (or None) are the same bit for bit: every array, every edge."""
    assert (a is None) == (b is None)
    if a is None:
        return
    assert a.plane is b.plane and a.gate == b.gate
    for name in ("columns", "d", "sigma_d", "v_top", "v_bottom"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), name
    assert list(a.edges) == list(b.edges)
    for e, x in a.edges.items():
        y = b.edges[e]
        assert (x.which, x.free) == (y.which, y.free)
        for name in ("point", "u", "sigma"):
            assert np.array_equal(getattr(x, name), getattr(y, name), equal_nan=True), name


def test_predict_plane_equals_the_reference(scenario_frames):
    """Every wall of every scenario map from every frame's pose and perturbed ones (ends behind the camera, walls
    out of view), with the prior and a wide one: the same prediction bit for bit, or none alike."""
    config = Config()
    rng = np.random.default_rng(61)
    n = 0
    for frame in scenario_frames:
        camera = config.camera(frame[4])
        for X in [frame[6]] + [frame[6] + rng.normal(0, [0.5, 0.5, 0.3]) for _ in range(3)]:
            for cov in (np.diag([0.05, 0.05, 0.02]) ** 2, np.diag([0.5, 0.5, 0.2]) ** 2):
                for plane in frame[5]:
                    got = P.predict_plane(camera, X, cov, plane, config.planes)
                    assert_same_prediction(got, predict_plane_reference(camera, X, cov, plane, config.planes))
                    n += got is not None
    assert n > 100


# ------------------------------------------------------------------ the camera frame's pose as Python floats
def test_camera_frame_equals_the_reference():
    """:meth:`StereoCamera._frame` of poses given as float64, float32 and integer arrays, lists and tuples of NumPy
    scalars: the same five numbers as with each element taken by ``float`` (the former code)."""
    from stablemarks.geometry import StereoCamera

    rng = np.random.default_rng(67)
    for _ in range(500):
        cam = StereoCamera(mount_x=float(rng.normal(0, 0.2)), mount_y=float(rng.normal(0, 0.2)),
                           pan=float(rng.uniform(-1, 1)))
        X = np.array([rng.normal(0, 5), rng.normal(0, 5), rng.uniform(-7, 7)])
        for pose in (X, X.astype(np.float32), np.round(X).astype(int), X.tolist(), tuple(np.float32(v) for v in X)):
            x, y, th = (float(v) for v in pose)
            c_th, s_th = math.cos(th), math.sin(th)
            psi = (th + cam.pan + math.pi) % (2.0 * math.pi) - math.pi
            want = (x + (c_th * cam.mount_x - s_th * cam.mount_y), y + (s_th * cam.mount_x + c_th * cam.mount_y), psi,
                    math.cos(psi), math.sin(psi))
            got = cam._frame(pose)
            assert all(type(v) is float for v in got) and got == want


# ------------------------------------------------------------------ the relative model's central differences
def relative_error_model_reference(camera, fit, boundary, u_left, u_right, t, measured=False, step_px=0.01,
                                   step_line=1e-4):
    """The former :func:`~stablemarks.landmarks.relative_error_model`: every perturbed column triangulated and fused
    with the line in NumPy batches."""
    cov_ub = boundary.cov_uv_measured if measured and boundary.cov_uv_measured is not None else boundary.cov_uv
    if cov_ub is None:
        return None, None, None
    X = fit.X
    n_f = len(np.atleast_1d(u_left))
    u_f = np.stack([np.asarray(u_left, dtype=float).ravel(), np.asarray(u_right, dtype=float).ravel()], axis=-1)
    steps = np.array([[0.0, 0.0], [step_px, 0.0], [-step_px, 0.0], [0.0, step_px], [0.0, -step_px]])
    uf = u_f[None, :, :] + steps[:, None, :]
    ub = np.asarray(boundary.u, dtype=float)[None, :] + steps
    P_f, cov_f = camera.triangulate(uf[..., 0], uf[..., 1], X)
    P_b, cov_b = camera.triangulate(ub[:, 0], ub[:, 1], X, cov_uv=cov_ub)
    nrm = fit.plane.normal
    hf = np.stack([P_f[0] - step_line * nrm, P_f[0] + step_line * nrm])
    hb = np.stack([P_b[0] - step_line * nrm, P_b[0] + step_line * nrm])
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
        slope.append((fit.fuse_point(P_f[0], cov_f[0], b=fit.b + h)[0]
                      - fit.fuse_point(P_b[0], cov_b[0], b=fit.b + h)[0]) @ t)
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
    """The error model of every plane's members from every boundary found, both boundary variances (``measured``),
    at the members' columns and at columns moved by up to a few pixels (a pair of crossed columns: none), two
    steps: the same shared covariance bit for bit, the Jacobians and own σ to 1e-9 of their size (the 2×2 and dot
    products summed left to right where NumPy's may fuse multiply-adds: the derivatives differ by ~1e-12), None
    alike."""
    config = Config()
    rng = np.random.default_rng(71)
    n = n_none = 0
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        pairs = front.kept_pairs
        for plane in model.planes:
            idx = np.flatnonzero(plane.members)
            for b in plane.boundaries:
                t = L._inward(plane.fit.plane, b.edge)
                for measured in (False, True):
                    ul, ur = pairs.u_left[idx], pairs.u_right[idx]
                    for u_l, u_r in ((ul, ur), (ul + rng.normal(0, 2, len(ul)), ur + rng.normal(0, 2, len(ur))),
                                     (ur, ul)):
                        for steps in ((0.01, 1e-4), (0.1, 1e-3)):
                            got = L.relative_error_model(camera, plane.fit, b, u_l, u_r, t, measured, *steps)
                            want = relative_error_model_reference(camera, plane.fit, b, u_l, u_r, t, measured, *steps)
                            assert (got[0] is None) == (want[0] is None)
                            if want[0] is None:
                                n_none += 1
                                continue
                            J, own, cov = got
                            assert J.shape == want[0].shape and own.shape == want[1].shape
                            assert np.allclose(J, want[0], rtol=1e-9, atol=1e-9 * np.abs(want[0]).max())
                            assert np.allclose(own, want[1], rtol=1e-9, atol=1e-9 * np.abs(want[1]).max())
                            assert np.array_equal(cov, want[2])
                            n += 1
    assert n > 40 and n_none > 5


# ------------------------------------------------------------------ one ray, one sight line past the map's walls
def test_one_ray_equals_ray_distances_and_segments_block(scenario_frames):
    """:func:`~stablemarks.maps.nearest_crossing` and :func:`~stablemarks.maps.sight_blocked` of single rays and sight
    lines from every frame's camera (and random points) past every scenario map's walls but one (or all):
    :func:`~stablemarks.maps.ray_distances` and :func:`~stablemarks.maps.segments_block` of the same, bit for bit;
    :meth:`Map.others` the walls, the index left out and those kept as before."""
    from stablemarks.maps import kept_walls, nearest_crossing, segments_block, sight_blocked

    rng = np.random.default_rng(73)
    n = n_hit = n_blocked = 0
    for frame in scenario_frames:
        world_map = frame[5]
        walls = world_map.segments()
        ids = [p.id for p in world_map]
        for plane_id in [*ids, "not a wall"]:
            got_walls, exclude, kept = world_map.others(plane_id)
            assert np.array_equal(got_walls, walls) and not got_walls.flags.writeable
            assert exclude == ([ids.index(plane_id)] if plane_id in ids else [])
            assert np.array_equal(kept, kept_walls(len(walls), exclude))
            for _ in range(30):
                o = np.asarray(frame[6][:2], float) + rng.normal(0, 1.0, 2)
                a = rng.uniform(-np.pi, np.pi)
                ray = np.array([np.cos(a), np.sin(a)])
                want = ray_distances(o, ray, walls, exclude=exclude)[0]
                got = nearest_crossing(float(o[0]), float(o[1]), float(ray[0]), float(ray[1]), got_walls, kept)
                assert got == want
                target = walls[rng.integers(len(walls)), rng.integers(2)] + rng.normal(0, 0.01, 2)
                d = target - o
                blocked = bool(segments_block(o, target, walls, exclude=exclude)[0])
                assert sight_blocked(float(o[0]), float(o[1]), float(d[0]), float(d[1]), got_walls, kept) == blocked
                n += 1
                n_hit += bool(np.isfinite(want))
                n_blocked += blocked
    assert n > 1000 and n_hit > 300 and n_blocked > 100


def edge_occluded_reference(camera, X, world_map, plane, edge):
    """The former :func:`~stablemarks.landmarks.edge_occluded`: :func:`~stablemarks.maps.segments_block`."""
    from stablemarks.maps import segments_block

    walls, exclude = L._other_walls(world_map, plane)
    return bool(segments_block(camera.optical_centres(X)[0], plane.edge(edge), walls, exclude=exclude)[0])


def test_edge_occluded_equals_the_reference(scenario_frames):
    """Both ends of every wall of every scenario map from every frame's pose and perturbed ones: the same answer."""
    config = Config()
    rng = np.random.default_rng(79)
    n = n_yes = 0
    for frame in scenario_frames:
        camera = config.camera(frame[4])
        for X in [frame[6]] + [frame[6] + rng.normal(0, [1.0, 1.0, 0.5]) for _ in range(5)]:
            for plane in frame[5]:
                for edge in ("p1", "p2"):
                    got = L.edge_occluded(camera, X, frame[5], plane, edge)
                    assert got is edge_occluded_reference(camera, X, frame[5], plane, edge)
                    n += 1
                    n_yes += got
    assert n > 500 and 50 < n_yes < n - 50


# ------------------------------------------------------------------ the frame's line noise
def robust_scale_reference(candidates):
    """The former :func:`~stablemarks.landmarks._robust_scale`: ``np.isfinite`` and ``np.median``."""
    z = []
    for c in candidates:
        sigma = c.sigma_wall_line
        if np.isfinite(c.wall_offset) and np.isfinite(sigma) and sigma > 0:
            z.append(abs(c.wall_offset) / sigma)
    return (1.4826 * float(np.median(z)) if z else np.nan), len(z)


def test_robust_scale_equals_the_reference(scenario_models):
    """Every scenario frame's candidates, all of them and random subsets (even and odd counts, none), with offsets
    and σ made NaN, infinite or zero here and there: the same scale and count, bit for bit."""
    rng = np.random.default_rng(83)
    n = 0
    for _, _, _, model in scenario_models:
        cands = list(model.candidates)
        for _ in range(20):
            chosen = [c for c in cands if rng.random() < 0.6]
            changed = []
            for c in chosen:
                r = rng.random()
                if r < 0.05:
                    c = L._replace(c, wall_offset=float(rng.choice([np.nan, np.inf])))
                elif r < 0.1:
                    c = L._replace(c, sigma_wall_offset=float(rng.choice([np.nan, np.inf, 0.0])), sigma_wall_fit=0.0)
                changed.append(c)
            got, want = L._robust_scale(changed), robust_scale_reference(changed)
            assert got[1] == want[1] and (got[0] == want[0] or (np.isnan(got[0]) and np.isnan(want[0])))
            n += got[1]
    assert n > 200


# ------------------------------------------------------------------ the plane fit's normal equations
def inverse_spd2_reference(N, max_cond=1e12):
    """The former ``planes._inverse_spd2`` of a 2×2 matrix."""
    p, q, r = N[0, 0], N[0, 1], N[1, 1]
    det = p * r - q * q
    lam_max = 0.5 * (p + r) + np.hypot(0.5 * (p - r), q)
    if not lam_max > 0 or not det / lam_max * max_cond >= lam_max:
        return None
    return np.array([[r, -q], [-q, p]]) / det


def fit_plane_reference(
    camera,
    X,
    disparity,
    prediction,
    config=P.PlaneConfig(),
) -> object:
    """The former :func:`~stablemarks.planes.fit_plane`: the normal matrix made as an array and inverted by the
    former ``_inverse_spd2`` (:func:`inverse_spd2_reference`), the final residuals from the inliers' points."""
    plane = prediction.plane
    rows, cols = prediction.box(disparity.shape[0], config.row_margin_px)
    disp = np.ascontiguousarray(disparity[rows, cols])
    band = P._band(disp, rows.start, prediction.d, prediction.sigma_d, prediction.v_top, prediction.v_bottom,
                 float(prediction.gate), float(config.row_margin_px))
    n = int(np.count_nonzero(band))
    if n < config.min_pixels:
        return P.FailedFit(plane, f"{n} disparity pixels in the predicted band (need {config.min_pixels})", n)
    if np.count_nonzero(band.any(axis=0)) < config.min_columns:
        return P.FailedFit(plane, "band pixels span too few columns", n)
    X = np.asarray(X, dtype=float)
    cam = camera.camera_pose(X)
    fwd = np.array([np.cos(cam.theta), np.sin(cam.theta)])
    right = np.array([np.sin(cam.theta), -np.cos(cam.theta)])
    r = fwd + ((prediction.columns - camera.cu) / camera.f)[:, None] * right  # (K, 2)
    r_s, r_o = r @ plane.direction, r @ plane.normal
    c_s, c_o = float(plane.along(cam.translation)), float(plane.offset(cam.translation))
    fb = camera.f * camera.baseline
    frame = (r_s, r_o, c_s, c_o, fb, config.sigma_nu(camera))
    if np.count_nonzero(band[rows.start % 2 :: 2, cols.start % 2 :: 2]) < config.min_pixels // 4:
        s, o, sigma_o = P._wall_points(disp, band, 0, 0, 1, *frame)
    else:
        s, o, sigma_o = P._wall_points(disp, band, rows.start % 2, cols.start % 2, 2, *frame)
    w_all = 1.0 / sigma_o**2
    inl = np.ones(len(s), dtype=bool)
    a, b = P.median(o), 0.0
    s0 = P.median(s)
    scale = 1.0
    min_inliers = max(3, len(s) * config.min_pixels // (2 * n))
    for _ in range(4):
        scale, inl, wgt, s_in, o_in = P._reweight(s, o, sigma_o, w_all, inl, float(a), float(b), float(s0),
                                                float(config.outlier_sigma))
        if len(wgt) < min_inliers:
            return P.FailedFit(plane, "too few pixels agree on one wall line", n)
        sum_w = float(wgt.sum())
        s0 = float(wgt @ s_in) / sum_w
        ds = s_in - s0
        w_ds = wgt * ds
        N = np.array([[sum_w, w_ds.sum()], [w_ds.sum(), w_ds @ ds]])
        N_inv = inverse_spd2_reference(N)
        if N_inv is None:
            return P.FailedFit(plane, "wall seen over too short a span to fit", n)
        a, b = (float(v) for v in N_inv @ np.array([wgt @ o_in, w_ds @ o_in]))
    res = (o[inl] - a - b * (s[inl] - s0)) / sigma_o[inl]
    chi2_dof = float(res @ res) / max(1, int(np.count_nonzero(inl)) - 2)
    cov_R = N_inv * max(1.0, chi2_dof) * config.correlation_px * len(s) / n
    if config.disparity_bias_px > 0:
        depth = (s_in - c_s) * (fwd @ plane.direction) + (o_in - c_o) * (fwd @ plane.normal)
        g = -(depth / fb) * ((o_in - c_o) - b * (s_in - c_s))
        J_beta = N_inv @ np.array([wgt @ g, w_ds @ g])
        cov_R = cov_R + config.disparity_bias_px**2 * np.outer(J_beta, J_beta)
    keep = P._on_line(disp, band, *frame, a, b, s0, config.outlier_sigma * scale)
    region = np.zeros(disparity.shape, dtype=bool)
    region[rows, cols] = keep
    return P.PlaneFit(plane, prediction, a, b, s0, cov_R, region, n, int(np.count_nonzero(keep)),
                    chi2_dof, X, (rows, cols))



INDEPENDENT = {"planes": {"fit_covariance": "independent"}}
"""The former pipeline's fitted-wall covariance (the clustered one came later and is tested in test_fit_covariance)."""


def test_fit_plane_equals_the_reference(scenario_frames, scenario_models):
    """Every predicted plane of every scenario frame on its disparity image, cluttered and thinned (every failure
    too): the same fit bit for bit (line, covariance, χ², region) or the same failure."""
    rng = np.random.default_rng(89)
    config = Config().with_overrides(INDEPENDENT)  # the reference predates planes.fit_covariance "clustered"
    n_fits = 0
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for pred in model.predictions:
            disp = np.array(front.disparity.left)
            for d in disparity_variants(disp, rng):
                other = P.PlaneConfig(outlier_sigma=2.0, disparity_bias_px=0.03, fit_covariance="independent")
                for pc in (config.planes, other):
                    new = P.fit_plane(camera, model.X, d, pred, pc)
                    ref = fit_plane_reference(camera, model.X, d, pred, pc)
                    assert type(new) is type(ref)
                    if not new:
                        assert (new.reason, new.n_pixels) == (ref.reason, ref.n_pixels)
                        continue
                    for name in ("a", "b", "s0", "n_points", "n_inliers", "chi2_dof"):
                        assert getattr(new, name) == getattr(ref, name), name
                    assert np.array_equal(new.cov_R, ref.cov_R) and np.array_equal(new.region, ref.region)
                    n_fits += 1
    assert n_fits > 40


def test_inverse_spd2_equals_the_reference():
    """:func:`~stablemarks.planes._inverse_spd2` of the three numbers against the former function of the matrix, on
    random symmetric matrices from well to ill conditioned, singular and indefinite ones: the same inverse or None."""
    rng = np.random.default_rng(97)
    n_none = 0
    for _ in range(5000):
        p, r = rng.uniform(0, 10, 2) * 10.0 ** rng.integers(-6, 6, 2)
        q = float(rng.choice([np.sqrt(p * r) * rng.uniform(-1, 1), np.sqrt(p * r), rng.normal() * 1e3]))
        N = np.array([[p, q], [q, r]])
        got, want = P._inverse_spd2(p, q, r), inverse_spd2_reference(N)
        assert (got is None) == (want is None)
        if want is None:
            n_none += 1
        else:
            assert got.dtype == want.dtype and np.array_equal(got, want)
    assert 100 < n_none < 4900


# ------------------------------------------------------------------ the right image's band, from a table
@njit(cache=False)
def right_band_reference(sub, c0, v0, u0, d, sigma_d, v_top, v_bottom, gate, row_margin):
    """The former ``landmarks._right_band``: the interpolation's differences taken per pixel."""
    h, w = sub.shape
    K = len(d)
    u_last = u0 + K - 1
    out = np.zeros((h, w), dtype=np.bool_)
    for i in range(h):
        v = float(v0 + i)
        for k in range(w):
            disp = float(sub[i, k])
            u = float(c0 + k) + disp
            if not (u >= u0 and u <= u_last):
                continue
            j = int(u - u0)
            if j == K - 1:
                out[i, k] = (abs(disp - d[j]) <= gate * sigma_d[j] and v >= v_top[j] - row_margin
                             and v <= v_bottom[j] + row_margin)
                continue
            frac = u - float(u0 + j)
            dp = (d[j + 1] - d[j]) * frac + d[j]
            sp = (sigma_d[j + 1] - sigma_d[j]) * frac + sigma_d[j]
            if not abs(disp - dp) <= gate * sp:
                continue
            vt = (v_top[j + 1] - v_top[j]) * frac + v_top[j]
            vb = (v_bottom[j + 1] - v_bottom[j]) * frac + v_bottom[j]
            out[i, k] = v >= vt - row_margin and v <= vb + row_margin
    return out


def test_right_region_equals_the_reference(scenario_frames, scenario_models):
    """The right image's region of every scenario plane (its whole rows, and the search windows of both edges),
    on the frame's right disparities and on noisy ones, two row margins; and predictions of float32 arrays: the same
    mask bit for bit as the former per-pixel differences."""
    rng = np.random.default_rng(101)
    n = 0
    for _, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        right = np.array(front.disparity.right)
        noisy = right + rng.normal(0, 1.0, right.shape).astype(np.float32)
        for pred in model.predictions:
            preds = [pred, P.PlanePrediction(pred.plane, pred.columns, *(np.asarray(a, np.float32) for a in (
                pred.d, pred.sigma_d, pred.v_top, pred.v_bottom)), pred.edges, pred.gate)]
            for p in preds:
                for disp in (right, noisy):
                    H, W = disp.shape
                    for margin in (0.0, 4.0):
                        for columns in (None, (int(pred.columns[0]) - 30, int(pred.columns[0]) + 40),
                                        (int(pred.columns[-1]) - 60, int(pred.columns[-1]))):
                            v0, c0, block = L._right_block(p, disp, margin, columns)
                            c1 = W - 1 if columns is None else min(W - 1, int(columns[1]))
                            cs = 0 if columns is None else max(0, int(columns[0]))
                            if c1 < cs or block.size == 0:
                                continue
                            v1 = v0 + block.shape[0] - 1
                            want = right_band_reference(disp[v0 : v1 + 1, cs : c1 + 1], cs, v0, int(p.columns[0]),
                                                        p.d, p.sigma_d, p.v_top, p.v_bottom, float(p.gate), margin)
                            assert c0 == cs and np.array_equal(block, want)
                            n += int(want.sum())
    assert n > 100_000


def test_dilate_equals_the_reference():
    """:func:`~stablemarks.planes.dilate` of random masks (contiguous, sliced views, one pixel, empty, other dtypes)
    against the former uint8 copy and its ``astype(bool)``: the same mask."""
    import cv2

    rng = np.random.default_rng(103)
    for _ in range(200):
        H, W = (int(v) for v in rng.integers(1, 60, 2))
        mask = rng.random((H + 5, W + 7)) < rng.uniform(0.01, 0.9)
        for region in (mask, mask[2 : H + 2, 3 : W + 3], mask[::2, ::3], mask.astype(np.uint8)):
            for px in (0, 1, 3):
                got = P.dilate(region, px)
                if px == 0:
                    assert got is region
                    continue
                k = np.ones((2 * px + 1, 2 * px + 1), np.uint8)
                want = cv2.dilate(region.astype(np.uint8), k).astype(bool)
                assert got.dtype == bool and np.array_equal(got, want)


# ------------------------------------------------------------------ the whole frame against the former code
def _frame_former(monkeypatch):
    """Swap every step this pass replaced back to its former code (the references above and those of
    tests/test_speedups_7.py), for :func:`test_frame_equals_the_former_pipeline`."""
    from stablemarks import geometry
    from stablemarks import pipeline as PL

    from .test_speedups_7 import block_boundary_columns_reference, edge_depth_step_reference

    def frame_reference(self, X):  # the former StereoCamera._frame: float() of each element
        x, y, th = (float(v) for v in X)
        c_th, s_th = math.cos(th), math.sin(th)
        psi = (th + self.pan + math.pi) % (2.0 * math.pi) - math.pi
        cx = x + (c_th * self.mount_x - s_th * self.mount_y)
        cy = y + (s_th * self.mount_x + c_th * self.mount_y)
        return cx, cy, psi, math.cos(psi), math.sin(psi)

    def right_block_reference(prediction, disparity_right, row_margin=0.0, columns=None):
        H, W = disparity_right.shape
        c0, c1 = (0, W - 1) if columns is None else (max(0, int(columns[0])), min(W - 1, int(columns[1])))
        if c1 < c0:
            return 0, 0, np.zeros((0, 0), dtype=bool)
        v0 = max(0, int(np.floor(prediction.v_top.min() - row_margin)))
        v1 = min(H - 1, int(np.ceil(prediction.v_bottom.max() + row_margin)))
        if v1 < v0:
            return 0, 0, np.zeros((0, 0), dtype=bool)
        return v0, c0, right_band_reference(
            disparity_right[v0 : v1 + 1, c0 : c1 + 1], c0, v0, int(prediction.columns[0]), prediction.d,
            prediction.sigma_d, prediction.v_top, prediction.v_bottom, float(prediction.gate), float(row_margin))

    def robust_minimum_variance(cols, k, lo, hi):
        got = robust_minimum_variance_reference(cols, k, lo, hi)
        return got if got[0] else (0, np.nan, np.nan)

    def dilate_reference(region, px):
        import cv2

        if px <= 0:
            return region
        return cv2.dilate(region.astype(np.uint8), np.ones((2 * px + 1, 2 * px + 1), np.uint8)).astype(bool)

    monkeypatch.setattr(geometry.StereoCamera, "_frame", frame_reference)
    monkeypatch.setattr(P, "predict_plane", predict_plane_reference)
    monkeypatch.setattr(PL, "fit_plane", fit_plane_reference)
    monkeypatch.setattr(P, "dilate", dilate_reference)
    for name, ref in (("other_wall_gap", other_wall_gap_reference),
                      ("_robust_minimum_variance", robust_minimum_variance),
                      ("relative_error_model", relative_error_model_reference), ("_right_block", right_block_reference),
                      ("edge_occluded", edge_occluded_reference), ("edge_depth_step", edge_depth_step_reference),
                      ("_robust_scale", robust_scale_reference),
                      ("_block_boundary_columns", block_boundary_columns_reference)):
        monkeypatch.setattr(L, name, ref)


def _frame_outputs(frames, config):
    """Per frame: the model (plane_regions, run_front_end, select_landmarks from the true pose) and the EKF after
    one association and update with the frame's kept pairs (its landmarks from the frame's selected candidates)."""
    from stablemarks.estimation import JointEKF, NewLandmark
    from stablemarks.pipeline import plane_regions, run_front_end, select_landmarks

    from .conftest import COV_PRIOR

    out = []
    for _, _, left, right, camera, world_map, X in frames:
        reg = plane_regions(camera, X, COV_PRIOR, world_map, config, left.shape)
        model = select_landmarks(run_front_end(left, right, config, reg), camera, world_map, X, COV_PRIOR, config)
        ekf = None
        if model.selected:
            ekf = JointEKF(config.camera(camera), X, COV_PRIOR, config.ekf)
            ekf.add_landmarks([NewLandmark.wall(world_map[c.plane_id], c.s, c.edge) for c in model.selected],
                              np.diag([c.sigma_s**2 for c in model.selected]))
            pairs = model.front.kept_pairs
            measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
            chosen = ekf.select_for_update(ekf.associate_joint(measured, 0.0))
            ekf.update([(i, measured[j]) for i, j in chosen])
        out.append((model, ekf))
    return out


def test_frame_equals_the_former_pipeline(scenario_frames, monkeypatch):
    """Every scenario frame through the regions, the front end, the planes, the boundaries, the candidates and one EKF
    update, with this pass's code and with every step it replaced swapped back: the same kept pairs, predictions,
    fits and regions, boundaries, candidates (their relative model's Jacobian and own σ to 1e-9), selection and
    reasons, and EKF state and covariance (to 1e-9: the landmarks' σ enter it)."""
    config = Config().with_overrides(INDEPENDENT)
    new = _frame_outputs(scenario_frames, config)
    _frame_former(monkeypatch)
    old = _frame_outputs(scenario_frames, config)
    monkeypatch.undo()
    n_cands = n_ekf = 0
    for (m1, e1), (m2, e2) in zip(new, old, strict=True):
        assert np.array_equal(m1.front.kept, m2.front.kept)
        assert len(m1.predictions) == len(m2.predictions)
        for p1, p2 in zip(m1.predictions, m2.predictions, strict=True):
            assert_same_prediction(p1, p2)
        for f1, f2 in zip(m1.fits, m2.fits, strict=True):
            assert type(f1) is type(f2) and bool(f1) == bool(f2)
            if f1:
                assert (f1.a, f1.b, f1.s0, f1.n_inliers, f1.chi2_dof) == (f2.a, f2.b, f2.s0, f2.n_inliers, f2.chi2_dof)
                assert np.array_equal(f1.cov_R, f2.cov_R) and np.array_equal(f1.region, f2.region)
        for pl1, pl2 in zip(m1.planes, m2.planes, strict=True):
            assert np.array_equal(pl1.members, pl2.members) and pl1.searched == pl2.searched
            assert [why for _, why in pl1.rejected_boundaries] == [why for _, why in pl2.rejected_boundaries]
            for b1, b2 in zip(pl1.boundaries + [b for b, _ in pl1.rejected_boundaries if b is not None],
                              pl2.boundaries + [b for b, _ in pl2.rejected_boundaries if b is not None], strict=True):
                for name, x in b1.__dict__.items():
                    y = b2.__dict__[name]
                    if x is None or y is None:
                        assert x is y, name
                    elif isinstance(x, np.ndarray):
                        assert np.array_equal(x, y, equal_nan=True), name
                    else:
                        assert x == y or (x != x and y != y), name
        assert len(m1.candidates) == len(m2.candidates)
        for c1, c2 in zip(m1.candidates, m2.candidates, strict=True):
            assert_close_candidate(c1, c2)
            assert (c1.selected, c1.reason) == (c2.selected, c2.reason)
        n_cands += len(m1.candidates)
        assert (e1 is None) == (e2 is None)
        if e1 is not None:
            assert np.allclose(e1.state, e2.state, rtol=1e-9, atol=1e-12)
            assert np.allclose(e1.cov, e2.cov, rtol=1e-9, atol=1e-15)
            n_ekf += 1
    assert n_cands > 50 and n_ekf >= 4


def assert_close_candidate(a, b) -> None:
    """Two candidates have the same fields in the same order, of the same types, the same strings, flags and
    integers, and the same numbers, arrays too — the relative model's (``shared_jacobian``, ``sigma_own``) to 1e-9
    of their size (its 2×2 and dot products are summed left to right, NumPy's BLAS may fuse multiply-adds)."""
    assert type(a) is type(b)
    assert list(a.__dict__) == list(b.__dict__)
    for name, x in a.__dict__.items():
        y = b.__dict__[name]
        assert type(x) is type(y), name
        if name in ("shared_jacobian", "sigma_own") and x is not None:
            assert np.allclose(x, y, rtol=1e-9, atol=1e-9 * np.nanmax(np.abs(y), initial=0.0), equal_nan=True), name
        elif isinstance(x, np.ndarray):
            assert np.array_equal(x, y, equal_nan=True), name
        else:
            assert x == y or (x != x and y != y), name


# ------------------------------------------------------------------ one column pair triangulated
def test_triangulate_one_pair_equals_the_array_path():
    """:meth:`StereoCamera.triangulate` of one column pair (Python numbers, NumPy scalars, 0-d arrays) with a pose and
    a full column covariance against the array path it takes for a (1,) pair: the same point and covariance bit for
    bit, NaN where the disparity is not positive."""
    from stablemarks.geometry import StereoCamera

    rng = np.random.default_rng(109)
    n_nan = 0
    for _ in range(3000):
        cam = StereoCamera(f=float(rng.uniform(200, 900)), cu=float(rng.uniform(100, 500)),
                           baseline=float(rng.uniform(0.05, 0.5)), mount_x=float(rng.normal(0, 0.2)),
                           mount_y=float(rng.normal(0, 0.2)), pan=float(rng.uniform(-1, 1)))
        X = np.array([rng.normal(0, 3), rng.normal(0, 3), rng.uniform(-np.pi, np.pi)])
        ul = float(rng.uniform(0, 640))
        ur = ul - float(rng.choice([rng.uniform(0.1, 60), 0.0, -rng.uniform(0, 5)]))
        A = rng.normal(size=(2, 2))
        cov = A @ A.T + float(rng.uniform(0, 1))
        want_p, want_cov = cam.triangulate(np.array([ul]), np.array([ur]), X, cov_uv=cov[None])
        for u in ((ul, ur), (np.float64(ul), np.float64(ur)), (np.array(ul), np.array(ur))):
            p, c = cam.triangulate(*u, X, cov_uv=cov)
            assert p.shape == (2,) and c.shape == (2, 2)
            assert np.array_equal(p, want_p[0], equal_nan=True) and np.array_equal(c, want_cov[0], equal_nan=True)
        n_nan += bool(np.isnan(want_p).any())
    assert n_nan > 500


# ------------------------------------------------------------------ the boundary search
def search_boundary_reference(
    camera,
    fit,
    edge: str,
    disparity_right,
    members_u,
    config=L.LandmarkConfig(),
    plane_config=P.PlaneConfig(),
    window_px=15.0,
    border_sigma_px=None,
    bridge_px=None,
) -> object:
    """The former :func:`~stablemarks.landmarks.search_boundary`: :func:`~stablemarks.landmarks.robust_rows` and
    :func:`~stablemarks.landmarks.minimum_variance_column` of each image's rows, the snap onto a member pair and the
    column covariance in NumPy."""
    w = L.boundary_window(config, window_px)
    pred = fit.prediction
    plane = fit.plane
    e = pred.edges[edge]
    X = fit.X
    u_inner = L._inner_columns(camera, X, plane, edge)
    u_b = np.zeros(2)
    var_b = np.zeros(2)
    rows_used = 0
    snapped = False
    H, W = fit.region.shape
    v0, v1, _ = fit.box[0].indices(H)
    regions = [(fit.region[v0:max(v0, v1)], v0, 0), None]
    if disparity_right is not None and np.all(np.isfinite(e.u)):
        lo_r, hi_r = e.window(1, config.search_sigma)
        rv0, rc0, block = L._right_block(pred, disparity_right, plane_config.row_margin_px,
                                       (int(np.floor(lo_r)) - 1, int(np.ceil(hi_r)) + 1))
        regions[1] = (block, rv0, rc0)
    outwards = [-1 if e.u[img] < u_inner[img] else 1 for img in (0, 1)]
    right_found = True
    for img in (0, 1):
        outward = outwards[img]
        lo, hi = e.window(img, config.search_sigma)
        if img == 0:  # the left region exists only inside the plane's predicted window
            lo, hi = max(lo, pred.window[0]), min(hi, pred.window[1])
        if regions[img] is None:
            rows, cols = np.zeros(0, int), np.zeros(0)
        else:
            block, bv0, bu0 = regions[img]
            rows, cols = L._block_boundary_columns(block, bv0, bu0, disparity_right.shape[1] if img else W, lo, hi,
                                                 outward, int(w // 2) if bridge_px is None else int(bridge_px))
            keep = L.robust_rows(cols, config.row_outlier_mad)
            rows, cols = rows[keep], cols[keep]
        if len(rows) < config.min_boundary_rows:
            if img == 0:
                return None
            right_found = False
            continue
        m, var = L.minimum_variance_column(cols, lo, hi)
        if img == 0:
            rows_used = len(rows)
        u_b[img] = m
        var_b[img] = var + camera.sigma_img**2
    if len(members_u):
        beyond = (members_u - u_b) * np.asarray(outwards)
        near = (beyond[:, 0] > 0) & (beyond[:, 0] <= w)
        if right_found:
            near &= np.abs(beyond[:, 1]) <= w
        if np.any(near):
            k = np.flatnonzero(near)[np.argmax(beyond[near, 0])]
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
    cov_uv = np.diag(var_b) + var_w
    sigma_u = np.sqrt(np.diag(cov_uv))
    P, cov = camera.triangulate(u_b[0], u_b[1], X, cov_uv=cov_uv)
    if not np.all(np.isfinite(P)):
        d_here, _ = pred.disparity_at(u_b[0])
        u_b[1] = u_b[0] - float(d_here)
        P, cov = camera.triangulate(u_b[0], u_b[1], X, cov_uv=cov_uv)
    P_hat, cov_hat = fit.fuse_point(P, cov)
    t = L._inward(plane, edge)
    sigma_along = float(np.sqrt(t @ cov_hat @ t))
    sigma_m = np.nan
    if config.filter_boundary_sigma == "measured":
        _, cov_m = camera.triangulate(u_b[0], u_b[1], X, cov_uv=np.diag(var_b))
        _, cov_m = fit.fuse_point(P, cov_m)
        sigma_m = float(np.sqrt(t @ cov_m @ t))
    return L.Boundary(plane.id, edge, u_b, sigma_u, P_hat, cov_hat, sigma_along, snapped, rows_used, t, sigma_m,
                    cov_uv, np.diag(var_b) if config.filter_boundary_sigma == "measured" else None)



def test_search_boundary_equals_the_reference(scenario_frames, scenario_models):
    """Both free edges of every fitted wall of every scenario frame, with the plane's members, none, a random half and
    the members moved by a few pixels (snapping onto another pair, or none), bridging 2 px or the window, both
    boundary variances and border allowances: the same boundary bit for bit, or none alike."""
    config = Config()
    rng = np.random.default_rng(113)
    n = n_snapped = 0
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        pairs = front.kept_pairs
        for plane in model.planes:
            idx = np.flatnonzero(plane.members)
            mu = np.stack([pairs.u_left[idx], pairs.u_right[idx]], axis=-1) if len(idx) else np.zeros((0, 2))
            variants = [mu, np.zeros((0, 2)), mu[rng.random(len(mu)) < 0.5], mu + rng.normal(0, 4, mu.shape)]
            for edge in plane.fit.plane.free_edges:
                if not np.all(np.isfinite(plane.fit.prediction.edges[edge].u)):
                    continue
                for members_u in variants:
                    for lc, border, bridge in ((config.landmarks, (0.25, None), None),
                                               (L.LandmarkConfig(filter_boundary_sigma="measured"), None, 2),
                                               (config.landmarks, 0.5, 30)):
                        args = (camera, plane.fit, edge, front.disparity.right, members_u, lc, config.planes, 15.0,
                                border, bridge)
                        got, want = L.search_boundary(*args), search_boundary_reference(*args)
                        assert (got is None) == (want is None)
                        if want is None:
                            continue
                        for name, x in want.__dict__.items():
                            y = got.__dict__[name]
                            if x is None or y is None:
                                assert x is y, name
                            elif isinstance(x, np.ndarray):
                                assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), name
                            else:
                                assert type(x) is type(y) and (x == y or (x != x and y != y)), name
                        n += 1
                        n_snapped += want.snapped
    assert n > 100 and 20 < n_snapped < n - 20
