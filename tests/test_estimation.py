import numpy as np
import pytest
import yaml
from scipy.stats import chi2

from stablemarks.errors import ConfigError, GeometryError, InputError
from stablemarks.estimation import BLAS_PIN_MIN_DIM, EKFConfig, JointEKF, NewLandmark, _add_sym_rank, motion
from stablemarks.geometry import StereoCamera, wrap_angle
from stablemarks.maps import Map, ReferencePlane

from .helpers import assert_psd, numerical_jacobian

CAM = StereoCamera(mount_x=0.15, mount_y=-0.04, mount_height=1.1)
# A wall 5 m ahead of a robot at the origin facing +y, free edge p1 on the left; a second wall seen from p2.
WALL = ReferencePlane("partition", (-1.5, 5.0), (1.5, 5.0), free_edges=("p1",))
BOARD = ReferencePlane("board", (2.5, 4.0), (0.5, 6.0), free_edges=("p2",))
WORLD = Map((WALL, BOARD))
X0 = np.array([0.0, 0.0, np.pi / 2])


def random_spd(rng, n, scale=1.0):
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T / n + 0.1 * np.eye(n))


def mixed_landmarks(rng):
    """Wall landmarks on both walls (both edge conventions) and free points, all in front of X0."""
    return [
        NewLandmark.wall(WALL, rng.uniform(0.5, 2.5)),
        NewLandmark.point((rng.uniform(-1.0, 1.0), rng.uniform(3.0, 4.5)), 0.1, 1.2),
        NewLandmark.wall(BOARD, rng.uniform(0.3, 1.5), edge="p2"),
        NewLandmark.wall(WALL, rng.uniform(0.5, 2.5), z_low=0.2, z_high=1.7),
        NewLandmark.point((rng.uniform(-1.0, 1.0), rng.uniform(3.0, 4.5))),
    ]


def random_filter(rng, scale=1e-3):
    """A filter whose full covariance is a random SPD matrix (pose, landmarks and every cross term)."""
    lms = mixed_landmarks(rng)
    D = sum(lm.dim for lm in lms)
    A = random_spd(rng, 3 + D, scale)
    pose = X0 + rng.normal(scale=[0.05, 0.05, 0.02])
    ekf = JointEKF(CAM, pose, A[:3, :3])
    ekf.add_landmarks(lms, A[3:, 3:], cov_pose_new=A[:3, 3:])
    np.testing.assert_array_equal(ekf.cov, 0.5 * (A + A.T))
    return ekf, lms


# ------------------------------------------------------------- dense reference
def dense_observation(cam, x, lms, ids_rows, pan):
    """Stacked columns (2m,) and the full H (2m, N), built landmark by landmark from the camera model."""
    cam = cam.with_pan(pan)
    offsets = np.cumsum([3] + [lm.dim for lm in lms])
    h, H = [], np.zeros((2 * len(ids_rows), len(x)))
    for j, r in enumerate(ids_rows):
        lm, o = lms[r], offsets[r]
        if lm.kind == "wall":
            p = lm.plane.point_at(x[o], lm.edge)
            t = lm.plane.direction * (1.0 if lm.edge == "p1" else -1.0)
            J_p_l = t[:, None]
        else:
            p = x[o:o + 2]
            J_p_l = np.eye(2)
        uv, J_X, J_p = cam.project_columns(x[:3], p, jacobians=True)
        h.append(uv)
        H[2 * j:2 * j + 2, :3] = J_X
        H[2 * j:2 * j + 2, o:o + lm.dim] = J_p @ J_p_l
    return np.concatenate(h), H


class DenseEKF:
    """Textbook EKF with full matrices: F (N, N), H (2m, N), Joseph form with (I − KH)."""

    def __init__(self, x, P):
        self.x, self.P = x.copy(), P.copy()

    def predict(self, U, cov_U):
        N = len(self.x)
        X_new, J_X, J_U = motion(self.x[:3], U, jacobians=True)
        F = np.eye(N)
        F[:3, :3] = J_X
        G = np.zeros((N, 3))
        G[:3] = J_U
        self.x[:3] = X_new
        self.P = F @ self.P @ F.T + G @ cov_U @ G.T

    def update(self, z, hx, H, R):
        S = H @ self.P @ H.T + R
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ (z - hx)
        self.x[2] = wrap_angle(self.x[2])
        I_KH = np.eye(len(self.x)) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ R @ K.T


# -------------------------------------------------------------------- motion
@pytest.mark.parametrize("seed", range(5))
def test_motion_jacobians_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    X = np.array([rng.normal(), rng.normal(), rng.uniform(-3.0, 3.0)])
    U = rng.normal(scale=[0.3, 0.1, 0.2])
    if seed == 0:
        U = np.zeros(3)  # standing still
    _, J_X, J_U = motion(X, U, jacobians=True)
    np.testing.assert_allclose(J_X, numerical_jacobian(lambda q: motion(q, U), X), atol=1e-8)
    np.testing.assert_allclose(J_U, numerical_jacobian(lambda q: motion(X, q), U), atol=1e-8)


