"""Public dataset folders as frame sources: KITTI odometry and EuRoC MAV sequences.

Neither dataset has wheel odometry, and neither has a map of walls: both come from the user. The
odometry is our odometry CSV (:mod:`stablemarks.io.sources`: ``stamp,x,y,theta``, at any stamps,
interpolated at the frames): ``--odometry CSV``, or ``odometry.csv`` in the dataset folder. Frames
outside its time span are left out.

KITTI odometry (one sequence folder, e.g. ``dataset/sequences/00``)::

    00/
      calib.txt        # "P0: 12 numbers" … 3×4 rectified projections, row-major; P0 left gray, P1 right gray
      times.txt        # one stamp [s] per frame
      image_0/000000.png …   # left, rectified 8-bit gray
      image_1/000000.png …   # right, same names
      odometry.csv     # ours (not KITTI's), unless --odometry
    ../../poses/00.txt       # optional: ground truth, 12 numbers per frame (camera 0's pose, 3×4 row-major)

``f = P0[0,0]``, ``(cu, cv) = (P0[0,2], P0[1,2])``, ``baseline = −P1[0,3] / P1[0,0]``. The ground truth is
camera 0's pose in the first camera frame (``x`` right, ``y`` down, ``z`` forward); on the floor that is
``x = t_z``, ``y = −t_x``, ``theta = atan2(−R[0,2], R[2,2])``. The mount defaults to KITTI's: the
cameras 1.65 m above the road.

EuRoC MAV (the folder holding ``mav0/``, or ``mav0`` itself)::

    mav0/cam0/data.csv         # "#timestamp [ns],filename" then one row per image
    mav0/cam0/data/<t>.png     # raw (distorted) 8-bit gray images
    mav0/cam0/sensor.yaml      # T_BS (4×4 sensor in body), resolution [w, h], intrinsics [fu, fv, cu, cv],
                               #   distortion_model radial-tangential, distortion_coefficients [k1, k2, p1, p2]
    mav0/cam1/…                # the right camera, likewise
    mav0/state_groundtruth_estimate0/data.csv   # optional: t [ns], p (x, y, z) [m], q (w, x, y, z)

The stereo extrinsics are ``T_cam1_cam0 = T_B_cam1⁻¹ T_B_cam0``, and the rectification is computed with
``cv2.stereoRectify`` (zero disparity at infinity, ``alpha = 0``), as for an OpenCV calibration file;
``--calib`` replaces it. The mount (``--camera``, or ``mount.yaml`` in the dataset folder) is required.
The ground truth is the body's pose in its world frame, projected on the floor.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from ..errors import ConfigError, SequenceError, expected
from ..geometry import wrap_angle
from ..maps import COORDINATE_LIMIT, INT64_MAX, STAMP_LIMIT, parse_yaml
from .calibration import Mount, StereoCalibration, _stereo_rectify, load_calibration
from .images import MAX_IMAGE_SIDE, load_image_gray
from .recorded import (
    SYNC_TOLERANCE,
    RecordedSource,
    check_stamps,
    frames_with_odometry,
    load_mount_near,
    load_world_map,
    match_stamps,
    poses_at,
    read_odometry_csv,
    yaw_of_quaternion,
)

KITTI_MOUNT = Mount(mount_height=1.65)
"""KITTI's cameras: 1.65 m above the road, the robot frame under the left camera."""


def _odometry_file(odometry, folder: Path, what: str) -> Path:
    if odometry is not None:
        return Path(odometry)
    if (folder / "odometry.csv").is_file():
        return folder / "odometry.csv"
    raise SequenceError(f"{folder}: {what} has no wheel odometry: put an odometry.csv (stamp,x,y,theta) in the "
                        "folder or pass `odometry` (an odometry CSV)")


