"""Landmarks entered in a frame that found none of the filter's landmarks, tied to the pose (``ekf.tie_blind_entries``,
off by default): their boundary was told from other lines by the pose alone, so they enter where their rays from the
pose meet the mapped wall, with the cross-covariance to the pose that implies, as a SLAM filter enters what it
measures."""

import numpy as np
import pytest

import stablemarks as sm
from stablemarks.estimation import JointEKF, NewLandmark
from stablemarks.geometry import StereoCamera
from stablemarks.maps import ReferencePlane
from stablemarks.methods import along_wall_jacobian, ray_on_wall
from stablemarks.sim.export import write_simulated_sequence
from stablemarks.sim.run import simulate_run

from .helpers import assert_psd

WALL = ReferencePlane("wall", (-2.0, 3.0), (2.0, 3.0))  # along +x, 3 m ahead of a robot at the origin facing +y
X0 = np.array([0.0, 0.0, np.pi / 2])


@pytest.mark.parametrize("edge", ["p1", "p2"])
def test_the_rays_hit_point_moves_along_the_wall_with_the_pose(edge):
    cam = StereoCamera()
    u = np.array([cam.cu, cam.cu + 150.0])
    G = along_wall_jacobian(cam, X0, WALL, edge, u)
    sign = 1.0 if edge == "p1" else -1.0
    # moving the robot along the wall moves the hit point by as much; towards it, a ray off the axis slides out
    np.testing.assert_allclose(G[:, 0], sign, atol=1e-6)
    Zc = 3.0 - cam.mount_y if hasattr(cam, "mount_y") else 3.0
    slope = (u - cam.cu) / cam.f
    assert G[0, 1] == pytest.approx(0.0, abs=1e-6)
    assert G[1, 1] == pytest.approx(-sign * slope[1], rel=1e-3)
    # turning left by δ moves the hit point of the central ray to the left by about its range
    assert G[0, 2] == pytest.approx(-sign * Zc, rel=0.1)
    # the hit point itself: measured from either end, the two distances make the wall's length, and a column
    # further right hits further right
    s = ray_on_wall(cam, X0, WALL, edge, u)
    np.testing.assert_allclose(s + ray_on_wall(cam, X0, WALL, "p2" if edge == "p1" else "p1", u), WALL.length)
    assert sign * (s[1] - s[0]) > 0


def _observed_again(tied: bool):
    cam = StereoCamera()
    ekf = JointEKF(cam, X0, np.diag([0.05, 0.05, np.deg2rad(5.0)]) ** 2)
    u = np.array([cam.cu - 120.0, cam.cu + 90.0])
    s = np.array([1.5, 2.6])
    new = [NewLandmark.wall(WALL, v) for v in s]
    cov = np.diag([0.01, 0.01]) ** 2
    if tied:
        G = along_wall_jacobian(cam, X0, WALL, "p1", u)
        ekf.add_landmarks(new, cov + G @ ekf.cov_pose @ G.T, cov_pose_new=ekf.cov_pose @ G.T)
    else:
        ekf.add_landmarks(new, cov)
    assert_psd(ekf.cov)
    before = ekf.cov_pose
    z = ekf.predict_observation(ekf.landmark_ids).uv  # seen again where they were entered, from the same pose
    ekf.update([(i, tuple(z[j])) for j, i in enumerate(ekf.landmark_ids)])
    assert_psd(ekf.cov)
    return before, ekf.cov_pose


def test_tied_landmarks_seen_again_from_the_same_place_do_not_fix_the_heading():
    """Two landmarks entered blind and seen again from where they were entered: tied, the heading keeps most of
    its uncertainty (5° → 3.7°: only what the two lines' depths say of the mapped wall's angle); entered as if
    independent of the pose, the same two would cut it to 0.9°, as if their places along the wall were known."""
    before, tied = _observed_again(True)
    _, free = _observed_again(False)
    assert np.sqrt(tied[2, 2]) > 0.6 * np.sqrt(before[2, 2])
    assert np.sqrt(free[2, 2]) < 0.25 * np.sqrt(before[2, 2])


