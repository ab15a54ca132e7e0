import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stablemarks.errors import GeometryError, InputError
from stablemarks.geometry import SE2, StereoCamera, wrap_angle

from .helpers import numerical_jacobian

angles = st.floats(-np.pi, np.pi)
coords = st.floats(-5.0, 5.0)


def camera(pan=0.0, mount=(0.2, -0.05)):
    return StereoCamera(mount_x=mount[0], mount_y=mount[1], mount_height=1.1, pan=pan)


def point_in_front(cam, X, depth, lateral):
    """A world point at (lateral, depth) in the left camera of pose X."""
    return cam.from_camera(X, lateral, depth)


# ---------------------------------------------------------------- SE2
@given(coords, coords, angles, coords, coords, angles)
def test_se2_compose_inverse(x1, y1, t1, x2, y2, t2):
    a, b = SE2(x1, y1, t1), SE2(x2, y2, t2)
    ident = a @ a.inverse()
    assert np.allclose(ident.as_array(), 0, atol=1e-9)
    np.testing.assert_allclose((a @ b).matrix(), a.matrix() @ b.matrix(), atol=1e-9)
    p = np.array([[0.3, -1.2], [2.0, 0.5]])
    np.testing.assert_allclose(a.inverse().transform(a.transform(p)), p, atol=1e-9)
    np.testing.assert_allclose(a.between(a @ b).as_array()[:2], b.as_array()[:2], atol=1e-9)


def test_wrap_angle():
    np.testing.assert_allclose(wrap_angle([np.pi, -np.pi, 3 * np.pi / 2, 0.1]), [-np.pi, -np.pi, -np.pi / 2, 0.1])


