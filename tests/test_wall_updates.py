"""The fitted walls as measurements of the pose (``ekf.wall_updates``), with the disparity error each wall's pixels
share as a state of the filter (:meth:`JointEKF.add_aux`) instead of noise counted anew in every frame."""

import numpy as np
import pytest

import stablemarks as sm
from stablemarks.errors import ConfigError, InputError
from stablemarks.estimation import JointEKF, NewLandmark
from stablemarks.geometry import StereoCamera
from stablemarks.maps import ReferencePlane
from stablemarks.planes import PlaneConfig, fit_plane, predict_plane
from stablemarks.sim.export import write_simulated_sequence
from stablemarks.sim.run import simulate_run

from .helpers import assert_psd
from .test_planes import CAM, COV0, PARTITION, X0, synthetic_disparity

WALL = ReferencePlane("wall", (-1.0, 3.0), (2.0, 3.0))


@pytest.mark.parametrize("wall", [PARTITION, ReferencePlane("angled", (-1.0, 3.0), (1.5, 5.0), z=(0.0, 2.0))])
def test_the_fits_shared_disparity_jacobian_matches_finite_differences(wall):
    """``PlaneFit.J_bias = ∂(a, b)/∂β``: every pixel's disparity moved by ``β`` and the wall fitted again."""
    disp = synthetic_disparity(CAM, X0, [wall], noise=0.05, rng=np.random.default_rng(3))
    pred = predict_plane(CAM, X0, COV0, wall)
    fit = fit_plane(CAM, X0, disp, pred, PlaneConfig())
    h = 1e-3
    up = fit_plane(CAM, X0, disp + np.float32(h), pred, PlaneConfig())
    down = fit_plane(CAM, X0, disp - np.float32(h), pred, PlaneConfig())
    J = (np.array([up.a, up.b]) - np.array([down.a, down.b])) / (2 * h)
    assert fit.J_bias[0] == pytest.approx(J[0], rel=0.02)
    # the slope's part is second order (the weights and the pixels' mean along the wall move too)
    assert abs(fit.J_bias[1] - J[1]) <= 0.02 * abs(J[0]) / wall.length
    # and the same J the configured σ_β puts into the fit's covariance
    with_bias = fit_plane(CAM, X0, disp, pred, PlaneConfig(disparity_bias_px=0.05))
    np.testing.assert_allclose(with_bias.cov_R - fit.cov_R, 0.05**2 * np.outer(fit.J_bias, fit.J_bias),
                               rtol=1e-9, atol=1e-15)


def _filter_with_landmarks():
    camera = StereoCamera()
    ekf = JointEKF(camera, np.array([0.0, 0.0, np.pi / 2]), np.diag([0.02, 0.03, 0.01]) ** 2)
    new = [NewLandmark.wall(WALL, s) for s in (0.5, 1.5, 2.5)]
    C = np.diag([0.004, 0.005, 0.006]) ** 2 + 1e-6
    ekf.add_landmarks(new, C, cov_pose_new=np.full((3, 3), 1e-5))
    return ekf


def test_an_auxiliary_state_leaves_the_landmarks_as_they_were():
    ekf = _filter_with_landmarks()
    before = {i: ekf.landmark(i) for i in ekf.landmark_ids}
    cov_before = ekf.cov
    i = ekf.add_aux("wall:a", 0.03**2)
    assert i == 3 and ekf.aux_index("wall:a") == 3 and ekf.aux_index("wall:b") is None
    assert ekf.add_aux("wall:b", 0.01) == 4
    for j, lm in before.items():
        after = ekf.landmark(j)
        np.testing.assert_array_equal(after.value, lm.value)
        np.testing.assert_array_equal(after.cov, lm.cov)
    P = ekf.cov
    keep = [0, 1, 2, 5, 6, 7]
    np.testing.assert_array_equal(P[np.ix_(keep, keep)], cov_before)
    assert P[3, 3] == 0.03**2 and P[4, 4] == 0.01 and not P[3, keep].any()
    assert len(ekf.to_dict(joint=True)["cov_landmarks"]) == 3
    # a landmark removed and one added keep the auxiliary states where they are
    ekf.remove_landmark(ekf.landmark_ids[0])
    ekf.add_landmarks([NewLandmark.wall(WALL, 2.0)], [[1e-4]])
    assert ekf.aux_index("wall:a") == 3 and len(ekf.state) == 3 + 2 + 3
    with pytest.raises(InputError):
        ekf.add_aux("wall:a", 1.0)
    with pytest.raises(InputError):
        ekf.add_aux("wall:c", 0.0)


