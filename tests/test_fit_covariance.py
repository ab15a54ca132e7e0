"""The fitted wall's covariance (``planes.fit_covariance``): cluster-robust over SAD-window stripes, never below the
independent model's."""

import numpy as np
import pytest

from stablemarks.config import Config, parse_config
from stablemarks.errors import ConfigError
from stablemarks.maps import ReferencePlane
from stablemarks.planes import PlaneConfig, _at_least, _clustered_cov, fit_plane, predict_plane

from .helpers import assert_psd
from .test_planes import CAM, COV0, X0, synthetic_disparity

ANGLED = ReferencePlane("angled", (-1.0, 3.0), (1.5, 5.0), z=(0.0, 2.0))
CLUSTERED, INDEPENDENT = PlaneConfig(fit_covariance="clustered"), PlaneConfig(fit_covariance="independent")


def test_at_least_is_at_least_both():
    rng = np.random.default_rng(0)
    for _ in range(200):
        A, B = rng.normal(size=(2, 2, 2))
        P = A @ A.T + 1e-6 * np.eye(2)
        Q = B @ B.T * rng.uniform(0.01, 10.0)
        R = _at_least(P, Q)
        np.testing.assert_allclose(R, R.T)
        assert np.linalg.eigvalsh(R - P).min() >= -1e-9 * np.trace(P)
        assert np.linalg.eigvalsh(R - Q).min() >= -1e-9 * np.trace(R)
    P = np.diag([4.0, 1.0])
    np.testing.assert_allclose(_at_least(P, 0.5 * P), P)  # a smaller one changes nothing
    np.testing.assert_allclose(_at_least(P, 3.0 * P), 3.0 * P)


def test_at_least_in_closed_form_equals_the_eigen_decomposition():
    """The closed form against the same construction with LAPACK (Cholesky, eigh), which it replaced for speed."""

    def by_lapack(cov, other):
        L = np.linalg.cholesky(cov)
        Li = np.linalg.inv(L)
        w, V = np.linalg.eigh(Li @ other @ Li.T)
        if w.max() <= 1.0:
            return cov
        out = L @ ((V * np.maximum(w, 1.0)) @ V.T) @ L.T
        return 0.5 * (out + out.T)

    rng = np.random.default_rng(3)
    for i in range(2000):
        A, B = rng.normal(size=(2, 2, 2)) * rng.uniform(1e-3, 1e2, 2)[:, None, None]
        P = A @ A.T + 1e-6 * np.eye(2)
        Q = [B @ B.T, np.outer(B[0], B[0]), P * rng.uniform(0.2, 3.0)][i % 3]
        want = by_lapack(P, Q)
        np.testing.assert_allclose(_at_least(P, Q), want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


def test_clustered_covariance_of_a_mean_is_the_spread_of_the_cluster_means():
    """A line through points whose errors are shared by clusters: with one slope the sandwich reduces to the
    familiar variance of a weighted mean of cluster sums; checked against that closed form."""
    rng = np.random.default_rng(1)
    G, m = 12, 30
    cluster = np.repeat(np.arange(G), m)
    ds = np.tile(np.linspace(-1.0, 1.0, m), G) + np.repeat(np.linspace(-3, 3, G), m)
    r = np.repeat(rng.normal(0.0, 0.1, G), m) + rng.normal(0.0, 0.01, G * m)
    w = np.ones(G * m)
    N = np.array([[w.sum(), w @ ds], [w @ ds, w @ ds**2]])
    N_inv = np.linalg.inv(N)
    cov = _clustered_cov(N_inv, w, r, ds, cluster)
    scores = np.array([[r[cluster == g].sum(), (r * ds)[cluster == g].sum()] for g in range(G)])
    expected = N_inv @ (scores.T @ scores) @ N_inv * G / (G - 1)
    np.testing.assert_allclose(cov, expected, rtol=1e-12)
    assert np.all(_clustered_cov(N_inv, w, r, ds, np.zeros(G * m, dtype=np.int64)) == 0.0)  # one cluster: nothing


def _stripe_noise(shape, start, width, sigma, rng):
    """Disparity errors shared by stripes ``width`` columns wide from column ``start`` on (what one SAD window's
    columns have in common)."""
    per_stripe = rng.normal(0.0, sigma, shape[1] // width + 2)
    stripe = (np.arange(shape[1]) - start) // width + 1
    return np.broadcast_to(per_stripe[stripe], shape).astype(np.float32)


@pytest.mark.parametrize("wall", [ANGLED], ids=["angled"])
def test_clustered_covariance_covers_errors_shared_by_window_stripes(wall):
    """Monte Carlo over disparity images whose errors are shared by the fit's 15-column stripes (plus a little
    pixel noise): the fitted offset's error variance is matched by the clustered covariance (within a factor 2) and
    underestimated by the independent model (below half); with independent pixel noise alone the clustered
    covariance is the independent model's (the sandwich is the smaller there)."""
    pred = predict_plane(CAM, X0, COV0, wall)
    clean = synthetic_disparity(CAM, X0, [wall])
    truth = fit_plane(CAM, X0, clean, pred, INDEPENDENT)
    start = pred.box(*clean.shape[:1], INDEPENDENT.row_margin_px)[1].start  # the fit's stripes start there
    err, var_cl, var_ind = [], [], []
    rng = np.random.default_rng(5)
    for _ in range(60):
        disp = clean + _stripe_noise(clean.shape, start, 15, 0.15, rng)
        disp = disp + rng.normal(0, 0.02, clean.shape).astype(np.float32)
        cl, ind = fit_plane(CAM, X0, disp, pred, CLUSTERED), fit_plane(CAM, X0, disp, pred, INDEPENDENT)
        assert cl and ind
        assert (cl.a, cl.b) == (ind.a, ind.b)  # the line itself is the same
        assert_psd(cl.cov_R)
        assert np.linalg.eigvalsh(cl.cov_R - ind.cov_R).min() >= -1e-12
        err.append(cl.a - truth.a)
        var_cl.append(cl.cov_R[0, 0])
        var_ind.append(ind.cov_R[0, 0])
    mse = float(np.mean(np.square(err)))
    assert 0.5 < np.mean(var_cl) / mse < 2.0, (np.mean(var_cl), mse)
    assert np.mean(var_ind) / mse < 0.5, (np.mean(var_ind), mse)

    iid = clean + rng.normal(0, 0.2, clean.shape).astype(np.float32)
    cl, ind = fit_plane(CAM, X0, iid, pred, CLUSTERED), fit_plane(CAM, X0, iid, pred, INDEPENDENT)
    np.testing.assert_allclose(cl.cov_R, ind.cov_R, rtol=1e-9, atol=1e-9 * np.trace(ind.cov_R))


def test_the_setting_is_checked_and_the_paper_keeps_the_independent_model():
    assert Config().planes.fit_covariance == "clustered"
    assert Config.preset("paper").planes.fit_covariance == "independent"
    assert parse_config({"planes": {"fit_covariance": "independent"}}).planes.fit_covariance == "independent"
    with pytest.raises(ConfigError, match=r"my\.yaml: planes: planes\.fit_covariance: expected one of clustered, "
                                          r"independent, got 'sandwich'"):
        parse_config({"planes": {"fit_covariance": "sandwich"}}, "my.yaml")
