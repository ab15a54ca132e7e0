"""inflate_inconsistent: variance added only where the frame's innovations contradict the landmark model."""

import numpy as np
import pytest

from stablemarks.estimation import EKFConfig, JointEKF, NewLandmark
from stablemarks.estimation.consistency import inflate_inconsistent
from stablemarks.geometry import StereoCamera
from stablemarks.maps import ReferencePlane

from .helpers import assert_psd

CAM = StereoCamera(mount_x=0.15, mount_y=-0.04, mount_height=1.1, sigma_img=0.06)
FRONT = ReferencePlane("front", (4.0, 2.0), (4.0, -2.0), free_edges=("p1", "p2"))
SIDE = ReferencePlane("side", (1.0, -1.2), (5.0, -1.2), free_edges=("p2",))
SIGMA_PX = 0.06


def _filter(front_s, side_s, sigma_s=1e-3, pose_sigma=(0.02, 0.02, 0.01)):
    """A filter at the origin with two groups of wall landmarks: ``front_s`` on a frontal wall, ``side_s`` on a side
    wall seen at a slant; each group entered with its own covariance (independent here)."""
    ekf = JointEKF(CAM, np.zeros(3), np.diag(np.square(pose_sigma)), EKFConfig())
    a = ekf.add_landmarks([NewLandmark.wall(FRONT, s) for s in front_s], sigma_s**2 * np.eye(len(front_s)))
    b = ekf.add_landmarks([NewLandmark.wall(SIDE, s, edge="p2") for s in side_s], sigma_s**2 * np.eye(len(side_s)))
    groups = {i: 1 for i in a} | {i: 2 for i in b}
    return ekf, a, b, groups


def _observe(ekf, ids, true_state, rng, noise=SIGMA_PX):
    """Observations of ``ids`` generated at ``true_state`` with white column noise."""
    h, _ = ekf.observation_model(ids)
    z = h(true_state).reshape(-1, 2) + rng.normal(0.0, noise, (len(ids), 2))
    return [(i, z[k]) for k, i in enumerate(ids)]


def test_consistent_observations_add_nothing():
    rng = np.random.default_rng(3)
    fired = 0
    for _ in range(40):
        ekf, a, b, groups = _filter([0.6, 1.1, 1.7, 2.4], [1.0, 1.6, 2.3])
        truth = ekf.state
        truth[:3] += rng.normal(0.0, [0.02, 0.02, 0.01])
        for i in a + b:
            truth[ekf.state_slice(i)] += rng.normal(0.0, 1e-3)
        P0 = ekf.cov
        out = inflate_inconsistent(ekf, _observe(ekf, a + b, truth, rng), 0.0, groups, 1e-3)
        fired += bool(out)
        if not out:
            np.testing.assert_array_equal(ekf.cov, P0)
    assert fired <= 2  # about 12 directions a frame at p = 0.001: a false alarm in ~1 frame of 100


def test_a_group_shifted_along_its_wall_is_widened_not_the_pose():
    rng = np.random.default_rng(4)
    ekf, a, b, groups = _filter([0.6, 1.1, 1.7, 2.4], [1.0, 1.6, 2.3])
    truth = ekf.state
    for i in b:  # the side wall's boundary was snapped 4 cm off: its whole group is off, by 40 σ
        truth[ekf.state_slice(i)] += 0.04
    P0 = ekf.cov
    out = inflate_inconsistent(ekf, _observe(ekf, a + b, truth, rng), 0.0, groups, 1e-3)
    assert out and out[0].ids == tuple(b) and out[0].group
    assert out[0].t > 50
    # about the missing variance: (4 cm)² give or take the test's noise
    assert 0.3 * 0.04**2 < out[0].alpha < 3 * 0.04**2
    P = ekf.cov
    assert_psd(P)
    np.testing.assert_allclose(P, P.T, atol=0)
    np.testing.assert_array_equal(P[:3, :3], P0[:3, :3])  # the pose's covariance is left alone
    idx = [ekf.state_slice(i).start for i in b]
    assert np.all(np.diag(P)[idx] > np.diag(P0)[idx])


def test_one_landmark_off_is_widened_alone():
    rng = np.random.default_rng(5)
    ekf, a, b, groups = _filter([0.6, 1.1, 1.7, 2.4], [1.0, 1.6, 2.3])
    truth = ekf.state
    truth[ekf.state_slice(a[2])] += 0.03
    out = inflate_inconsistent(ekf, _observe(ekf, a + b, truth, rng), 0.0, groups, 1e-3)
    assert out and out[0].ids == (a[2],) and not out[0].group


