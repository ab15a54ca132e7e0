"""The joint error model of landmarks modelled from one boundary, the fitted wall's check against the map, and
pattern association that does not mistake aliasing for a kidnap."""

from dataclasses import replace

import numpy as np
import pytest

from stablemarks.landmarks import fit_disagreements, relative_error_model
from stablemarks.pipeline import process_frame

from .conftest import COV_PRIOR
from .helpers import assert_psd


@pytest.fixture(scope="module")
def lab_view(lab_scenario, lab_sim, lab_first_frame):
    cam = lab_scenario.camera.with_pan(lab_sim.pans[0])
    X0 = lab_sim.poses[0].as_array()
    fl = process_frame(lab_first_frame.left, lab_first_frame.right, cam, lab_scenario.map, X0, COV_PRIOR)
    plane = next(p for p in fl.planes if sum(c.selected for c in p.candidates) >= 2)
    return cam, fl, plane


def test_every_candidate_carries_its_share_of_the_line_and_the_boundary(lab_view):
    _, fl, _ = lab_view
    assert fl.candidates
    for c in fl.candidates:
        assert c.shared_jacobian.shape == (4,) and np.all(np.isfinite(c.shared_jacobian))
        assert c.shared_cov.shape == (4, 4)
        assert_psd(c.shared_cov)
        assert 0 < c.sigma_own < 0.05
        # the boundary's columns move every feature the same way, whatever its distance from the edge
        assert np.allclose(c.shared_jacobian[2:], fl.candidates[0].shared_jacobian[2:]) or \
            c.plane_id != fl.candidates[0].plane_id or c.edge != fl.candidates[0].edge


def test_the_error_model_predicts_the_estimator_spread(lab_view):
    """Monte Carlo through the estimator itself (triangulate, fuse with a perturbed line, distance from a perturbed
    boundary): the sample covariance of the distances matches ``J Σ Jᵀ + diag(σ_own²)``, off-diagonal included."""
    cam, fl, plane = lab_view
    cands = [c for c in plane.candidates if c.edge == plane.boundaries[0].edge]
    b = next(bd for bd in plane.boundaries if bd.edge == cands[0].edge)
    fit = plane.fit
    t = b.inward
    u = np.array([[c.u_left, c.u_right] for c in cands])
    J, own, S = relative_error_model(cam, fit, b, u[:, 0], u[:, 1], t)
    model = J @ S @ J.T + np.diag(own**2)
    rng = np.random.default_rng(1)
    n = 3000
    R = rng.multivariate_normal([fit.a, fit.b], fit.cov_R, n)
    UB = rng.multivariate_normal(b.u, b.cov_uv, n)
    UF = u[None] + cam.sigma_img * rng.standard_normal((n, *u.shape))
    d = np.empty((n, len(cands)))
    for k in range(n):
        line = replace(fit, a=R[k, 0], b=R[k, 1])
        P_f, cov_f = cam.triangulate(UF[k, :, 0], UF[k, :, 1], fit.X)
        P_b, cov_b = cam.triangulate(UB[k, 0], UB[k, 1], fit.X, cov_uv=b.cov_uv)
        d[k] = (line.fuse_point(P_f, cov_f)[0] - line.fuse_point(P_b, cov_b)[0]) @ t
    sample = np.cov(d.T).reshape(len(cands), len(cands))
    sd = np.sqrt(np.diag(model))
    assert np.allclose(np.sqrt(np.diag(sample)), sd, rtol=0.1)
    assert np.allclose(sample / np.outer(sd, sd), model / np.outer(sd, sd), atol=0.1)


def test_the_slope_moves_far_features_more():
    """``∂s/∂b`` grows with the distance from the edge (the fitted line turns about its centre): a shared error
    the independent ``σ_b² 11ᵀ + diag(σ_f²)`` cannot hold."""
    from .test_landmarks import BASE, run_scene

    result, _ = run_scene(BASE)
    cands = sorted(result.candidates, key=lambda c: c.s)
    assert len(cands) >= 2
    slopes = [abs(c.shared_jacobian[1]) for c in cands]
    assert slopes[-1] > slopes[0]


def test_entering_uses_the_joint_model(lab_view, lab_scenario):
    from stablemarks.estimation import JointEKF
    from stablemarks.methods import enter_wall_landmarks

    cam, fl, plane = lab_view
    group = [c for c in fl.selected if c.plane_id == plane.fit.plane.id]
    group = [c for c in group if c.edge == group[0].edge]
    ekf = JointEKF(cam, fl.X, COV_PRIOR)
    out = enter_wall_landmarks(ekf, lab_scenario.map, group, 0)
    ids, _, cov = out.priors[0]
    J = np.stack([c.shared_jacobian for c in group])
    expect = J @ group[0].shared_cov @ J.T + np.diag([c.sigma_own**2 for c in group])
    assert np.allclose(cov, expect)
    assert_psd(ekf.cov)


# ------------------------------------------------------------------ the fitted wall against the map
def test_a_fitted_wall_where_the_map_puts_it_passes_and_a_turned_one_does_not(lab_view):
    cam, fl, plane = lab_view
    fit = plane.fit
    on_map = replace(fit, a=0.0, b=0.0, cov_R=np.diag([1e-4, 1e-4]))
    assert fit_disagreements(cam, on_map, COV_PRIOR)[0] == pytest.approx(0.0)
    turned = replace(on_map, b=0.25)  # another surface, 14° off, with a tight fit
    tight = np.diag([1e-4, 1e-4, 0.005**2])
    assert fit_disagreements(cam, turned, tight)[0] > 100
    # the wall a heading error of 0.25 rad shows is plausible when the heading is that uncertain
    from stablemarks.landmarks import seen_wall_jacobian

    a, b = seen_wall_jacobian(cam, on_map)[:, 2] * 0.25
    loose = np.diag([1e-4, 1e-4, 0.25**2])
    assert fit_disagreements(cam, replace(on_map, a=a, b=b), loose)[0] < 13.8
    assert fit_disagreements(cam, replace(on_map, a=a, b=b), tight)[0] > 100


