"""The batch smoother (``gtsam_batch``, the evaluation's accuracy reference) and its place in the evaluation."""

import math
import sys
from dataclasses import replace

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from gtsam.symbol_shorthand import L, X  # noqa: E402

from stablemarks import evaluation  # noqa: E402
from stablemarks.config import Config  # noqa: E402
from stablemarks.errors import InputError  # noqa: E402
from stablemarks.estimation import JointEKF, NewLandmark  # noqa: E402
from stablemarks.evaluation import (  # noqa: E402
    SMOOTHER,
    Trial,
    available_methods,
    check_goals,
    check_methods,
    make_trials,
    run_trials,
    start_belief,
    summarize,
    truncate_run,
)
from stablemarks.geometry import SE2, StereoCamera, wrap_angle  # noqa: E402
from stablemarks.localizer import FrameRecord  # noqa: E402
from stablemarks.maps import Map, ReferencePlane  # noqa: E402
from stablemarks.metrics import ate_rmse  # noqa: E402
from stablemarks.online import OnlineResult, run_online  # noqa: E402
from stablemarks.sim.run import simulate_run  # noqa: E402
from stablemarks.sim.source import SimulatedSource  # noqa: E402
from stablemarks.smoother import batch_smooth, group_prior_factor, observation_factor, wall_factor  # noqa: E402

from .helpers import numerical_jacobian  # noqa: E402

WALL = ReferencePlane("wall", (-1.0, 3.0), (2.0, 3.0), free_edges=("p1",))
COV0 = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2


def _record(k, pose, *, odometry=None, cov_odometry=None, pan=0.0, measurements=(), priors=()):
    pose = np.asarray(pose, dtype=float)
    return FrameRecord(index=k, stamp=0.5 * k, pan=pan, pan_command=pan, pose=pose, cov_pose=np.eye(3),
                       dead_reckoning=pose, odometry=odometry, cov_odometry=cov_odometry,
                       measurements=list(measurements), landmark_priors=list(priors))


def _result(records, ekf, cov0, start):
    records[0] = replace(records[0], dead_reckoning=np.asarray(start, dtype=float))
    return OnlineResult("fake", "stablemarks", records, ekf, Map((WALL,)), cov0=cov0)


# ---------------------------------------------------------------- factors
@pytest.mark.parametrize("edge", ["p1", "p2"])
def test_observation_factor_jacobians_match_central_differences(edge):
    """The factor's Jacobians, w.r.t. gtsam's tangent spaces (Pose2 body frame, s), against differences of
    its own residual under ``Pose2.retract``; with a pan and an off-centre mount."""
    rng = np.random.default_rng(11)
    camera = StereoCamera(mount_x=0.12, mount_y=-0.04)
    sigma = 0.5
    for _ in range(5):
        pose = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.5, 0.5), np.pi / 2 + rng.uniform(-0.4, 0.4)])
        pan = rng.uniform(-0.3, 0.3)
        s = rng.uniform(0.5, 2.5)
        z = rng.uniform(200.0, 400.0, size=2)
        factor = observation_factor(X(0), L(3), camera.with_pan(pan), WALL, edge, z, sigma)

        def values(delta, pose=pose, s=s):
            v = gtsam.Values()
            v.insert(X(0), gtsam.Pose2(*pose).retract(delta[:3]))
            v.insert(L(3), np.array([s + delta[3]]))
            return v

        A, b = factor.linearize(values(np.zeros(4))).jacobian()
        residual = factor.unwhitenedError(values(np.zeros(4)))
        numeric = numerical_jacobian(lambda d, f=factor: f.unwhitenedError(values(d)), np.zeros(4))
        np.testing.assert_allclose(A * sigma, numeric, rtol=1e-6, atol=1e-6 * np.abs(numeric).max())
        np.testing.assert_allclose(b * sigma, -residual, rtol=1e-12)
        uv = camera.with_pan(pan).project_columns(pose, WALL.point_at(s, edge))
        np.testing.assert_allclose(residual, uv - z, rtol=1e-12)


