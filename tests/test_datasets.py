"""Dataset folders: KITTI odometry and EuRoC MAV layouts written from a short simulated lab run, read back
frame for frame; EuRoC's extrinsics and rectification from its sensor.yaml files; broken folders."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from stablemarks.cli import main
from stablemarks.errors import ConfigError, ImageError, InputError, SequenceError
from stablemarks.geometry import wrap_angle
from stablemarks.io.datasets import KITTI_MOUNT, FolderSource, euroc_calibration, kitti_planar_poses
from stablemarks.io.sources import open_source
from stablemarks.io.trajectory import read_tum

from .test_sources import (
    N_FRAMES,
    PERIOD,
    assert_same_frames,
    lab_odometry,
    lab_recording,
    lab_truth,
    write_lab_inputs,
)


def write_odometry_csv(path, stamps, poses) -> None:
    path.write_text("stamp,x,y,theta\n" + "".join(f"{t!r},{x!r},{y!r},{th!r}\n" for t, (x, y, th) in
                                                  zip(np.asarray(stamps).tolist(), poses.tolist(), strict=True)))


def kitti_pose_lines(poses) -> str:
    """Floor poses as KITTI camera poses (x right, y down, z forward): the inverse of ``kitti_planar_poses``."""
    lines = []
    for x, y, th in poses:
        c, s = math.cos(th), math.sin(th)
        M = np.array([[c, 0.0, -s, -y], [0.0, 1.0, 0.0, 0.0], [s, 0.0, c, x]])
        lines.append(" ".join(f"{v:.12e}" for v in M.ravel()))
    return "\n".join(lines) + "\n"


def write_kitti(root, *, odometry=True, mount=True):
    """``root/sequences/07`` with images, calib.txt, times.txt, odometry.csv, mount.yaml; ``root/poses/07.txt``."""
    run, frames = lab_recording()
    cam = run.scenario.camera
    seq = root / "sequences" / "07"
    for side in ("image_0", "image_1"):
        (seq / side).mkdir(parents=True)
    for k, f in enumerate(frames):
        cv2.imwrite(str(seq / "image_0" / f"{k:06d}.png"), f.left)
        cv2.imwrite(str(seq / "image_1" / f"{k:06d}.png"), f.right)
    P0 = np.array([[cam.f, 0, cam.cu, 0], [0, cam.f, cam.cv, 0], [0, 0, 1, 0]])
    P1 = P0.copy()
    P1[0, 3] = -cam.f * cam.baseline
    calib = {"P0": P0, "P1": P1, "P2": P0, "P3": P1, "Tr": np.eye(4)[:3]}
    (seq / "calib.txt").write_text("".join(f"{k}: {' '.join(f'{v:.12e}' for v in m.ravel())}\n"
                                           for k, m in calib.items()))
    (seq / "times.txt").write_text("".join(f"{PERIOD * k:.6e}\n" for k in range(N_FRAMES)))
    if odometry:
        write_odometry_csv(seq / "odometry.csv", PERIOD * np.arange(N_FRAMES), lab_odometry())
    if mount:
        (seq / "mount.yaml").write_text(f"mount: {{height: {cam.mount_height}}}\n")
    (root / "poses").mkdir()
    (root / "poses" / "07.txt").write_text(kitti_pose_lines(lab_truth()))
    return seq


SENSOR_YAML = """%YAML:1.0
# General sensor definitions.
sensor_type: camera
comment: simulated {name}

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [{T_BS}]

