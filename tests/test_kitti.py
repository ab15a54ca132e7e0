"""``write_kitti``: the left camera's poses relative to its first, in the camera frame, as KITTI gives them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stablemarks.errors import InputError
from stablemarks.io.trajectory import kitti_camera_poses, write_kitti


def read_kitti(path) -> np.ndarray:
    """A KITTI odometry pose file (``poses/XX.txt``): one 3×4 ``[R | t]`` per line, 12 numbers row-major."""
    rows = []
    for number, line in enumerate(Path(path).read_text().splitlines(), start=1):
        fields = line.split()
        assert len(fields) == 12, f"line {number}: {len(fields)} numbers"
        rows.append([float(v) for v in fields])
    return np.array(rows).reshape(-1, 3, 4)


def R_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def camera_in_map(pose, pan=0.0, mount=(0.0, 0.0), height=1.0) -> np.ndarray:
    """The left camera's pose (4, 4) in the map, built from the conventions (independently of the code)."""
    x, y, th = pose
    psi = th + pan
    forward = np.array([np.cos(psi), np.sin(psi), 0.0])
    left = np.array([-np.sin(psi), np.cos(psi), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    T = np.eye(4)
    T[:3, :3] = np.column_stack([-left, -up, forward])  # camera x right, y down, z forward
    c, s = np.cos(th), np.sin(th)
    T[:3, 3] = [x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1], height]
    return T


def test_the_first_line_is_the_identity(tmp_path):
    poses = np.array([[2.0, -1.0, 0.7], [2.5, -0.6, 0.8]])
    T = read_kitti(write_kitti(tmp_path / "t.kitti", poses, pans=[0.3, -0.2], mount=(0.1, 0.05)))
    np.testing.assert_allclose(T[0], np.eye(3, 4), atol=1e-12)


@pytest.mark.parametrize("theta", [0.0, np.pi / 2, 2.5])
def test_driving_forward_1m_is_camera_z_plus_1(tmp_path, theta):
    d = np.array([np.cos(theta), np.sin(theta)])
    poses = np.array([[1.0, 2.0, theta], [*(np.array([1.0, 2.0]) + d), theta]])
    T = read_kitti(write_kitti(tmp_path / "t.kitti", poses))  # the old call: no pans, no mount
    np.testing.assert_allclose(T[1], np.column_stack([np.eye(3), [0.0, 0.0, 1.0]]), atol=1e-9)


def test_a_left_turn_is_a_rotation_about_the_cameras_minus_y(tmp_path):
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2]])  # a quarter turn to the left on the spot
    T = read_kitti(write_kitti(tmp_path / "t.kitti", poses))
    R = T[1, :, :3]
    np.testing.assert_allclose(R, R_y(-np.pi / 2), atol=1e-9)
    # the camera now looks where its left (−x) was, its up (−y) stays up
    np.testing.assert_allclose(R[:, 2], [-1.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(R[:, 1], [0.0, 1.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(T[1, :, 3], 0.0, atol=1e-9)
    # a right turn the other way; a turn of 30° to the left, then 1 m ahead: ahead and to the left
    T = kitti_camera_poses([[0.0, 0.0, 0.0], [np.cos(np.pi / 6), np.sin(np.pi / 6), np.pi / 6]])
    np.testing.assert_allclose(T[1, :, :3], R_y(-np.pi / 6), atol=1e-9)
    np.testing.assert_allclose(T[1, :, 3], [-0.5, 0.0, np.cos(np.pi / 6)], atol=1e-9)


def test_pan_and_mount(tmp_path):
    # the head pans 30° to the left about the optical centre: the camera turns, it does not move
    T = kitti_camera_poses([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], pans=[0.0, np.pi / 6], mount=(0.2, 0.1))
    np.testing.assert_allclose(T[1, :, :3], R_y(-np.pi / 6), atol=1e-9)
    np.testing.assert_allclose(T[1, :, 3], 0.0, atol=1e-9)
    # the robot turns on the spot: a camera mounted 0.2 m ahead of its centre swings around it
    T = kitti_camera_poses([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2]], mount=(0.2, 0.0))
    # its centre moves from (0.2, 0) to (0, 0.2) in the map: 0.2 m back and 0.2 m to the left of camera 0
    np.testing.assert_allclose(T[1, :, 3], [-0.2, 0.0, -0.2], atol=1e-9)


def test_round_trip_with_a_kitti_reader(tmp_path):
    rng = np.random.default_rng(3)
    n = 25
    poses = np.column_stack([np.cumsum(rng.normal(0.1, 0.05, n)), np.cumsum(rng.normal(0.0, 0.05, n)),
                             np.cumsum(rng.normal(0.0, 0.1, n))])
    pans = rng.uniform(-0.5, 0.5, n)
    mount = (0.12, -0.03)
    path = write_kitti(tmp_path / "t.kitti", poses, pans, mount=mount)
    lines = path.read_text().splitlines()
    assert len(lines) == n and all(len(line.split()) == 12 for line in lines)
    T = read_kitti(path)
    np.testing.assert_allclose(T, kitti_camera_poses(poses, pans, mount=mount), atol=1e-8)
    for k in range(n):
        R = T[k, :, :3]
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-8)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-8)
        # the relative pose is camera_0⁻¹ camera_k, whatever the camera's height
        expected = np.linalg.inv(camera_in_map(poses[0], pans[0], mount)) @ camera_in_map(poses[k], pans[k], mount)
        np.testing.assert_allclose(T[k], expected[:3], atol=1e-8)
        # and the heading and the path come back: camera_0 · T_k in the map
        back = camera_in_map(poses[0], pans[0], mount, height=0.4) @ np.vstack([T[k], [0, 0, 0, 1]])
        forward = back[:3, 2]
        assert np.arctan2(forward[1], forward[0]) == pytest.approx(
            np.arctan2(np.sin(poses[k, 2] + pans[k]), np.cos(poses[k, 2] + pans[k])), abs=1e-8)
        assert back[2, 3] == pytest.approx(0.4, abs=1e-9)  # the camera stays at its height


def test_bad_input_is_an_input_error(tmp_path):
    poses = np.zeros((3, 3))
    with pytest.raises(InputError, match=r"pans: expected pans of shape \(3,\), one per pose"):
        write_kitti(tmp_path / "t.kitti", poses, pans=[0.0, 0.1])
    with pytest.raises(InputError, match="pans: expected finite numbers"):
        write_kitti(tmp_path / "t.kitti", poses, pans=[0.0, np.nan, 0.0])
    with pytest.raises(InputError, match="mount"):
        write_kitti(tmp_path / "t.kitti", poses, mount=(0.1,))
    with pytest.raises(InputError, match=r"poses: expected poses of shape \(n, 3\)"):
        write_kitti(tmp_path / "t.kitti", np.zeros((3, 2)))
    assert not (tmp_path / "t.kitti").exists()
