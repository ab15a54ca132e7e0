"""Checks of the s9 speed pass: each rewritten step against the code it replaced (kept here as a reference, or,
for ``triangulate``, the array code the method keeps for columns of other shapes), bit for bit unless said
otherwise."""

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


def _random_camera_and_pose(rng) -> tuple[StereoCamera, np.ndarray]:
    cam = StereoCamera(f=float(rng.uniform(200, 900)), cu=float(rng.uniform(100, 500)),
                       baseline=float(rng.uniform(0.05, 0.5)), mount_x=float(rng.normal(0, 0.2)),
                       mount_y=float(rng.normal(0, 0.2)), pan=float(rng.uniform(-1, 1)))
    return cam, np.array([rng.normal(0, 3), rng.normal(0, 3), rng.uniform(-np.pi, np.pi)])


def test_project_columns_kernel_equals_the_array_code():
    """Points (2,), (n, 2) and (a, n, 2), with and without Jacobians, 0 to 30 of them, some behind the camera: the
    same columns and Jacobians as the former array code, shapes and dtypes, bit for bit, NaN where it had NaN."""
    rng = np.random.default_rng(907)
    n_nan = 0
    for _ in range(1500):
        cam, X = _random_camera_and_pose(rng)
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


# ------------------------------------------------------------------ the EKF's projection kept at its own state
def _random_filter(rng):
    from stablemarks.estimation import JointEKF, NewLandmark
    from stablemarks.maps import ReferencePlane

    cam = StereoCamera(mount_x=float(rng.normal(0, 0.1)), pan=float(rng.uniform(-0.5, 0.5)))
    X = np.array([rng.normal(0, 0.3), rng.normal(0, 0.3), np.pi / 2 + rng.normal(0, 0.3)])
    ekf = JointEKF(cam, X, np.diag([0.05, 0.05, 0.02]) ** 2)
    wall = ReferencePlane("w", (-3.0, 4.0), (3.0, 4.0), free_edges=("p1", "p2"))
    n_wall, n_point = int(rng.integers(1, 9)), int(rng.integers(0, 6))
    new = [NewLandmark.wall(wall, float(s)) for s in rng.uniform(0.5, 5.5, n_wall)]
    new += [NewLandmark.point((float(rng.uniform(-3, 3)), float(rng.uniform(2, 6)))) for _ in range(n_point)]
    D = n_wall + 2 * n_point
    A = rng.normal(0, 0.05, (D, D))
    ekf.add_landmarks(new, A @ A.T + 1e-4 * np.eye(D))
    return ekf


def _same(got, want):
    for x, y in zip(got, want, strict=True):
        assert x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True)


def test_projection_kept_at_the_state_equals_the_projection_of_the_rows():
    """Any rows (all, a subset in any order, none) at the filter's state, at a copy of it and elsewhere: the same
    arrays as projecting those rows alone; the kept projection follows the state changed in place, the landmarks
    added or removed and another pan."""
    rng = np.random.default_rng(911)
    n_hits = 0
    for _ in range(200):
        ekf = _random_filter(rng)
        n = ekf.n_landmarks
        for step in range(4):
            cam = ekf._camera(float(rng.choice([0.0, 0.1])))
            for x in (ekf._x, ekf._x.copy(), ekf._x + rng.normal(0, 0.01, len(ekf._x))):
                for rows in (np.arange(n), rng.permutation(n)[: int(rng.integers(0, n + 1))]):
                    hit = ekf._projected is not None and ekf._projected[1] == x.tobytes() \
                        and ekf._projected[0] is cam
                    n_hits += hit
                    _same(ekf._project(rows, x, cam), ekf._project_rows(rows, x, cam))
            if step == 0:
                ekf.predict(rng.normal(0, 0.05, 3), 1e-4 * np.eye(3))  # the state changed in place
            elif step == 1:
                ekf.remove_landmark(ekf.landmark_ids[0]) if n > 1 else None
                n = ekf.n_landmarks
            elif step == 2:
                from stablemarks.estimation import NewLandmark

                ekf.add_landmarks([NewLandmark.point((0.5, 3.0))], 1e-3 * np.eye(2))
                n = ekf.n_landmarks
    assert n_hits > 1000


def test_predict_observation_and_update_with_the_kept_projection_equal_those_without(monkeypatch):
    """associate_joint → select_for_update → update as a frame runs them, with the projection kept and with
    every projection computed anew: the same pairs, state and covariance, bit for bit."""
    from stablemarks.estimation import JointEKF

    rng = np.random.default_rng(913)
    for _ in range(60):
        ekf = _random_filter(rng)
        uv = ekf.predict_observation().uv
        measured = uv[np.isfinite(uv).all(axis=1)] + rng.normal(0, 0.7, (int(np.isfinite(uv).all(axis=1).sum()), 2))
        results = []
        for kept in (True, False):
            e = ekf.copy()
            if not kept:
                monkeypatch.setattr(JointEKF, "_project", JointEKF._project_rows)
            chosen = e.select_for_update(e.associate_joint(measured, 0.0))
            res = e.update([(i, measured[j]) for i, j in chosen], iterations=3)
            results.append((chosen, e._x.copy(), e._P.copy(), res))
            monkeypatch.undo()
        (c1, x1, P1, r1), (c2, x2, P2, r2) = results
        assert c1 == c2 and np.array_equal(x1, x2) and np.array_equal(P1, P2)
        assert np.array_equal(r1.nis, r2.nis) and r1.nis_total == r2.nis_total


# ------------------------------------------------------------------ triangulate of column arrays by the kernel
def triangulate_reference(cam: StereoCamera, u_l, u_r, X, cov_X=None, sigma_img=None, cov_uv=None):
    """:meth:`StereoCamera.triangulate`'s array code, which columns of any other shape still take: the same columns
    as (n, 1), the result back to (n, ...)."""
    if sigma_img is not None and np.ndim(sigma_img) == 2:
        sigma_img = np.asarray(sigma_img)[:, None, :]
    p, cov = cam.triangulate(np.asarray(u_l)[:, None], np.asarray(u_r)[:, None], X, cov_X, sigma_img=sigma_img,
                             cov_uv=cov_uv)
    return p[:, 0], cov[:, 0]


def test_triangulate_kernel_equals_the_array_code():
    """Column arrays (n,) in the world, with the camera's σ, a σ per image, a full covariance per pair and the pose
    covariance, some pairs of zero or negative disparity: the same points and covariances bit for bit."""
    rng = np.random.default_rng(919)
    n_nan = 0
    for _ in range(1500):
        cam, X = _random_camera_and_pose(rng)
        n = int(rng.integers(0, 20))
        u_l = rng.uniform(0, 640, n)
        u_r = u_l - rng.uniform(-5, 60, n)
        A = rng.normal(0, 0.1, (3, 3))
        options = [{}, {"sigma_img": 0.7}, {"sigma_img": rng.uniform(0.2, 2, (n, 2))},
                   {"cov_uv": np.eye(2) * 0.3 + 0.1}, {"cov_X": A @ A.T}]
        for kw in options:
            got = cam.triangulate(u_l, u_r, X, **kw)
            want = triangulate_reference(cam, u_l, u_r, X, **kw)
            _same(got, want)
        n_nan += bool(np.isnan(got[0]).any())
    assert n_nan > 100
