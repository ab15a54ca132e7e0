"""Frame sources for recorded runs: stamp checks, stereo pairing, odometry resampling, the odometry CSV, and
``open_source``'s dispatch and errors. Also the shared test recording (a short simulated lab run) that
test_bags, test_datasets and test_run_command write in their formats."""

from __future__ import annotations

import functools
import math
import re

import numpy as np
import pytest

from stablemarks.errors import InputError, SequenceError
from stablemarks.geometry import SE2, wrap_angle
from stablemarks.io.calibration import save_camera_info_pair
from stablemarks.io.sequence import SequenceSource, write_sequence
from stablemarks.io.sources import (
    check_stamps,
    match_stamps,
    open_source,
    poses_at,
    read_odometry_csv,
    yaw_of_quaternion,
)
from stablemarks.maps import Map, ReferencePlane

N_FRAMES = 4
T0 = 1_700_000_000.0
"""Stamp of the first frame [s] (a real clock, so float rounding of large stamps is exercised)."""
PERIOD = 0.5


# ------------------------------------------------------------------ the shared recording
@functools.lru_cache(maxsize=1)
def lab_recording():
    """The lab's simulated run and its first ``N_FRAMES`` rendered frames (rendered once per session)."""
    from stablemarks.sim import load_scenario, simulate_run

    run = simulate_run(load_scenario("lab"))
    return run, tuple(run.render(k) for k in range(N_FRAMES))


def lab_stamps() -> np.ndarray:
    return T0 + PERIOD * np.arange(N_FRAMES)


def lab_odometry() -> np.ndarray:
    """(N, 3) wheel-odometry poses: the run's dead reckoning."""
    run, _ = lab_recording()
    return np.array([p.as_array() for p in run.dead_reckoning[:N_FRAMES]])


def lab_truth() -> np.ndarray:
    run, _ = lab_recording()
    return np.array([p.as_array() for p in run.poses[:N_FRAMES]])


def write_lab_inputs(folder) -> dict:
    """Calibration folder (camera_info pair), mount file and map of the lab: the command line's inputs."""
    run, _ = lab_recording()
    cam = run.scenario.camera
    folder.mkdir(parents=True, exist_ok=True)
    save_camera_info_pair(folder / "calib", cam)
    mount = folder / "mount.yaml"
    mount.write_text(f"mount: {{x: {cam.mount_x}, y: {cam.mount_y}, height: {cam.mount_height}, pan_deg: 0.0}}\n")
    run.scenario.map.save(folder / "map.yaml")
    return {"calib": folder / "calib", "mount": mount, "map": folder / "map.yaml"}


def write_lab_sequence(out):
    """The recording as our sequence folder, stamped like the bags."""
    run, frames = lab_recording()
    return write_sequence(out, name="lab", camera=run.scenario.camera, world_map=run.scenario.map,
                          stamps=lab_stamps(), odometry=lab_odometry(), pans=np.array(run.pans[:N_FRAMES]),
                          images=((f.left, f.right) for f in frames), groundtruth=lab_truth(),
                          initial_pose=run.scenario.robot.start)


def assert_same_frames(source, stamps=None, pans=None):
    """``source`` gives the recording's images, stamps (default :func:`lab_stamps`, to 1 µs), pans (default the
    run's) and odometry increments."""
    run, frames = lab_recording()
    assert len(source) == N_FRAMES
    stamps = lab_stamps() if stamps is None else stamps
    pans = run.pans if pans is None else pans
    got = list(source)
    np.testing.assert_allclose([f.stamp for f in got], stamps, rtol=0, atol=1e-6)
    np.testing.assert_allclose(source.initial_pose, run.poses[0].as_array(), rtol=0, atol=1e-12)
    assert [f.index for f in got] == list(range(N_FRAMES))
    for k, f in enumerate(got):
        assert f.pan == pytest.approx(pans[k], abs=1e-12)
        np.testing.assert_array_equal(f.left, frames[k].left)
        np.testing.assert_array_equal(f.right, frames[k].right)
        if k:
            U = SE2.from_array(got[k - 1].odometry).between(SE2.from_array(f.odometry))
            np.testing.assert_allclose(U.as_array(), run.odometry[k].as_array(), rtol=0, atol=1e-12)


# ------------------------------------------------------------------ stamps
def test_check_stamps_tells_duplicates_from_disorder():
    check_stamps([1.0, 2.0, 3.0], "x")
    with pytest.raises(SequenceError, match=r"^/cam: duplicate timestamp: message 2 is stamped 2\.000000000 s"):
        check_stamps(np.array([1, 2, 2], dtype=np.int64) * 10**9, "/cam")
    with pytest.raises(SequenceError, match=r"timestamps out of order: message 1 is stamped 0\.500000000 s after "
                                            r"message 0 stamped 1\.000000000 s"):
        check_stamps([1.0, 0.5, 3.0], "f")


def test_match_stamps_pairs_mutual_nearest_within_tolerance():
    left = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    right = np.array([0.002, 0.9, 1.003, 2.5, 3.004, 3.006])
    pairs = match_stamps(left, right, 0.005)
    # 1.0 pairs with 1.003 (not 0.9); 2.0 has no partner; 3.0 takes the nearer 3.004; 4.0 none.
    np.testing.assert_array_equal(pairs, [[0, 0], [1, 2], [3, 4]])
    assert match_stamps(left, right, 0.0).shape == (0, 2)
    assert match_stamps([], right, 1.0).shape == (0, 2)
    np.testing.assert_array_equal(match_stamps([5.0], [5.001], 0.01), [[0, 0]])