def test_the_pose_moves_the_seen_wall_as_the_geometry_says(lab_view):
    """A heading error turns the wall seen through the belief by as much (``|∂b/∂θ| = 1``) and a position error
    does not turn it; a step along the wall's normal moves its offset one for one, a step along it not at all."""
    from stablemarks.landmarks import seen_wall_jacobian

    cam, fl, plane = lab_view
    J = seen_wall_jacobian(cam, plane.fit)
    n, t = plane.fit.plane.normal, plane.fit.plane.direction
    assert abs(J[1, 2]) == pytest.approx(1.0, rel=1e-3)
    assert np.allclose(J[1, :2], 0.0, atol=1e-6)
    assert abs(J[0, :2] @ n) == pytest.approx(1.0, rel=1e-6)
    assert J[0, :2] @ t == pytest.approx(0.0, abs=1e-6)


# ------------------------------------------------------------------ aliasing is not a kidnap
def test_an_aliased_pattern_is_matched_at_the_offset_the_pose_allows():
    """Four landmarks 0.4 m apart. This frame's boundary is 0.4 m off (one spacing), so its candidates sit where the
    next features were mapped: the offset matching all four pairs each line with its neighbour's landmark, which
    the confident pose rules out. The wall's next-best offset (three features, each with its own landmark) is
    compatible and is taken; nothing is reported as disagreeing with the odometry."""
    from types import SimpleNamespace

    from stablemarks.estimation import associate_frame

    from .test_association import COV_POSE, WALL, X0, _cand, _ekf, _Pairs

    s_true = np.array([0.5, 0.9, 1.3, 1.7])
    ekf = _ekf(s=tuple(s_true), polarity=(0, 0, 0, 0))
    ids = ekf.landmark_ids
    cam = ekf.camera
    # the lines where they are (columns at the true pose = the belief), their positions measured 0.4 m too far
    uv = ekf.predict_observation(ids).uv
    cands = [_cand(WALL, s + 0.4, k) for k, s in enumerate(s_true)]
    model = SimpleNamespace(planes=[SimpleNamespace(fit=SimpleNamespace(plane=WALL), candidates=cands)])
    report: dict = {}
    got = associate_frame(ekf, _Pairs(4), uv, 0.0, model, np.zeros(4, dtype=int), cam.optical_centres(X0)[0], report)
    assert sorted(got) == sorted(zip(ids, range(4), strict=True))
    assert not report["incompatible"]
    assert COV_POSE[2, 2] < 1e-4  # the pose is confident: the aliased match moves every line by 0.4 m


def _reference_error_model(camera, fit, boundary, u_left, u_right, t, step_px=0.01, step_line=1e-4):
    """The error model one central difference at a time through the estimator (the former implementation)."""
    X, cov_ub = fit.X, boundary.cov_uv
    u_f = np.stack([u_left, u_right], axis=-1)

    def distances(line, ub, uf):
        P_f, cov_f = camera.triangulate(uf[:, 0], uf[:, 1], X)
        P_b, cov_b = camera.triangulate(ub[0], ub[1], X, cov_uv=cov_ub)
        return (line.fuse_point(P_f, cov_f)[0] - line.fuse_point(P_b, cov_b)[0]) @ t

    ub0 = np.asarray(boundary.u, dtype=float)
    J = np.empty((len(u_f), 4))
    for i, key in enumerate(("a", "b")):
        hi, lo = (replace(fit, **{key: getattr(fit, key) + d}) for d in (step_line, -step_line))
        J[:, i] = (distances(hi, ub0, u_f) - distances(lo, ub0, u_f)) / (2 * step_line)
    own = np.zeros(len(u_f))
    for i in range(2):
        e = np.zeros(2)
        e[i] = step_px
        J[:, 2 + i] = (distances(fit, ub0 + e, u_f) - distances(fit, ub0 - e, u_f)) / (2 * step_px)
        own += ((distances(fit, ub0, u_f + e) - distances(fit, ub0, u_f - e)) / (2 * step_px) * camera.sigma_img) ** 2
    return J, np.sqrt(own)


def test_the_batched_error_model_equals_one_difference_at_a_time(lab_view):
    """All perturbations in one batch (and the offset's step as a shift along the normal) give the same numbers as
    the differences taken one by one."""
    cam, fl, _ = lab_view
    checked = 0
    for plane in fl.planes:
        for b in plane.boundaries:
            cands = [c for c in plane.candidates if c.edge == b.edge]
            if not cands:
                continue
            u = np.array([[c.u_left, c.u_right] for c in cands])
            J, own, _ = relative_error_model(cam, plane.fit, b, u[:, 0], u[:, 1], b.inward)
            J_ref, own_ref = _reference_error_model(cam, plane.fit, b, u[:, 0], u[:, 1], b.inward)
            np.testing.assert_allclose(J, J_ref, rtol=1e-7, atol=1e-9)
            np.testing.assert_allclose(own, own_ref, rtol=1e-7)
            checked += 1
    assert checked
