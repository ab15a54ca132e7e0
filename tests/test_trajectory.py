"""TUM and KITTI trajectory files: round trips, the exact text evo reads, and errors naming file and line."""

from __future__ import annotations

import numpy as np
import pytest

from stablemarks.errors import InputError
from stablemarks.geometry import wrap_angle
from stablemarks.io.trajectory import TUM_HEADER, read_tum, write_tum


def random_poses(rng, n):
    theta = rng.uniform(-np.pi, np.pi, n)
    theta[:4] = [np.pi - 1e-7, -np.pi + 1e-7, 0.0, -2.5]  # both sides of the wrap, zero, negative
    return np.column_stack([rng.uniform(-50, 50, n), rng.uniform(-50, 50, n), theta])


def test_tum_round_trip_keeps_stamps_positions_and_yaw(tmp_path):
    rng = np.random.default_rng(0)
    poses = random_poses(rng, 50)
    stamps = 1.7e9 + np.cumsum(rng.uniform(0.01, 0.2, 50))
    path = write_tum(tmp_path / "t.tum", stamps, poses)
    got_stamps, got = read_tum(path)
    np.testing.assert_allclose(got_stamps, stamps, rtol=0, atol=1e-6)  # float64 at 1.7e9 s: ~2e-7 s
    np.testing.assert_allclose(got[:, :2], poses[:, :2], rtol=0, atol=1e-6)
    assert np.all(np.abs(wrap_angle(got[:, 2] - poses[:, 2])) < 1e-8)
    assert np.all((got[:, 2] >= -np.pi) & (got[:, 2] < np.pi))


def test_tum_text_is_what_evo_reads(tmp_path):
    poses = np.array([[1.0, 2.0, np.pi / 2], [-0.5, 0.25, -np.pi / 3]])
    path = write_tum(tmp_path / "t.tum", [0.0, 0.5], poses)
    lines = path.read_text().splitlines()
    assert lines[0] == TUM_HEADER
    assert lines[1] == "0.000000000 1.000000000 2.000000000 0 0 0 0.707106781187 0.707106781187"
    for line in lines[1:]:  # evo: csv with a single space, 8 entries, no trailing delimiter
        assert len(line.split(" ")) == 8
    m = np.loadtxt(path, comments="#")
    assert m.shape == (2, 8)
    np.testing.assert_allclose(np.linalg.norm(m[:, 4:], axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(m[1, 6:], [np.sin(-np.pi / 6), np.cos(-np.pi / 6)], atol=1e-9)


def test_read_tum_takes_the_yaw_of_any_unit_quaternion(tmp_path):
    yaw, tilt = 2.0, 0.05
    # q = rot_z(yaw) * rot_x(tilt), stored scalar last; -q is the same rotation.
    cz, sz, cx, sx = np.cos(yaw / 2), np.sin(yaw / 2), np.cos(tilt / 2), np.sin(tilt / 2)
    q = np.array([cz * sx, sz * sx, sz * cx, cz * cx])
    text = "\n".join([
        "# a comment", "",
        "1.0 3.0 4.0 1.5 " + " ".join(f"{v:.12f}" for v in q),
        "2.0 3.0 4.0 1.5 " + " ".join(f"{-v:.12f}" for v in q),
        "3.0 0 0 0 0.0 0.0 -0.7071 0.7071",  # 4 decimals, as the TUM benchmark's own files
    ])
    (tmp_path / "gt.txt").write_text(text)
    stamps, poses = read_tum(tmp_path / "gt.txt")
    np.testing.assert_array_equal(stamps, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(poses[:2], [[3.0, 4.0, yaw]] * 2, atol=1e-9)
    assert poses[2, 2] == pytest.approx(-np.pi / 2, abs=1e-9)


@pytest.mark.parametrize("line, message", [
    ("0.0 1 2 0 0 0 0", r"t\.tum line 3: expected 8 numbers: timestamp tx ty tz qx qy qz qw, got '0.0 1 2 0 0 0 0'"),
    ("0.0 1 2 0 0 0 0 x", r"t\.tum line 3: expected 8 numbers"),
    ("0.0 1 nan 0 0 0 0 1", r"t\.tum line 3: expected finite numbers"),
    ("0.0 1 2 0 0 0 0 0.5", r"t\.tum line 3: expected a unit quaternion qx qy qz qw, got 'norm 0.5'"),
])
def test_read_tum_errors_name_file_and_line(tmp_path, line, message):
    (tmp_path / "t.tum").write_text(f"# header\n0.0 0 0 0 0 0 0 1\n{line}\n")
    with pytest.raises(InputError, match=message):
        read_tum(tmp_path / "t.tum")


def test_read_tum_missing_or_empty(tmp_path):
    with pytest.raises(InputError, match=r"nope\.tum: no such trajectory file"):
        read_tum(tmp_path / "nope.tum")
    (tmp_path / "empty.tum").write_text(TUM_HEADER + "\n")
    with pytest.raises(InputError, match=r"empty\.tum: no poses"):
        read_tum(tmp_path / "empty.tum")


def test_write_tum_checks_shapes_and_leaves_no_file(tmp_path):
    with pytest.raises(InputError, match=r"poses: expected poses of shape \(n, 3\)"):
        write_tum(tmp_path / "t.tum", [0.0], [[1.0, 2.0]])
    with pytest.raises(InputError, match=r"stamps: expected stamps of shape \(2,\)"):
        write_tum(tmp_path / "t.tum", [0.0], np.zeros((2, 3)))
    with pytest.raises(InputError, match=r"poses: expected finite numbers"):
        write_tum(tmp_path / "t.tum", [0.0], [[np.nan, 0.0, 0.0]])
    assert list(tmp_path.iterdir()) == []


