"""Opening recorded runs as frame sources for the on-line loop (:func:`stablemarks.online.run_online`).

A source gives the camera, the map, the start pose, and per frame the stamp, the odometry increment with
its covariance, the head's pan and the rectified stereo pair (the protocol of
:class:`stablemarks.online.SequenceSource`). :func:`open_source` recognises what a path holds:

==========================  ===============================================================  =========================
what                        recognised by                                                    module
==========================  ===============================================================  =========================
our sequence folder         a folder with ``sequence.yaml``                                  :mod:`.sequence`
ROS 1 / ROS 2 bag           a ``.bag``, ``.mcap`` or ``.db3`` file, or a folder with         :mod:`.bags`
                            ``metadata.yaml``
KITTI odometry sequence     a folder with ``calib.txt``, ``times.txt`` and ``image_0/``      :mod:`.datasets`
EuRoC MAV sequence          a folder with ``mav0/`` (or the ``mav0`` folder itself)          :mod:`.datasets`
==========================  ===============================================================  =========================

A bag or a dataset folder carries no map of walls, and a bag no calibration: they come from the command
line (``--map``, ``--calib``, ``--camera``). Everything is read and cross-checked when the source is
opened, including the first stereo pair against the calibration, so a broken input fails before the run.

:class:`RecordedSource` is what bags and datasets share: frames at stamps, wheel-odometry poses resampled
at these stamps (:func:`poses_at`), pans, and images decoded on demand by the subclass
(:meth:`RecordedSource.raw_pair`), converted to 8-bit gray and rectified here.

Odometry CSV (our ``odometry.csv``, at any stamps, e.g. a ``nav_msgs/Odometry`` topic exported)::

    stamp,x,y,theta
    1403636579.763555527,0.0,0.0,0.0

``stamp`` [s] strictly increasing; ``x, y`` [m], ``theta`` [rad] the robot's pose in the odometry frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import ImageError, InputError, SequenceError, expected
from ..geometry import SE2, StereoCamera
from ..maps import Map
from .calibration import Mount, StereoCalibration, load_calibration, load_mount
from .images import to_gray8

BAG_SUFFIXES = (".bag", ".mcap", ".db3")
"""Suffixes of bag files :func:`open_source` reads (ROS 1, ROS 2 MCAP, ROS 2 sqlite3)."""

SYNC_TOLERANCE = 0.005
"""Default largest stamp difference [s] between the left and right image of a pair, and between a frame
and the nearest odometry pose when it falls outside the odometry's time span."""

_ODOMETRY_COLUMNS = ("stamp", "x", "y", "theta")


# ------------------------------------------------------------------ stamps and poses
def check_stamps(stamps, where: str) -> None:
    """Raise :class:`SequenceError` unless ``stamps`` (n,) increase strictly; ``where`` names the stream.

    The message tells a duplicate from an out-of-order stamp and gives the message numbers (from 0).
    """
    t = np.asarray(stamps)
    d = np.diff(t)
    bad = np.flatnonzero(d <= 0)
    if not len(bad):
        return
    i = int(bad[0])
    what = "duplicate timestamp" if d[i] == 0 else "timestamps out of order"
    raise SequenceError(f"{where}: {what}: message {i + 1} is stamped {_seconds(t[i + 1])} after message {i} "
                        f"stamped {_seconds(t[i])} (expected strictly increasing stamps)")


def _seconds(t) -> str:
    """A stamp for messages: integer nanoseconds or float seconds, shown in seconds."""
    return f"{int(t) / 1e9:.9f} s" if isinstance(t, int | np.integer) else f"{float(t):.9f} s"


