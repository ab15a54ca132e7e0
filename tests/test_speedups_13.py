"""Issue 13, the per-frame pipeline faster (thirteenth pass): every rewritten function against the former
implementation (kept here as the reference) on frames of the simulated scenarios ``lab``, ``room``, ``corridor``,
``office`` and ``hall`` and on random inputs — the same values, bit for bit.

:func:`~stablemarks.planes.fit_plane` now makes the band with its counts in one pass, the points with their weights
and columns in another, sums the inliers' weights in the kernels (NumPy's pairwise order), takes the final residuals
and the stripes' scores of the clustered covariance in one pass (no ``np.unique``), and classifies the band's pixels
with one division each (:func:`~stablemarks.planes._on_line_region`); :func:`~stablemarks.planes.predict_plane`
computes the columns' depths, disparities and rows in two numba passes; :func:`~stablemarks.pipeline._plans_work`
and :meth:`~stablemarks.pipeline.RegionDisparity.found` are numba loops. The matrix products (BLAS) are still
NumPy's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stablemarks import pipeline as PL
from stablemarks import planes as P
from stablemarks.config import Config
from stablemarks.maps import Map, visible_parts

from .conftest import COV_PRIOR
from .helpers import assert_same_candidate

SCENARIOS = ("lab", "room", "corridor", "office", "hall")


@pytest.fixture(scope="module")
def frames():
    """Three frames of each scenario (first, middle, last) through the pipeline in regions from the true pose:
    ``(name, k, camera, map, X, front end, model, (left, right))``."""
    from stablemarks.sim.run import simulate_run
    from stablemarks.sim.scenario import load_scenario

    config = Config()
    out = []
    for name in SCENARIOS:
        run = simulate_run(load_scenario(name))
        for k in (0, len(run) // 2, len(run) - 1):
            f = run.render(k)
            cam = config.camera(run.scenario.camera.with_pan(run.pans[k]))
            X = run.poses[k].as_array()
            reg = PL.plane_regions(cam, X, COV_PRIOR, run.scenario.map, config, f.left.shape)
            front = PL.run_front_end(f.left, f.right, config, reg)
            out.append((name, k, cam, run.scenario.map, X, front,
                        PL.select_landmarks(front, cam, run.scenario.map, X, COV_PRIOR, config), (f.left, f.right)))
    return out


# ------------------------------------------------------------------ the former implementation (the reference)
def former_clustered_cov(N_inv, w, r, ds, cluster) -> np.ndarray:
    """The former :func:`~stablemarks.planes._clustered_cov`."""
    ids, inv = np.unique(cluster, return_inverse=True)
    G = len(ids)
    if G < 2:
        return np.zeros((2, 2))
    wr = w * r
    S = np.stack([np.bincount(inv, weights=wr, minlength=G), np.bincount(inv, weights=wr * ds, minlength=G)], axis=1)
    M = S.T @ S
    return N_inv @ M @ N_inv * (G / (G - 1.0))


def former_fit_plane(camera, X, disparity, prediction, config=P.PlaneConfig()):
    """The former :func:`~stablemarks.planes.fit_plane`, its per-pixel kernels (unchanged) taken from the module."""
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
        i0, k0, step = 0, 0, 1
    else:
        i0, k0, step = rows.start % 2, cols.start % 2, 2
    s, o, sigma_o = P._wall_points(disp, band, i0, k0, step, *frame)
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
        N_inv = P._inverse_spd2(sum_w, w_ds.sum(), w_ds @ ds)
        if N_inv is None:
            return P.FailedFit(plane, "wall seen over too short a span to fit", n)
        a, b = (float(v) for v in N_inv @ np.array([wgt @ o_in, w_ds @ o_in]))
    res = P._residuals(s, o, sigma_o, inl, a, b, s0)[0][inl]
    chi2_dof = float(res @ res) / max(1, len(res) - 2)
    cov_R = N_inv * max(1.0, chi2_dof) * config.correlation_px * len(s) / n
    if config.fit_covariance == "clustered":
        column = np.nonzero(band[i0::step, k0::step])[1] * step + k0
        cov_R = P._at_least(cov_R, former_clustered_cov(N_inv, wgt, o_in - a - b * ds, ds,
                                                        (column[inl] // max(1.0, config.correlation_px))
                                                        .astype(np.int64)))
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


def former_predict_plane(camera, X, cov_X, plane, config=P.PlaneConfig()):
    """The former :func:`~stablemarks.planes.predict_plane` (:func:`~stablemarks.planes.column_depth_on_wall` and
    the camera's disparity methods, unchanged, as it called them)."""
    X = np.asarray(X, dtype=float)
    cov_X = np.asarray(cov_X, dtype=float)
    gate = config.gate_sigma
    ends = np.stack([plane.P1, plane.P2])
    uv, J_X, _ = camera.project_columns(X, ends, jacobians=True)
    cov_I = J_X @ cov_X @ np.swapaxes(J_X, -1, -2)
    sig = np.sqrt(np.stack([cov_I[:, 0, 0], cov_I[:, 1, 1]], axis=-1) + camera.sigma_img**2)
    edges = {
        w: P.EdgePrediction(w, ends[i], uv[i], sig[i], w in plane.free_edges) for i, w in enumerate(("p1", "p2"))
    }
    _, Zc = camera.to_camera(X, ends)
    if np.all(~(Zc > 1e-3)):
        return None
    W = camera.width
    if np.all(np.isfinite(uv[:, 0])):
        lo = P._nan_extreme(min, (uv[:, 0] - gate * sig[:, 0]).tolist())
        hi = P._nan_extreme(max, (uv[:, 0] + gate * sig[:, 0]).tolist())
    else:
        inside = np.isfinite(uv[:, 0])
        u_in = uv[inside, 0][0]
        s_in = sig[inside, 0][0]
        parts = visible_parts(Map((plane,)), camera, X, max_range=config.max_range, margin_px=-config.view_margin_px)
        if not parts:
            return None
        probe = plane.point_at(np.array([np.mean(parts[0].intervals[0])]))[0]
        u_probe = camera.project_columns(X, probe)[0]
        lo, hi = (u_in - gate * s_in, W - 0.5) if u_probe >= u_in else (-0.5, u_in + gate * s_in)
    u0 = int(min(max(float(np.ceil(lo)), 0.0), W - 1))
    u1 = int(min(max(float(np.floor(hi)), 0.0), W - 1))
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


def former_plans_work(plans, sad, shape) -> float:
    """The former :func:`~stablemarks.pipeline._plans_work`."""
    H, W = shape
    r = sad.block_size // 2
    dense_row = W - 2 * r
    if H <= 2 * r or dense_row <= 0:
        return 0.0
    total = np.zeros(H)
    for ptr, runs in plans:
        if len(runs):
            width = (runs[:, 1] - runs[:, 0] + sad.num_disparities - 1).astype(float)
            total += np.add.reduceat(np.append(width, 0.0), ptr[:-1]) * (np.diff(ptr) > 0)
    total = np.where(4 * total >= 3 * dense_row, dense_row, total)[r : H - r]
    return float(np.minimum(total, dense_row).sum() / (dense_row * (H - 2 * r)))


def former_found(self, image: int) -> tuple[float, float]:
    """The former :meth:`~stablemarks.pipeline.RegionDisparity.found`."""
    if self._found[image] is None:
        box = self._box[image]
        if box is None:
            self._found[image] = (np.inf, -np.inf)
        else:
            r0, r1, c0, c1 = box
            sub = self._valid[r0:r1, c0:c1] if image == 0 else np.isfinite(self._images[1][r0:r1, c0:c1])
            cols = np.flatnonzero(sub.any(axis=0))
            self._found[image] = (float(cols[0] + c0), float(cols[-1] + c0)) if len(cols) else (np.inf, -np.inf)
    return self._found[image]


# ------------------------------------------------------------------ comparisons
def assert_same_fit(new, old) -> None:
    assert type(new) is type(old)
    if not new:
        assert (new.reason, new.n_pixels) == (old.reason, old.n_pixels)
        return
    for name in ("a", "b", "s0", "n_points", "n_inliers", "chi2_dof"):
        x, y = getattr(new, name), getattr(old, name)
        assert type(x) is type(y) and x == y, name
    assert new.cov_R.dtype == old.cov_R.dtype and new.cov_R.tobytes() == old.cov_R.tobytes()
    assert new.region.dtype == old.region.dtype and np.array_equal(new.region, old.region)
    assert new.box == old.box and new.prediction is old.prediction


def assert_same_prediction(a, b) -> None:
    assert (a is None) == (b is None)
    if a is None:
        return
    assert a.plane is b.plane and a.gate == b.gate
    for name in ("columns", "d", "sigma_d", "v_top", "v_bottom"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y, equal_nan=True), name
    assert list(a.edges) == list(b.edges)
    for e, x in a.edges.items():
        y = b.edges[e]
        assert (x.which, x.free) == (y.which, y.free)
        for name in ("point", "u", "sigma"):
            assert np.array_equal(getattr(x, name), getattr(y, name), equal_nan=True), name


def disparity_variants(disp, pred, row_margin, rng):
    """The disparity image, with clutter in front of the wall in its band's box, and thinned."""
    cluttered = disp.copy()
    rows, cols = pred.box(disp.shape[0], row_margin)
    box = cluttered[rows, cols]
    patch = rng.random(box.shape) < 0.2
    box[patch] += rng.uniform(0.5, 3.0, int(patch.sum())).astype(box.dtype)
    sparse = disp.copy()
    sparse[rng.random(disp.shape) < 0.97] = np.nan
    return disp, cluttered, sparse


# ------------------------------------------------------------------ the tests
def test_fit_plane_equals_the_former(frames):
    """Every predicted plane of every frame on its disparity image, cluttered and thinned, with the clustered and the
    independent covariance, a shared disparity bias, another outlier limit and stripe width: the same fit bit for
    bit (line, covariance, χ², region) or the same failure."""
    rng = np.random.default_rng(131)
    configs = (P.PlaneConfig(), P.PlaneConfig(fit_covariance="independent"),
               P.PlaneConfig(disparity_bias_px=0.03, outlier_sigma=2.0, correlation_px=7.5),
               P.PlaneConfig(correlation_px=0.5, min_pixels=40))
    n_fits = n_failed = 0
    for _name, _k, cam, _map, X, front, model, _ in frames:
        for pred in model.predictions:
            for d in disparity_variants(np.array(front.disparity.left), pred, 4.0, rng):
                for pc in configs:
                    new = P.fit_plane(cam, X, d, pred, pc)
                    assert_same_fit(new, former_fit_plane(cam, X, d, pred, pc))
                    n_fits += bool(new)
                    n_failed += not new
    assert n_fits > 100 and n_failed > 10


def test_fit_plane_on_a_float64_view_equals_the_former(frames):
    """A disparity image of float64, handed as a non-contiguous view: the same fit."""
    _name, _k, cam, _map, X, front, model, _ = frames[0]
    big = np.zeros((front.disparity.left.shape[0], 2 * front.disparity.left.shape[1]))
    big[:, ::2] = front.disparity.left
    view = big[:, ::2]
    for pred in model.predictions:
        assert_same_fit(P.fit_plane(cam, X, view, pred), former_fit_plane(cam, X, view, pred))


def test_predict_plane_equals_the_former(frames):
    """Every wall of every scenario map from every frame's pose and perturbed ones (ends behind the camera, walls
    out of view), with the prior and a wide one: the same prediction bit for bit, or none alike; and
    :func:`~stablemarks.planes.predict_planes` the same list."""
    config = Config()
    rng = np.random.default_rng(132)
    n = 0
    for _name, _k, cam, world_map, X0, _front, _model, _ in frames:
        for X in [X0] + [X0 + rng.normal(0, [0.5, 0.5, 0.3]) for _ in range(4)]:
            for cov in (np.diag([0.05, 0.05, 0.02]) ** 2, np.diag([0.5, 0.5, 0.2]) ** 2):
                for plane in world_map:
                    got = P.predict_plane(cam, X, cov, plane, config.planes)
                    assert_same_prediction(got, former_predict_plane(cam, X, cov, plane, config.planes))
                    n += got is not None
                news = P.predict_planes(cam, X, cov, world_map, config.planes)
                olds = [p for p in (former_predict_plane(cam, X, cov, part.plane, config.planes) for part in
                                    visible_parts(world_map, cam, X, max_range=config.planes.max_range,
                                                  margin_px=-config.planes.view_margin_px,
                                                  planes=world_map.reference_planes)) if p is not None]
                assert len(news) == len(olds)
                for a, b in zip(news, olds, strict=True):
                    assert_same_prediction(a, b)
    assert n > 200


def test_box_and_rows_reached_equal_the_former(frames):
    """:meth:`PlanePrediction.box` from the cached rows the wall reaches: the former slices."""
    for _name, _k, _cam, _map, _X, front, model, _ in frames:
        H = front.disparity.left.shape[0]
        for pred in model.predictions:
            assert pred.rows_reached == (float(pred.v_top.min()), float(pred.v_bottom.max()))
            for margin in (0.0, 4.0, 37.5, 1e4):
                v0 = max(0, int(np.ceil(pred.v_top.min() - margin)))
                v1 = max(v0 - 1, min(H - 1, int(np.floor(pred.v_bottom.max() + margin))))
                assert pred.box(H, margin) == (slice(v0, v1 + 1), slice(pred.window[0], pred.window[1] + 1))


def test_on_line_region_equals_on_line_at_the_limit(frames):
    """:func:`~stablemarks.planes._on_line_region` (one division a pixel, the exact test where the margin does not
    decide) against :func:`~stablemarks.planes._on_line` on every fitted wall, with limits equal to pixels' own
    normalised residuals and one float either side of them (the exact test decides there), and limits that are not
    positive numbers: the same region and count."""
    rng = np.random.default_rng(133)
    config = Config()
    n_limits = 0
    for _name, _k, cam, _map, X, front, model, _ in frames:
        disparity = front.disparity.left
        for fit in (f for f in model.fits if f):
            pred = fit.prediction
            rows, cols = pred.box(disparity.shape[0], config.planes.row_margin_px)
            disp = np.ascontiguousarray(disparity[rows, cols])
            if disp.shape[1] != len(pred.columns):
                continue  # a window with columns left out: the kernels read the columns' rays by box column
            band = P._band(disp, rows.start, pred.d, pred.sigma_d, pred.v_top, pred.v_bottom, float(pred.gate),
                           config.planes.row_margin_px)
            c = cam.camera_pose(X)
            fwd = np.array([np.cos(c.theta), np.sin(c.theta)])
            right = np.array([np.sin(c.theta), -np.cos(c.theta)])
            r = fwd + ((pred.columns - cam.cu) / cam.f)[:, None] * right
            frame = (r @ pred.plane.direction, r @ pred.plane.normal, float(pred.plane.along(c.translation)),
                     float(pred.plane.offset(c.translation)), cam.f * cam.baseline, config.planes.sigma_nu(cam))
            r_s, r_o, c_s, c_o, fb, sigma_nu = frame
            with np.errstate(divide="ignore", invalid="ignore"):
                Z = fb / disp.astype(float)
                s = c_s + Z * r_s
                o = c_o + Z * r_o
                q = np.abs((o - fit.a - fit.b * (s - fit.s0)) / (np.abs(r_o) * (Z * Z / fb * sigma_nu) + 1e-6))
            on_wall = q[band]
            picks = rng.choice(on_wall, 12)
            limits = [0.02, 0.1, 1.0, 0.0, -1.0, math.inf, math.nan, float(on_wall.max()), float(on_wall.min())]
            limits += [float(x) for x in picks] + [float(np.nextafter(x, 0)) for x in picks]
            limits += [float(np.nextafter(x, np.inf)) for x in picks[:4]]
            for limit in limits:
                want = np.zeros(disparity.shape, dtype=bool)
                want[rows, cols] = P._on_line(disp, band, *frame, fit.a, fit.b, fit.s0, limit)
                got = np.zeros(disparity.shape, dtype=bool)
                count = P._on_line_region(got, rows.start, cols.start, disp, band, *frame, fit.a, fit.b, fit.s0, limit)
                assert np.array_equal(got, want), limit
                assert count == int(np.count_nonzero(want))
                n_limits += 1
    assert n_limits > 500


def test_band_counts_equal_the_band_and_its_counts(frames):
    """:func:`~stablemarks.planes._band_counts` against :func:`~stablemarks.planes._band` and the NumPy counts
    :func:`~stablemarks.planes.fit_plane` took of it, on every prediction's box (also thinned), both parities."""
    rng = np.random.default_rng(134)
    for _name, _k, _cam, _map, _X, front, model, _ in frames:
        for pred in model.predictions:
            for d in disparity_variants(np.array(front.disparity.left), pred, 4.0, rng):
                rows, cols = pred.box(d.shape[0], 4.0)
                disp = np.ascontiguousarray(d[rows, cols])
                args = (disp, rows.start, pred.d, pred.sigma_d, pred.v_top, pred.v_bottom, float(pred.gate), 4.0)
                band = P._band(*args)
                for i_half, k_half in ((0, 0), (1, 0), (0, 1), (1, 1)):
                    got_band, n, n_cols, n_half = P._band_counts(*args, i_half, k_half)
                    assert np.array_equal(got_band, band)
                    assert n == np.count_nonzero(band)
                    assert n_cols == np.count_nonzero(band.any(axis=0))
                    assert n_half == np.count_nonzero(band[i_half::2, k_half::2])


def test_pairwise_sum_equals_numpy():
    """:func:`~stablemarks.planes._pairwise_sum` against ``np.add.reduce`` on 0 to 300 numbers and longer arrays (a
    wall's points are thousands), of mixed scales: bit for bit."""
    rng = np.random.default_rng(135)
    for n in [*range(0, 300), 511, 1000, 4097, 8529, 20000, 65537]:
        a = rng.normal(size=n) * rng.uniform(1, 1e6) + rng.uniform(-1e3, 1e3)
        assert P._pairwise_sum(a, 0, n) == np.add.reduce(a)
        if n > 3:
            assert P._pairwise_sum(a, 3, n - 3) == np.add.reduce(a[3:])


def test_fit_kernels_equal_the_array_expressions():
    """The fit's fused steps against the array expressions they replaced, on random points: the weights and columns
    of the points, the reweighting with the weights' sum, the centred sums, the final residuals and the stripes'
    scores (several stripe widths, some stripes empty, one stripe)."""
    rng = np.random.default_rng(136)
    for _trial in range(150):
        n = int(rng.integers(3, 3000))
        s = rng.normal(0, 2, n)
        o = rng.normal(0, 0.01, n) + (rng.random(n) < 0.2) * rng.normal(0, 0.3, n)
        sigma_o = rng.uniform(1e-3, 0.05, n)
        w_all = 1.0 / sigma_o**2
        inl = rng.random(n) < 0.8
        inl[:3] = True
        a, b, s0 = float(rng.normal(0, 0.01)), float(rng.normal(0, 0.01)), float(rng.normal())
        k = float(rng.choice([2.0, 3.0]))
        got = P._reweight_sum(s, o, sigma_o, w_all, inl, a, b, s0, k)
        want = P._reweight(s, o, sigma_o, w_all, inl, a, b, s0, k)
        assert got[0] == want[0]
        for x, y in zip(got[1:5], want[1:], strict=True):
            assert x.dtype == y.dtype and np.array_equal(x, y)
        assert got[5] == float(want[2].sum())
        wgt, s_in = want[2], want[3]
        ds, w_ds, sum_w_ds = P._centred(wgt, s_in, s0)
        assert np.array_equal(ds, s_in - s0) and np.array_equal(w_ds, wgt * (s_in - s0))
        assert sum_w_ds == (wgt * (s_in - s0)).sum()
        column = rng.integers(0, int(rng.choice([3, 40, 400])), n)
        width = float(rng.choice([1.0, 7.5, 15.0, 1e6]))
        res, scores = P._final_residuals(s, o, sigma_o, w_all, inl, a, b, s0, column, width, True)
        assert np.array_equal(res, ((o - a - b * (s - s0)) / sigma_o)[inl])
        cluster = (column[inl] // width).astype(np.int64)
        N_inv = np.array([[2.0, 0.3], [0.3, 1.0]])
        want_cov = former_clustered_cov(N_inv, w_all[inl], (o - a - b * (s - s0))[inl], (s - s0)[inl], cluster)
        assert P._sandwich(N_inv, scores).tobytes() == want_cov.tobytes()
        assert P._clustered_cov(N_inv, w_all[inl], (o - a - b * (s - s0))[inl], (s - s0)[inl],
                                cluster).tobytes() == want_cov.tobytes()
        assert len(P._final_residuals(s, o, sigma_o, w_all, inl, a, b, s0, column, width, False)[1]) == 0


def test_plans_work_equals_the_former():
    """:func:`~stablemarks.pipeline._plans_work` against the former array expressions on random rectangles in images
    of random sizes and block sizes (empty ones, rows without runs, rows over three quarters of the dense row)."""
    from stablemarks.config import SADConfig
    from stablemarks.vision.area_stereo import _STEP, _planning_runs, _region_runs

    rng = np.random.default_rng(137)
    n = 0
    for trial in range(1500):
        H, W = int(rng.integers(1, 80)), int(rng.integers(1, 160))
        sad = SADConfig(block_size=int(rng.choice([3, 5, 15])), num_disparities=int(rng.choice([16, 32, 64])))
        rects = np.stack([rng.integers(-5, H + 5, 6), rng.integers(-5, H + 5, 6), rng.integers(-20, W + 20, 6),
                          rng.integers(-20, W + 20, 6)], axis=1)[: int(rng.integers(0, 7))]
        plans = [_planning_runs(*_region_runs(rc, (H, W), "regions"), sad.num_disparities, _STEP, W)
                 for rc in (rects, rects[::-1][: trial % 4])]
        got, want = PL._plans_work(plans, sad, (H, W)), former_plans_work(plans, sad, (H, W))
        assert type(got) is type(want) and got == want
        n += want > 0
    assert n > 300


def test_found_columns_equal_the_former():
    """:func:`~stablemarks.pipeline._valid_columns_valid` / ``_finite`` (what :meth:`RegionDisparity.found` reads)
    against ``np.flatnonzero(sub.any(axis=0))``'s ends on random masks and images, in random boxes."""
    rng = np.random.default_rng(138)
    for _ in range(3000):
        H, W = int(rng.integers(1, 30)), int(rng.integers(1, 40))
        p = float(rng.choice([0.0, 0.01, 0.1, 0.6]))
        valid = rng.random((H, W)) < p
        image = np.where(rng.random((H, W)) < p, rng.random((H, W)), np.nan).astype(np.float32)
        r0, r1 = sorted(rng.integers(0, H + 1, 2))
        c0, c1 = sorted(rng.integers(0, W + 1, 2))
        for arr, fn, ok in ((valid, PL._valid_columns_valid, valid), (image, PL._valid_columns_finite,
                                                                        np.isfinite(image))):
            cols = np.flatnonzero(ok[r0:r1, c0:c1].any(axis=0))
            first, last = fn(arr, r0, r1, c0, c1)
            if len(cols):
                assert (first, last) == (cols[0] + c0, cols[-1] + c0)
            else:
                assert first > last


def test_frame_equals_the_former_pipeline(frames, monkeypatch):
    """Every frame through the regions, the front end and the landmark stage with the former functions (fit,
    prediction, the region work, the lazy images' valid columns) and with the new ones: the same predictions, fits,
    candidates and warnings, bit for bit."""
    config = Config()

    def run_all():
        out = []
        for _name, _k, cam, world_map, X, _front, _model, (left, right) in frames:  # the front end made anew
            reg = PL.plane_regions(cam, X, COV_PRIOR, world_map, config, left.shape)
            front = PL.run_front_end(left, right, config, reg)
            out.append((reg, PL.select_landmarks(front, cam, world_map, X, COV_PRIOR, config)))
        return out

    new = run_all()
    with monkeypatch.context() as m:
        m.setattr(PL, "fit_plane", former_fit_plane)
        m.setattr(PL, "predict_planes", lambda camera, X, cov_X, world_map, config: [
            p for p in (former_predict_plane(camera, X, cov_X, part.plane, config) for part in visible_parts(
                world_map, camera, X, max_range=config.max_range, margin_px=-config.view_margin_px,
                planes=world_map.reference_planes)) if p is not None])
        m.setattr(PL, "_plans_work", former_plans_work)
        m.setattr(PL.RegionDisparity, "found", former_found)
        old = run_all()
    n_cands = 0
    for (reg_a, a), (reg_b, b) in zip(new, old, strict=True):
        assert np.array_equal(reg_a.left, reg_b.left) and np.array_equal(reg_a.right, reg_b.right)
        assert reg_a.windows == reg_b.windows
        for x, y in zip(reg_a.predictions, reg_b.predictions, strict=True):
            assert_same_prediction(x, y)
        assert len(a.predictions) == len(b.predictions)
        for x, y in zip(a.fits, b.fits, strict=True):
            assert type(x) is type(y)
            if x:
                for name in ("a", "b", "s0", "n_points", "n_inliers", "chi2_dof"):
                    assert getattr(x, name) == getattr(y, name), name
                assert x.cov_R.tobytes() == y.cov_R.tobytes() and np.array_equal(x.region, y.region)
        assert a.warnings == b.warnings
        assert len(a.candidates) == len(b.candidates)
        for x, y in zip(a.candidates, b.candidates, strict=True):
            assert_same_candidate(x, y)
            n_cands += 1
    assert n_cands > 20


def test_the_tests_can_fail(frames):
    """The comparisons above see a change in the last bit: a fit whose slope moved by one float, a prediction with
    one disparity nudged, a region with one pixel more."""
    _name, _k, cam, _map, X, front, model, _ = frames[0]
    pred = model.predictions[0]
    fit = P.fit_plane(cam, X, front.disparity.left, pred)
    from dataclasses import replace

    with pytest.raises(AssertionError):
        assert_same_fit(replace(fit, b=float(np.nextafter(fit.b, np.inf))), fit)
    region = fit.region.copy()
    region[fit.box[0].start, fit.box[1].start] ^= True
    with pytest.raises(AssertionError):
        assert_same_fit(replace(fit, region=region), fit)
    d = pred.d.copy()
    d[0] = np.nextafter(d[0], np.inf)
    with pytest.raises(AssertionError):
        assert_same_prediction(replace(pred, d=d), pred)