# ---------------------------------------------------------- projection
@settings(max_examples=60, deadline=None)
@given(coords, coords, angles, st.floats(-0.6, 0.6), st.floats(0.5, 12.0), st.floats(-3.0, 3.0))
def test_column_jacobians_match_finite_differences(x, y, th, pan, depth, lateral):
    cam = camera(pan)
    X = np.array([x, y, th])
    p = point_in_front(cam, X, depth, lateral)
    _, J_X, J_p = cam.project_columns(X, p, jacobians=True)
    np.testing.assert_allclose(J_X, numerical_jacobian(lambda q: cam.project_columns(q, p), X), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(J_p, numerical_jacobian(lambda q: cam.project_columns(X, q), p), rtol=1e-5, atol=1e-5)


@settings(max_examples=60, deadline=None)
@given(coords, coords, angles, st.floats(-0.6, 0.6), st.floats(0.5, 12.0), st.floats(-3.0, 3.0),
       st.floats(0.0, 1.0), st.floats(1.0, 2.5))
def test_line_jacobians_match_finite_differences(x, y, th, pan, depth, lateral, zl, zh):
    cam = camera(pan)
    X = np.array([x, y, th])
    p = point_in_front(cam, X, depth, lateral)
    L = np.array([p[0], p[1], zl, zh])
    I, J_X, J_L = cam.project_line(X, L, jacobians=True)
    np.testing.assert_allclose(I, cam.project_line(X, L))
    np.testing.assert_allclose(J_X, numerical_jacobian(lambda q: cam.project_line(q, L), X), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(J_L, numerical_jacobian(lambda q: cam.project_line(X, q), L), rtol=1e-5, atol=1e-5)


@settings(max_examples=60, deadline=None)
@given(coords, coords, angles, st.floats(-0.6, 0.6), st.floats(0.5, 12.0), st.floats(-3.0, 3.0))
def test_disparity_jacobian_and_eq8(x, y, th, pan, depth, lateral):
    cam = camera(pan)
    X = np.array([x, y, th])
    p = point_in_front(cam, X, depth, lateral)
    d, J_X, J_p = cam.disparity(X, p, jacobians=True)
    uv = cam.project_columns(X, p)
    assert d == pytest.approx(uv[0] - uv[1], rel=1e-9)  # Eq 7 without noise
    assert d == pytest.approx(cam.f * cam.baseline / depth, rel=1e-9)  # Eq 8
    np.testing.assert_allclose(J_X, numerical_jacobian(lambda q: cam.disparity(q, p), X), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(J_p, numerical_jacobian(lambda q: cam.disparity(X, q), p), rtol=1e-5, atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(coords, coords, angles, st.floats(-0.6, 0.6), st.floats(0.5, 12.0), st.floats(-3.0, 3.0))
def test_project_then_triangulate_round_trip(x, y, th, pan, depth, lateral):
    cam = camera(pan)
    X = np.array([x, y, th])
    p = point_in_front(cam, X, depth, lateral)
    uv = cam.project_columns(X, p)
    q, cov = cam.triangulate(uv[0], uv[1], X)
    np.testing.assert_allclose(q, p, atol=1e-8)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    # camera-frame variant
    c, _ = cam.triangulate(uv[0], uv[1])
    np.testing.assert_allclose(c, [lateral, depth], atol=1e-8)


def test_triangulation_jacobians_match_finite_differences():
    rng = np.random.default_rng(1)
    cam = camera(0.3)
    for _ in range(30):
        X = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        p = point_in_front(cam, X, rng.uniform(1, 8), rng.uniform(-2, 2))
        uv = cam.project_columns(X, p)
        Xc, Zc = cam.to_camera(X, p)
        J_X = cam.triangulation_jacobian_pose(X, Xc, Zc)
        num = numerical_jacobian(lambda q, uv=uv: cam.triangulate(uv[0], uv[1], q)[0], X)
        np.testing.assert_allclose(J_X, num, rtol=1e-6, atol=1e-6)


def test_triangulation_covariance_by_monte_carlo():
    rng = np.random.default_rng(7)
    cam = camera(0.2)
    X = np.array([0.5, -0.3, 0.4])
    cov_X = np.diag([0.02, 0.03, 0.01]) ** 2
    p = point_in_front(cam, X, 4.0, 0.7)
    uv = cam.project_columns(X, p)
    _, cov = cam.triangulate(uv[0], uv[1], X, cov_X)
    n = 40000
    Xs = X + rng.multivariate_normal(np.zeros(3), cov_X, n)
    us = uv + rng.normal(0, cam.sigma_img, (n, 2))
    samples = np.array([cam.triangulate(u[0], u[1], Xi)[0] for u, Xi in zip(us[:4000], Xs[:4000], strict=True)])
    np.testing.assert_allclose(np.cov(samples.T), cov, rtol=0.15)


def test_eq4_eq5_and_eq10_covariances():
    cam = camera(0.1)
    X = np.array([0.0, 0.0, np.pi / 2])
    cov_X = np.diag([0.05, 0.05, np.deg2rad(2)]) ** 2
    p = np.array([0.3, 4.0])
    eq5 = cam.cov_columns(X, cov_X, p)
    eq4 = cam.cov_columns(X, cov_X, p, cov_points=np.diag([0.1, 0.0]) ** 2)
    assert np.all(np.diag(eq4) > np.diag(eq5))
    _, J_X, _ = cam.project_columns(X, p, jacobians=True)
    np.testing.assert_allclose(eq5, J_X @ cov_X @ J_X.T)
    sd = cam.sigma_disparity(X, cov_X, p)
    _, J_d_X, _ = cam.disparity(X, p, jacobians=True)
    assert sd == pytest.approx(np.sqrt(J_d_X @ cov_X @ J_d_X + 2 * cam.sigma_img**2))
    assert sd >= np.sqrt(2) * cam.sigma_img


def test_behind_camera():
    cam = camera()
    X = np.zeros(3)
    assert np.all(np.isnan(cam.project_columns(X, [-1.0, 0.0])))
    with pytest.raises(GeometryError, match="behind the camera"):
        cam.project_line(X, [-1.0, 0.0, 0.0, 1.0])
    assert np.all(np.isnan(cam.triangulate(100.0, 110.0)[0]))  # negative disparity


def test_heights_of_projected_line():
    cam = camera()
    X = np.array([1.0, 2.0, 0.3])
    p = point_in_front(cam, X, 3.0, 0.2)
    L = np.array([p[0], p[1], 0.4, 1.9])
    I = cam.project_line(X, L)
    L2, _ = cam.triangulate_line(*I, X)
    np.testing.assert_allclose(L2, L, atol=1e-9)
    assert I[2] < I[3]  # v_top above v_bottom


@pytest.mark.parametrize("field,value", [("f", -1.0), ("baseline", 0.0), ("width", 0), ("cu", float("nan"))])
def test_camera_validation(field, value):
    with pytest.raises(InputError, match=f"camera.{field}: expected"):
        StereoCamera(**{field: value})


def test_column_ray_points_at_projection():
    cam = camera(-0.2)
    X = np.array([0.3, 0.1, 1.0])
    p = point_in_front(cam, X, 5.0, -1.0)
    u = cam.project_columns(X, p)[0]
    ray = cam.column_ray(X, u)
    c, _ = cam.optical_centres(X)
    direction = (p - c) / np.linalg.norm(p - c)
    np.testing.assert_allclose(ray, direction, atol=1e-12)


def test_triangulation_with_separate_column_sigmas():
    cam = camera(0.0)
    X = np.array([0.0, 0.0, np.pi / 2])
    p = point_in_front(cam, X, 4.0, 0.5)
    uv = cam.project_columns(X, p)
    _, cov_equal = cam.triangulate(uv[0], uv[1], X, sigma_img=2.0)
    _, cov_pair = cam.triangulate(uv[0], uv[1], X, sigma_img=np.array([2.0, 2.0]))
    np.testing.assert_allclose(cov_pair, cov_equal)
    _, cov_left_only = cam.triangulate(uv[0], uv[1], X, sigma_img=np.array([2.0, 0.0]))
    _, cov_right_only = cam.triangulate(uv[0], uv[1], X, sigma_img=np.array([0.0, 2.0]))
    np.testing.assert_allclose(cov_left_only + cov_right_only, cov_equal)

    _, cov_full = cam.triangulate(uv[0], uv[1], X, cov_uv=np.diag([4.0, 4.0]))
    np.testing.assert_allclose(cov_full, cov_equal)
    # fully correlated columns (same shift in both images): disparity unchanged, depth error vanishes
    _, cov_corr = cam.triangulate(uv[0], uv[1], X, cov_uv=4.0 * np.ones((2, 2)))
    assert cov_corr[1, 1] < 1e-3 * cov_equal[1, 1]
