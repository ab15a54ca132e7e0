"""Opening recorded runs as frame sources (:class:`~stablemarks.frames.FrameSource`): :func:`open_sequence`.

A source gives the camera, the map, the start pose when it knows one, and per frame the stamp, the rectified
stereo pair, the wheel-odometry pose and the head's pan. :func:`open_sequence` recognises what a path holds:

==========================  ===============================================================  =========================
what                        recognised by                                                    module
==========================  ===============================================================  =========================
our sequence folder         a folder with ``sequence.yaml``                                  :mod:`.sequence`
ROS 1 / ROS 2 bag           a ``.bag``, ``.mcap`` or ``.db3`` file, or a folder with         :mod:`.bags`
                            ``metadata.yaml``
KITTI odometry sequence     a folder with ``calib.txt``, ``times.txt`` and ``image_0/``      :mod:`.datasets`
EuRoC MAV sequence          a folder with ``mav0/`` (or the ``mav0`` folder itself)          :mod:`.datasets`
==========================  ===============================================================  =========================

A bag or a dataset folder carries no map of walls: it comes from the argument ``map``. A bag's calibration,
mount, start pose and ground truth come from its own topics (``sensor_msgs/CameraInfo``, ``/tf_static`` and
``/tf``, ``/initialpose``, ``groundtruth_topic``) unless the arguments ``calib``, ``mount`` and
``start_pose`` give them. Everything is read and cross-checked when the source is
opened, including the first stereo pair against the calibration, so a broken input fails before the run.

What bags and dataset folders share lives in :mod:`.recorded`; this module only recognises a path and
opens it (it imports the readers; none of them imports it).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from ..errors import InputError, SequenceError, expected
from ..maps import COORDINATE_LIMIT
from .bags import BASE_FRAME, open_bag
from .datasets import open_euroc, open_kitti
from .recorded import (  # noqa: F401  (re-exported: what bags and datasets share)
    BAG_SUFFIXES,
    SYNC_TOLERANCE,
    RecordedSource,
    check_stamps,
    frames_with_odometry,
    load_mount_near,
    load_stereo_calibration,
    load_world_map,
    match_stamps,
    poses_at,
    read_odometry_csv,
    yaw_of_quaternion,
)
from .sequence import SEQUENCE_FILE, SequenceSource, load_sequence

MAX_TOLERANCE = 60.0
"""Largest stamp tolerance [s] :func:`open_sequence` takes (pairing and odometry)."""


def _start_pose(pose):
    """A start pose (3,): finite, within ±:data:`~stablemarks.maps.COORDINATE_LIMIT` (metres and radians)."""
    import numpy as np

    try:
        X = np.asarray(pose, dtype=float).reshape(3)
    except (TypeError, ValueError):
        raise InputError(expected("a pose (x, y, theta)", pose, where="start_pose")) from None
    if not (np.all(np.isfinite(X)) and np.all(np.abs(X) <= COORDINATE_LIMIT)):
        raise InputError(expected(f"a finite pose within ±{COORDINATE_LIMIT:g}", X.tolist(), where="start_pose"))
    return X


# ------------------------------------------------------------------ dispatch
def _kind(p: Path) -> str | None:
    """What a path holds: "sequence", "bag", "kitti", "euroc" or None."""
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


def open_sequence(
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
    left_info_topic: str | None = None,
    right_info_topic: str | None = None,
    base_frame: str | None = None,
    groundtruth_topic: str | None = None,
):
    """Open a recorded run as a :class:`~stablemarks.frames.FrameSource` (kinds in the module docstring):
    anything ``stablemarks run`` accepts, with its options as keyword arguments.

    Parameters
    ----------
    path : the sequence folder, bag file or folder, or dataset folder.
    left_topic, right_topic, odom_topic : a bag's image topics (``sensor_msgs/Image`` or
        ``sensor_msgs/CompressedImage``) and odometry topic (``nav_msgs/Odometry``); bags only, required.
    pan_topic, pan_joint : a bag's head-pan topic (``std_msgs/Float64`` or ``sensor_msgs/JointState`` with
        the joint ``pan_joint``); without it every frame has the mount's pan.
    calib : calibration folder (``left.yaml``/``right.yaml``) or OpenCV file; bags (which otherwise read
        their ``sensor_msgs/CameraInfo`` topics) and EuRoC (which otherwise computes it from its
        ``sensor.yaml`` files).
    map : the map of walls (any format :func:`~stablemarks.io.mapfiles.load_any_map` reads); required for
        bags and datasets, replaces a sequence folder's own map.
    mount : the mount file; default ``mount.yaml`` beside the calibration (KITTI: 1.65 m high; a bag without
        either: its tf from ``base_frame`` to the left image's frame).
    odometry : an odometry CSV (module docstring) for a dataset folder; default ``odometry.csv`` in it.
    tolerance : largest stamp difference [s] within a stereo pair and to the nearest odometry pose outside
        the odometry's time span.
    start_pose : (3,) the robot's start in the map (the source's ``initial_pose``); default the sequence's
        ``initial_pose`` (None when it has none), for a bag the last ``/initialpose`` before the first frame
        (its covariance becomes the source's ``initial_cov``), else the first odometry pose.
    left_info_topic, right_info_topic : a bag's ``sensor_msgs/CameraInfo`` topics; default the
        ``camera_info`` beside each image topic. Not read when ``calib`` is given.
    base_frame : a bag's robot frame for the tf mount (default ``base_link``; its origin on the floor).
    groundtruth_topic : a bag's true poses (``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or
        ``PoseWithCovarianceStamped``), interpolated at the frames (the source's ``groundtruth``).

    Raises :class:`~stablemarks.errors.InputError` (a :class:`SequenceError` for the recording itself) naming
    what is missing or wrong, and the options that do not apply to what ``path`` holds.
    """
    p = Path(path)
    if not p.exists():
        raise SequenceError(f"{p}: no such file or folder")
    if not (math.isfinite(tolerance) and tolerance >= 0):
        raise InputError(expected("a non-negative time [s]", tolerance, where="tolerance"))
    if tolerance > MAX_TOLERANCE:
        raise InputError(expected(f"a time of at most {MAX_TOLERANCE:g} s", tolerance, where="tolerance"))
    if start_pose is not None:
        start_pose = _start_pose(start_pose)
    kind = _kind(p)
    given = {"left_topic": left_topic, "right_topic": right_topic, "odom_topic": odom_topic,
             "pan_topic": pan_topic, "pan_joint": pan_joint, "calib": calib, "map": map,
             "mount": mount, "odometry": odometry, "left_info_topic": left_info_topic,
             "right_info_topic": right_info_topic, "base_frame": base_frame, "groundtruth_topic": groundtruth_topic}
    allowed = {
        "sequence": {"map"},
        "bag": {"left_topic", "right_topic", "odom_topic", "pan_topic", "pan_joint", "calib", "map", "mount",
                "left_info_topic", "right_info_topic", "base_frame", "groundtruth_topic"},
        "kitti": {"map", "mount", "odometry"},
        "euroc": {"calib", "map", "mount", "odometry"},
    }
    if kind is not None:
        unused = [k for k, v in given.items() if v is not None and k not in allowed[kind]]
        if unused:
            what = {"sequence": "a sequence folder", "bag": "a bag", "kitti": "a KITTI folder",
                    "euroc": "a EuRoC folder"}[kind]
            takes = ", ".join(f"`{k}`" for k in sorted(allowed[kind]))
            raise InputError(f"{p}: `{unused[0]}` does not apply to {what} (it takes {takes})")
    if kind == "sequence":
        sequence = load_sequence(p)
        if map is not None:
            sequence = replace(sequence, world_map=load_world_map(map, str(p)))
        return SequenceSource(sequence, start_pose=start_pose)
    if kind == "bag":
        return open_bag(p, left_topic=left_topic, right_topic=right_topic, odom_topic=odom_topic,
                        pan_topic=pan_topic, pan_joint=pan_joint, calib=calib, map=map, mount=mount,
                        tolerance=tolerance, start_pose=start_pose, left_info_topic=left_info_topic,
                        right_info_topic=right_info_topic, base_frame=base_frame or BASE_FRAME,
                        groundtruth_topic=groundtruth_topic)
    if kind == "kitti":
        return open_kitti(p, map=map, mount=mount, odometry=odometry, tolerance=tolerance, start_pose=start_pose)
    if kind == "euroc":
        return open_euroc(p, calib=calib, map=map, mount=mount, odometry=odometry, tolerance=tolerance,
                          start_pose=start_pose)
    raise SequenceError(
        f"{p}: not a recording stablemarks reads: expected a sequence folder (sequence.yaml), a bag "
        f"({', '.join(BAG_SUFFIXES)} file, or a ROS 2 bag folder with metadata.yaml), a KITTI odometry folder "
        "(calib.txt, times.txt, image_0/, image_1/) or a EuRoC MAV folder (mav0/)"
    )




open_source = open_sequence
"""The former name of :func:`open_sequence`."""
