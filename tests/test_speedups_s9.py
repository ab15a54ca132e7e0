"""Checks of the s9 speed pass: each rewritten step against the code it replaced (kept here as a reference),
bit for bit unless said otherwise."""

from __future__ import annotations

import numpy as np

from stablemarks.geometry import MIN_DEPTH, StereoCamera


# ------------------------------------------------------------------ project_columns by the compiled kernel
def project_columns_reference(cam: StereoCamera, X, points, jacobians: bool = False):
    """The former array code of :meth:`StereoCamera.project_columns` (the general case)."""
    p = np.asarray(points, dtype=float)
    cx, cy, _, c, s = cam._frame(X)
    dx = p[..., 0] - cx
    dy = p[..., 1] - cy
    Xc = s * dx - c * dy
    Zc = c * dx + s * dy
    Zs = np.where(Zc > MIN_DEPTH, Zc, np.nan)
    uv = np.empty(p.shape)
    uv[..., 0] = ul = cam.cu + cam.f * Xc / Zs
    uv[..., 1] = ul - cam.f * cam.baseline / Zs
    if not jacobians:
        return uv
    f, b = cam.f, cam.baseline
    dul_dXc = f / Zs
    dul_dZc = -f * Xc / Zs**2
    dur_dZc = dul_dZc + f * b / Zs**2
    J_I_p = np.empty(p.shape[:-1] + (2, 2))
    J_I_p[..., 0, 0] = dul_dXc * s + dul_dZc * c
    J_I_p[..., 0, 1] = dul_dXc * -c + dul_dZc * s
    J_I_p[..., 1, 0] = dul_dXc * s + dur_dZc * c
    J_I_p[..., 1, 1] = dul_dXc * -c + dur_dZc * s
    r0, r1 = cam._centre_rate(X)
    dXc_dth = c * dx + s * dy - (s * r0 - c * r1)
    dZc_dth = -s * dx + c * dy - (c * r0 + s * r1)
    J_I_X = np.empty(p.shape[:-1] + (2, 3))
    J_I_X[..., :2] = -J_I_p
    J_I_X[..., 0, 2] = dul_dXc * dXc_dth + dul_dZc * dZc_dth
    J_I_X[..., 1, 2] = dul_dXc * dXc_dth + dur_dZc * dZc_dth
    return uv, J_I_X, J_I_p


def test_project_columns_kernel_equals_the_array_code():
    """Points (2,), (n, 2) and (a, n, 2), with and without Jacobians, 0 to 30 of them, some behind the camera: the
    same columns and Jacobians as the former array code, shapes and dtypes, bit for bit, NaN where it had NaN."""
    rng = np.random.default_rng(907)
    n_nan = 0
    for _ in range(1500):
        cam = StereoCamera(f=float(rng.uniform(200, 900)), cu=float(rng.uniform(100, 500)),
                           baseline=float(rng.uniform(0.05, 0.5)), mount_x=float(rng.normal(0, 0.2)),
                           mount_y=float(rng.normal(0, 0.2)), pan=float(rng.uniform(-1, 1)))
        X = np.array([rng.normal(0, 3), rng.normal(0, 3), rng.uniform(-np.pi, np.pi)])
        n = int(rng.integers(0, 31))
        for p in (rng.normal(0, 5, (n, 2)), rng.normal(0, 5, 2), rng.normal(0, 5, (2, n, 2)),
                  np.asfortranarray(rng.normal(0, 5, (n, 2)))):
            for jac in (True, False):
                got = cam.project_columns(X, p, jacobians=jac)
                want = project_columns_reference(cam, X, p, jac)
                got, want = (got, want) if jac else ((got,), (want,))
                for x, y in zip(got, want, strict=True):
                    assert x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True)
            n_nan += bool(np.isnan(got[0]).any())
    assert n_nan > 100