def test_a_frame_that_finds_no_landmark_enters_its_new_ones_tied(lab_scenario, tmp_path, monkeypatch):
    seq = sm.open_sequence(write_simulated_sequence(simulate_run(lab_scenario, seed=4), tmp_path / "lab",
                                                    n_frames=6))
    frames = list(seq)
    on = sm.Config().with_overrides({"ekf": {"tie_blind_entries": True}})
    loc = sm.Localizer(seq.world_map, seq.camera, start_pose=seq.initial_pose, config=on)
    for f in frames[:3]:
        rec = loc.step(f.stamp, f.left, f.right, odometry=f.odometry, pan=f.pan).record
        assert not rec.landmark_couplings  # the first frame's are the map's: not tied
    # the next frame finds none of the filter's landmarks (all dropped, as after a long blind stretch)
    for i in loc.ekf.landmark_ids:
        loc.ekf.remove_landmark(i)
    est = loc.step(frames[3].stamp, frames[3].left, frames[3].right, odometry=frames[3].odometry, pan=frames[3].pan)
    rec = est.record
    assert rec.new and not rec.observed
    assert sorted(i for ids, _, _ in rec.landmark_couplings for i in ids) == sorted(rec.new)
    # each where its line's ray from the pose meets the mapped wall, not at its distance from the boundary
    cam = seq.camera.with_pan(frames[3].pan)
    for (ids, G, X), (ids2, values, _) in zip(rec.landmark_couplings, rec.landmark_priors, strict=True):
        assert ids == ids2
        cands = [c for c, i in zip(est.entered.candidates, est.entered.ids, strict=True) if i in ids]
        plane = seq.world_map[cands[0].plane_id]
        np.testing.assert_allclose(values, ray_on_wall(cam, X, plane, cands[0].edge, [c.u_left for c in cands]),
                                   atol=1e-9)
        np.testing.assert_allclose(G, along_wall_jacobian(cam, X, plane, cands[0].edge, [c.u_left for c in cands]),
                                   atol=1e-9)
    P = loc.ekf.cov
    assert np.abs(P[:3, 3:]).max() > 0  # cross-covariance with the pose
    assert_psd(P)
    # off (the default), the same frame enters them independent of the pose
    off = sm.Localizer(seq.world_map, seq.camera, start_pose=seq.initial_pose, config=sm.Config())
    for f in frames[:3]:
        off.step(f.stamp, f.left, f.right, odometry=f.odometry, pan=f.pan)
    for i in off.ekf.landmark_ids:
        off.ekf.remove_landmark(i)
    rec = off.step(frames[3].stamp, frames[3].left, frames[3].right, odometry=frames[3].odometry,
                   pan=frames[3].pan).record
    assert rec.new and not rec.landmark_couplings


def test_widened_blind_entries_hold_the_poses_uncertainty_without_following_it(lab_scenario, tmp_path):
    """``ekf.widen_blind_entries``: a frame that finds none of the filter's landmarks enters its new ones at their
    distance from the boundary (as the map's), but as uncertain along the wall as the pose is there (``+ G P_XX
    Gᵀ``: the boundary may be any line the pose let through), with no cross-covariance to the pose."""
    seq = sm.open_sequence(write_simulated_sequence(simulate_run(lab_scenario, seed=4), tmp_path / "lab",
                                                    n_frames=6))
    frames = list(seq)
    on = sm.Config().with_overrides({"ekf": {"widen_blind_entries": True}})
    off = sm.Config()
    recs = {}
    for name, cfg in (("on", on), ("off", off)):
        loc = sm.Localizer(seq.world_map, seq.camera, start_pose=seq.initial_pose, config=cfg)
        for f in frames[:3]:
            loc.step(f.stamp, f.left, f.right, odometry=f.odometry, pan=f.pan)
        for i in loc.ekf.landmark_ids:
            loc.ekf.remove_landmark(i)
        est = loc.step(frames[3].stamp, frames[3].left, frames[3].right, odometry=frames[3].odometry,
                       pan=frames[3].pan)
        assert est.record.new and not est.record.observed and not est.record.landmark_couplings
        P = loc.ekf.cov
        assert_psd(P)
        np.testing.assert_array_equal(P[:3, 3:], 0.0)
        recs[name] = est
    on_est, off_est = recs["on"], recs["off"]
    cam = seq.camera.with_pan(frames[3].pan)
    on_priors, off_priors = on_est.record.landmark_priors, off_est.record.landmark_priors
    assert [ids for ids, _, _ in on_priors] == [ids for ids, _, _ in off_priors]
    for (ids, values, cov), (_, values_off, cov_off) in zip(on_priors, off_priors, strict=True):
        np.testing.assert_array_equal(values, values_off)  # the same places
        cands = [c for c, i in zip(on_est.entered.candidates, on_est.entered.ids, strict=True) if i in ids]
        plane = seq.world_map[cands[0].plane_id]
        # the predicted pose of that frame (the filter's before its update: none happened)
        X = on_est.record.pose
        G = along_wall_jacobian(cam, X, plane, cands[0].edge, [c.u_left for c in cands])
        np.testing.assert_allclose(cov, np.asarray(cov_off) + G @ on_est.record.cov_pose @ G.T, rtol=1e-9,
                                   atol=1e-12)


def test_blind_entries_are_tied_or_widened_not_both():
    from stablemarks.errors import ConfigError

    with pytest.raises(ConfigError, match="at most one"):
        sm.Config().with_overrides({"ekf": {"tie_blind_entries": True, "widen_blind_entries": True}})