def match_stamps(t_left, t_right, tolerance) -> np.ndarray:
    """Stereo pairs ``(M, 2)`` of indices ``(i, j)``: ``t_left[i]`` and ``t_right[j]`` are each other's
    nearest stamp and differ by at most ``tolerance`` (same unit as the stamps).

    Both stamp arrays must increase strictly; mutual nearest neighbours are one to one and keep the order.
    """
    tl = np.asarray(t_left)
    tr = np.asarray(t_right)
    if len(tl) == 0 or len(tr) == 0:
        return np.zeros((0, 2), dtype=int)

    def nearest(a, b):
        j = np.clip(np.searchsorted(b, a), 1, len(b) - 1) if len(b) > 1 else np.zeros(len(a), dtype=int)
        if len(b) > 1:
            j = np.where(np.abs(b[j - 1] - a) <= np.abs(b[j] - a), j - 1, j)
        return j

    j = nearest(tl, tr)
    back = nearest(tr, tl)
    i = np.arange(len(tl))
    ok = (back[j] == i) & (np.abs(tr[j] - tl) <= tolerance)
    return np.column_stack([i[ok], j[ok]]).astype(int)


def poses_at(t_src, poses_src, stamps, tolerance: float = SYNC_TOLERANCE) -> np.ndarray:
    """Poses ``(n, 3)`` ``(x [m], y [m], theta [rad])`` at ``stamps`` (n,) [s] from poses at ``t_src`` (m,).

    Linear interpolation inside the span of ``t_src`` (heading on the shortest arc); outside it the
    nearest end pose when it is within ``tolerance`` [s], else a row of NaN.
    """
    from .sequence import _interpolate_poses

    t_src = np.asarray(t_src, dtype=float)
    poses_src = np.asarray(poses_src, dtype=float)
    stamps = np.asarray(stamps, dtype=float)
    out = _interpolate_poses(t_src, poses_src, stamps)
    for end in (0, -1):
        near = np.isnan(out[:, 0]) & (np.abs(stamps - t_src[end]) <= tolerance)
        out[near] = poses_src[end]
    return out