def test_motion_composes_in_the_robot_frame():
    X = motion([1.0, 2.0, np.pi / 2], [0.5, 0.1, np.pi])
    np.testing.assert_allclose(X, [0.9, 2.5, -np.pi / 2], atol=1e-12)


# --------------------------------------------------------------- observation
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("pan", [0.0, 0.3])
def test_observation_jacobians_match_finite_differences(seed, pan):
    rng = np.random.default_rng(seed)
    ekf, lms = random_filter(rng)
    ids = ekf.landmark_ids[::-1]
    h, H = ekf.observation_model(ids, pan)
    np.testing.assert_allclose(H, numerical_jacobian(h, ekf.state), rtol=1e-6, atol=1e-6)
    # ... and equals the landmark-by-landmark construction and predict_observation's blocks.
    hd, Hd = dense_observation(CAM, ekf.state, lms, [ekf.landmark_ids.index(i) for i in ids], pan)
    np.testing.assert_allclose(h(ekf.state), hd, atol=1e-10)
    np.testing.assert_allclose(H, Hd, atol=1e-10)
    pred = ekf.predict_observation(ids, pan)
    np.testing.assert_allclose(pred.uv.ravel(), hd, atol=1e-10)
    for j, i in enumerate(ids):
        Hj = Hd[2 * j:2 * j + 2]
        np.testing.assert_allclose(pred.J_I_X[j], Hj[:, :3], atol=1e-10)
        sl = ekf.state_slice(i)
        np.testing.assert_allclose(pred.J_I_l[j][:, :sl.stop - sl.start], Hj[:, sl], atol=1e-10)
        np.testing.assert_allclose(pred.S[j], Hj @ ekf.cov @ Hj.T + 0.25 * np.eye(2), atol=1e-10)


def test_observation_uses_the_frames_pan():
    ekf, _ = random_filter(np.random.default_rng(1))
    pts = np.array([ekf.landmark_position(i) for i in ekf.landmark_ids])
    pred = ekf.predict_observation(None, pan=0.2)
    np.testing.assert_allclose(pred.uv, CAM.with_pan(0.2).project_columns(ekf.pose, pts), atol=1e-12)


# ------------------------------------------------------- against the dense EKF
@pytest.mark.parametrize("seed", range(6))
def test_predict_and_update_equal_the_dense_reference(seed):
    rng = np.random.default_rng(seed)
    ekf, lms = random_filter(rng)
    dense = DenseEKF(ekf.state, ekf.cov)
    for step in range(4):
        U = rng.normal(scale=[0.1, 0.02, 0.05])
        cov_U = random_spd(rng, 3, 1e-4)
        ekf.predict(U, cov_U)
        dense.predict(U, cov_U)
        np.testing.assert_allclose(ekf.state, dense.x, atol=1e-10)
        np.testing.assert_allclose(ekf.cov, dense.P, atol=1e-10)
        pan = rng.uniform(-0.2, 0.2)
        ids = [int(i) for i in rng.permutation(ekf.landmark_ids)[: rng.integers(1, 6)]]
        pred = ekf.predict_observation(ids, pan)
        z = pred.uv + rng.normal(scale=0.5, size=pred.uv.shape)
        res = ekf.update(list(zip(ids, z, strict=True)), pan, frame=step)
        hx, H = dense_observation(CAM, dense.x, lms, [ekf.landmark_ids.index(i) for i in ids], pan)
        dense.update(z.ravel(), hx, H, 0.25 * np.eye(2 * len(ids)))
        np.testing.assert_allclose(ekf.state, dense.x, atol=1e-10)
        np.testing.assert_allclose(ekf.cov, dense.P, atol=1e-10)
        np.testing.assert_allclose(res.innovations.ravel(), z.ravel() - hx, atol=1e-10)
    assert res.dof == 2 * len(ids)


@pytest.mark.parametrize("block", [1, 4, 7, 64])
def test_symmetric_rank_update_by_strips(block):
    rng = np.random.default_rng(block)
    n, r = 23, 6
    P = random_spd(rng, n)
    A, K = rng.normal(size=(n, r)), rng.normal(size=(n, r))
    Q = P.copy()
    _add_sym_rank(Q, A, K, block=block)
    np.testing.assert_allclose(Q, P + A @ K.T + K @ A.T, atol=1e-12)
    np.testing.assert_array_equal(Q, Q.T)


def test_large_state_update_equals_the_dense_reference():
    # Several strips of the symmetric update and the one-thread BLAS path.
    rng = np.random.default_rng(12)
    n = BLAS_PIN_MIN_DIM + 40
    lms = [NewLandmark.wall(WALL, v) for v in rng.uniform(0.3, 2.9, n)]
    L = rng.normal(scale=0.02, size=(3 + n, 8))
    P0 = L @ L.T + 1e-4 * np.eye(3 + n)
    ekf = JointEKF(CAM, X0, P0[:3, :3])
    ekf.add_landmarks(lms, P0[3:, 3:], cov_pose_new=P0[:3, 3:])
    dense = DenseEKF(ekf.state, ekf.cov)
    ids = [int(i) for i in rng.choice(ekf.landmark_ids, 6, replace=False)]
    z = ekf.predict_observation(ids).uv + rng.normal(scale=0.5, size=(6, 2))
    ekf.update(list(zip(ids, z, strict=True)))
    hx, H = dense_observation(CAM, dense.x, lms, [ekf.landmark_ids.index(i) for i in ids], 0.0)
    dense.update(z.ravel(), hx, H, 0.25 * np.eye(12))
    np.testing.assert_allclose(ekf.state, dense.x, atol=1e-10)
    np.testing.assert_allclose(ekf.cov, dense.P, atol=1e-10)
    np.testing.assert_array_equal(ekf.cov, ekf.cov.T)