def test_wall_factor_jacobians_match_central_differences():
    """The fitted wall's factor (``ekf.wall_updates``): residual ``H (X − X_lin) + J_β β − ν``, Jacobians w.r.t.
    gtsam's tangent spaces against differences of its own residual."""
    from gtsam.symbol_shorthand import B

    rng = np.random.default_rng(2)
    X_lin = np.array([0.1, -0.2, 1.3])
    H = rng.normal(size=(2, 3))
    J_b = rng.normal(size=2)
    nu = rng.normal(size=2) * 1e-2
    factor = wall_factor(X(0), B(0), nu, H, J_b, np.diag([1e-4, 4e-4]), X_lin)
    pose = X_lin + np.array([0.01, -0.02, 0.03])

    def values(delta):
        v = gtsam.Values()
        v.insert(X(0), gtsam.Pose2(*pose).retract(delta[:3]))
        v.insert(B(0), np.array([0.02 + delta[3]]))
        return v

    residual = factor.unwhitenedError(values(np.zeros(4)))
    np.testing.assert_allclose(residual, H @ (pose - X_lin) + J_b * 0.02 - nu, rtol=1e-12, atol=1e-15)
    A, _ = factor.linearize(values(np.zeros(4))).jacobian()
    numeric = numerical_jacobian(lambda d: factor.unwhitenedError(values(d)), np.zeros(4))
    W = np.linalg.cholesky(np.linalg.inv(np.diag([1e-4, 4e-4]))).T  # gtsam whitens with R^(-1/2)
    np.testing.assert_allclose(np.linalg.solve(W, A), numeric, rtol=1e-6, atol=1e-8)


def test_group_prior_factor_is_the_joint_gaussian():
    rng = np.random.default_rng(4)
    M = rng.normal(size=(3, 3))
    cov = M @ M.T + 0.1 * np.eye(3)
    mean = rng.normal(size=3)
    factor = group_prior_factor([L(0), L(1), L(2)], mean, cov)
    v = gtsam.Values()
    s = rng.normal(size=3)
    for i in range(3):
        v.insert(L(i), np.array([s[i]]))
    e = s - mean
    assert factor.error(v) == pytest.approx(0.5 * e @ np.linalg.solve(cov, e), rel=1e-10)


