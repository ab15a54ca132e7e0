"""Shared test helpers."""

from __future__ import annotations

import numpy as np


def numerical_jacobian(fun, x, eps: float = 1e-6) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` at ``x`` (float64): shape ``fun(x).shape + x.shape``."""
    x = np.asarray(x, dtype=float)
    f0 = np.asarray(fun(x), dtype=float)
    J = np.zeros(f0.shape + x.shape)
    for i in np.ndindex(x.shape):
        dx = np.zeros_like(x)
        dx[i] = eps
        J[(...,) + i] = (np.asarray(fun(x + dx)) - np.asarray(fun(x - dx))) / (2 * eps)
    return J


def assert_psd(P: np.ndarray, tol: float = 1e-9) -> None:
    """Assert ``P`` is symmetric positive semi-definite."""
    P = np.asarray(P)
    assert np.allclose(P, P.T, atol=tol * max(1.0, np.abs(P).max())), "covariance not symmetric"
    w = np.linalg.eigvalsh(0.5 * (P + P.T))
    assert w.min() >= -tol * max(1.0, abs(w).max()), f"covariance not PSD: min eigenvalue {w.min()}"