def test_nis_matches_its_definition():
    rng = np.random.default_rng(3)
    ekf, _ = random_filter(rng)
    ids = ekf.landmark_ids[:3]
    pred = ekf.predict_observation(ids)
    h, H = ekf.observation_model(ids)
    S = H @ ekf.cov @ H.T + 0.25 * np.eye(6)
    z = pred.uv + rng.normal(size=pred.uv.shape)
    nu = (z - pred.uv).ravel()
    res = ekf.update(list(zip(ids, z, strict=True)))
    assert res.nis_total == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-10)
    for j in range(3):
        Sj = S[2 * j:2 * j + 2, 2 * j:2 * j + 2]
        assert res.nis[j] == pytest.approx(nu[2 * j:2 * j + 2] @ np.linalg.solve(Sj, nu[2 * j:2 * j + 2]), rel=1e-10)


def test_update_with_no_observation_is_a_no_op():
    ekf, _ = random_filter(np.random.default_rng(4))
    x, P = ekf.state, ekf.cov
    res = ekf.update([], pan=0.1)
    assert res.dof == 0 and res.nis_total == 0.0
    np.testing.assert_array_equal(ekf.state, x)
    np.testing.assert_array_equal(ekf.cov, P)
    assert all(ekf.landmark(i).n_observed == 0 for i in ekf.landmark_ids)


def test_counters_and_frames():
    ekf = JointEKF(CAM, X0, np.diag([1e-3, 1e-3, 1e-4]))
    (a, b) = ekf.add_landmarks([NewLandmark.wall(WALL, 1.0), NewLandmark.wall(WALL, 2.0)], 1e-3 * np.eye(2), frame=3)
    pred = ekf.predict_observation([a])
    ekf.update([(a, pred.uv[0])], frame=5)
    la, lb = ekf.landmark(a), ekf.landmark(b)
    assert (la.n_observed, la.first_frame, la.last_frame) == (1, 3, 5)
    assert (lb.n_observed, lb.first_frame, lb.last_frame) == (0, 3, 3)


# ----------------------------------------------------------------- stability
def test_covariance_stays_symmetric_psd_over_a_long_random_run():
    # 800 frames: some 2000 predict / add (joint, with and without pose cross-covariance) / update / remove steps
    rng = np.random.default_rng(11)
    ekf = JointEKF(CAM, X0, np.diag([1e-2, 1e-2, 1e-3]))
    for step in range(800):
        ekf.predict(rng.normal(scale=[0.05, 0.01, 0.05]), random_spd(rng, 3, 1e-5))
        if rng.random() < 0.3 or ekf.n_landmarks < 3:
            # new landmarks ahead of the estimated pose, with a joint covariance and a cross-covariance to X
            n_new = int(rng.integers(1, 4))
            cam_xy = CAM.from_camera(ekf.pose, rng.uniform(-1.5, 1.5, n_new), rng.uniform(2.0, 6.0, n_new))
            new = [NewLandmark.point(p) if rng.random() < 0.5 else
                   NewLandmark.wall(ReferencePlane(f"w{step}_{j}", tuple(p), tuple(p + rng.normal(size=2))), 0.0)
                   for j, p in enumerate(cam_xy)]
            D = sum(lm.dim for lm in new)
            B = rng.normal(scale=0.3, size=(3, D)) * (rng.random() < 0.5)
            P_XX = ekf.cov_pose
            ekf.add_landmarks(new, B.T @ P_XX @ B + random_spd(rng, D, 1e-3), cov_pose_new=P_XX @ B, frame=step)
        while ekf.n_landmarks > 25:
            ekf.remove_landmark(int(rng.choice(ekf.landmark_ids)))
        pan = rng.uniform(-0.3, 0.3)
        pred = ekf.predict_observation(None, pan)
        obs = [(int(i), uv + rng.normal(scale=0.5, size=2)) for i, uv, ok in zip(pred.ids, pred.uv, pred.in_view,
                                                                                   strict=True) if ok]
        pairs = ekf.select_for_update([(i, j) for j, (i, _) in enumerate(obs)], pan)
        ekf.update([obs[j] for _, j in pairs], pan, frame=step)
        P = ekf.cov
        np.testing.assert_array_equal(P, P.T)  # exactly symmetric, by construction
        if step % 200 == 0:
            assert_psd(P)
    assert_psd(ekf.cov)
    assert np.all(np.isfinite(ekf.state))


