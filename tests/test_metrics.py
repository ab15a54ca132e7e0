import numpy as np
import pytest
from scipy.stats import chi2

from stablemarks.metrics import (
    along_wall_nees,
    ate_rmse,
    chi2_bounds,
    fraction_inside,
    nees,
    pose_nees,
    position_errors,
)


def test_chi2_bounds_of_the_issue():
    lo, hi = chi2_bounds(50, 3)
    assert (round(lo, 2), round(hi, 2)) == (2.36, 3.72)
    # One run of one dof: the plain 95 % interval of χ²(1).
    assert chi2_bounds(1, 1) == pytest.approx((chi2.ppf(0.025, 1), chi2.ppf(0.975, 1)))
    # More runs: narrower around d.
    lo100, hi100 = chi2_bounds(100, 3)
    assert lo < lo100 < 3.0 < hi100 < hi


def test_nees_of_a_known_error():
    # e = (0.1, -0.2, 0), P = diag(0.01, 0.04, 1): 1 + 1 + 0 = 2.
    e = np.array([[0.1, -0.2, 0.0]])
    P = np.diag([0.01, 0.04, 1.0])[None]
    assert nees(e, P) == pytest.approx([2.0])
    # Correlated: e = (1, 1), P = [[2, 1], [1, 2]] → eᵀP⁻¹e = 2/3.
    assert nees(np.array([[1.0, 1.0]]), np.array([[[2.0, 1.0], [1.0, 2.0]]])) == pytest.approx([2 / 3])
    assert nees(np.zeros((0, 3)), np.zeros((0, 3, 3))).shape == (0,)


def test_pose_nees_wraps_the_angle():
    est = np.array([[1.0, 2.0, np.pi - 0.01]])
    truth = np.array([[1.0, 2.0, -np.pi + 0.01]])
    cov = np.diag([1.0, 1.0, 0.02**2])[None]
    assert pose_nees(est, cov, truth) == pytest.approx([1.0])


def test_pose_nees_is_chi2_on_samples():
    rng = np.random.default_rng(0)
    n = 20000
    A = rng.standard_normal((3, 3))
    P = A @ A.T + 0.1 * np.eye(3)
    e = rng.standard_normal((n, 3)) @ np.linalg.cholesky(P).T
    v = pose_nees(e, np.broadcast_to(P, (n, 3, 3)), np.zeros((n, 3)))
    assert v.mean() == pytest.approx(3.0, abs=0.1)


def test_along_wall_nees_tests_one_direction():
    # Wall along x: the error across it (y) does not count; along it 0.03 m with σ 0.01 m → 9.
    pos = np.array([[1.03, 5.0]])
    truth = np.array([[1.0, 4.0]])
    cov = np.array([[[1e-4, 0.0], [0.0, 7.0]]])
    assert along_wall_nees(pos, cov, truth, np.array([[1.0, 0.0]])) == pytest.approx([9.0])
    # A wall landmark's rank-1 covariance along a diagonal wall: (s − s_true)² / var_s.
    t = np.array([1.0, 1.0]) / np.sqrt(2)
    ds, var_s = 0.05, 0.02**2
    got = along_wall_nees(truth + ds * t, var_s * np.outer(t, t)[None], truth, t[None])
    assert got == pytest.approx([ds**2 / var_s])


def test_fraction_inside_and_trajectory_errors():
    assert fraction_inside([1.0, 2.5, 3.0, 4.0], (2.0, 3.0)) == 0.5
    assert np.isnan(fraction_inside([], (0.0, 1.0)))
    est = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 1.0]])
    truth = np.zeros((2, 3))
    assert position_errors(est, truth) == pytest.approx([0.0, 5.0])
    assert ate_rmse(est, truth) == pytest.approx(np.sqrt(12.5))
