"""What recorded runs share: stamps, odometry resampled at the frames, and :class:`RecordedSource`.

Bags (:mod:`.bags`) and dataset folders (:mod:`.datasets`) are frames at stamps with wheel-odometry poses
resampled at these stamps (:func:`poses_at`), pans, and images decoded on demand by the subclass
(:meth:`RecordedSource.raw_pair`), converted to 8-bit gray and rectified here. Each is a
:class:`~stablemarks.frames.FrameSource`.

Odometry CSV (our ``odometry.csv``, at any stamps, e.g. a ``nav_msgs/Odometry`` topic exported)::

    stamp,x,y,theta
    1403636579.763555527,0.0,0.0,0.0

``stamp`` [s] strictly increasing; ``x, y`` [m], ``theta`` [rad] the robot's pose in the odometry frame.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from ..errors import ConfigError, ImageError, InputError, SequenceError, expected
from ..frames import Frame
from ..geometry import StereoCamera
from ..maps import COORDINATE_LIMIT, STAMP_LIMIT, Map
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
    values = np.array([[_number(row[c], f"{path} line {line}: {c}", STAMP_LIMIT if c == "stamp" else COORDINATE_LIMIT)
                        for c in _ODOMETRY_COLUMNS] for line, row in rows])
    check_stamps(values[:, 0], str(path))
    return values[:, 0], values[:, 1:]


# ------------------------------------------------------------------ inputs from the command line
def load_world_map(path: str | Path | None, what: str) -> Map:
    """The map of walls from ``path`` (any map file :func:`stablemarks.io.mapfiles.load_any_map` reads), with
    at least one wall; ``what`` names the recording in the error when no map is given."""
    if path is None:
        raise InputError(f"{what} carries no map of walls: pass `map` (our map YAML, a ROS map_server "
                         "map.yaml or GeoJSON walls)")
    from .mapfiles import load_any_map

    try:
        world_map = load_any_map(path)
    except RecursionError:  # a JSON file nested thousands of levels deep
        raise ConfigError(f"{path}: nested too deeply to be a map file") from None
    if not len(world_map):
        raise InputError(f"{path}: no walls: the map must hold at least one wall")
    return world_map


def load_mount_near(mount: str | Path | None, calib: str | Path | None, default: Mount | None = None,
                    what: str = "the recording") -> Mount:
    """The camera mount: the file ``mount``, else ``mount.yaml`` beside the calibration (in
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
    raise InputError(f"no camera mount for {what}: pass `mount` (a mount.yaml, mount: {{x, y, height, pan_deg}}: "
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
    start_pose : (3,) the robot's start in the map (its :attr:`initial_pose`); default the first odometry
        pose (the odometry frame taken as the map frame).
    groundtruth : (n, 3) true poses at the frame stamps (NaN where unknown), or None.
    start_cov : (3, 3) covariance of ``start_pose`` over x [m], y [m], yaw [rad] when the recording gives one
        (its :attr:`initial_cov`; None: the caller's default).
    notes : sentences for the user about what was left out (frames without odometry, unmatched images).
    pan_recorded : whether ``pans`` were recorded per frame (a pan topic, a moving joint on /tf); False: every
        frame has the mount's pan (a head that cannot move, or one whose pan the recording does not give).
    sources : where each input came from, ``{what: where}`` (e.g. ``{"calibration": "camera_info
        /cam/left/camera_info, /cam/right/camera_info"}``), for the run's ``config.yaml``.

    Subclasses implement :meth:`raw_pair`; :meth:`close` releases open files.
    """

    config_defaults: dict = {}

    def __init__(self, name: str, calibration: StereoCalibration, camera: StereoCamera, world_map: Map,
                 stamps, odometry, pans, *, start_pose=None, groundtruth=None, start_cov=None,
                 notes: Sequence[str] = (), sources: dict[str, str] | None = None, pan_recorded: bool = True):
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
        self.initial_pose = self.odometry_poses[0].copy() if start_pose is None else np.asarray(start_pose, float)
        self.groundtruth = None if groundtruth is None else np.asarray(groundtruth, dtype=float)
        if self.groundtruth is not None and self.groundtruth.shape != (n, 3):
            raise InputError(expected(f"ground truth ({n}, 3)", self.groundtruth.shape, where=name))
        self.initial_cov = None if start_cov is None else np.asarray(start_cov, dtype=float)
        if self.initial_cov is not None and self.initial_cov.shape != (3, 3):
            raise InputError(expected("a (3, 3) start covariance", self.initial_cov.shape, where=name))
        self.notes = list(notes)
        self.sources = dict(sources or {})
        self.pan_recorded = bool(pan_recorded)

    # -- the FrameSource protocol
    def __len__(self) -> int:
        return len(self.stamps)

    def __iter__(self) -> Iterator[Frame]:
        for k in range(len(self)):
            left, right = self.pair(k)
            yield Frame(k, float(self.stamps[k]), left, right, self.odometry_poses[k].copy(), float(self.pans[k]),
                        true_pose=self.true_pose(k))

    def pair(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The rectified pair ``(left, right)`` of frame ``k``, (H, W) ``uint8`` each."""
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
            return left, right
        return self.calibration.rectify(left, right)

    def true_pose(self, k: int) -> np.ndarray | None:
        """(3,) the true pose of frame ``k`` in the map, or None."""
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


def load_stereo_calibration(calib: str | Path | None, what: str) -> StereoCalibration:
    """The calibration ``--calib`` (folder with left.yaml/right.yaml, or an OpenCV file); required."""
    if calib is None:
        raise InputError(f"{what} carries no calibration: pass `calib`: a folder with left.yaml and "
                         "right.yaml (ROS camera_info) or an OpenCV stereo calibration file")
    return load_calibration(calib)


def config_sources_text(sources: dict[str, str]) -> str:
    """``sources`` as YAML comment lines for the top of a run's ``config.yaml``: ``# sources:`` then
    ``#   what: where``. Comments, so the file still loads with ``--config`` (a configuration has no such
    section); without the leading ``# `` the block is YAML. Empty for no sources."""
    if not sources:
        return ""
    import yaml

    text = yaml.safe_dump({"sources": {str(k): str(v) for k, v in sources.items()}}, sort_keys=False,
                          allow_unicode=True, width=1000)
    return "".join(f"# {line}\n" for line in text.splitlines())


def note_sources(config_path: str | Path | None, sources: dict[str, str]) -> None:
    """Put :func:`config_sources_text` at the top of a run's ``config.yaml`` (nothing when either is missing)."""
    if config_path is None or not sources or not Path(config_path).is_file():
        return
    path = Path(config_path)
    tmp = path.with_name(f".{path.name}.sources.tmp")
    tmp.write_text(config_sources_text(sources) + path.read_text())
    tmp.replace(path)