# ------------------------------------------------------------- association
def two_landmark_filter(sigma_s=1e-4):
    ekf = JointEKF(CAM, X0, np.diag([1e-4, 1e-4, 1e-6]))
    ids = ekf.add_landmarks([NewLandmark.wall(WALL, 1.2), NewLandmark.wall(WALL, 1.27)], sigma_s * np.eye(2))
    return ekf, ids


def test_measurement_far_from_every_prediction_is_gated_out():
    ekf, (a, b) = two_landmark_filter()
    uv = ekf.predict_observation([a, b]).uv
    assert ekf.associate(uv[:1] + [40.0, 40.0]) == []
    # the right disparity but 40 px aside: still no pair; the good one alongside is kept
    assert ekf.associate(np.vstack([uv[0] + 40.0, uv[1] + 0.3])) == [(b, 1)]
    assert ekf.associate(np.zeros((0, 2))) == []


def test_swapped_measurements_are_assigned_correctly():
    ekf, (a, b) = two_landmark_filter()
    uv = ekf.predict_observation([a, b]).uv
    assert ekf.associate(uv[::-1] + 0.4) == [(b, 0), (a, 1)]
    # Measurement 0 is nearest to a, but only a can explain measurement 1: the one-to-one optimum gives 0 to b.
    pred = ekf.predict_observation([a, b])
    mid = 0.55 * uv[0] + 0.45 * uv[1]
    z = np.vstack([mid, uv[0] - 0.25 * (uv[1] - uv[0])])
    nu = z[None] - uv[:, None]
    d2 = np.einsum("cki,cij,ckj->ck", nu, np.linalg.inv(pred.S), nu)
    gate = EKFConfig().gate
    assert d2[0, 0] < d2[1, 0] <= gate and d2[0, 1] <= gate < d2[1, 1]  # the setting is what it claims
    assert ekf.associate(z) == [(b, 0), (a, 1)]


def test_extra_cost_breaks_ties():
    ekf, (a, b) = two_landmark_filter(sigma_s=0.05**2)  # uncertain: both gates cover both measurements
    uv = ekf.predict_observation([a, b]).uv
    z = np.vstack([0.5 * (uv[0] + uv[1])] * 2)
    assert len(ekf.associate(z)) == 2
    extra = np.array([[0.0, 50.0], [50.0, 0.0]])  # e.g. heights: measurement 0 looks like a, 1 like b
    assert ekf.associate(z, candidates=[a, b], extra_cost=extra) == [(a, 0), (b, 1)]
    assert ekf.associate(z, candidates=[a, b], extra_cost=extra[::-1]) == [(b, 0), (a, 1)]


def test_landmark_out_of_view_is_no_candidate():
    ekf, (a, b) = two_landmark_filter()
    (c,) = ekf.add_landmarks([NewLandmark.point((0.0, -3.0))], 1e-4 * np.eye(2))  # behind the robot
    assert set(ekf.visible()) == {a, b}
    # turn left by 50°: the wall leaves the image
    ekf.predict([0.0, 0.0, np.radians(50.0)], np.diag([1e-6, 1e-6, 1e-6]))
    pred = ekf.predict_observation([a, b, c])
    assert not pred.in_view.any()
    assert np.isfinite(pred.uv[:2]).all() and np.isnan(pred.uv[2]).all()
    assert ekf.associate(pred.uv[:2]) == []
    # ... and panning the head back brings it into view again
    assert set(ekf.visible(pan=-np.radians(50.0))) == {a, b}


def test_update_behind_the_camera_raises():
    ekf = JointEKF(CAM, X0, np.eye(3) * 1e-4)
    (c,) = ekf.add_landmarks([NewLandmark.point((0.0, -3.0))], 1e-4 * np.eye(2))
    with pytest.raises(GeometryError, match=f"landmark {c} is behind the camera"):
        ekf.update([(c, (300.0, 290.0))])


# ------------------------------------------------------------------- selection
def test_information_gain_is_the_pose_log_det_reduction():
    rng = np.random.default_rng(5)
    ekf, _ = random_filter(rng)
    ids = ekf.landmark_ids
    gain = ekf.information_gain(ids, pan=0.1)
    for i, g in zip(ids, gain, strict=True):
        f = ekf.copy()
        f.update([(i, f.predict_observation([i], 0.1).uv[0])], pan=0.1)
        reduction = 0.5 * (np.linalg.slogdet(ekf.cov_pose)[1] - np.linalg.slogdet(f.cov_pose)[1])
        assert g == pytest.approx(reduction, rel=1e-7)


def test_selection_prefers_less_uncertain_landmarks():
    ekf = JointEKF(CAM, X0, np.diag([0.05, 0.05, 0.01]) ** 2)
    s = [0.6, 0.9, 1.2, 1.5, 1.8, 2.1]
    sigma = [0.2, 0.01, 0.2, 0.02, 0.2, 0.005]
    ids = ekf.add_landmarks([NewLandmark.wall(WALL, v) for v in s], np.diag(sigma) ** 2)
    pairs = [(i, j) for j, i in enumerate(ids)]
    chosen = ekf.select_for_update(pairs, k=3)
    assert {i for i, _ in chosen} == {ids[1], ids[3], ids[5]}
    assert len(ekf.select_for_update(pairs)) == 6 and ekf.select_for_update([], k=3) == []