def test_poses_at_interpolates_and_takes_the_nearest_end_within_tolerance():
    t = np.array([0.0, 1.0, 2.0])
    poses = np.array([[0.0, 0.0, math.pi - 0.1], [1.0, 2.0, -math.pi + 0.1], [2.0, 2.0, -math.pi + 0.3]])
    out = poses_at(t, poses, [0.5, 1.0, 1.5, -0.004, 2.004, -0.01, 2.5], tolerance=0.005)
    np.testing.assert_allclose(out[0, :2], [0.5, 1.0], atol=1e-12)
    assert abs(wrap_angle(out[0, 2] - math.pi)) < 1e-12  # across ±π on the short arc, not through 0
    np.testing.assert_allclose(out[1], poses[1], atol=1e-12)
    np.testing.assert_allclose(out[2, :2], [1.5, 2.0])
    assert wrap_angle(out[2, 2] - (-math.pi + 0.2)) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_array_equal(out[3], poses[0])
    np.testing.assert_array_equal(out[4], poses[2])
    assert np.isnan(out[5:]).all()


def test_yaw_of_quaternion_is_the_heading_of_any_rotation():
    rng = np.random.default_rng(4)
    theta = rng.uniform(-math.pi, math.pi, 20)
    np.testing.assert_allclose(yaw_of_quaternion(0.0, 0.0, np.sin(theta / 2), np.cos(theta / 2)), theta, atol=1e-12)
    # A small pitch (10° about y) then yaw 40°: the heading stays 40°.
    yaw, pitch = math.radians(40), math.radians(10)
    qw, qx, qy, qz = (math.cos(yaw / 2) * math.cos(pitch / 2), -math.sin(yaw / 2) * math.sin(pitch / 2),
                      math.cos(yaw / 2) * math.sin(pitch / 2), math.sin(yaw / 2) * math.cos(pitch / 2))
    assert yaw_of_quaternion(qx, qy, qz, qw) == pytest.approx(yaw, abs=1e-12)


# ------------------------------------------------------------------ odometry CSV
def test_read_odometry_csv_and_its_errors(tmp_path):
    path = tmp_path / "odometry.csv"
    path.write_text("stamp,x,y,theta\n1.5,0.0,0.0,0.1\n2.0,0.25,0.0,0.2\n")
    t, poses = read_odometry_csv(path)
    np.testing.assert_array_equal(t, [1.5, 2.0])
    np.testing.assert_array_equal(poses, [[0.0, 0.0, 0.1], [0.25, 0.0, 0.2]])
    path.write_text("stamp,x,y,theta\n2.0,0,0,0\n2.0,1,0,0\n")
    with pytest.raises(SequenceError, match=r"odometry\.csv: duplicate timestamp"):
        read_odometry_csv(path)
    path.write_text("stamp,x,y,theta\n1.0,0,zero,0\n")
    with pytest.raises(SequenceError, match=r"odometry\.csv line 2: y: expected a number, got 'zero'"):
        read_odometry_csv(path)
    with pytest.raises(SequenceError, match=r"nope\.csv: no such odometry file"):
        read_odometry_csv(tmp_path / "nope.csv")


# ------------------------------------------------------------------ open_source
def test_open_source_reads_our_folder_and_replaces_its_map(tmp_path):
    folder = write_lab_sequence(tmp_path / "lab")
    source = open_source(folder)
    assert isinstance(source, SequenceSource)
    assert_same_frames(source)
    other = Map((ReferencePlane("w", (0.0, 5.0), (1.0, 5.0), name="w", free_edges=("p1",)),))
    other.save(tmp_path / "other.yaml")
    assert open_source(folder, map=tmp_path / "other.yaml").world_map == other


def test_open_source_errors_name_what_is_missing(tmp_path):
    with pytest.raises(SequenceError, match=r"nowhere: no such file or folder"):
        open_source(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(SequenceError, match=r"empty: not a recording stablemarks reads: expected a sequence folder "
                                            r"\(sequence\.yaml\), a bag"):
        open_source(tmp_path / "empty")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(SequenceError, match="not a recording"):
        open_source(tmp_path / "notes.txt")
    folder = write_lab_sequence(tmp_path / "lab")
    message = "`left_topic` does not apply to a sequence folder (it takes `map`)"
    with pytest.raises(InputError, match=re.escape(message)):
        open_source(folder, left_topic="/left")
    with pytest.raises(InputError, match=r"tolerance: expected a non-negative time"):
        open_source(folder, tolerance=-1.0)


def test_lab_recording_odometry_is_the_runs():
    """The shared recording's odometry poses integrate the run's noisy increments (what every format stores)."""
    run, _ = lab_recording()
    odo = lab_odometry()
    for k in range(1, N_FRAMES):
        U = SE2.from_array(odo[k - 1]).between(SE2.from_array(odo[k]))
        np.testing.assert_allclose(U.as_array(), run.odometry[k].as_array(), atol=1e-12)
    assert np.linalg.norm(odo[-1, :2] - lab_truth()[-1, :2]) > 1e-4  # noisy: not the truth