# Camera specific definitions.
rate_hz: 2
resolution: [{width}, {height}]
camera_model: pinhole
intrinsics: [{f}, {f}, {cu}, {cv}] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [{D}]
"""


def write_sensor_yaml(cam_dir, name, T_BS, K, D, size):
    cam_dir.mkdir(parents=True, exist_ok=True)
    (cam_dir / "sensor.yaml").write_text(SENSOR_YAML.format(
        name=name, T_BS=", ".join(repr(float(v)) for v in np.ravel(T_BS)), width=size[0], height=size[1],
        f=K[0, 0], cu=K[0, 2], cv=K[1, 2], D=", ".join(repr(float(v)) for v in D)))


def write_euroc(root, *, groundtruth=True):
    """``root/mav0`` with both cameras of the lab (already rectified: identity extrinsic rotation, no
    distortion), ``root/odometry.csv`` and ``root/mount.yaml``."""
    run, frames = lab_recording()
    cam = run.scenario.camera
    K = np.array([[cam.f, 0, cam.cu], [0, cam.f, cam.cv], [0, 0, 1.0]])
    stamps_ns = [1_403_636_579_763_555_584 + k * 500_000_000 for k in range(N_FRAMES)]
    mav0 = root / "mav0"
    for name, side, x in (("cam0", "left", 0.0), ("cam1", "right", cam.baseline)):
        T_BS = np.eye(4)
        T_BS[0, 3] = x
        write_sensor_yaml(mav0 / name, name, T_BS, K, np.zeros(4), (cam.width, cam.height))
        (mav0 / name / "data").mkdir()
        rows = ["#timestamp [ns],filename"]
        for k, t in enumerate(stamps_ns):
            cv2.imwrite(str(mav0 / name / "data" / f"{t}.png"), getattr(frames[k], side))
            rows.append(f"{t},{t}.png")
        (mav0 / name / "data.csv").write_text("\n".join(rows) + "\n")
    stamps = np.array(stamps_ns) / 1e9
    write_odometry_csv(root / "odometry.csv", stamps, lab_odometry())
    (root / "mount.yaml").write_text(f"mount: {{height: {cam.mount_height}}}\n")
    if groundtruth:
        gt = mav0 / "state_groundtruth_estimate0"
        gt.mkdir()
        lines = ["#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
                 "v_RS_R_x [m s^-1]"]
        for t, (x, y, th) in zip(stamps_ns, lab_truth().tolist(), strict=True):
            lines.append(f"{t},{x!r},{y!r},1.5,{math.cos(th / 2)!r},0.0,0.0,{math.sin(th / 2)!r},0.1")
        (gt / "data.csv").write_text("\n".join(lines) + "\n")
    return root, stamps


@pytest.fixture(scope="module")
def lab_map(tmp_path_factory):
    return write_lab_inputs(tmp_path_factory.mktemp("inputs"))["map"]


# ------------------------------------------------------------------ KITTI
def test_kitti_folder_gives_the_recordings_frames(tmp_path, lab_map):
    seq = write_kitti(tmp_path)
    source = open_source(seq, map=lab_map)
    assert isinstance(source, FolderSource) and source.name == "07"
    assert_same_frames(source, stamps=PERIOD * np.arange(N_FRAMES), pans=[0.0] * N_FRAMES)  # a fixed head
    run, _ = lab_recording()
    assert source.camera.f == run.scenario.camera.f and source.camera.cu == run.scenario.camera.cu
    assert source.camera.baseline == pytest.approx(run.scenario.camera.baseline, rel=1e-12)
    assert source.camera.mount_height == run.scenario.camera.mount_height
    assert source.calibration.is_rectified
    truth = np.array([source.true_pose(k) for k in range(N_FRAMES)])
    np.testing.assert_allclose(truth[:, :2], lab_truth()[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(truth[:, 2] - lab_truth()[:, 2]), 0.0, atol=1e-9)


def test_kitti_planar_poses_reads_the_camera_frame(tmp_path):
    path = tmp_path / "00.txt"
    poses = np.array([[0.0, 0.0, 0.0], [2.0, -1.0, 0.5], [-3.0, 4.0, -2.5]])
    path.write_text(kitti_pose_lines(poses))
    np.testing.assert_allclose(kitti_planar_poses(path), poses, atol=1e-12)
    # A camera 1 m to the right of the start (KITTI x = +1) is 1 m to the robot's right: y = -1.
    path.write_text("1 0 0 1 0 1 0 0 0 0 1 0\n")
    np.testing.assert_allclose(kitti_planar_poses(path), [[0.0, -1.0, 0.0]], atol=1e-12)


def test_kitti_run_from_the_command_line(tmp_path, lab_map):
    seq = write_kitti(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(seq), "--map", str(lab_map), "--out", str(out), "--method", "dead_reckoning",
                 "--no-figures", "--kitti"]) == 0
    stamps, truth = read_tum(out / "groundtruth.tum")
    np.testing.assert_allclose(stamps, PERIOD * np.arange(N_FRAMES))
    np.testing.assert_allclose(truth[:, :2], lab_truth()[:, :2], atol=1e-6)
    assert (out / "trajectory.kitti").is_file()


def test_kitti_without_odometry_says_it_is_required(tmp_path, lab_map):
    seq = write_kitti(tmp_path, odometry=False)
    with pytest.raises(SequenceError, match=r"07: KITTI has no wheel odometry: put an odometry\.csv "
                                            r"\(stamp,x,y,theta\) in the folder or pass `odometry` "
                                            r"\(an odometry CSV\)"):
        open_source(seq, map=lab_map)
    write_odometry_csv(tmp_path / "odo.csv", PERIOD * np.arange(N_FRAMES), lab_odometry())
    assert len(open_source(seq, map=lab_map, odometry=tmp_path / "odo.csv")) == N_FRAMES


def test_kitti_default_mount_and_broken_files(tmp_path, lab_map):
    seq = write_kitti(tmp_path, mount=False)
    assert open_source(seq, map=lab_map).camera.mount_height == KITTI_MOUNT.mount_height == 1.65
    with pytest.raises(InputError, match=r"carries no map of walls"):
        open_source(seq)
    times = (seq / "times.txt").read_text()
    (seq / "times.txt").write_text(times + "9.9\n")
    with pytest.raises(SequenceError, match=r"times\.txt: 5 stamps, but .*image_0 has 4 images"):
        open_source(seq, map=lab_map)
    (seq / "times.txt").write_text(times.replace("5.000000e-01", "1.500000e+00"))
    with pytest.raises(SequenceError, match=r"times\.txt: timestamps out of order: message 2"):
        open_source(seq, map=lab_map)
    (seq / "times.txt").write_text(times)
    calib = (seq / "calib.txt").read_text()
    (seq / "calib.txt").write_text("\n".join(line for line in calib.splitlines() if not line.startswith("P1")))
    with pytest.raises(SequenceError, match=r"calib\.txt: missing P1"):
        open_source(seq, map=lab_map)
    (seq / "calib.txt").write_text(calib.replace("P0: 5", "P0: 5 6"))
    with pytest.raises(SequenceError, match=r"calib\.txt line 1: P0: expected 12 numbers"):
        open_source(seq, map=lab_map)
    (seq / "calib.txt").write_text(calib)
    (seq / "image_1" / "000002.png").unlink()
    with pytest.raises(SequenceError, match=r"000002\.png: no such file \(image_1 needs the same names"):
        open_source(seq, map=lab_map)


def test_kitti_images_of_another_size_than_the_calibration(tmp_path, lab_map):
    seq = write_kitti(tmp_path)
    img = cv2.imread(str(seq / "image_1" / "000000.png"), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(seq / "image_1" / "000000.png"), img[:, :320])
    with pytest.raises(ImageError, match=r"image_1/000000\.png: right image is 320×480 px but the calibration "
                                         r".*calib\.txt is for 640×480 px"):
        open_source(seq, map=lab_map)


# ------------------------------------------------------------------ EuRoC
def test_euroc_folder_gives_the_recordings_frames(tmp_path, lab_map):
    root, stamps = write_euroc(tmp_path / "MH_01_easy")
    for path in (root, root / "mav0"):
        source = open_source(path, map=lab_map)
        assert source.name == "MH_01_easy"
        assert_same_frames(source, stamps=stamps, pans=[0.0] * N_FRAMES)
        truth = np.array([source.true_pose(k) for k in range(N_FRAMES)])
        np.testing.assert_allclose(truth[:, :2], lab_truth()[:, :2], atol=1e-9)
        np.testing.assert_allclose(wrap_angle(truth[:, 2] - lab_truth()[:, 2]), 0.0, atol=1e-9)
    run, _ = lab_recording()
    cam, want = source.camera, run.scenario.camera
    assert (cam.f, cam.cu, cam.cv) == pytest.approx((want.f, want.cu, want.cv), abs=1e-9)
    assert cam.baseline == pytest.approx(want.baseline, rel=1e-12)


def test_euroc_extrinsics_and_rectification_from_sensor_yaml(tmp_path):
    """Random camera poses in the body frame, distortion: the rectified rows of a body point agree."""
    rng = np.random.default_rng(7)
    size = (752, 480)
    K1 = np.array([[458.7, 0, 367.2], [0, 457.3, 248.4], [0, 0, 1]])
    K2 = np.array([[457.6, 0, 379.0], [0, 456.1, 255.2], [0, 0, 1]])
    D1, D2 = np.array([-0.28, 0.074, 2e-4, 1.8e-5]), np.array([-0.283, 0.075, -1e-4, -3e-5])
    R_B_C0 = cv2.Rodrigues(np.array([0.02, -1.57, 0.01]))[0]
    R_C0_C1 = cv2.Rodrigues(rng.normal(0, 0.01, 3))[0]
    T_B_C0, T_B_C1 = np.eye(4), np.eye(4)
    T_B_C0[:3, :3], T_B_C0[:3, 3] = R_B_C0, [-0.02, -0.06, 0.01]
    T_B_C1[:3, :3] = R_B_C0 @ R_C0_C1
    T_B_C1[:3, 3] = T_B_C0[:3, 3] + R_B_C0 @ np.array([0.11, 0.001, -0.0005])  # cam1 11 cm to cam0's right
    mav0 = tmp_path / "mav0"
    write_sensor_yaml(mav0 / "cam0", "cam0", T_B_C0, K1, D1, size)
    write_sensor_yaml(mav0 / "cam1", "cam1", T_B_C1, K2, D2, size)
    calib = euroc_calibration(mav0)
    assert calib.baseline == pytest.approx(0.11, abs=2e-3)
    # Body points in front of cam0, seen by both raw cameras, land on the same rectified row.
    p_c0 = np.column_stack([rng.uniform(-1, 1, 20), rng.uniform(-0.6, 0.6, 20), rng.uniform(2, 6, 20)])
    p_b = p_c0 @ R_B_C0.T + T_B_C0[:3, 3]
    # (cv2.undistortPoints' default 5 iterations leave up to 0.03 px with this distortion: iterate to convergence.)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    v = []
    for T_B_C, K, D, R_rect, P in ((T_B_C0, K1, D1, calib.R1, calib.P1), (T_B_C1, K2, D2, calib.R2, calib.P2)):
        T_C_B = np.linalg.inv(T_B_C)
        uv = cv2.projectPoints(p_b, cv2.Rodrigues(T_C_B[:3, :3])[0], T_C_B[:3, 3], K, D)[0]
        v.append(cv2.undistortPointsIter(uv, K, D, R_rect, P, criteria).reshape(-1, 2)[:, 1])
    np.testing.assert_allclose(v[0], v[1], atol=1e-6)
    # Swapped cameras are refused.
    write_sensor_yaml(mav0 / "cam1", "cam1", T_B_C0, K1, D1, size)
    write_sensor_yaml(mav0 / "cam0", "cam0", T_B_C1, K2, D2, size)
    with pytest.raises(ConfigError, match=r"expected cam1 to the right of cam0"):
        euroc_calibration(mav0)


def test_euroc_broken_folders(tmp_path, lab_map):
    root, _ = write_euroc(tmp_path / "V1", groundtruth=False)
    source = open_source(root, map=lab_map)
    assert source.true_pose(0) is None
    (root / "odometry.csv").rename(tmp_path / "odo.csv")
    with pytest.raises(SequenceError, match=r"EuRoC has no wheel odometry: put an odometry\.csv"):
        open_source(root, map=lab_map)
    assert len(open_source(root, map=lab_map, odometry=tmp_path / "odo.csv")) == N_FRAMES
    (tmp_path / "odo.csv").rename(root / "odometry.csv")
    (root / "mount.yaml").unlink()
    with pytest.raises(InputError, match=r"no camera mount for the EuRoC sequence .*: pass `mount`"):
        open_source(root, map=lab_map)
    (root / "mount.yaml").write_text("mount: {height: 1.0}\n")
    sensor = (root / "mav0" / "cam1" / "sensor.yaml").read_text()
    (root / "mav0" / "cam1" / "sensor.yaml").write_text(sensor.replace("camera_model: pinhole",
                                                                       "camera_model: omni"))
    with pytest.raises(ConfigError, match=r"cam1/sensor\.yaml: camera_model: expected camera_model pinhole, "
                                          r"got 'omni'"):
        open_source(root, map=lab_map)
    (root / "mav0" / "cam1" / "sensor.yaml").write_text(sensor.replace("intrinsics: [", "intrinsics: [1, "))
    with pytest.raises(ConfigError, match=r"cam1/sensor\.yaml: intrinsics: expected 4 finite numbers"):
        open_source(root, map=lab_map)
    (root / "mav0" / "cam1" / "sensor.yaml").write_text(sensor)
    csv = (root / "mav0" / "cam0" / "data.csv").read_text().splitlines()
    (root / "mav0" / "cam0" / "data.csv").write_text("\n".join([csv[0], csv[1], csv[1], *csv[3:]]) + "\n")
    with pytest.raises(SequenceError, match=r"cam0/data\.csv: duplicate timestamp: message 1"):
        open_source(root, map=lab_map)
    (root / "mav0" / "cam0" / "data.csv").write_text("\n".join([csv[0], *csv[2:]]) + "\n")
    source = open_source(root, map=lab_map)  # cam1's first image has no partner: left out
    assert len(source) == N_FRAMES - 1
    assert source.notes == ["0 cam0 and 1 cam1 images have no partner within 5 ms"]
    np.testing.assert_allclose(source.stamps[0], 1_403_636_580.263555584, atol=1e-6)