# ------------------------------------------------------------- consistency
def simulate_run(rng, *, joint: bool, n_steps: int = 25):
    """Drive toward a wall with 8 known-true landmarks; return pose NEES per step and final landmark NEES."""
    s_true = np.linspace(0.6, 2.7, 8)
    sigma_b, sigma_f = 0.05, 0.01  # shared boundary error, per-feature error [m]
    cov_true = sigma_b**2 * np.ones((8, 8)) + sigma_f**2 * np.eye(8)
    cov_init = cov_true if joint else np.diag(np.diag(cov_true))
    s_est = s_true + rng.normal(scale=sigma_b) + rng.normal(scale=sigma_f, size=8)
    P0 = np.diag([0.05, 0.05, 0.02]) ** 2
    X_true = X0 + np.linalg.cholesky(P0) @ rng.normal(size=3)
    ekf = JointEKF(CAM, X0, P0)
    ids = ekf.add_landmarks([NewLandmark.wall(WALL, v) for v in s_est], cov_init)
    points = WALL.point_at(s_true)
    pan = 0.05
    nees = []
    for step in range(n_steps):
        U_true = np.array([0.1, 0.0, 0.02 * np.sin(step / 3.0)])
        cov_U = np.diag([0.01, 0.005, 0.005]) ** 2
        X_true = motion(X_true, U_true)
        ekf.predict(U_true + np.linalg.cholesky(cov_U) @ rng.normal(size=3), cov_U)
        uv = CAM.with_pan(pan).project_columns(X_true, points)
        seen = np.all(CAM.in_image(uv), axis=1)
        z = uv + rng.normal(scale=0.5, size=uv.shape)
        obs = [(ids[j], z[j]) for j in np.flatnonzero(seen)]
        chosen = ekf.select_for_update([(i, j) for j, (i, _) in enumerate(obs)], pan)
        ekf.update([obs[j] for _, j in chosen], pan, frame=step)
        e = X_true - ekf.pose
        e[2] = wrap_angle(e[2])
        nees.append(e @ np.linalg.solve(ekf.cov_pose, e))
    e_l = ekf.state[3:] - s_true
    return np.array(nees), float(e_l @ np.linalg.solve(ekf.cov[3:, 3:], e_l))


def test_monte_carlo_consistency_and_joint_boundary_initialisation():
    runs = 30
    rng = np.random.default_rng(2024)
    joint = [simulate_run(rng, joint=True) for _ in range(runs)]
    indep = [simulate_run(rng, joint=False) for _ in range(runs)]
    lo, hi = chi2.ppf([0.025, 0.975], 3 * runs) / runs
    pose_nees = np.mean([r[0] for r in joint], axis=0)
    assert np.mean((pose_nees > lo) & (pose_nees < hi)) >= 0.7, pose_nees
    pose_nees_indep = np.mean([r[0] for r in indep], axis=0)  # overconfident: the check can fail
    assert np.mean(pose_nees_indep < hi) < 0.3, pose_nees_indep
    # landmark NEES (8 dof): the joint initialisation stays inside the bounds, the independent one does not
    lo8, hi8 = chi2.ppf([0.025, 0.975], 8 * runs) / runs
    nees_joint = np.mean([r[1] for r in joint])
    nees_indep = np.mean([r[1] for r in indep])
    assert lo8 < nees_joint < hi8
    assert nees_indep > hi8


def _wide_prior_nees(iterations: int, runs: int, seed: int = 7) -> np.ndarray:
    """Pose NEES after one update from a wide prior (σ 0.15 m, 6°: a blind stretch, a turn) with three
    well-known wall landmarks, the measurements drawn at the camera's own line noise."""
    rng = np.random.default_rng(seed)
    cov0 = np.diag([0.15, 0.15, np.deg2rad(6.0)]) ** 2
    lms = [NewLandmark.wall(WALL, 1.0), NewLandmark.wall(WALL, 2.0), NewLandmark.wall(BOARD, 0.8, edge="p2")]
    out = []
    for _ in range(runs):
        X_true = X0 + rng.multivariate_normal(np.zeros(3), cov0)
        truth = JointEKF(CAM, X_true, cov0)
        ids = truth.add_landmarks(lms, np.eye(3) * 1e-6, cov_pose_new=np.zeros((3, 3)))
        z = truth.predict_observation(ids).uv + rng.normal(scale=CAM.sigma_img, size=(3, 2))
        ekf = JointEKF(CAM, X0, cov0)
        ekf.add_landmarks(lms, np.eye(3) * 1e-6, cov_pose_new=np.zeros((3, 3)))
        ekf.update(list(zip(ids, z, strict=True)), iterations=iterations)
        e = X_true - ekf.pose
        e[2] = wrap_angle(e[2])
        out.append(e @ np.linalg.solve(ekf.cov_pose, e))
    return np.array(out)


