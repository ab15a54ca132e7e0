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


def assert_same_candidate(a, b) -> None:
    """Two :class:`~stablemarks.landmarks.Candidate` s are the same bit for bit: the same fields in the same order,
    each of the same type and value (arrays element-wise, NaN equal to NaN)."""
    from stablemarks.landmarks import Candidate

    assert type(a) is type(b) is Candidate
    assert list(a.__dict__) == list(b.__dict__)
    for name, x in a.__dict__.items():
        y = b.__dict__[name]
        assert type(x) is type(y), name
        if isinstance(x, np.ndarray):
            assert np.array_equal(x, y, equal_nan=True), name
        else:
            assert x == y or (x != x and y != y), name


def boundary_model_inputs(scenario_frames, scenario_models, config):
    """For every boundary found on every plane of the scenario frames (the ``scenario_frames`` and
    ``scenario_models`` fixtures): ``(camera, plane model, boundary, pairs, member indices, contrast steps)``, the
    arguments :func:`~stablemarks.landmarks.model_features` takes."""
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        pairs = front.kept_pairs
        step = front.left_segments.contrast[pairs.left_index] / 4.0
        for plane in model.planes:
            idx = np.flatnonzero(plane.members)
            for b in plane.boundaries:
                yield camera, plane, b, pairs, idx, step