def test_a_shift_a_pose_explains_is_not_tested():
    """One frontal wall's group seen alone: its common shift along the wall is a sideways move of the robot."""
    rng = np.random.default_rng(6)
    ekf, a, _, groups = _filter([0.6, 1.1, 1.7, 2.4], [1.0, 1.6, 2.3])
    truth = ekf.state
    for i in a:
        truth[ekf.state_slice(i)] += 0.04
    assert not any(f.ids == tuple(a) for f in inflate_inconsistent(ekf, _observe(ekf, a, truth, rng), 0.0, groups,
                                                                     1e-3))


@pytest.mark.parametrize("p, n", [(0.0, 7), (1e-3, 2)])
def test_off_or_too_few_observations_do_nothing(p, n):
    rng = np.random.default_rng(7)
    ekf, a, b, groups = _filter([0.6, 1.1, 1.7, 2.4], [1.0, 1.6, 2.3])
    truth = ekf.state
    for i in b:
        truth[ekf.state_slice(i)] += 0.04
    P0 = ekf.cov
    ids = (a + b)[:n]
    assert inflate_inconsistent(ekf, _observe(ekf, ids, truth, rng), 0.0, groups, p) == []
    np.testing.assert_array_equal(ekf.cov, P0)


def test_the_localizer_logs_what_it_widened(lab_scenario):
    """With ``ekf.inflation_p`` the localizer tests each update (a group's landmarks are recorded at entry) and
    every ``log.jsonl`` line has ``inflated``; off (the default) it is empty and nothing is tested."""
    import json

    import stablemarks as sm
    from stablemarks.sim.run import simulate_run
    from stablemarks.sim.source import SimulatedSource

    run = simulate_run(lab_scenario, seed=2)
    narrow = {"noise": {"sigma_img": 0.02, "boundary_px": 0.02}, "ekf": {"landmark_sigma_floor": 0.0}}
    for p in (0.0, 0.5):  # 0.5 and lines taken to 0.02 px: a test that fires on ordinary frames too
        source = SimulatedSource(run, frames=5)
        cfg = sm.Config().with_overrides(narrow).with_overrides({"ekf": {"inflation_p": p}}).with_source_defaults(
            source.config_defaults)
        loc = sm.Localizer(source.world_map, source.camera, start_pose=run.dead_reckoning[0], config=cfg)
        fired = []
        for f in source:
            rec = loc.step(f.stamp, f.left, f.right, odometry=f.odometry, pan=f.pan).record
            line = json.loads(json.dumps(rec.to_dict()))
            assert isinstance(line["inflated"], list)
            fired += line["inflated"]
            assert_psd(loc.ekf.cov)
        if p == 0.0:
            assert not fired
        else:
            assert fired and all(d["alpha"] > 0 and d["t"] > 0 for d in fired)
            assert {i for d in fired for i in d["ids"]} <= set(loc.ekf.landmark_ids) | set(loc.retired)


def test_the_floor_grows_with_range():
    """``ekf.landmark_sigma_floor_per_m``: after an update a wall landmark is held no more certain than the floor
    plus this times its range from the camera; the nearer one's floor is lower. Off (0) nothing is added."""
    from stablemarks.errors import ConfigError

    per_m = 0.001
    for k in (0.0, per_m):
        ekf = JointEKF(CAM, np.zeros(3), np.diag([1e-4, 1e-4, 1e-6]),
                       EKFConfig(landmark_sigma_floor=0.0, landmark_sigma_floor_per_m=k))
        ids = ekf.add_landmarks([NewLandmark.wall(FRONT, 1.0), NewLandmark.wall(SIDE, 2.5, edge="p2")],
                                1e-8 * np.eye(2))
        for _ in range(3):
            z = ekf.predict_observation(ids).uv
            ekf.update([(i, z[j]) for j, i in enumerate(ids)])
        centre = CAM.optical_centres(ekf.pose)[0]
        for i in ids:
            var = ekf.cov[ekf.state_slice(i), ekf.state_slice(i)][0, 0]
            rng = float(np.hypot(*(ekf.landmark_position(i) - centre)))
            if k:
                assert var == pytest.approx((k * rng) ** 2, rel=1e-9)
            else:
                assert var < 1e-8
        assert_psd(ekf.cov)
    with pytest.raises(ConfigError, match="landmark_sigma_floor_per_m"):
        EKFConfig(landmark_sigma_floor_per_m=-1.0)