def test_iterated_update_is_consistent_from_a_wide_prior():
    runs = 100
    lo, hi = chi2.ppf([0.005, 0.995], 3 * runs) / runs
    single = _wide_prior_nees(1, runs)
    iterated = _wide_prior_nees(EKFConfig().iterations, runs)
    assert single.mean() > 10 * hi, single.mean()  # one linearisation at the prior: overconfident
    assert lo < iterated.mean() < hi, iterated.mean()
    assert np.mean(iterated > chi2.ppf(0.99, 3)) < 0.05


def test_iterated_update_never_raises_the_map_cost():
    """Each accepted Gauss–Newton step lowers the MAP cost: the iterated result is never worse, by the cost
    both minimise, than the ordinary update's."""
    rng = np.random.default_rng(11)
    cov0 = np.diag([0.3, 0.3, np.deg2rad(10.0)]) ** 2
    lms = [NewLandmark.wall(WALL, 1.2), NewLandmark.wall(BOARD, 0.8, edge="p2")]  # 4 columns, 5 unknowns
    for _ in range(30):
        X_true = X0 + rng.multivariate_normal(np.zeros(3), cov0)
        truth = JointEKF(CAM, X_true, cov0)
        ids = truth.add_landmarks(lms, np.eye(2) * 1e-4, cov_pose_new=np.zeros((3, 2)))
        uv = truth.predict_observation(ids).uv
        if not np.all(np.isfinite(uv)):
            continue
        z = uv + rng.normal(scale=CAM.sigma_img, size=(2, 2))
        results = []
        for iterations in (1, 5):
            ekf = JointEKF(CAM, X0, cov0)
            ekf.add_landmarks(lms, np.eye(2) * 1e-4, cov_pose_new=np.zeros((3, 2)))
            rows = ekf._rows(ids, "test")
            idx = np.concatenate([np.arange(3), ekf._idx2[rows].ravel()])
            cost = ekf._map_cost(rows, idx, z, ekf.state.copy(), ekf.camera)
            ekf.update(list(zip(ids, z, strict=True)), iterations=iterations)
            results.append(cost(ekf.state)[0])
        assert results[1] <= results[0] + 1e-9


def test_iterations_stop_once_converged():
    a, b = _wide_prior_nees(10, 5, seed=3), _wide_prior_nees(50, 5, seed=3)
    np.testing.assert_allclose(a, b, rtol=1e-6)
    with pytest.raises(ConfigError, match="ekf.iterations"):
        EKFConfig(iterations=0)


# ------------------------------------------------------- bookkeeping and I/O
def test_wall_landmark_position_and_rank_one_covariance():
    ekf = JointEKF(CAM, X0, np.eye(3) * 1e-4)
    a, b = ekf.add_landmarks([NewLandmark.wall(BOARD, 0.5, edge="p2"), NewLandmark.wall(WALL, 1.0)],
                             np.array([[4e-4, 1e-4], [1e-4, 9e-4]]))
    np.testing.assert_allclose(ekf.landmark_position(a), BOARD.P2 - 0.5 * BOARD.direction, atol=1e-12)
    np.testing.assert_allclose(ekf.landmark_position(b), [-0.5, 5.0], atol=1e-12)
    cov2d = ekf.landmark_cov2d(a)
    np.testing.assert_allclose(cov2d, 4e-4 * np.outer(BOARD.direction, BOARD.direction), atol=1e-15)
    assert np.linalg.matrix_rank(cov2d, tol=1e-12) == 1
    assert ekf.n_landmarks == 2 and ekf.state_slice(b) == slice(4, 5)


def test_remove_landmark_marginalises_it_out():
    rng = np.random.default_rng(8)
    ekf, _ = random_filter(rng)
    ids = ekf.landmark_ids
    keep = np.ones(len(ekf.state), dtype=bool)
    keep[ekf.state_slice(ids[1])] = False
    x, P = ekf.state[keep], ekf.cov[np.ix_(keep, keep)]
    pred = ekf.predict_observation([ids[0], ids[2]], 0.1)
    ekf.remove_landmark(ids[1])
    assert ekf.landmark_ids == [ids[0]] + ids[2:]
    np.testing.assert_array_equal(ekf.state, x)
    np.testing.assert_array_equal(ekf.cov, P)
    after = ekf.predict_observation([ids[0], ids[2]], 0.1)
    np.testing.assert_allclose(after.S, pred.S, atol=1e-12)
    (new,) = ekf.add_landmarks([NewLandmark.point((0.0, 3.0))], 1e-3 * np.eye(2))
    assert new not in ids  # ids are never reused


def test_cross_covariance_with_the_pose_keeps_the_joint_covariance_psd():
    rng = np.random.default_rng(9)
    ekf, _ = random_filter(rng)
    B = rng.normal(size=(3, 2))
    P_XX = ekf.cov_pose
    ekf.add_landmarks([NewLandmark.point((0.3, 3.0))], B.T @ P_XX @ B + 1e-6 * np.eye(2), cov_pose_new=P_XX @ B)
    assert_psd(ekf.cov, tol=1e-12)
    np.testing.assert_allclose(ekf.cov[:3, -2:], P_XX @ B, atol=1e-15)