# ------------------------------------------------------------------ graphs
def test_without_observations_it_returns_the_odometry_chain_and_its_covariance():
    """No landmark: the optimum is dead reckoning, and the marginals are the filter's predictions (checks that
    our increment ``U = X_{k-1}⁻¹ X_k`` and its covariance map onto ``BetweenFactorPose2`` exactly), even
    started far from it and turning through ±π."""
    rng = np.random.default_rng(7)
    start = np.array([1.0, -2.0, 2.9])
    ekf = JointEKF(StereoCamera(), start, COV0)
    chain = SE2.from_array(start)
    records = [_record(0, start + rng.normal(scale=0.1, size=3))]
    truth, covs = [start], [COV0]
    for k in range(1, 8):
        U = np.array([rng.uniform(0.0, 0.4), rng.uniform(-0.1, 0.1), rng.uniform(-0.6, 0.6)])
        Mc = rng.normal(scale=0.02, size=(3, 3))
        cov_U = Mc @ Mc.T + 1e-4 * np.eye(3)
        ekf.predict(U, cov_U)
        chain = chain @ SE2.from_array(U)
        truth.append(chain.as_array())
        covs.append(ekf.cov_pose)
        records.append(_record(k, chain.as_array() + rng.normal(scale=0.1, size=3), odometry=U, cov_odometry=cov_U))
    out = batch_smooth(_result(records, ekf, COV0, start), StereoCamera())
    truth = np.array(truth)
    np.testing.assert_allclose(out.poses[:, :2], truth[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(out.poses[:, 2] - truth[:, 2]), 0.0, atol=1e-9)
    np.testing.assert_allclose(out.cov_poses, np.array(covs), rtol=1e-7, atol=1e-12)
    assert out.landmarks == {} and out.error_final < 1e-15 < out.error_initial


def test_a_turn_on_the_spot_with_singular_odometry_covariance():
    """The odometry model gives a pure turn no sideways error: a singular covariance (the loop's corners)."""
    from stablemarks.motion import OdometryNoise

    start = np.array([0.0, 0.0, 0.0])
    ekf = JointEKF(StereoCamera(), start, COV0)
    records = [_record(0, start)]
    pose = SE2.from_array(start)
    for k, U in enumerate([np.array([0.2, 0.0, 0.0]), np.array([0.0, 0.0, np.pi / 18]),
                           np.array([0.2, 0.0, 0.0])], start=1):
        cov_U = OdometryNoise().covariance(SE2.from_array(U))
        ekf.predict(U, cov_U)
        pose = pose @ SE2.from_array(U)
        records.append(_record(k, pose.as_array(), odometry=U, cov_odometry=cov_U))
    assert np.linalg.matrix_rank(records[2].cov_odometry) < 3
    out = batch_smooth(_result(records, ekf, COV0, start), StereoCamera())
    np.testing.assert_allclose(out.poses[-1], pose.as_array(), atol=1e-9)


def test_correlated_group_prior_is_honoured():
    """Two landmarks entered together (shared boundary error) and one of them measured almost exactly from a
    known pose: the other one moves by the conditional Gaussian, ``v_b + Σ_ba/Σ_aa (s_a − v_a)``, and its
    variance shrinks to ``Σ_bb − Σ_ba²/Σ_aa``."""
    pose = np.array([0.0, 0.0, np.pi / 2])
    cov0 = np.diag([1e-6, 1e-6, 1e-6]) ** 2
    sigma_b, sigma_f = 0.05, 0.01
    cov = sigma_b**2 * np.ones((2, 2)) + sigma_f**2 * np.eye(2)
    v = np.array([1.05, 1.4])
    s_a = 1.0
    camera = StereoCamera(sigma_img=1e-3)
    ekf = JointEKF(camera, pose, cov0)
    ids = ekf.add_landmarks([NewLandmark.wall(WALL, v[0]), NewLandmark.wall(WALL, v[1])], cov)
    u_l, u_r = camera.project_columns(pose, WALL.point_at(s_a))
    record = _record(0, pose, measurements=[(ids[0], u_l, u_r)], priors=[(ids, list(v), cov)])
    config = Config().with_overrides({"noise": {"sigma_img": 1e-3}})
    out = batch_smooth(_result([record], ekf, cov0, pose), camera, config)
    a, b = (out.landmarks[i] for i in ids)
    assert a.s == pytest.approx(s_a, abs=1e-5)
    assert b.s == pytest.approx(v[1] + cov[1, 0] / cov[0, 0] * (s_a - v[0]), abs=1e-5)
    assert b.var_s == pytest.approx(cov[1, 1] - cov[1, 0] ** 2 / cov[0, 0], rel=1e-3)
    np.testing.assert_allclose(b.position, WALL.point_at(b.s))
    np.testing.assert_allclose(b.cov2d, b.var_s * np.diag([1.0, 0.0]), atol=1e-15)


@pytest.fixture(scope="module")
def lab_short(lab_scenario):
    """The full method on the lab's first 11 frames, with the start belief drawn from its covariance."""
    run = truncate_run(simulate_run(lab_scenario, seed=5), 11)
    result = run_online(SimulatedSource(run), start_pose=start_belief(run, COV0), start_cov=COV0)
    return result, batch_smooth(result, lab_scenario.camera)


def test_smoothing_the_lab_run_beats_the_filter_and_dead_reckoning(lab_short):
    result, out = lab_short
    T = result.true_poses
    assert sum(len(r.measurements) for r in result.records) > 20
    ate = ate_rmse(out.poses, T)
    assert ate <= ate_rmse(result.poses, T) and ate < ate_rmse(result.dead_reckoning, T)
    assert out.error_final < out.error_initial and out.iterations >= 1
    assert set(out.landmarks) == set(result.ekf.landmark_ids)
    for i, lm in out.landmarks.items():
        # batch uses every observation the filter used: no landmark less certain than in the filter
        assert 0.0 < lm.var_s <= result.ekf.landmark(i).cov[0, 0] * (1 + 1e-3)  # up to the linearisation points
    assert np.all(np.linalg.eigvalsh(out.cov_poses) > 0)


def test_smoothing_a_run_with_wall_updates_uses_the_walls(lab_scenario):
    """With ``ekf.wall_updates`` the records hold the fitted walls; the smoother takes them with one shared
    disparity error per wall, as the filter does, and still beats the filter."""
    config = Config().with_overrides({"ekf": {"wall_updates": True}, "planes": {"disparity_bias_px": 0.03}})
    run = truncate_run(simulate_run(lab_scenario, seed=5), 8)
    result = run_online(SimulatedSource(run), start_pose=start_belief(run, COV0), start_cov=COV0, config=config)
    assert any(r.wall_measurements for r in result.records)
    out = batch_smooth(result, lab_scenario.camera, config)
    T = result.true_poses
    assert ate_rmse(out.poses, T) <= ate_rmse(result.poses, T)
    # without the walls' factors the smoother knows the pose less well
    plain = replace(result, records=[replace(r, wall_measurements=[]) for r in result.records])
    without = batch_smooth(plain, lab_scenario.camera, config)
    assert np.mean(np.linalg.det(out.cov_poses)) < np.mean(np.linalg.det(without.cov_poses))


# ---------------------------------------------------------------- failures
def test_missing_gtsam_says_what_to_install(monkeypatch, lab_short):
    result, _ = lab_short
    monkeypatch.setitem(sys.modules, "gtsam", None)
    with pytest.raises(InputError, match=r"pip install 'stablemarks\[gtsam\]'"):
        batch_smooth(result, result.ekf.camera)
    monkeypatch.setattr(evaluation, "gtsam_available", lambda: False)
    assert SMOOTHER not in available_methods()
    with pytest.raises(InputError, match=r"methods: expected one of .* \(.*pip install 'stablemarks\[gtsam\]'\)"):
        check_methods(["stablemarks", SMOOTHER])


def test_point_landmarks_are_refused():
    camera = StereoCamera()
    pose = np.array([0.0, 0.0, np.pi / 2])
    ekf = JointEKF(camera, pose, COV0)
    (i,) = ekf.add_landmarks([NewLandmark.point((0.0, 3.0))], 0.01 * np.eye(2))
    u_l, u_r = camera.project_columns(pose, np.array([0.0, 3.0]))
    res = _result([_record(0, pose, measurements=[(i, u_l, u_r)])], ekf, COV0, pose)
    with pytest.raises(InputError, match="batch_smooth: expected wall landmarks"):
        batch_smooth(res, camera)


# -------------------------------------------------------------- evaluation
def test_gtsam_batch_is_an_evaluation_method_sharing_the_full_methods_job():
    assert available_methods()[-1] == SMOOTHER and check_methods([SMOOTHER]) == (SMOOTHER,)
    trials = make_trials(["lab"], 2, ["dead_reckoning", "stablemarks", SMOOTHER], seed=1, frames=2)
    assert [[(t.index, t.method) for t in b] for b in evaluation._bundles(trials)] == [
        [(0, "dead_reckoning")], [(0, "stablemarks"), (0, SMOOTHER)],
        [(1, "dead_reckoning")], [(1, "stablemarks"), (1, SMOOTHER)]]
    assert SMOOTHER in {t.method for t in make_trials(["lab"], 1, frames=2)}


def test_run_trials_smooths_the_same_stablemarks_run(monkeypatch):
    calls = []

    def counted(source, localizer=None, **kw):
        calls.append(kw["method"])
        return run_online(source, localizer, **kw)

    monkeypatch.setattr(evaluation, "run_online", counted)
    seed = 123
    full, smooth = run_trials([Trial("lab", 0, seed, "stablemarks", frames=3),
                               Trial("lab", 0, seed, SMOOTHER, frames=3)])
    assert calls == ["stablemarks"]
    assert set(full) == set(smooth) and smooth["method"] == SMOOTHER and smooth["nis"] == []
    assert smooth["frames"] == 3 and len(smooth["nees_pose"]) == 3 and smooth["landmarks"]
    assert [lm["id"] for lm in smooth["landmarks"]] == [lm["id"] for lm in full["landmarks"]]
    assert smooth["ate_rmse"] != full["ate_rmse"]
    summary = summarize([full, smooth])["lab"]
    assert math.isnan(summary[SMOOTHER]["selection_precision"]) and math.isnan(summary[SMOOTHER]["nis_mean"])
    assert summary[SMOOTHER]["ate_rmse"] == pytest.approx(smooth["ate_rmse"])
    goal = {g.name: g for g in check_goals({"lab": summary})}[f"ATE / {SMOOTHER}'s ATE"]
    assert float(goal.value) == pytest.approx(full["ate_rmse"] / smooth["ate_rmse"], rel=1e-2)
    assert goal.met is (full["ate_rmse"] <= 2 * smooth["ate_rmse"])
    with pytest.raises(InputError, match="run_trials: expected tasks of one run"):
        run_trials([Trial("lab", 0, seed, "stablemarks", frames=3), Trial("lab", 1, seed + 1, SMOOTHER, frames=3)])