def _numbers(text: str, where: str, limit: float = COORDINATE_LIMIT) -> list[float]:
    """The numbers of a line, each finite and of magnitude at most ``limit``."""
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        raise SequenceError(expected("numbers separated by spaces", text.strip(), where=where)) from None
    if not all(math.isfinite(v) for v in values):
        raise SequenceError(expected("finite numbers", text.strip(), where=where))
    if any(abs(v) > limit for v in values):
        raise SequenceError(expected(f"numbers within ±{limit:g}", text.strip(), where=where))
    return values


def _nanoseconds(text: str, where: str) -> int:
    """An integer time stamp [ns] that fits int64."""
    try:
        value = int(text) if len(text.strip()) <= 20 else None
    except ValueError:
        value = None
    if value is None or abs(value) > INT64_MAX:
        raise SequenceError(expected("an integer timestamp [ns]", text, where=where))
    return value


class FolderSource(RecordedSource):
    """A dataset whose frames are pairs of image files (``left_paths``, ``right_paths``, one per frame)."""

    def __init__(self, *args, left_paths, right_paths, **kwargs):
        self.left_paths = tuple(left_paths)
        self.right_paths = tuple(right_paths)
        super().__init__(*args, **kwargs)

    def raw_pair(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        return load_image_gray(self.left_paths[k]), load_image_gray(self.right_paths[k])

    def frame_name(self, k: int) -> str:
        return f"{self.left_paths[k]}, {self.right_paths[k]}"


def _check_first(source: RecordedSource) -> RecordedSource:
    source.pair(0)
    return source


# ------------------------------------------------------------------ KITTI
def read_kitti_calib(path: str | Path) -> dict[str, np.ndarray]:
    """The 3×4 matrices of a KITTI ``calib.txt`` (``"NAME: 12 numbers"`` per line), by name."""
    path = Path(path)
    out = {}
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        name, sep, rest = line.partition(":")
        where = f"{path} line {number}"
        if not sep:
            raise SequenceError(expected("'NAME: 12 numbers'", line.strip(), where=where))
        values = _numbers(rest, f"{where}: {name.strip()}")
        if len(values) != 12:
            raise SequenceError(expected("12 numbers (a 3×4 matrix, row-major)", len(values),
                                         where=f"{where}: {name.strip()}"))
        out[name.strip()] = np.array(values).reshape(3, 4)
    for name in ("P0", "P1"):
        if name not in out:
            raise SequenceError(f"{path}: missing {name} (expected the 3×4 projections P0 and P1 of the gray cameras)")
    return out


def kitti_calibration(path: str | Path, image_size: tuple[int, int]) -> StereoCalibration:
    """The rectified calibration of a KITTI ``calib.txt``: ``K = P[:, :3]``, no distortion, no rotation."""
    m = read_kitti_calib(path)
    P1, P2 = m["P0"], m["P1"]
    if not P2[0, 3] < 0:
        raise SequenceError(expected("P1[0,3] = −f·baseline < 0", float(P2[0, 3]), where=f"{path}: P1"))
    T = np.array([P2[0, 3] / P2[0, 0] - P1[0, 3] / P1[0, 0], 0.0, 0.0])
    return StereoCalibration(image_size, P1[:, :3], np.zeros(5), P2[:, :3], np.zeros(5), np.eye(3), T, np.eye(3),
                             np.eye(3), P1, P2, "image_0", "image_1", source=str(path))


def kitti_planar_poses(path: str | Path) -> np.ndarray:
    """Floor poses ``(n, 3)`` of a KITTI poses file (module docstring)."""
    path = Path(path)
    rows = [(number, line) for number, line in enumerate(path.read_text().splitlines(), start=1) if line.strip()]
    M = np.zeros((len(rows), 12))
    for i, (number, line) in enumerate(rows):
        values = _numbers(line, f"{path} line {number}")
        if len(values) != 12:
            raise SequenceError(expected("12 numbers (a 3×4 pose, row-major)", len(values),
                                         where=f"{path} line {number}"))
        M[i] = values
    M = M.reshape(-1, 3, 4)
    return np.column_stack([M[:, 2, 3], -M[:, 0, 3], np.arctan2(-M[:, 0, 2], M[:, 2, 2])])


def open_kitti(path: str | Path, *, map=None, mount=None, odometry=None, tolerance: float = SYNC_TOLERANCE,
               start_pose=None) -> FolderSource:
    """Open a KITTI odometry sequence folder (module docstring); every file is checked here."""
    root = Path(path)
    what = f"the KITTI sequence {root}"
    for name in ("calib.txt", "times.txt", "image_0", "image_1"):
        if not (root / name).exists():
            raise SequenceError(f"{root / name}: no such {'folder' if name.startswith('image') else 'file'} (a KITTI "
                                "sequence has calib.txt, times.txt, image_0/ and image_1/)")
    world_map = load_world_map(map, what)
    lefts = sorted((root / "image_0").glob("*.png"))
    rights = [root / "image_1" / p.name for p in lefts]
    if not lefts:
        raise SequenceError(f"{root / 'image_0'}: no PNG images")
    missing = next((p for p in rights if not p.is_file()), None)
    if missing is not None:
        raise SequenceError(f"{missing}: no such file (image_1 needs the same names as image_0)")
    times_path = root / "times.txt"
    stamps = []
    for number, line in enumerate(times_path.read_text().splitlines(), start=1):
        if line.strip():
            values = _numbers(line, f"{times_path} line {number}", STAMP_LIMIT)
            if len(values) != 1:
                raise SequenceError(expected("one stamp [s]", line.strip(), where=f"{times_path} line {number}"))
            stamps.append(values[0])
    stamps = np.array(stamps)
    if len(stamps) != len(lefts):
        raise SequenceError(f"{times_path}: {len(stamps)} stamps, but {root / 'image_0'} has {len(lefts)} images "
                            "(expected one stamp per image)")
    check_stamps(stamps, str(times_path))
    first = load_image_gray(lefts[0])
    calibration = kitti_calibration(root / "calib.txt", (first.shape[1], first.shape[0]))
    camera = calibration.stereo_camera(load_mount_near(mount, root, default=KITTI_MOUNT))
    t_odom, poses = read_odometry_csv(_odometry_file(odometry, root, "KITTI"))
    keep, odom, notes = frames_with_odometry(stamps, t_odom, poses, tolerance, what)
    groundtruth = None
    gt_path = root.parent.parent / "poses" / f"{root.name}.txt"
    if gt_path.is_file():
        groundtruth = kitti_planar_poses(gt_path)
        if len(groundtruth) != len(stamps):
            raise SequenceError(f"{gt_path}: {len(groundtruth)} poses, but {times_path} has {len(stamps)} stamps "
                                "(expected one pose per frame)")
        groundtruth = groundtruth[keep]
    idx = np.flatnonzero(keep)
    return _check_first(FolderSource(
        root.name, calibration, camera, world_map, stamps[keep], odom, np.full(len(idx), camera.pan),
        start_pose=start_pose, groundtruth=groundtruth, notes=notes,
        left_paths=[lefts[i] for i in idx], right_paths=[rights[i] for i in idx]))


# ------------------------------------------------------------------ EuRoC
def _read_sensor_yaml(path: Path) -> dict:
    """A EuRoC ``sensor.yaml`` (its first line ``%YAML:1.0`` is OpenCV's, not YAML's: dropped)."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise SequenceError(f"{path}: no such sensor file") from None
    text = "\n".join("" if line.startswith("%YAML") else line for line in text.splitlines())
    data = parse_yaml(text, str(path))
    if not isinstance(data, dict):
        raise ConfigError(expected("a mapping", type(data).__name__, where=str(path)))
    return data


def read_euroc_camera(cam_dir: str | Path) -> tuple[tuple[int, int], np.ndarray, np.ndarray, np.ndarray]:
    """``(image_size (w, h), K (3, 3), D (4,), T_B_S (4, 4))`` from a EuRoC camera's ``sensor.yaml``."""
    path = Path(cam_dir) / "sensor.yaml"
    d = _read_sensor_yaml(path)

    def field(key: str, n: int, what: str) -> np.ndarray:
        value = d.get(key)
        if isinstance(value, dict):
            value = value.get("data")
        if value is None:
            raise ConfigError(f"{path}: missing field {key!r} ({what})")
        try:
            arr = np.array(value, dtype=float).ravel()
        except (TypeError, ValueError):
            raise ConfigError(expected(f"{n} numbers ({what})", value, where=f"{path}: {key}")) from None
        if arr.size != n or not np.all(np.isfinite(arr)):
            raise ConfigError(expected(f"{n} finite numbers ({what})", value, where=f"{path}: {key}"))
        return arr

    model = d.get("camera_model", "pinhole")
    if model != "pinhole":
        raise ConfigError(expected("camera_model pinhole", model, where=f"{path}: camera_model"))
    dist = d.get("distortion_model", "radial-tangential")
    if dist not in ("radial-tangential", "radtan", "plumb_bob"):
        raise ConfigError(expected("distortion_model radial-tangential", dist, where=f"{path}: distortion_model"))
    w, h = field("resolution", 2, "[width, height] px")
    if not (0 < w <= MAX_IMAGE_SIDE and 0 < h <= MAX_IMAGE_SIDE and w.is_integer() and h.is_integer()):
        raise ConfigError(expected("a positive integer [width, height]", d.get("resolution"),
                                   where=f"{path}: resolution"))
    fu, fv, cu, cv = field("intrinsics", 4, "[fu, fv, cu, cv] px")
    K = np.array([[fu, 0.0, cu], [0.0, fv, cv], [0.0, 0.0, 1.0]])
    D = field("distortion_coefficients", 4, "[k1, k2, p1, p2]")
    T_B_S = field("T_BS", 16, "the camera's pose in the body frame, 4×4 row-major").reshape(4, 4)
    return (int(w), int(h)), K, D, T_B_S


def euroc_calibration(mav0: str | Path) -> StereoCalibration:
    """The stereo calibration of ``mav0/cam0`` (left) and ``mav0/cam1`` (right), rectified by ``cv2.stereoRectify``."""
    mav0 = Path(mav0)
    size0, K1, D1, T_B_C0 = read_euroc_camera(mav0 / "cam0")
    size1, K2, D2, T_B_C1 = read_euroc_camera(mav0 / "cam1")
    if size0 != size1:
        raise ConfigError(f"{mav0}: cam0 is {size0[0]}×{size0[1]} px but cam1 {size1[0]}×{size1[1]} px "
                          "(expected the same resolution)")
    T_C1_C0 = np.linalg.inv(T_B_C1) @ T_B_C0
    R, T = T_C1_C0[:3, :3], T_C1_C0[:3, 3]
    if not T[0] < 0:
        raise ConfigError(expected("cam1 to the right of cam0 (T[0] < 0 in cam1's frame)", float(T[0]),
                                   where=f"{mav0}: T_BS of cam0 and cam1"))
    R1, R2, P1, P2 = _stereo_rectify(K1, D1, K2, D2, size0, R, T)
    return StereoCalibration(size0, K1, D1, K2, D2, R, T, R1, R2, P1, P2, "cam0", "cam1", source=str(mav0))


def read_euroc_images(cam_dir: str | Path) -> tuple[np.ndarray, list[Path]]:
    """``(stamps (n,) int64 [ns], image paths)`` of a EuRoC camera's ``data.csv``; every image must exist."""
    cam_dir = Path(cam_dir)
    path = cam_dir / "data.csv"
    if not path.is_file():
        raise SequenceError(f"{path}: no such file (the camera's image list: #timestamp [ns],filename)")
    stamps, paths = [], []
    with path.open(newline="") as fh:
        for number, row in enumerate(csv.reader(fh), start=1):
            if not row or row[0].lstrip().startswith("#"):
                continue
            where = f"{path} line {number}"
            if len(row) != 2:
                raise SequenceError(expected("2 fields: timestamp [ns],filename", ",".join(row), where=where))
            stamps.append(_nanoseconds(row[0], where))
            image = cam_dir / "data" / row[1].strip()
            if not image.is_file():
                raise SequenceError(f"{where}: {image}: no such image")
            paths.append(image)
    if not stamps:
        raise SequenceError(f"{path}: no images")
    t = np.array(stamps, dtype=np.int64)
    check_stamps(t, str(path))
    return t, paths


def euroc_groundtruth(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps (n,) [s], floor poses (n, 3))`` of ``state_groundtruth_estimate0/data.csv``."""
    path = Path(path)
    stamps, rows = [], []
    with path.open(newline="") as fh:
        for number, row in enumerate(csv.reader(fh), start=1):
            if not row or row[0].lstrip().startswith("#"):
                continue
            if len(row) < 8:
                raise SequenceError(expected("at least 8 fields: t, px, py, pz, qw, qx, qy, qz", len(row),
                                             where=f"{path} line {number}"))
            where = f"{path} line {number}"
            stamps.append(_nanoseconds(row[0], where))
            rows.append(_numbers(" ".join(row[1:8]), where))
    if not rows:
        raise SequenceError(f"{path}: no poses")
    t = np.array(stamps, dtype=np.int64)
    check_stamps(t, str(path))
    m = np.array(rows)
    yaw = yaw_of_quaternion(m[:, 4], m[:, 5], m[:, 6], m[:, 3])
    return t / 1e9, np.column_stack([m[:, 0], m[:, 1], wrap_angle(yaw)])


def open_euroc(path: str | Path, *, calib=None, map=None, mount=None, odometry=None,
               tolerance: float = SYNC_TOLERANCE, start_pose=None) -> FolderSource:
    """Open a EuRoC MAV sequence (module docstring); every file is checked here."""
    root = Path(path)
    mav0 = root if root.name == "mav0" and (root / "cam0").is_dir() else root / "mav0"
    folder = mav0.parent
    what = f"the EuRoC sequence {folder}"
    world_map = load_world_map(map, what)
    calibration = load_calibration(calib) if calib is not None else euroc_calibration(mav0)
    camera = calibration.stereo_camera(load_mount_near(mount, calib if calib is not None else folder, what=what))
    t0, left = read_euroc_images(mav0 / "cam0")
    t1, right = read_euroc_images(mav0 / "cam1")
    pairs = match_stamps(t0, t1, int(round(tolerance * 1e9)))
    if not len(pairs):
        raise SequenceError(f"{mav0}: no stereo pairs: no cam0 image has a cam1 image within {tolerance * 1e3:g} ms")
    notes = []
    if len(pairs) < max(len(t0), len(t1)):
        notes.append(f"{len(t0) - len(pairs)} cam0 and {len(t1) - len(pairs)} cam1 images have no partner within "
                     f"{tolerance * 1e3:g} ms")
    stamps = t0[pairs[:, 0]] / 1e9
    t_odom, poses = read_odometry_csv(_odometry_file(odometry, folder, "EuRoC"))
    keep, odom, more = frames_with_odometry(stamps, t_odom, poses, tolerance, what)
    pairs, stamps = pairs[keep], stamps[keep]
    groundtruth = None
    gt_path = mav0 / "state_groundtruth_estimate0" / "data.csv"
    if gt_path.is_file():
        groundtruth = poses_at(*euroc_groundtruth(gt_path), stamps, tolerance)
    return _check_first(FolderSource(
        folder.name, calibration, camera, world_map, stamps, odom, np.full(len(stamps), camera.pan),
        start_pose=start_pose, groundtruth=groundtruth, notes=notes + more,
        left_paths=[left[i] for i in pairs[:, 0]], right_paths=[right[j] for j in pairs[:, 1]]))