def test_landmarks_round_trip_through_yaml():
    rng = np.random.default_rng(10)
    ekf, _ = random_filter(rng)
    pred = ekf.predict_observation(ekf.landmark_ids[:2])
    ekf.update(list(zip(ekf.landmark_ids[:2], pred.uv + 0.3, strict=True)), frame=np.int64(7))
    ekf.add_landmarks([NewLandmark.wall(WALL, 1.0, z_low=np.float64(0.1), z_high=np.float32(1.5))], [[1e-4]])
    for joint in (True, False):
        data = yaml.safe_load(yaml.safe_dump(ekf.to_dict(joint=joint)))
        assert data["landmarks"][0]["n_observed"] == 1 and data["landmarks"][0]["last_frame"] == 7
        later = JointEKF(CAM, [1.0, 0.0, 0.0], np.eye(3) * 1e-2)
        assert later.load_prior_landmarks(data, WORLD) == ekf.landmark_ids
        for i in ekf.landmark_ids:
            a, b = ekf.landmark(i), later.landmark(i)
            assert (a.kind, a.plane_id, a.edge, a.z_low, a.n_observed) == (b.kind, b.plane_id, b.edge, b.z_low,
                                                                              b.n_observed)
            np.testing.assert_allclose(b.position, a.position, atol=1e-12)
            np.testing.assert_allclose(b.cov2d, a.cov2d, atol=1e-15)
        np.testing.assert_array_equal(later.cov[:3, 3:], 0.0)
        P_ll, Q_ll = ekf.cov[3:, 3:], later.cov[3:, 3:]
        if joint:
            np.testing.assert_allclose(Q_ll, P_ll, atol=1e-15)
        else:
            np.testing.assert_allclose(np.diag(Q_ll), np.diag(P_ll), atol=1e-15)
            assert np.count_nonzero(Q_ll) < np.count_nonzero(P_ll)
    (new,) = later.add_landmarks([NewLandmark.point((0.0, 3.0))], 1e-3 * np.eye(2))
    assert new == max(ekf.landmark_ids) + 1


@pytest.mark.parametrize(
    "entry, match",
    [
        ({"id": 0, "kind": "wall", "plane": "door", "s": 1.0, "var_s": 1e-3},
         r"map_landmarks.yaml: landmarks\[0\]\.plane: expected a plane"),
        ({"id": 0, "kind": "wall", "plane": "partition", "s": 1.0}, "missing field 'var_s'"),
        ({"id": 0, "kind": "wall", "plane": "partition", "s": 1.0, "var_s": -1.0}, "var_s: expected a non-negative"),
        ({"id": 0, "kind": "wall", "plane": "partition", "edge": "p3", "s": 1.0, "var_s": 1.0}, "edge: expected one"),
        ({"id": 0, "kind": "line", "x": 1.0}, r"kind: expected one of \('wall', 'point'\), got 'line'"),
        ({"id": "a", "kind": "point"}, "id: expected an integer id"),
        ({"id": 0, "kind": "point", "x": 1.0, "y": 2.0, "cov": [[1.0, 0.0]]}, "cov: expected a finite 2×2 matrix"),
    ],
)
def test_load_prior_landmarks_rejects_bad_entries(entry, match):
    ekf = JointEKF(CAM, X0, np.eye(3))
    with pytest.raises(ConfigError, match=match):
        ekf.load_prior_landmarks([entry], WORLD, source="map_landmarks.yaml")


def test_load_prior_landmarks_rejects_used_ids():
    ekf = JointEKF(CAM, X0, np.eye(3))
    ekf.add_landmarks([NewLandmark.point((0.0, 3.0))], np.eye(2))
    entry = {"id": 0, "kind": "point", "x": 1.0, "y": 2.0, "cov": [[1.0, 0.0], [0.0, 1.0]]}
    with pytest.raises(ConfigError, match=r"lm\.yaml: .*expected 1 distinct unused landmark ids, got \[0\]"):
        ekf.load_prior_landmarks({"landmarks": [entry]}, WORLD, source="lm.yaml")
    with pytest.raises(ConfigError, match="missing field 'landmarks'"):
        ekf.load_prior_landmarks({"planes": []}, WORLD, source="lm.yaml")