def test_the_update_with_auxiliary_states_is_the_kalman_update_in_joseph_form():
    ekf = _filter_with_landmarks()
    a = ekf.add_aux("wall:a", 0.04**2)
    b = ekf.add_aux("wall:b", 0.02**2)
    rng = np.random.default_rng(5)
    H = rng.normal(size=(4, 3))
    H_aux = rng.normal(size=(4, 2)) * 0.1
    R = np.diag([1e-6, 4e-4, 2e-6, 1e-4])
    nu = rng.normal(size=4) * 1e-3
    x, P = ekf.state, ekf.cov
    Hf = np.zeros((4, len(x)))
    Hf[:, :3], Hf[:, [a, b]] = H, H_aux
    K = P @ Hf.T @ np.linalg.inv(Hf @ P @ Hf.T + R)
    I_KH = np.eye(len(x)) - K @ Hf
    expected_P = I_KH @ P @ I_KH.T + K @ R @ K.T
    m2 = ekf.update_pose_aux(nu, H, [a, b], H_aux, R)
    np.testing.assert_allclose(ekf.state, x + K @ nu, atol=1e-12)
    np.testing.assert_allclose(ekf.cov, expected_P, atol=1e-14)
    assert m2 == pytest.approx(nu @ np.linalg.solve(Hf @ P @ Hf.T + R, nu))
    assert_psd(ekf.cov)
    with pytest.raises(InputError):
        ekf.update_pose_aux(nu, H, [0, b], H_aux, R)  # the pose is not an auxiliary state


def test_a_wall_seen_again_from_the_same_place_is_not_counted_anew():
    """The same wall fitted in 20 frames from a robot that stands still: with its shared error a state, the
    pose across the wall is known about as well as one frame's fit with that error tells (the shared error does
    not average out); counted as noise in every frame it would be known 4.5 times better than that."""
    H = np.array([[0.0, -1.0, 0.0]])  # the wall's offset measures y
    J_beta = np.array([0.16])  # [m/px]
    sigma_beta, sigma_w = 0.03, 0.002
    shared = (J_beta[0] * sigma_beta) ** 2
    runs = {}
    for aux in (True, False):
        ekf = JointEKF(StereoCamera(), np.zeros(3), np.diag([0.05, 0.05, 0.02]) ** 2)
        i = ekf.add_aux("wall:w", sigma_beta**2) if aux else None
        for _ in range(20):
            if aux:
                ekf.update_pose_aux([0.0], H, [i], J_beta[None, :], [[sigma_w**2]])
            else:
                ekf.update_pose([0.0], H, [[sigma_w**2 + shared]])
        runs[aux] = ekf.cov_pose[1, 1]
    one_frame = 1.0 / (1.0 / 0.05**2 + 1.0 / (sigma_w**2 + shared))
    assert runs[True] == pytest.approx(1.0 / (1.0 / 0.05**2 + 1.0 / (shared + sigma_w**2 / 20)), rel=1e-6)
    assert runs[True] > 0.8 * one_frame
    assert runs[False] < one_frame / 4.5


@pytest.fixture(scope="module")
def lab_seq(tmp_path_factory, lab_scenario):
    return write_simulated_sequence(simulate_run(lab_scenario, seed=3), tmp_path_factory.mktemp("seq") / "lab",
                                    n_frames=8)


def test_a_run_with_wall_updates_estimates_each_walls_shared_error(lab_seq):
    seq = sm.open_sequence(lab_seq)
    runs = {}
    for on in (True, False):
        config = sm.Config().with_overrides({"ekf": {"wall_updates": on}, "planes": {"disparity_bias_px": 0.03}})
        loc = sm.Localizer(seq.world_map, seq.camera, start_pose=seq.initial_pose, config=config)
        for f in seq:
            loc.step(f.stamp, f.left, f.right, odometry=f.odometry, pan=f.pan)
        runs[on] = loc
    loc = runs[True]
    keys = [k for k in loc.ekf._aux]
    assert keys and all(k.startswith("wall:") and k[5:] in {p.id for p in seq.world_map} for k in keys)
    assert_psd(loc.ekf.cov)
    # the walls' errors are learnt: each one's variance below its prior
    P = loc.ekf.cov
    assert all(P[loc.ekf.aux_index(k), loc.ekf.aux_index(k)] < 0.03**2 for k in keys)
    # and the pose across the walls is known better than from the landmarks alone
    assert np.linalg.det(loc.ekf.cov_pose) < np.linalg.det(runs[False].ekf.cov_pose)
    assert not runs[False].ekf._aux


def test_walls_update_only_while_they_tell_the_pose_something(lab_seq):
    """``ekf.wall_info_ratio``: a wall updates the pose only while the pose's variance across it is at least that
    many times the fit's, in any frame; the first form (ratio 0) updated from every wall, only in frames with a
    pattern of landmarks. With 1 the lab's run uses fewer walls, also in a frame without such a pattern; a ratio
    no wall reaches uses none."""
    seq = sm.open_sequence(lab_seq)
    used = {}
    for ratio in (0.0, 1.0, 1e6):
        config = sm.Config().with_overrides({"ekf": {"wall_updates": True, "wall_info_ratio": ratio},
                                             "planes": {"disparity_bias_px": 0.03}})
        loc = sm.Localizer(seq.world_map, seq.camera, start_pose=seq.initial_pose, config=config)
        used[ratio] = [len(loc.step(f.stamp, f.left, f.right, odometry=f.odometry, pan=f.pan).record.wall_measurements)
                       for f in seq]
        assert_psd(loc.ekf.cov)
    # also in a frame without a pattern of landmarks, where the first form used none
    assert any(a > 0 and b == 0 for a, b in zip(used[1.0], used[0.0], strict=True))
    assert sum(used[1.0]) < sum(used[0.0])  # informative walls only
    assert sum(used[1e6]) == 0
    with pytest.raises(ConfigError, match="wall_info_ratio"):
        sm.Config().with_overrides({"ekf": {"wall_info_ratio": -1}})
