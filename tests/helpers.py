"""Shared test helpers."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

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


def disparity_variants(disp: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A disparity image as it is, cluttered (a fifth of its pixels 1.5 px nearer) and thinned (97 % of its
    pixels invalid), the inputs the plane fit's equality tests run on."""
    cluttered = disp.copy()
    cluttered[rng.random(disp.shape) < 0.2] += np.float32(1.5)
    sparse = disp.copy()
    sparse[rng.random(disp.shape) < 0.97] = np.nan
    return disp, cluttered, sparse


def edit_sequence(src: Path, dst: Path, column: str, change) -> Path:
    """A copy ``dst`` of the sequence folder ``src`` with ``column`` of odometry.csv (``x``, ``y``) or frames.csv
    (``pan``) replaced, row ``k`` by ``change(k, value)``."""
    shutil.copytree(src, dst)
    name = "odometry.csv" if column in ("x", "y") else "frames.csv"
    with open(dst / name) as f:
        rows = list(csv.DictReader(f))
    for k, r in enumerate(rows):
        r[column] = str(change(k, float(r[column])))
    with open(dst / name, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return dst


def drop_pan_column(src: Path, dst: Path) -> Path:
    """A copy ``dst`` of the sequence folder ``src`` whose frames.csv has no pan column."""
    shutil.copytree(src, dst)
    with open(dst / "frames.csv") as f:
        rows = list(csv.DictReader(f))
    with open(dst / "frames.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=[k for k in rows[0] if k != "pan"], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    return dst


def position_rmse(poses, truth) -> float:
    """RMS of the position error [m] of poses (n, ≥2) against truth (n, ≥2)."""
    d = np.asarray(poses)[:, :2] - np.asarray(truth)[:, :2]
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