def yaw_of_quaternion(qx, qy, qz, qw):
    """Heading [rad] about ``z`` of unit quaternions (Hamilton, any tilt): ``atan2(2(w z + x y), 1 − 2(y² + z²))``."""
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def read_odometry_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an odometry CSV (format in the module docstring): ``(stamps (n,) [s], poses (n, 3))``.

    Errors (:class:`SequenceError`) name the file and line; stamps must increase strictly.
    """
    from .sequence import _number, _read_csv

    path = Path(path)
    if not path.is_file():
        raise SequenceError(f"{path}: no such odometry file (columns {','.join(_ODOMETRY_COLUMNS)})")
    rows = _read_csv(path, "odometry file", _ODOMETRY_COLUMNS)
    values = np.array([[_number(row[c], f"{path} line {line}: {c}") for c in _ODOMETRY_COLUMNS]
                       for line, row in rows])
    check_stamps(values[:, 0], str(path))
    return values[:, 0], values[:, 1:]


# ------------------------------------------------------------------ inputs from the command line
def load_world_map(path: str | Path | None, what: str) -> Map:
    """The map of walls from ``path`` (any map file :func:`stablemarks.io.mapfiles.load_any_map` reads);
    ``what`` names the recording in the error when no map is given."""
    if path is None:
        raise InputError(f"{what} carries no map of walls: pass --map MAP (our map YAML, a ROS map_server "
                         "map.yaml or GeoJSON walls)")
    from .mapfiles import load_any_map

    return load_any_map(path)


def load_mount_near(mount: str | Path | None, calib: str | Path | None, default: Mount | None = None,
                    what: str = "the recording") -> Mount:
    """The camera mount: the file ``mount`` (``--camera``), else ``mount.yaml`` beside the calibration (in
    the calibration folder or beside an OpenCV file), else ``default``; with none of them an error."""
    if mount is not None:
        return load_mount(mount)
    if calib is not None:
        c = Path(calib)
        beside = (c if c.is_dir() else c.parent) / "mount.yaml"
        if beside.is_file():
            return load_mount(beside)
    if default is not None:
        return default
    raise InputError(f"no camera mount for {what}: pass --camera MOUNT.yaml (mount: {{x, y, height, pan_deg}}: "
                     "where the stereo head sits on the robot; its height above the floor matters)")


# ------------------------------------------------------------------ the shared source
class RecordedSource:
    """Frames of a recording at ``stamps`` with odometry poses resampled at them; pixels on demand.

    Parameters
    ----------
    name : the recording's name (default output folder ``results/<name>``).
    calibration : the raw images' calibration; images are rectified through it unless already rectified.
    camera : the rectified :class:`StereoCamera` on its mount.
    world_map : the map of walls.
    stamps : (n,) frame times [s], strictly increasing.
    odometry : (n, 3) wheel-odometry poses ``(x [m], y [m], theta [rad])`` at the frame stamps.
    pans : (n,) head pan of each frame relative to the robot's heading [rad].
    start_pose : (3,) the robot's start in the map; default the first odometry pose (the odometry frame
        taken as the map frame).
    noise : the odometry noise model (default :class:`~stablemarks.motion.OdometryNoise`).
    groundtruth : (n, 3) true poses at the frame stamps (NaN where unknown), or None.
    notes : sentences for the user about what was left out (frames without odometry, unmatched images).

    Subclasses implement :meth:`raw_pair`; :meth:`close` releases open files.
    """

    recorded_pan = True

    def __init__(self, name: str, calibration: StereoCalibration, camera: StereoCamera, world_map: Map,
                 stamps, odometry, pans, *, start_pose=None, noise=None, groundtruth=None,
                 notes: Sequence[str] = ()):
        from ..motion import OdometryNoise

        self.name = name
        self.calibration = calibration
        self.camera = camera
        self.world_map = world_map
        self.stamps = np.asarray(stamps, dtype=float)
        self.odometry_poses = np.asarray(odometry, dtype=float)
        self.pans = np.asarray(pans, dtype=float)
        n = len(self.stamps)
        if n == 0:
            raise SequenceError(f"{name}: no frames")
        if self.odometry_poses.shape != (n, 3) or self.pans.shape != (n,):
            raise InputError(expected(f"odometry ({n}, 3) and pans ({n},)",
                                      (self.odometry_poses.shape, self.pans.shape), where=name))
        check_stamps(self.stamps, f"{name}: frames")
        self.noise = noise or OdometryNoise()
        self.start_pose = self.odometry_poses[0].copy() if start_pose is None else np.asarray(start_pose, float)
        self.groundtruth = None if groundtruth is None else np.asarray(groundtruth, dtype=float)
        self.notes = list(notes)

    # -- the source protocol
    def __len__(self) -> int:
        return len(self.stamps)

    def stamp(self, k: int) -> float:
        return float(self.stamps[k])

    def odometry(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Increment ``T_{k-1}⁻¹ T_k`` (3,) in the robot frame of frame ``k − 1`` and its covariance (3, 3)."""
        if k == 0:
            U = SE2()
        else:
            U = SE2.from_array(self.odometry_poses[k - 1]).between(SE2.from_array(self.odometry_poses[k]))
        return U.as_array(), self.noise.covariance(U)

    def pan(self, k: int, X_belief, previous) -> float:
        return float(self.pans[k])

    def images(self, k: int, pan: float):
        """The rectified pair ``(left, right)``, (H, W) ``uint8`` each, and no truth."""
        left, right = self.raw_pair(k)
        where = self.frame_name(k)
        left, right = to_gray8(left, f"{where} left"), to_gray8(right, f"{where} right")
        w, h = self.calibration.image_size
        for side, img in (("left", left), ("right", right)):
            if img.shape != (h, w):
                cal = f"calibration {self.calibration.source}" if self.calibration.source else "calibration"
                raise ImageError(f"{where}: {side} image is {img.shape[1]}×{img.shape[0]} px but the {cal} is for "
                                 f"{w}×{h} px")
        if self.calibration.is_rectified:
            return left, right, None
        left, right = self.calibration.rectify(left, right)
        return left, right, None

    def true_pose(self, k: int) -> np.ndarray | None:
        if self.groundtruth is None or np.isnan(self.groundtruth[k, 0]):
            return None
        return self.groundtruth[k].copy()

    # -- for subclasses
    def raw_pair(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The raw images ``(left, right)`` of frame ``k`` as recorded, (H, W[, C]) any depth."""
        raise NotImplementedError

    def frame_name(self, k: int) -> str:
        """How messages name frame ``k``."""
        return f"{self.name} frame {k} (stamp {self.stamps[k]:.9f} s)"

    def close(self) -> None:
        """Release open files (nothing here)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def frames_with_odometry(stamps, t_odom, poses_odom, tolerance: float, what: str):
    """Keep the frames whose stamp the odometry covers: ``(keep (n,) bool, poses (n_kept, 3), notes)``.

    Frames before the first or after the last odometry pose (beyond ``tolerance`` [s]) are left out with
    a note; none left is a :class:`SequenceError` naming both time spans.
    """
    stamps = np.asarray(stamps, dtype=float)
    poses = poses_at(t_odom, poses_odom, stamps, tolerance)
    keep = ~np.isnan(poses[:, 0])
    notes = []
    if not keep.any():
        raise SequenceError(f"{what}: no frame within the odometry's time span: frames {stamps[0]:.3f} to "
                            f"{stamps[-1]:.3f} s, odometry {t_odom[0]:.3f} to {t_odom[-1]:.3f} s")
    if not keep.all():
        notes.append(f"{int((~keep).sum())} of {len(stamps)} frames left out: outside the odometry's time span "
                     f"({t_odom[0]:.3f} to {t_odom[-1]:.3f} s)")
    return keep, poses[keep], notes


# ------------------------------------------------------------------ dispatch
def _kind(p: Path) -> str | None:
    """What a path holds: "sequence", "bag", "kitti", "euroc" or None."""
    from .sequence import SEQUENCE_FILE

    if p.is_file():
        return "bag" if p.suffix.lower() in BAG_SUFFIXES else None
    if (p / SEQUENCE_FILE).is_file():
        return "sequence"
    if (p / "metadata.yaml").is_file():
        return "bag"
    if (p / "calib.txt").is_file() and (p / "times.txt").is_file() and (p / "image_0").is_dir():
        return "kitti"
    if (p / "mav0").is_dir() or (p.name == "mav0" and (p / "cam0").is_dir()):
        return "euroc"
    return None


def open_source(
    path: str | Path,
    *,
    left_topic: str | None = None,
    right_topic: str | None = None,
    odom_topic: str | None = None,
    pan_topic: str | None = None,
    pan_joint: str | None = None,
    calib: str | Path | None = None,
    map: str | Path | None = None,
    mount: str | Path | None = None,
    odometry: str | Path | None = None,
    tolerance: float = SYNC_TOLERANCE,
    start_pose=None,
    noise=None,
):
    """Open a recorded run as a source for :func:`~stablemarks.online.run_online` (kinds in the module docstring).

    Parameters
    ----------
    path : the sequence folder, bag file or folder, or dataset folder.
    left_topic, right_topic, odom_topic : a bag's image topics (``sensor_msgs/Image`` or
        ``sensor_msgs/CompressedImage``) and odometry topic (``nav_msgs/Odometry``); bags only, required.
    pan_topic, pan_joint : a bag's head-pan topic (``std_msgs/Float64`` or ``sensor_msgs/JointState`` with
        the joint ``pan_joint``); without it every frame has the mount's pan.
    calib : calibration folder (``left.yaml``/``right.yaml``) or OpenCV file; bags and EuRoC (which
        otherwise computes it from its ``sensor.yaml`` files).
    map : the map of walls (any format :func:`~stablemarks.io.mapfiles.load_any_map` reads); required for
        bags and datasets, replaces a sequence folder's own map.
    mount : the mount file (``--camera``); default ``mount.yaml`` beside the calibration (KITTI: 1.65 m high).
    odometry : an odometry CSV (module docstring) for a dataset folder; default ``odometry.csv`` in it.
    tolerance : largest stamp difference [s] within a stereo pair and to the nearest odometry pose outside
        the odometry's time span.
    start_pose : (3,) the robot's start in the map; default the sequence's ``initial_pose`` or, for bags and
        datasets, the first odometry pose.
    noise : the odometry noise model (:class:`~stablemarks.motion.OdometryNoise`).

    Raises :class:`~stablemarks.errors.InputError` (a :class:`SequenceError` for the recording itself) naming
    what is missing or wrong, and the options that do not apply to what ``path`` holds.
    """
    p = Path(path)
    if not p.exists():
        raise SequenceError(f"{p}: no such file or folder")
    if not (math.isfinite(tolerance) and tolerance >= 0):
        raise InputError(expected("a non-negative time [s]", tolerance, where="tolerance"))
    kind = _kind(p)
    given = {"--left-topic": left_topic, "--right-topic": right_topic, "--odom-topic": odom_topic,
             "--pan-topic": pan_topic, "--pan-joint": pan_joint, "--calib": calib, "--map": map,
             "--camera": mount, "--odometry": odometry}
    allowed = {
        "sequence": {"--map"},
        "bag": {"--left-topic", "--right-topic", "--odom-topic", "--pan-topic", "--pan-joint", "--calib", "--map",
                "--camera"},
        "kitti": {"--map", "--camera", "--odometry"},
        "euroc": {"--calib", "--map", "--camera", "--odometry"},
    }
    if kind is not None:
        unused = [k for k, v in given.items() if v is not None and k not in allowed[kind]]
        if unused:
            what = {"sequence": "a sequence folder", "bag": "a bag", "kitti": "a KITTI folder",
                    "euroc": "a EuRoC folder"}[kind]
            raise InputError(f"{p}: {unused[0]} does not apply to {what} (it takes "
                             f"{', '.join(sorted(allowed[kind])) or 'none of them'})")
    if kind == "sequence":
        from ..online import SequenceSource
        from .sequence import load_sequence

        sequence = load_sequence(p)
        if map is not None:
            sequence = replace(sequence, world_map=load_world_map(map, str(p)))
        return SequenceSource(sequence, noise=noise, start_pose=start_pose)
    if kind == "bag":
        from .bags import open_bag

        return open_bag(p, left_topic=left_topic, right_topic=right_topic, odom_topic=odom_topic,
                        pan_topic=pan_topic, pan_joint=pan_joint, calib=calib, map=map, mount=mount,
                        tolerance=tolerance, start_pose=start_pose, noise=noise)
    if kind == "kitti":
        from .datasets import open_kitti

        return open_kitti(p, map=map, mount=mount, odometry=odometry, tolerance=tolerance,
                          start_pose=start_pose, noise=noise)
    if kind == "euroc":
        from .datasets import open_euroc

        return open_euroc(p, calib=calib, map=map, mount=mount, odometry=odometry, tolerance=tolerance,
                          start_pose=start_pose, noise=noise)
    raise SequenceError(
        f"{p}: not a recording stablemarks reads: expected a sequence folder (sequence.yaml), a bag "
        f"({', '.join(BAG_SUFFIXES)} file, or a ROS 2 bag folder with metadata.yaml), a KITTI odometry folder "
        "(calib.txt, times.txt, image_0/, image_1/) or a EuRoC MAV folder (mav0/)"
    )


def load_stereo_calibration(calib: str | Path | None, what: str) -> StereoCalibration:
    """The calibration ``--calib`` (folder with left.yaml/right.yaml, or an OpenCV file); required."""
    if calib is None:
        raise InputError(f"{what} carries no calibration: pass --calib DIR (left.yaml and right.yaml, ROS "
                         "camera_info) or --calib FILE (OpenCV stereo calibration)")
    return load_calibration(calib)