def test_bad_inputs_raise_with_expected_got():
    with pytest.raises(ConfigError, match=r"ekf.gate_probability: expected a probability in \(0, 1\), got 1.5"):
        EKFConfig(gate_probability=1.5)
    with pytest.raises(ConfigError, match="ekf.max_updates_per_frame: expected a positive integer, got 0"):
        EKFConfig(max_updates_per_frame=0)
    with pytest.raises(InputError, match="ekf.cov_pose: expected a positive semi-definite matrix"):
        JointEKF(CAM, X0, -np.eye(3))
    with pytest.raises(InputError, match=r"ekf.pose: expected a finite pose"):
        JointEKF(CAM, [0.0, 1.0], np.eye(3))
    with pytest.raises(InputError, match="wall landmark.edge: expected one of"):
        NewLandmark.wall(WALL, 1.0, edge="left")
    with pytest.raises(InputError, match=r"point landmark.value: expected 2 finite number\(s\)"):
        NewLandmark.point((1.0, np.nan))
    ekf, _ = random_filter(np.random.default_rng(0))
    with pytest.raises(InputError, match=r"add_landmarks.cov_new: expected a finite 1×1 matrix, got shape \(2, 2\)"):
        ekf.add_landmarks([NewLandmark.wall(WALL, 1.0)], np.eye(2))
    with pytest.raises(InputError, match="add_landmarks.cov_new: expected a symmetric matrix"):
        ekf.add_landmarks([NewLandmark.point((0.0, 3.0))], [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(InputError, match="joint covariance of pose and new landmarks: expected a positive semi"):
        ekf.add_landmarks([NewLandmark.wall(WALL, 1.0)], [[1e-9]], cov_pose_new=[[1.0], [1.0], [1.0]])
    with pytest.raises(InputError, match="update.observations: expected ids of landmarks in the filter, got 99"):
        ekf.update([(99, (300.0, 290.0))])
    i = ekf.landmark_ids[0]
    with pytest.raises(InputError, match="expected each landmark at most once"):
        ekf.update([(i, (300.0, 290.0)), (i, (301.0, 291.0))])
    with pytest.raises(InputError, match=r"predict.cov_U: expected a finite 3×3 matrix, got shape \(3,\)"):
        ekf.predict([0.1, 0.0, 0.0], [1.0, 1.0, 1.0])
    with pytest.raises(InputError, match=r"associate.extra_cost: expected a finite 5×1 matrix, got shape \(1, 1\)"):
        ekf.associate([[300.0, 290.0]], extra_cost=[[0.0]])


def test_joint_association_refuses_a_shifted_assignment():
    """A landmark out of sight must not take its neighbour's segment and push the others along."""
    cam = StereoCamera()
    plane = ReferencePlane("w", (0.0, 4.0), (2.0, 4.0), free_edges=("p1",))
    X = np.array([0.0, 0.0, np.pi / 2])
    ekf = JointEKF(cam, X, np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2)
    s = np.array([0.2, 0.3, 0.5, 0.55, 0.9])
    ekf.add_landmarks([NewLandmark.wall(plane, v) for v in s], 0.036**2 * np.eye(len(s)))
    uv = cam.project_columns(X, plane.point_at(s))
    measured = uv[:-1]  # the last landmark is not seen this frame
    pairs = ekf.associate_joint(measured)
    assert sorted(pairs) == [(i, i) for i in range(4)]
    assert ekf.joint_nis(pairs, measured) < 1.0
    shifted = [(i + 1, i) for i in range(4)]
    assert ekf.joint_nis(shifted, measured) > ekf.joint_nis(pairs, measured)


# ------------------------------------------------------- known points (free edges of the map)
@pytest.mark.parametrize("seed", range(3))
def test_known_point_update_equals_the_dense_reference(seed):
    rng = np.random.default_rng(seed)
    ekf, _ = random_filter(rng)
    dense = DenseEKF(ekf.state, ekf.cov)
    pan = rng.uniform(-0.2, 0.2)
    pts = np.array([WALL.edge("p1"), BOARD.edge("p2")])
    R = np.stack([random_spd(rng, 2, 0.5), random_spd(rng, 2, 0.3)])
    C = np.stack([np.diag([1e-4, 4e-4]), np.diag([2e-4, 1e-4])])
    uv, J_I_X, J_I_p = CAM.with_pan(pan).project_columns(ekf.pose, pts, jacobians=True)
    z = uv + rng.normal(scale=1.0, size=uv.shape)
    before = ekf.known_point_nis(pts, z, R, pan, cov_points=C)
    res = ekf.update_known_points(pts, z, R, pan, cov_points=C)
    H = np.zeros((4, len(dense.x)))
    H[:, :3] = J_I_X.reshape(4, 3)
    Rfull = np.zeros((4, 4))
    for j in range(2):
        Rfull[2 * j:2 * j + 2, 2 * j:2 * j + 2] = R[j] + J_I_p[j] @ C[j] @ J_I_p[j].T
    dense.update(z.ravel(), uv.ravel(), H, Rfull)
    np.testing.assert_allclose(ekf.state, dense.x, atol=1e-10)
    np.testing.assert_allclose(ekf.cov, dense.P, atol=1e-10)
    np.testing.assert_array_equal(ekf.cov, ekf.cov.T)
    assert_psd(ekf.cov)
    np.testing.assert_allclose(res.nis, before, rtol=1e-9)


def test_known_point_update_rejects_bad_input():
    ekf = JointEKF(CAM, X0, np.diag([0.01, 0.01, 1e-3]))
    with pytest.raises(InputError, match="update_known_points"):
        ekf.update_known_points([WALL.edge("p1")], [[300.0, 280.0]], np.eye(2))  # one (2, 2), not (1, 2, 2)
    assert ekf.update_known_points(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2))).dof == 0
