"""Recorded sequences: a folder of stereo frames with calibration, map, stamps, pans and wheel odometry.

``stablemarks simulate`` writes a scenario's run as such a folder and ``stablemarks run`` reads one; a
real robot's recording converted to it runs the same way. :func:`load_sequence` checks the whole folder
before anything runs and raises :class:`~stablemarks.errors.SequenceError` naming the file (and line)
that is missing or wrong; :func:`write_sequence` builds the folder under a temporary name beside the
target and renames it at the end, so a failure never leaves a half-written folder.

Folder layout (every path is given in ``sequence.yaml``, relative to the folder and inside it: an absolute
path or one that leads out with ``..`` is an error, a symbolic link inside the folder may point anywhere;
these are the names ``simulate`` uses)::

    DIR/
      sequence.yaml        # what is where (below)
      calib/left.yaml      # ROS camera_info of the left camera  } or an OpenCV stereo file
      calib/right.yaml     # ROS camera_info of the right camera }
      calib/mount.yaml     # where the head sits on the robot: mount: {x: 0.0, y: 0.0, height: 1.0, pan_deg: 0.0}
      map.yaml             # the map of walls (map file format)
      left/000000.png …    # left images, 8- or 16-bit, gray or colour
      right/000000.png …   # right images, same size as the left ones and the calibration
      frames.csv           # one row per stereo frame
      odometry.csv         # one wheel-odometry pose per frame
      groundtruth.tum      # optional: true poses, TUM format
      groundtruth.json     # optional: the simulator's per-frame truth

``sequence.yaml``::

    format: stablemarks-sequence    # required, exactly this
    version: 1                      # required
    name: lab                       # optional (default: the folder's name)
    description: ...                # optional free text
    calibration: calib              # required: folder with left.yaml + right.yaml, or an OpenCV .yml/.yaml/.xml
    mount: calib/mount.yaml         # optional (default: mount.yaml in the calibration folder, or beside the
                                    #   OpenCV file); the file itself is required: the camera height matters
    map: map.yaml                   # required
    frames: frames.csv              # required
    odometry: odometry.csv          # required
    groundtruth: groundtruth.tum    # optional
    truth: groundtruth.json         # optional
    initial_pose: {x: 0.0, y: 0.0, theta_deg: 90.0}   # optional: the robot's start in the map [m, deg]
    initial_cov: [[0.0025, 0, 0], [0, 0.0025, 0], [0, 0, 0.0003]]   # optional: its covariance over
                                    #   (x [m], y [m], theta [rad]), symmetric positive semi-definite

``frames.csv`` (comma-separated, header line first, columns in any order)::

    index,stamp,left,right,pan
    0,0.000000000,left/000000.png,right/000000.png,0.1303

- ``index``: frame number, an integer, strictly increasing (gaps allowed).
- ``stamp``: time of the stereo pair [s], strictly increasing.
- ``left``, ``right``: image paths relative to the folder, inside it.
- ``pan``: optional column, the head's pan relative to the robot's heading [rad], positive to the left;
  without it every frame has the mount's ``pan_deg``.

Images are rectified when the calibration says they are (identity rectification, no distortion,
``K = P[:, :3]``, as ``simulate`` writes it); otherwise they are raw and each pair is rectified through the
calibration when read.

``odometry.csv``::

    stamp,x,y,theta
    0.000000000,0.0,0.0,1.5707963267948966

One row per frame, in frame order, each at its frame's stamp (within 1 µs): the robot's pose ``x [m],
y [m], theta [rad]`` as its wheel odometry reports it (e.g. a ``nav_msgs/Odometry`` pose resampled at the
image stamps). The odometry frame's origin does not matter: only the increments between consecutive
poses are used (:meth:`Sequence.odometry_increment`).

``groundtruth.tum``: the true robot poses, TUM format (``timestamp tx ty tz qx qy qz qw``, see
:mod:`stablemarks.io.trajectory`), at any stamps in increasing order; they are interpolated linearly
(heading on the shortest arc) at the frame stamps, and frames outside their time span get none (NaN).
``evo_ape tum groundtruth.tum estimate.tum`` compares a run's trajectory with it.

``groundtruth.json`` (simulate only): the run's header (scenario, seed, camera, odometry noise) and, per
frame, the true pose, pan, exposure, noisy and true odometry increments, dead reckoning, and every
vertical image edge with its true position, columns and visibility (:mod:`stablemarks.sim.truth`).
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import uuid
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..errors import ImageError, InputError, SequenceError, expected
from ..frames import Frame
from ..geometry import SE2, StereoCamera, wrap_angle
from ..maps import COORDINATE_LIMIT, INT64_MAX, STAMP_LIMIT, Map, read_yaml
from ..maps import _number as map_number
from .calibration import (
    ROS_FILES,
    StereoCalibration,
    load_calibration,
    load_mount,
    save_calibration,
    save_camera_info_pair,
)
from .images import load_stereo_pair
from .trajectory import read_tum, write_tum

FORMAT = "stablemarks-sequence"
"""The ``format`` field of ``sequence.yaml``."""

VERSION = 1
"""The folder format version this module reads and writes."""

FRAME_PERIOD = 0.5
"""Time between the frames of a simulated run [s] (frames 0.1 m apart, as in the lab: 0.2 m/s)."""

STAMP_TOLERANCE = 1e-6
"""Largest difference [s] between an odometry stamp and its frame's stamp."""

SEQUENCE_FILE = "sequence.yaml"

_KEYS = ("format", "version", "name", "description", "calibration", "mount", "map", "frames", "odometry",
         "groundtruth", "truth", "initial_pose", "initial_cov")
_FRAME_COLUMNS = ("index", "stamp", "left", "right")
_ODOMETRY_COLUMNS = ("stamp", "x", "y", "theta")


# ------------------------------------------------------------------ the sequence
@dataclass(frozen=True, eq=False)
class Sequence:
    """A loaded, validated sequence folder (format in the module docstring); images are read on demand.

    Attributes
    ----------
    root : the folder.
    name, description : from ``sequence.yaml``.
    camera : the rectified :class:`StereoCamera` on its mount, with the mount's pan.
    calibration : the stereo calibration the images are rectified with (when they are raw).
    world_map : the map of walls.
    indices : (n,) frame numbers from ``frames.csv``.
    stamps : (n,) frame times [s], strictly increasing.
    left_paths, right_paths : the n image files of each camera.
    pans : (n,) head pan of each frame [rad].
    odometry : (n, 3) wheel-odometry poses ``(x [m], y [m], theta [rad])`` at the frame stamps.
    groundtruth : (n, 3) true poses at the frame stamps (NaN rows outside the ground truth's time span), or None.
    truth_path : the simulator's per-frame truth (``groundtruth.json``), or None.
    initial_pose : the robot's start in the map, or None.
    initial_cov : (3, 3) its covariance over ``(x, y, theta)`` [m², rad²], or None.
    pan_recorded : whether ``frames.csv`` gives each frame's pan (its ``pan`` column); False: every frame has the
        mount's pan, which is right only if the head did not move.
    """

    root: Path
    name: str
    camera: StereoCamera
    calibration: StereoCalibration
    world_map: Map
    indices: np.ndarray
    stamps: np.ndarray
    left_paths: tuple[Path, ...]
    right_paths: tuple[Path, ...]
    pans: np.ndarray
    odometry: np.ndarray
    groundtruth: np.ndarray | None = None
    truth_path: Path | None = None
    initial_pose: SE2 | None = None
    description: str = ""
    initial_cov: np.ndarray | None = None
    pan_recorded: bool = True

    def __post_init__(self) -> None:
        for name in ("indices", "stamps", "pans", "odometry", "groundtruth"):
            value = getattr(self, name)
            if value is not None:
                value = np.array(value)
                value.setflags(write=False)
                object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.stamps)

    def _check(self, k: int) -> int:
        if not 0 <= k < len(self):
            raise IndexError(f"frame {k} of a sequence of {len(self)} frames")
        return int(k)

    def frame(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The rectified pair ``(left, right)`` of frame ``k``: (H, W) ``uint8`` each.

        Raw images are rectified through :attr:`calibration`; :class:`~stablemarks.errors.ImageError` if a
        file cannot be read or has the wrong size.
        """
        k = self._check(k)
        return load_stereo_pair(self.left_paths[k], self.right_paths[k], self.calibration)

    def camera_at(self, k: int) -> StereoCamera:
        """The camera of frame ``k``: :attr:`camera` panned by ``pans[k]``."""
        return self.camera.with_pan(float(self.pans[self._check(k)]))

    def odometry_increment(self, k: int) -> SE2:
        """The odometry increment ``T_{k-1}⁻¹ T_k`` from frame ``k - 1`` to frame ``k``, in the robot frame of
        frame ``k - 1`` (the control of Eq 19); the identity for frame 0."""
        k = self._check(k)
        if k == 0:
            return SE2()
        return SE2.from_array(self.odometry[k - 1]).between(SE2.from_array(self.odometry[k]))


# ------------------------------------------------------------------ loading
@contextmanager
def _as_sequence_error() -> Iterator[None]:
    """Re-raise a user-input error from the loaders below as a :class:`SequenceError` (same message)."""
    try:
        yield
    except SequenceError:
        raise
    except InputError as exc:
        raise SequenceError(str(exc)) from None


def _number(text: str, where: str, limit: float = COORDINATE_LIMIT) -> float:
    """A CSV field as a finite number of magnitude at most ``limit``."""
    try:
        value = float(text)
    except ValueError:
        raise SequenceError(expected("a number", text, where=where)) from None
    if not math.isfinite(value):
        raise SequenceError(expected("a finite number", text, where=where))
    if abs(value) > limit:
        raise SequenceError(expected(f"a number within ±{limit:g}", text, where=where))
    return value


def _inside(root: Path, value: str, where: str) -> Path:
    """``root / value`` for a path ``value`` relative to the sequence folder that stays inside it (no absolute
    path, no ``..`` leading out; symbolic links inside the folder are followed wherever they point)."""
    rel = Path(value)
    if rel.is_absolute() or rel.drive or os.path.normpath(value).split(os.sep)[0] == os.pardir:
        raise SequenceError(expected("a path inside the sequence folder, relative to it", value, where=where))
    return root / rel


def _read_csv(path: Path, what: str, required: tuple[str, ...], optional: tuple[str, ...] = ()):
    """Rows ``(line number, {column: text})`` of a CSV file with a header; errors name the file and line."""
    if not path.is_file():
        raise SequenceError(f"{path}: no such {what} (listed in {SEQUENCE_FILE})")
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:  # a spreadsheet's byte-order mark is fine
            reader = csv.reader(fh)
            header = [h.strip() for h in next(reader, [])]
            columns = ",".join(required) + "".join(f"[,{c}]" for c in optional)
            missing = [c for c in required if c not in header]
            unknown = [c for c in header if c not in required + optional]
            if missing or unknown or len(set(header)) != len(header):
                raise SequenceError(expected(f"a header line with the columns {columns}", ",".join(header),
                                             where=f"{path} line 1"))
            rows = []
            for fields in reader:
                if not fields or all(not f.strip() for f in fields):
                    continue
                if len(fields) != len(header):
                    raise SequenceError(expected(f"{len(header)} fields ({','.join(header)})", len(fields),
                                                 where=f"{path} line {reader.line_num}"))
                rows.append((reader.line_num, {h: f.strip() for h, f in zip(header, fields, strict=True)}))
    except (csv.Error, UnicodeDecodeError) as exc:
        raise SequenceError(f"{path}: not a readable CSV file: {exc}") from None
    if not rows:
        raise SequenceError(f"{path}: no rows after the header line")
    return rows


def _increasing(values: list[float], lines: list[int], path: Path, column: str) -> None:
    for i in range(1, len(values)):
        if not values[i] > values[i - 1]:
            raise SequenceError(expected(f"more than the previous row's {values[i - 1]!r} (must increase strictly)",
                                         values[i], where=f"{path} line {lines[i]}: {column}"))


def _entry(meta: dict, key: str, root: Path, source: Path, required: bool = True) -> Path | None:
    value = meta.get(key)
    if value is None:
        if required:
            raise SequenceError(f"{source}: missing field {key!r}")
        return None
    if not isinstance(value, str) or not value.strip():
        raise SequenceError(expected("a path relative to the sequence folder", value, where=f"{source}: {key}"))
    return _inside(root, value, f"{source}: {key}")


def _initial_pose(value, source: Path) -> SE2 | None:
    if value is None:
        return None
    where = f"{source}: initial_pose"
    if not isinstance(value, dict) or set(value) - {"x", "y", "theta_deg"}:
        raise SequenceError(expected("a mapping {x: m, y: m, theta_deg: deg}", value, where=where))
    numbers = {}
    for key in ("x", "y", "theta_deg"):
        with _as_sequence_error():
            numbers[key] = map_number(value.get(key, 0.0), f"{where}.{key}")
    return SE2(numbers["x"], numbers["y"], float(wrap_angle(math.radians(numbers["theta_deg"]))))


def _initial_cov(value, source: Path) -> np.ndarray | None:
    if value is None:
        return None
    where = f"{source}: initial_cov"
    if not (isinstance(value, list) and len(value) == 3 and all(isinstance(r, list) and len(r) == 3 for r in value)):
        raise SequenceError(expected("a 3×3 list of numbers (x, y, theta) [m², rad²]", value, where=where))
    with _as_sequence_error():
        cov = np.array([[map_number(v, f"{where}[{i}][{j}]") for j, v in enumerate(r)] for i, r in enumerate(value)])
    if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-15) or np.linalg.eigvalsh(0.5 * (cov + cov.T)).min() < -1e-12:
        raise SequenceError(f"{where}: expected a symmetric positive semi-definite matrix, got {value!r}"[:300])
    return 0.5 * (cov + cov.T)


def _interpolate_poses(stamps_gt: np.ndarray, poses_gt: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """Poses (n, 3) at ``stamps``: linear in x, y and in the unwrapped heading; NaN outside ``stamps_gt``."""
    theta = np.unwrap(poses_gt[:, 2])
    out = np.column_stack([np.interp(stamps, stamps_gt, v, left=np.nan, right=np.nan)
                           for v in (poses_gt[:, 0], poses_gt[:, 1], theta)])
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def load_sequence(path: str | Path) -> Sequence:
    """Load and check a sequence folder (format in the module docstring).

    Everything but the pixels is read and cross-checked here, and the first stereo pair is read to check
    the image size against the calibration. Raises :class:`SequenceError` naming the file, and the line for
    CSV and TUM files: a missing folder, ``sequence.yaml``, calibration, mount, map, CSV or image; a wrong
    format or version; bad CSV columns or values; stamps or indices that do not increase strictly;
    odometry rows that do not match the frames one to one.
    """
    root = Path(path)
    if not root.is_dir():
        raise SequenceError(f"{root}: no such sequence folder")
    source = root / SEQUENCE_FILE
    if not source.is_file():
        raise SequenceError(f"{root}: not a sequence folder: no {SEQUENCE_FILE}")
    with _as_sequence_error():
        meta = read_yaml(source, "sequence file")
    if not isinstance(meta, dict):
        raise SequenceError(expected("a mapping with format, version, calibration, map, frames, odometry",
                                     type(meta).__name__, where=str(source)))
    unknown = sorted(str(k) for k in set(meta) - set(_KEYS))
    if unknown:
        raise SequenceError(f"{source}: {unknown[0]}: unknown field (known: {', '.join(_KEYS)})")
    if meta.get("format") != FORMAT:
        raise SequenceError(expected(repr(FORMAT), meta.get("format"), where=f"{source}: format"))
    if meta.get("version") != VERSION:
        raise SequenceError(expected(f"version {VERSION}", meta.get("version"), where=f"{source}: version"))
    name = meta.get("name", root.resolve().name)
    description = meta.get("description", "")
    for key, value in (("name", name), ("description", description)):
        if not isinstance(value, str):
            raise SequenceError(expected("a string", value, where=f"{source}: {key}"))

    # Camera: calibration + mount.
    calib_path = _entry(meta, "calibration", root, source)
    if not calib_path.exists():
        raise SequenceError(f"{calib_path}: no such calibration folder or file (listed in {SEQUENCE_FILE})")
    if calib_path.is_dir() and not all((calib_path / f).is_file() for f in ROS_FILES):
        missing = next(calib_path / f for f in ROS_FILES if not (calib_path / f).is_file())
        raise SequenceError(f"{missing}: no such camera_info file (the calibration folder needs "
                            f"{' and '.join(ROS_FILES)})")
    mount_path = _entry(meta, "mount", root, source, required=False)
    if mount_path is None:
        mount_path = (calib_path if calib_path.is_dir() else calib_path.parent) / "mount.yaml"
    if not mount_path.is_file():
        raise SequenceError(f"{mount_path}: no such mount file (mount: {{x, y, height, pan_deg}}: where the "
                            "stereo head sits on the robot)")
    with _as_sequence_error():
        calibration = load_calibration(calib_path)
        mount = load_mount(mount_path)
        camera = calibration.stereo_camera(mount)

    map_path = _entry(meta, "map", root, source)
    if not map_path.is_file():
        raise SequenceError(f"{map_path}: no such map file (listed in {SEQUENCE_FILE})")
    with _as_sequence_error():
        world_map = Map.load(map_path)

    # Frames.
    frames_path = _entry(meta, "frames", root, source)
    rows = _read_csv(frames_path, "frames file", _FRAME_COLUMNS, ("pan",))
    lines = [line for line, _ in rows]
    indices, stamps, pans, left, right = [], [], [], [], []
    for line, row in rows:
        where = f"{frames_path} line {line}"
        try:
            index = int(row["index"]) if len(row["index"]) <= 20 else None
        except ValueError:
            index = None
        if index is None or abs(index) > INT64_MAX:
            raise SequenceError(expected("an integer", row["index"], where=f"{where}: index"))
        indices.append(index)
        stamps.append(_number(row["stamp"], f"{where}: stamp", STAMP_LIMIT))
        pans.append(_number(row["pan"], f"{where}: pan") if "pan" in row else mount.pan)
        for side, paths in (("left", left), ("right", right)):
            if not row[side]:
                raise SequenceError(f"{where}: {side}: expected an image path, got an empty field")
            image = _inside(root, row[side], f"{where}: {side}")
            if not image.is_file():
                raise SequenceError(f"{where}: {side} image {image}: no such file")
            paths.append(image)
    _increasing(indices, lines, frames_path, "index")
    _increasing(stamps, lines, frames_path, "stamp")
    stamps = np.array(stamps)

    # Odometry: one pose per frame, at its stamp.
    odom_path = _entry(meta, "odometry", root, source)
    odom_rows = _read_csv(odom_path, "odometry file", _ODOMETRY_COLUMNS)
    if len(odom_rows) != len(rows):
        raise SequenceError(f"{odom_path}: {len(odom_rows)} rows, but {frames_path} has {len(rows)} frames "
                            "(expected one odometry pose per frame)")
    odometry = np.zeros((len(rows), 3))
    for k, (line, row) in enumerate(odom_rows):
        where = f"{odom_path} line {line}"
        t = _number(row["stamp"], f"{where}: stamp", STAMP_LIMIT)
        if abs(t - stamps[k]) > STAMP_TOLERANCE:
            raise SequenceError(f"{where}: stamp: expected {float(stamps[k])!r}, the stamp of frame {indices[k]} "
                                f"({frames_path} line {lines[k]}), got {t!r}")
        odometry[k] = [_number(row[c], f"{where}: {c}") for c in ("x", "y", "theta")]

    # Optional ground truth.
    groundtruth = None
    gt_path = _entry(meta, "groundtruth", root, source, required=False)
    if gt_path is not None:
        if not gt_path.is_file():
            raise SequenceError(f"{gt_path}: no such ground-truth file (listed in {SEQUENCE_FILE})")
        with _as_sequence_error():
            gt_stamps, gt_poses = read_tum(gt_path)
        bad = np.flatnonzero(np.diff(gt_stamps) <= 0)
        if len(bad):
            raise SequenceError(f"{gt_path}: stamps must increase strictly, got {float(gt_stamps[bad[0] + 1])!r} "
                                f"after {float(gt_stamps[bad[0]])!r}")
        groundtruth = _interpolate_poses(gt_stamps, gt_poses, stamps)
    truth_path = _entry(meta, "truth", root, source, required=False)
    if truth_path is not None and not truth_path.is_file():
        raise SequenceError(f"{truth_path}: no such truth file (listed in {SEQUENCE_FILE})")

    seq = Sequence(root, name, camera, calibration, world_map, np.array(indices), stamps, tuple(left),
                   tuple(right), np.array(pans), odometry, groundtruth, truth_path,
                   _initial_pose(meta.get("initial_pose"), source), description,
                   _initial_cov(meta.get("initial_cov"), source), pan_recorded=all("pan" in row for _, row in rows))
    with _as_sequence_error():
        seq.frame(0)
    return seq


# ------------------------------------------------------------------ writing
def image_name(side: str, k: int) -> str:
    """Path of frame ``k``'s image of camera ``side`` (``"left"``/``"right"``) inside a written folder."""
    return f"{side}/{k:06d}.png"


def _check_target(out: Path, force: bool) -> None:
    """Refuse to replace a file, a non-empty folder without ``force``, or a non-empty folder that is not a sequence."""
    if not out.exists():
        return
    if not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    if not any(out.iterdir()):
        return
    if not force:
        raise InputError(f"{out}: folder exists and is not empty (`force` replaces a sequence folder)")
    if not (out / SEQUENCE_FILE).is_file():
        raise InputError(f"{out}: not a sequence folder (no {SEQUENCE_FILE}); refusing to replace it, even "
                         "with `force`")


check_target = _check_target
"""Check a target folder of :func:`write_sequence` before any work (what ``_check_target`` refuses)."""


def _install(tmp: Path, out: Path, force: bool) -> None:
    """Move the finished folder ``tmp`` to ``out``, replacing what ``_check_target`` allowed there."""
    _check_target(out, force)  # again: the folder may have changed while we were writing
    if not out.exists():
        os.rename(tmp, out)
        return
    old = out.with_name(f".{out.name}.{uuid.uuid4().hex[:8]}.old")
    os.rename(out, old)
    try:
        os.rename(tmp, out)
    except OSError:
        os.rename(old, out)
        raise
    shutil.rmtree(old)


def _csv_text(header: tuple[str, ...], rows: Iterable[Iterable[object]]) -> str:
    lines = [",".join(header)]
    for row in rows:
        lines.append(",".join(str(v) for v in row))
    return "\n".join(lines) + "\n"


def write_sequence(
    out_dir: str | Path,
    *,
    name: str,
    camera: StereoCamera,
    world_map: Map,
    stamps,
    odometry,
    pans,
    images: Iterable[tuple[np.ndarray, np.ndarray]],
    calibration: StereoCalibration | None = None,
    groundtruth=None,
    truth: Callable[[], dict] | None = None,
    initial_pose: SE2 | None = None,
    description: str = "",
    force: bool = False,
    initial_cov=None,
) -> Path:
    """Write a sequence folder (format in the module docstring) and return its path.

    Parameters
    ----------
    out_dir : the folder to create. An existing empty folder is filled; an existing sequence folder is
        replaced only with ``force``; anything else is refused (:class:`InputError`) before any work.
    name, description : written to ``sequence.yaml``.
    camera : the rectified camera and its mount (``mount.yaml`` gets its mount and ``pan``).
    world_map : written as ``map.yaml``.
    stamps : (n,) frame times [s], strictly increasing.
    odometry : (n, 3) wheel-odometry poses ``(x [m], y [m], theta [rad])`` at the frame stamps.
    pans : (n,) head pan of each frame [rad], or None: not recorded, ``frames.csv`` gets no ``pan`` column and
        every frame has the mount's pan (what a recording without pans gives; ``run`` warns of it).
    images : n pairs ``(left, right)`` of (H, W[, C]) images, consumed one at a time (e.g. a generator
        that renders them), written as PNG.
    calibration : the raw camera's calibration when the images are raw; None writes the ideal rectified
        calibration of ``camera`` (the images are rectified).
    groundtruth : (n, 3) true poses at the frame stamps, written as ``groundtruth.tum``; or None.
    truth : called once after the last image, returns the JSON document written as ``groundtruth.json``.
    initial_pose : the robot's start in the map, or None.
    force : replace an existing sequence folder.
    initial_cov : (3, 3) the start pose's covariance over ``(x, y, theta)`` [m², rad²], or None.

    Everything is written into a temporary folder beside ``out_dir``, checked with :func:`load_sequence`,
    and renamed to ``out_dir`` only then: on any error (or interruption) the temporary folder is removed
    and ``out_dir`` is left as it was.
    """
    stamps = np.asarray(stamps, dtype=float)
    n = len(stamps)
    odometry = np.asarray(odometry, dtype=float)
    pans = None if pans is None else np.asarray(pans, dtype=float)
    if stamps.ndim != 1 or n == 0 or not np.all(np.isfinite(stamps)) or np.any(np.diff(stamps) <= 0):
        raise InputError("stamps: expected (n,) finite, strictly increasing stamps with n >= 1")
    for what, value, shape in (("odometry", odometry, (n, 3)), ("pans", pans, (n,)),
                               ("groundtruth", groundtruth, (n, 3))):
        if value is not None and (np.shape(value) != shape or not np.all(np.isfinite(value))):
            raise InputError(expected(f"finite numbers of shape {shape}", np.shape(value), where=what))
    out = Path(out_dir).resolve()
    _check_target(out, force)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{uuid.uuid4().hex[:8]}.tmp")
    tmp.mkdir()
    try:
        _write_contents(tmp, name, description, camera, world_map, stamps, odometry, pans, images, calibration,
                        groundtruth, truth, initial_pose, initial_cov)
        load_sequence(tmp)
        _install(tmp, out, force)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def _write_contents(tmp: Path, name, description, camera, world_map, stamps, odometry, pans, images,
                    calibration, groundtruth, truth, initial_pose, initial_cov=None) -> None:
    n = len(stamps)
    calib = tmp / "calib"
    if calibration is None:
        save_camera_info_pair(calib, camera)
    else:
        save_calibration(calibration, calib)
    (calib / "mount.yaml").write_text(yaml.safe_dump({"mount": {
        "x": camera.mount_x, "y": camera.mount_y, "height": camera.mount_height,
        "pan_deg": math.degrees(camera.pan)}}, sort_keys=False))
    world_map.save(tmp / "map.yaml")

    for side in ("left", "right"):
        (tmp / side).mkdir()
    count = 0
    for k, pair in enumerate(images):
        if k >= n:
            raise InputError(f"images: expected {n} stereo pairs, one per stamp, got more")
        for side, image in zip(("left", "right"), pair, strict=True):
            image = np.asarray(image)
            if image.shape[:2] != (camera.height, camera.width):
                raise ImageError(expected(f"a {camera.width}×{camera.height} px image like the camera",
                                          f"{image.shape[1]}×{image.shape[0]} px", where=f"{side} image {k}"))
            path = tmp / image_name(side, k)
            if not cv2.imwrite(str(path), image):
                raise ImageError(f"{path}: cannot write image")
        count += 1
    if count != n:
        raise InputError(f"images: expected {n} stereo pairs, one per stamp, got {count}")

    (tmp / "frames.csv").write_text(_csv_text(
        (*_FRAME_COLUMNS, "pan") if pans is not None else _FRAME_COLUMNS,
        ((k, f"{stamps[k]:.9f}", image_name("left", k), image_name("right", k),
          *(() if pans is None else (repr(float(pans[k])),))) for k in range(n))))
    (tmp / "odometry.csv").write_text(_csv_text(
        _ODOMETRY_COLUMNS, ((f"{stamps[k]:.9f}", *(repr(float(v)) for v in odometry[k])) for k in range(n))))

    meta: dict = {"format": FORMAT, "version": VERSION, "name": name}
    if description:
        meta["description"] = description
    meta.update(calibration="calib", mount="calib/mount.yaml", map="map.yaml", frames="frames.csv",
                odometry="odometry.csv")
    if groundtruth is not None:
        write_tum(tmp / "groundtruth.tum", stamps, groundtruth)
        meta["groundtruth"] = "groundtruth.tum"
    if truth is not None:
        (tmp / "groundtruth.json").write_text(json.dumps(truth(), indent=1, allow_nan=False))
        meta["truth"] = "groundtruth.json"
    if initial_pose is not None:
        meta["initial_pose"] = {"x": initial_pose.x, "y": initial_pose.y,
                                "theta_deg": math.degrees(initial_pose.theta)}
    if initial_cov is not None:
        meta["initial_cov"] = [[float(v) for v in row] for row in np.asarray(initial_cov, dtype=float)]
    (tmp / SEQUENCE_FILE).write_text(yaml.safe_dump(meta, sort_keys=False))


class SequenceSource:
    """A recorded sequence folder as a :class:`~stablemarks.frames.FrameSource` (pans as recorded).

    ``start_pose`` (3,) overrides the sequence's ``initial_pose`` (None: the sequence's, which may be None).
    """

    config_defaults: dict = {}

    def __init__(self, sequence: Sequence, start_pose=None):
        self.sequence = sequence
        self.name = sequence.name
        self.camera = sequence.camera
        self.world_map = sequence.world_map
        if start_pose is None and sequence.initial_pose is not None:
            start_pose = sequence.initial_pose.as_array()
        self.initial_pose = None if start_pose is None else np.asarray(start_pose, dtype=float)
        self.initial_cov = sequence.initial_cov
        self.notes: list[str] = []
        self.pan_recorded = sequence.pan_recorded

    def __len__(self) -> int:
        return len(self.sequence)

    def __iter__(self) -> Iterator[Frame]:
        seq = self.sequence
        for k in range(len(seq)):
            left, right = seq.frame(k)
            yield Frame(k, float(seq.stamps[k]), left, right, np.asarray(seq.odometry[k], dtype=float),
                        float(seq.pans[k]), true_pose=self.true_pose(k))

    def true_pose(self, k: int) -> np.ndarray | None:
        """(3,) the true pose of frame ``k`` in the map, or None."""
        gt = self.sequence.groundtruth
        return None if gt is None else np.asarray(gt[k], dtype=float)

    def close(self) -> None:
        """Nothing to release."""
