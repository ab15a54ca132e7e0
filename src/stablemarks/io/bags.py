"""Recorded ROS bags as frame sources: ROS 1 (``.bag``) and ROS 2 (sqlite3 ``.db3`` or MCAP), through
the ``rosbags`` package (``pip install 'stablemarks[ros]'``; no ROS installation needed).

Topics, named on the command line:

- left and right images (``--left-topic``, ``--right-topic``): ``sensor_msgs/Image`` (encodings
  ``mono8``, ``mono16``, ``bgr8``, ``rgb8``, ``bgra8``, ``rgba8``, ``8UC1``, ``16UC1``, ``8UC3``, ``8UC4``)
  or ``sensor_msgs/CompressedImage`` (any format OpenCV decodes: JPEG, PNG, …), raw or rectified as the
  calibration says;
- wheel odometry (``--odom-topic``): ``nav_msgs/Odometry``; its pose gives ``x``, ``y`` and the yaw;
- optionally the head's pan (``--pan-topic``): ``std_msgs/Float64`` [rad] (stamped by its bag time) or
  ``sensor_msgs/JointState`` (the joint ``--pan-joint``, or its only joint); without it every frame has
  the mount's pan (or the tf's, below);
- optionally the true poses (``--groundtruth-topic``): ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped``
  or ``PoseWithCovarianceStamped``, interpolated at the frame stamps (the source's ``groundtruth``).

What a robot's bag carries beside them replaces the files, unless they are given:

- the calibration (``--calib``): the ``sensor_msgs/CameraInfo`` beside each image topic (``/ns/left/image_raw``
  → ``/ns/left/camera_info``; a compressed image's ``/compressed`` dropped first) or ``--left-info-topic`` and
  ``--right-info-topic``: width, height, ``K``, ``D``, ``R``, ``P`` and the distortion model, checked and
  assembled as a camera_info file pair is (:mod:`.calibration`); the right ``P[0,3] = −f·B``. Images on
  ``image_rect*`` topics are taken as rectified (their camera is ``P``'s), others as raw. The first message of
  each topic is used;
- the mount (``--camera``, or ``mount.yaml`` beside ``--calib``): the tf transform from ``--base-frame``
  (default ``base_link``, its origin on the floor) to the left image's ``header.frame_id``, an optical frame
  (REP-103: z forward, x right, y down), chained through ``/tf_static`` and ``/tf``: its position gives
  ``x, y, height``, the heading of its z axis the pan. The head must be level (within 2°). When a transform
  of the chain moves (a pan joint on ``/tf``), each frame's pan is read from it (unless ``--pan-topic``);
- the start pose (``--pose``): the last ``/initialpose`` (``geometry_msgs/PoseWithCovarianceStamped``, in
  the map) stamped before the first frame, moved by the odometry from its stamp to the first frame when
  the odometry reaches back that far; its x, y, yaw covariance is the source's ``initial_cov`` (unless all
  zero). Without it, the first odometry pose.

:attr:`BagSource.sources` tells where each came from.

Stereo pairs are matched by header stamp: a left and a right image that are each other's nearest within
the tolerance (default 5 ms) form a frame, stamped by the left image. The odometry poses and pans are
interpolated linearly at the frame stamps (heading on the shortest arc); frames before the first or after
the last odometry message (beyond the tolerance) are left out, with a note. Each stream's header stamps
must increase strictly in the bag; a duplicate or out-of-order stamp is an error naming the topic.

Opening a bag reads it once to index the messages (bag time and header stamp of every image); the
images are decoded only when the loop asks for a frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np

from ..errors import ImageError, InputError, SequenceError, expected
from ..geometry import SE2
from ..maps import COORDINATE_LIMIT, Map
from .calibration import (
    _DISTORTION_MODELS,
    Mount,
    StereoCalibration,
    _check_intrinsics,
    _check_projection,
    _check_rotation,
    load_calibration,
    load_mount,
    stereo_from_camera_infos,
)
from .images import MAX_IMAGE_SIDE, check_image_size, imdecode_quietly
from .recorded import (
    BAG_SUFFIXES,
    SYNC_TOLERANCE,
    RecordedSource,
    check_stamps,
    frames_with_odometry,
    load_world_map,
    match_stamps,
    poses_at,
    yaw_of_quaternion,
)

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
ODOMETRY_TYPES = ("nav_msgs/msg/Odometry",)
PAN_TYPES = ("std_msgs/msg/Float64", "sensor_msgs/msg/JointState")
CAMERA_INFO_TYPES = ("sensor_msgs/msg/CameraInfo",)
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
INITIAL_POSE_TYPES = ("geometry_msgs/msg/PoseWithCovarianceStamped",)
GROUNDTRUTH_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped",
                     "geometry_msgs/msg/PoseWithCovarianceStamped")

TF_TOPICS = ("/tf_static", "/tf")
"""The tf topics read for the mount: static transforms, and the moving ones (a pan joint)."""

INITIAL_POSE_TOPIC = "/initialpose"
"""Where a start pose is read from (rviz's "2D Pose Estimate", AMCL's input)."""

BASE_FRAME = "base_link"
"""Default robot frame of the mount's tf chain (its origin taken on the floor, x forward, z up: REP-103)."""

MAX_MOUNT_TILT = math.radians(2.0)
"""Largest tilt or roll [rad] of the left optical frame from level that a tf mount may have: the method
takes the head as level (vertical wall edges vertical in the images)."""

MOUNT_DRIFT = 1e-3
"""Movement [m] of the left optical centre over the frames (a pan axis off the centre) above which a note says so."""

_ENCODINGS = {  # encoding → (channels, dtype, to BGR(A) by reversing the channels)
    "mono8": (1, np.uint8, False), "8UC1": (1, np.uint8, False),
    "mono16": (1, np.uint16, False), "16UC1": (1, np.uint16, False),
    "bgr8": (3, np.uint8, False), "8UC3": (3, np.uint8, False), "rgb8": (3, np.uint8, True),
    "bgra8": (4, np.uint8, False), "8UC4": (4, np.uint8, False), "rgba8": (4, np.uint8, True),
}
"""Raw ``sensor_msgs/Image`` encodings read (the ``8UC*`` ones taken as gray/BGR/BGRA)."""


def _rosbags():
    """The rosbags modules, or a one-line error telling how to install them."""
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.rosbag1 import ReaderError as ReaderError1
        from rosbags.rosbag2 import ReaderError as ReaderError2
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise InputError("reading bags needs the rosbags package: pip install 'stablemarks[ros]'") from None
    return AnyReader, (AnyReaderError, ReaderError1, ReaderError2), get_typestore(Stores.ROS2_HUMBLE)


def bag_paths(path: str | Path) -> list[Path]:
    """What ``AnyReader`` opens for ``path``: a ROS 1 ``.bag`` file, or a ROS 2 bag folder (a ``.db3`` or
    ``.mcap`` file inside a folder with ``metadata.yaml`` opens that folder; alone, the file itself)."""
    p = Path(path)
    if p.is_file() and p.suffix.lower() in (".db3", ".mcap") and (p.parent / "metadata.yaml").is_file():
        return [p.parent]
    if p.is_file() and p.suffix.lower() not in BAG_SUFFIXES:
        raise SequenceError(f"{p}: expected a bag ({', '.join(BAG_SUFFIXES)} file or a ROS 2 bag folder)")
    return [p]


def stamp_ns(msg) -> int:
    """A message's header stamp in integer nanoseconds."""
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def decode_image(msg, msgtype: str, where: str) -> np.ndarray:
    """Pixels of a ``sensor_msgs/Image`` or ``CompressedImage``: (H, W) or (H, W, C) ``uint8``/``uint16``,
    colour channels in OpenCV's BGR(A) order. :class:`ImageError` naming ``where`` for what cannot be read."""
    if msgtype.endswith("CompressedImage"):
        buf = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
        img, reason = imdecode_quietly(buf, cv2.IMREAD_UNCHANGED) if buf.size else (None, "no data")
        if img is None:
            why = f": {reason}" if reason else ""
            raise ImageError(f"{where}: cannot decode the compressed image (format {msg.format!r}{why})")
        return check_image_size(img, where)
    enc = str(msg.encoding)
    if enc not in _ENCODINGS:
        raise ImageError(f"{where}: unsupported image encoding {enc!r} (expected one of {', '.join(_ENCODINGS)})")
    channels, dtype, reverse = _ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * channels * np.dtype(dtype).itemsize
    data = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
    if not (0 < h <= MAX_IMAGE_SIDE and 0 < w <= MAX_IMAGE_SIDE):
        raise ImageError(f"{where}: a {w}×{h} image; expected 1 to {MAX_IMAGE_SIDE} px each way")
    if h <= 0 or w <= 0 or step < row or data.size < h * step:
        raise ImageError(f"{where}: a {w}×{h} {enc} image needs rows of at least {row} bytes and {h} rows, got "
                         f"step {step} and {data.size} bytes")
    rows = data[: h * step].reshape(h, step)[:, :row]
    order = ">" if msg.is_bigendian else "<"
    img = np.ascontiguousarray(rows).view(np.dtype(dtype).newbyteorder(order)).astype(dtype)
    img = img.reshape(h, w, channels) if channels > 1 else img.reshape(h, w)
    if reverse:
        img = np.ascontiguousarray(img[..., [2, 1, 0, 3][:channels]])
    return img


class BagSource(RecordedSource):
    """A stereo bag (module docstring) as a source for :func:`~stablemarks.online.run_online`.

    ``path`` the bag; the topics as in the module docstring; ``world_map`` the walls; ``calibration`` of the
    images (None: from the ``sensor_msgs/CameraInfo`` topics ``left_info_topic`` and ``right_info_topic``,
    default the ``camera_info`` beside each image topic); ``mount`` the head on the robot (None: from the
    bag's tf, ``base_frame`` to the left image's frame); ``tolerance`` [s] for pairing, odometry, tf and
    ground truth; ``start_pose`` (3,) in the map (None: the last ``/initialpose`` before the first frame,
    else the first odometry pose); ``groundtruth_topic`` the true poses. ``calibration_source`` and
    ``mount_source`` say where given ones came from (for :attr:`sources`). Use it as a context manager (or
    call :meth:`close`) to close the bag.
    """

    def __init__(self, path: str | Path, *, left_topic: str, right_topic: str, odom_topic: str, world_map: Map,
                 calibration: StereoCalibration | None = None, mount: Mount | None = None,
                 pan_topic: str | None = None, pan_joint: str | None = None, tolerance: float = SYNC_TOLERANCE,
                 start_pose=None, left_info_topic: str | None = None, right_info_topic: str | None = None,
                 base_frame: str = BASE_FRAME, groundtruth_topic: str | None = None,
                 calibration_source: str = "calibration given", mount_source: str = "mount given"):
        self.path = Path(path)
        self._AnyReader, self._errors, self._typestore = _rosbags()
        self.topics = {"left": left_topic, "right": right_topic}
        self._reader = None
        self._connections: dict[str, list] = {}
        base_frame = _frame_id(base_frame)
        if not base_frame:
            raise InputError(expected("a tf frame name", base_frame, where="base_frame"))
        ix = self._index(left_topic, right_topic, odom_topic, pan_topic, pan_joint,
                         info_topics=None if calibration is not None else (left_info_topic, right_info_topic),
                         want_tf=mount is None, want_initial_pose=start_pose is None,
                         groundtruth_topic=groundtruth_topic)
        t_left, bag_left = ix.images[left_topic]
        t_right, bag_right = ix.images[right_topic]
        pairs = match_stamps(t_left, t_right, int(round(tolerance * 1e9)))
        name = self.path.stem if self.path.is_file() else self.path.name
        if not len(pairs):
            raise SequenceError(
                f"{self.path}: no stereo pairs: no image on {left_topic} ({len(t_left)}, stamped "
                f"{_span(t_left)}) has one on {right_topic} ({len(t_right)}, stamped {_span(t_right)}) within "
                f"{tolerance * 1e3:g} ms")
        notes = list(ix.notes)
        unpaired = len(t_left) + len(t_right) - 2 * len(pairs)
        if unpaired:
            notes.insert(0, f"{len(t_left) - len(pairs)} left and {len(t_right) - len(pairs)} right images have "
                            f"no partner within {tolerance * 1e3:g} ms")
        stamps = t_left[pairs[:, 0]] / 1e9
        keep, odometry, more = frames_with_odometry(stamps, ix.t_odom / 1e9, ix.odom, tolerance,
                                                    f"{self.path}: {odom_topic}")
        notes += more
        pairs, stamps = pairs[keep], stamps[keep]
        sources = {"images": f"topics {left_topic}, {right_topic}", "odometry": f"topic {odom_topic}"}

        # The mount: given, or from tf (with the pan of each frame when the chain moves).
        tf_pans = None
        if mount is None:
            tree = TfTree(str(self.path), ix.tf)
            mount, tf_pans, keep, more, where = tree.mount(base_frame, ix.image_frame, stamps, tolerance,
                                                           left_topic)
            notes += more
            pairs, stamps, odometry = pairs[keep], stamps[keep], odometry[keep]
            sources["mount"] = where
        else:
            sources["mount"] = mount_source

        # The calibration: given, or from the CameraInfo topics.
        if calibration is None:
            rectified = all(_is_rectified_topic(t) for t in (left_topic, right_topic))
            calibration = calibration_from_camera_info(ix.info, str(self.path), rectified)
            sources["calibration"] = (f"camera_info {ix.info[0]['topic']}, {ix.info[1]['topic']}"
                                      + (" (images rectified: their P)" if rectified else ""))
        else:
            sources["calibration"] = calibration_source
        camera = calibration.stereo_camera(mount)

        if pan_topic is not None:
            pans = np.interp(stamps, ix.t_pan / 1e9, ix.pan)
            sources["pan"] = f"topic {pan_topic}" + (f" joint {pan_joint}" if pan_joint else "")
        elif tf_pans is not None:
            pans = tf_pans
            sources["pan"] = f"{sources['mount']} (per frame, /tf)"
        else:
            pans = np.full(len(stamps), camera.pan)
            sources["pan"] = f"the mount's ({sources['mount']})"

        # The start pose and its covariance: given, or the last /initialpose before the first frame.
        start_cov = None
        if start_pose is not None:
            sources["start_pose"] = "given (`start_pose`)"
        elif ix.initial_poses:
            start_pose, start_cov, where, more = _initial_pose(ix.initial_poses, stamps[0], ix.t_odom / 1e9,
                                                               ix.odom, odometry[0], tolerance, str(self.path))
            notes += more
            if start_pose is not None:
                sources["start_pose"] = where
                if start_cov is not None:
                    sources["start_covariance"] = INITIAL_POSE_TOPIC
        sources.setdefault("start_pose", f"the first odometry pose ({odom_topic})")

        groundtruth = None
        if groundtruth_topic is not None:
            groundtruth = poses_at(ix.t_gt / 1e9, ix.gt, stamps, tolerance)
            missing = int(np.isnan(groundtruth[:, 0]).sum())
            if missing == len(stamps):
                raise SequenceError(f"{self.path}: {groundtruth_topic}: no frame within the ground truth's time "
                                    f"span: frames {stamps[0]:.3f} to {stamps[-1]:.3f} s, ground truth "
                                    f"{_span(ix.t_gt)}")
            if missing:
                notes.append(f"{missing} of {len(stamps)} frames have no ground truth: outside the time span of "
                             f"{groundtruth_topic} ({_span(ix.t_gt)})")
            sources["groundtruth"] = f"topic {groundtruth_topic}"

        # What raw_pair fetches: (bag time, header stamp) of each frame's left and right message.
        self._left = [(int(bag_left[i]), int(t_left[i])) for i in pairs[:, 0]]
        self._right = [(int(bag_right[j]), int(t_right[j])) for j in pairs[:, 1]]
        super().__init__(name, calibration, camera, world_map, stamps, odometry, pans, start_pose=start_pose,
                         groundtruth=groundtruth, start_cov=start_cov, notes=notes, sources=sources,
                         pan_recorded=pan_topic is not None or tf_pans is not None)

    # -- reading
    def _open(self):
        try:
            reader = self._AnyReader(bag_paths(self.path), default_typestore=self._typestore)
            reader.open()
        except (*self._errors, OSError) as exc:
            raise SequenceError(f"{self.path}: cannot read the bag: {_reason(exc)}") from None
        return reader

    def _index(self, left_topic, right_topic, odom_topic, pan_topic, pan_joint, *, info_topics, want_tf,
               want_initial_pose, groundtruth_topic) -> SimpleNamespace:
        """One pass over the bag: image stamps and bag times, odometry poses, pan samples; and what is asked
        for: the CameraInfo of each camera (``info_topics`` (left, right), None entries for the defaults),
        the tf transforms, the ``/initialpose`` messages and the ground-truth poses."""
        reader = self._open()
        ix = SimpleNamespace(images={left_topic: ([], []), right_topic: ([], [])}, image_frame=None, info=None,
                             tf=[], initial_poses=[], notes=[])
        try:
            topics = reader.topics
            wanted = {"left_topic": (left_topic, IMAGE_TYPES), "right_topic": (right_topic, IMAGE_TYPES),
                      "odom_topic": (odom_topic, ODOMETRY_TYPES)}
            if pan_topic is not None:
                wanted["pan_topic"] = (pan_topic, PAN_TYPES)
            if groundtruth_topic is not None:
                wanted["groundtruth_topic"] = (groundtruth_topic, GROUNDTRUTH_TYPES)
            for option, (topic, types) in wanted.items():
                self._check_topic(topics, option, topic, types)
            info: dict[str, dict] = {}
            if info_topics is not None:
                for side, option, image, given in zip(("left", "right"), ("left_info_topic", "right_info_topic"),
                                                      (left_topic, right_topic), info_topics, strict=True):
                    topic = given if given is not None else camera_info_topic(image, topics[image].msgtype)
                    if given is None and topic not in topics:
                        raise InputError(f"the bag {self.path} carries no calibration: no topic {topic} (the "
                                         f"sensor_msgs/CameraInfo beside {image}): pass `calib` or `{option}`")
                    self._check_topic(topics, option, topic, CAMERA_INFO_TYPES)
                    info[topic] = {"topic": topic, "side": side, "option": option, "msg": None, "changes": 0}
                    wanted[option] = (topic, CAMERA_INFO_TYPES)
            tf_topics = []
            if want_tf:
                tf_topics = [t for t in TF_TOPICS if t in topics and topics[t].msgtype in TF_TYPES]
                if not tf_topics:
                    raise InputError(f"the bag {self.path} carries no camera mount: no /tf_static or /tf topic "
                                     "(tf2_msgs/TFMessage): pass `mount` (a mount.yaml)")
                for t in tf_topics:
                    wanted[t] = (t, TF_TYPES)
            initial_topic = None
            if want_initial_pose and INITIAL_POSE_TOPIC in topics:
                if topics[INITIAL_POSE_TOPIC].msgtype in INITIAL_POSE_TYPES:
                    initial_topic = INITIAL_POSE_TOPIC
                    wanted["initialpose"] = (INITIAL_POSE_TOPIC, INITIAL_POSE_TYPES)
                else:
                    ix.notes.append(f"{INITIAL_POSE_TOPIC} is {topics[INITIAL_POSE_TOPIC].msgtype}, not "
                                    f"{INITIAL_POSE_TYPES[0]}: not used")
            images = ix.images
            odom: list[tuple[int, float, float, float]] = []
            gt: list[tuple[int, float, float, float]] = []
            pan: list[tuple[int, float]] = []
            pan_names: set[tuple[str, ...]] = set()
            conns = [c for c in reader.connections if c.topic in {t for t, _ in wanted.values()}]
            for conn, t_bag, raw in reader.messages(connections=conns):
                topic = conn.topic
                msg = reader.deserialize(raw, conn.msgtype)
                if topic in images:
                    images[topic][0].append(stamp_ns(msg))
                    images[topic][1].append(t_bag)
                    if topic == left_topic and ix.image_frame is None:
                        ix.image_frame = _frame_id(msg.header.frame_id)
                if topic == odom_topic:
                    odom.append((stamp_ns(msg), *_planar_pose(msg.pose.pose)))
                if topic == groundtruth_topic:
                    pose = msg.pose if conn.msgtype.endswith("/PoseStamped") else msg.pose.pose
                    gt.append((stamp_ns(msg), *_planar_pose(pose)))
                if topic in info:
                    entry = info[topic]
                    fields = _camera_info_fields(msg)
                    if entry["msg"] is None:
                        entry["msg"] = fields
                    elif not _same_camera_info(entry["msg"], fields):
                        entry["changes"] += 1
                if topic in tf_topics:
                    static = topic == "/tf_static"
                    for tr in msg.transforms:
                        t, q = tr.transform.translation, tr.transform.rotation
                        ix.tf.append((_frame_id(tr.header.frame_id), _frame_id(tr.child_frame_id), stamp_ns(tr),
                                      static, (float(t.x), float(t.y), float(t.z)),
                                      (float(q.x), float(q.y), float(q.z), float(q.w)), topic))
                if topic == initial_topic:
                    stamp = stamp_ns(msg) or int(t_bag)  # an unstamped message: when it was recorded
                    p = msg.pose.pose
                    ix.initial_poses.append((stamp, _frame_id(msg.header.frame_id), _planar_pose(p),
                                             np.array(msg.pose.covariance, dtype=float)))
                if topic == pan_topic:
                    if conn.msgtype.endswith("Float64"):
                        pan.append((t_bag, float(msg.data)))
                        continue
                    names = tuple(str(n) for n in msg.name)
                    pan_names.add(names)
                    joint = pan_joint if pan_joint is not None else (names[0] if len(names) == 1 else None)
                    if joint is None:
                        raise SequenceError(f"{self.path}: {pan_topic}: joint states of several joints "
                                            f"({', '.join(names)}): pass `pan_joint`")
                    if joint in names:
                        pan.append((stamp_ns(msg), float(msg.position[names.index(joint)])))
        except (*self._errors, OSError) as exc:
            raise SequenceError(f"{self.path}: cannot read the bag: {_reason(exc)}") from None
        finally:
            reader.close()
        for topic in (left_topic, right_topic):
            t, bag_t = (np.array(v, dtype=np.int64) for v in images[topic])
            if not len(t):
                raise SequenceError(f"{self.path}: {topic}: no messages")
            check_stamps(t, f"{self.path}: {topic}")
            images[topic] = (t, bag_t)
        ix.t_odom, ix.odom = self._poses(odom, odom_topic)
        if groundtruth_topic is not None:
            ix.t_gt, ix.gt = self._poses(gt, groundtruth_topic)
        if info_topics is not None:
            for entry in info.values():
                if entry["msg"] is None:
                    raise InputError(f"the bag {self.path} carries no calibration: {entry['topic']} "
                                     f"(`{entry['option']}`) has no messages: pass `calib`")
                if entry["changes"]:
                    ix.notes.append(f"{entry['topic']}: {entry['changes']} messages differ from the first one; "
                                    "the first is used")
            ix.info = [{**e["msg"], "topic": e["topic"]} for e in info.values()]
        if pan_topic is not None:
            if not pan:
                known = ", ".join(sorted({n for names in pan_names for n in names}))
                raise SequenceError(f"{self.path}: {pan_topic}: no pan values"
                                    + (f" (no joint {pan_joint!r}; the joints are {known})" if known else ""))
            ix.t_pan = np.array([p[0] for p in pan], dtype=np.int64)
            check_stamps(ix.t_pan, f"{self.path}: {pan_topic}")
            ix.pan = np.array([p[1] for p in pan], dtype=float)
            _check_values(ix.pan, ix.t_pan, f"{self.path}: {pan_topic}", "pan")
        return ix

    def _poses(self, rows: list[tuple[int, float, float, float]], topic: str) -> tuple[np.ndarray, np.ndarray]:
        """Stamps [ns] and poses (n, 3) of a pose topic, checked: some, strictly increasing, finite."""
        if not rows:
            raise SequenceError(f"{self.path}: {topic}: no messages")
        t = np.array([r[0] for r in rows], dtype=np.int64)
        check_stamps(t, f"{self.path}: {topic}")
        poses = np.array([r[1:] for r in rows], dtype=float)
        _check_values(poses, t, f"{self.path}: {topic}", "pose")
        return t, poses

    def _check_topic(self, topics: dict, option: str, topic: str | None, types: Sequence[str]) -> None:
        if topic is None:
            raise InputError(f"{self.path}: a bag needs `{option}`, a topic of {' or '.join(types)}")
        if topic not in topics:
            have = ", ".join(f"{t} ({info.msgtype})" for t, info in sorted(topics.items())) or "none"
            raise SequenceError(f"{self.path}: no topic {topic!r} (`{option}`); the bag has: {have}")
        msgtype = topics[topic].msgtype
        if msgtype not in types:
            raise SequenceError(f"{self.path}: {topic} (`{option}`) is {msgtype}, expected {' or '.join(types)}")

    def _fetch(self, side: str, k: int) -> np.ndarray:
        t_bag, t_header = (self._left if side == "left" else self._right)[k]
        topic = self.topics[side]
        if self._reader is None:
            self._reader = self._open()
            self._connections = {t: [c for c in self._reader.connections if c.topic == t]
                                 for t in self.topics.values()}
        reader = self._reader
        where = f"{self.path}: {topic} message stamped {t_header / 1e9:.9f} s"
        try:
            for conn, _, raw in reader.messages(connections=self._connections[topic], start=t_bag, stop=t_bag + 1):
                msg = reader.deserialize(raw, conn.msgtype)
                if stamp_ns(msg) == t_header:
                    return decode_image(msg, conn.msgtype, where)
        except self._errors as exc:
            raise SequenceError(f"{where}: cannot read it: {_reason(exc)}") from None
        raise SequenceError(f"{where}: no longer in the bag (was it changed while reading?)")

    def raw_pair(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        return self._fetch("left", k), self._fetch("right", k)

    def frame_name(self, k: int) -> str:
        return f"{self.path} frame {k} ({self.topics['left']} and {self.topics['right']} at {self.stamps[k]:.9f} s)"

    def close(self) -> None:
        """Close the bag (reopened if a frame is read again)."""
        if self._reader is not None:
            self._reader.close()
            self._reader = None


def _check_values(values: np.ndarray, stamps: np.ndarray, where: str, what: str) -> None:
    """Every value finite and within ±:data:`~stablemarks.maps.COORDINATE_LIMIT` (metres, radians)."""
    bad = ~np.all(np.isfinite(values) & (np.abs(values) <= COORDINATE_LIMIT), axis=tuple(range(1, values.ndim)))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise SequenceError(f"{where}: message {i} (stamped {stamps[i] / 1e9:.9f} s): expected a finite {what} "
                            f"within ±{COORDINATE_LIMIT:g}, got {values[i].tolist()}")


def _span(t: np.ndarray) -> str:
    return f"{t[0] / 1e9:.3f} to {t[-1] / 1e9:.3f} s" if len(t) else "never"


def _reason(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or exc.__class__.__name__


def _frame_id(name) -> str:
    """A tf frame name as tf2 compares them: without a leading ``/`` (ROS 1's old style)."""
    return str(name).strip().lstrip("/")


def _planar_pose(pose) -> tuple[float, float, float]:
    """``(x, y, yaw)`` of a ``geometry_msgs/Pose``."""
    p, q = pose.position, pose.orientation
    return float(p.x), float(p.y), float(yaw_of_quaternion(q.x, q.y, q.z, q.w))


# ------------------------------------------------------------------ calibration from CameraInfo
def camera_info_topic(image_topic: str, msgtype: str = "") -> str:
    """The ``camera_info`` topic beside an image topic: its last name replaced (``/ns/left/image_raw`` →
    ``/ns/left/camera_info``); for a ``CompressedImage`` the transport's ``/compressed`` goes first."""
    parts = image_topic.rstrip("/").split("/")
    if msgtype.endswith("CompressedImage") and len(parts) > 2 and parts[-1] in ("compressed", "compressedDepth"):
        parts = parts[:-1]
    return "/".join([*parts[:-1], "camera_info"])


def _is_rectified_topic(image_topic: str) -> bool:
    """Whether an image topic carries rectified images by ROS's naming (``image_rect``, ``image_rect_color``,
    also under a transport such as ``…/image_rect/compressed``): its CameraInfo's ``P`` describes them."""
    parts = image_topic.rstrip("/").split("/")
    return any(p.startswith("image_rect") for p in parts[-2:])


def _camera_info_fields(msg) -> dict:
    """The fields of a ``sensor_msgs/CameraInfo`` (ROS 1 ``D, K, R, P`` or ROS 2 ``d, k, r, p``) as plain values."""
    def field(name):
        return getattr(msg, name) if hasattr(msg, name) else getattr(msg, name.upper())

    roi = msg.roi
    return {"width": int(msg.width), "height": int(msg.height), "distortion_model": str(msg.distortion_model),
            "D": np.array(field("d"), dtype=float), "K": np.array(field("k"), dtype=float),
            "R": np.array(field("r"), dtype=float), "P": np.array(field("p"), dtype=float),
            "binning": (int(msg.binning_x), int(msg.binning_y)),
            "roi": (int(roi.x_offset), int(roi.y_offset), int(roi.width), int(roi.height)),
            "frame": _frame_id(msg.header.frame_id)}


def _same_camera_info(a: dict, b: dict) -> bool:
    return all(np.array_equal(a[k], b[k]) if isinstance(a[k], np.ndarray) else a[k] == b[k]
               for k in ("width", "height", "distortion_model", "D", "K", "R", "P", "binning", "roi"))


def _camera_info(info: dict, where: str, rectified: bool) -> dict:
    """One camera of a CameraInfo (:func:`_camera_info_fields`), checked as a camera_info file is
    (:mod:`.calibration`'s checks); ``rectified``: the images are the rectified ones (``image_rect``), so the
    camera is ``P``'s: no distortion, identity rectification."""
    size = []
    for key in ("width", "height"):
        v = info[key]
        if not 0 < v <= MAX_IMAGE_SIDE:
            raise SequenceError(expected(f"a positive number of pixels, at most {MAX_IMAGE_SIDE}", v,
                                         where=f"{where}: {key}"))
        size.append(v)
    bx, by = info["binning"]
    x0, y0, rw, rh = info["roi"]
    if bx > 1 or by > 1 or x0 or y0 or (rw and rw != size[0]) or (rh and rh != size[1]):
        raise SequenceError(f"{where}: binning_x/binning_y {bx}/{by} and roi {rw}×{rh} at ({x0}, {y0}): expected "
                            "full-resolution images (binning 0 or 1, an empty or whole-image roi)")
    m = {}
    for key, shape in (("K", (3, 3)), ("R", (3, 3)), ("P", (3, 4))):
        a = info[key]
        if a.size != shape[0] * shape[1]:
            raise SequenceError(expected(f"{shape[0] * shape[1]} numbers", a.size, where=f"{where}: {key}"))
        if not np.all(np.isfinite(a)):
            raise SequenceError(expected("finite numbers", a.tolist(), where=f"{where}: {key}"))
        m[key] = a.reshape(shape)
    _check_intrinsics(m["K"], f"{where}: K")
    _check_rotation(m["R"], f"{where}: R")
    _check_projection(m["P"], f"{where}: P")
    D, model = info["D"], info["distortion_model"]
    if D.size and (model not in _DISTORTION_MODELS or D.size != _DISTORTION_MODELS[model]):
        models = " or ".join(f"{name} with {n} coefficients" for name, n in _DISTORTION_MODELS.items())
        raise SequenceError(expected(f"distortion_model {models} in D (or an empty D)", f"{model!r} with {D.size}",
                                     where=f"{where}: distortion_model"))
    if not np.all(np.isfinite(D)):
        raise SequenceError(expected("finite numbers", D.tolist(), where=f"{where}: D"))
    D = D if D.size else np.zeros(5)
    if rectified:
        return {"size": tuple(size), "K": m["P"][:, :3].copy(), "D": np.zeros(5), "R": np.eye(3), "P": m["P"]}
    return {"size": tuple(size), "K": m["K"], "D": D, "R": m["R"], "P": m["P"]}


def calibration_from_camera_info(infos: Sequence[dict], where: str, rectified: bool = False) -> StereoCalibration:
    """The :class:`StereoCalibration` of a left and a right CameraInfo (:func:`_camera_info_fields` plus
    ``topic``), as :func:`~stablemarks.io.calibration.load_camera_info_pair` builds it from files: the same
    checks, ``R = R2ᵀ R1``, ``T = R2ᵀ (Tx/f, 0, 0)`` with the right ``Tx = P[0,3] = −f·baseline``.
    ``rectified``: the images are already rectified (``image_rect`` topics), only ``P`` describes them.
    Errors name ``where``, the topic and the field."""
    left_info, right_info = infos
    left, right = (_camera_info(i, f"{where}: {i['topic']}", rectified) for i in infos)
    if left["size"] != right["size"]:
        (lw, lh), (rw, rh) = left["size"], right["size"]
        raise SequenceError(f"{where}: image sizes differ: {left_info['topic']} width/height is {lw}×{lh}, "
                            f"{right_info['topic']} is {rw}×{rh}")
    return stereo_from_camera_infos(
        left, right, (f"{where}: {left_info['topic']}: P", f"{where}: {right_info['topic']}: P"),
        (left_info.get("frame") or "left", right_info.get("frame") or "right"),
        f"{where} camera_info {left_info['topic']}, {right_info['topic']}")


# ------------------------------------------------------------------ the mount from tf
def _rotation(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) ``(x, y, z, w)``, normalised."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def _slerp(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Spherical interpolation (n, 4) between unit quaternions (n, 4) at fractions ``a`` (n,)."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    dot = np.clip(np.abs(dot), -1.0, 1.0)
    omega = np.arccos(dot)
    small = omega < 1e-9
    s = np.where(small, 1.0, np.sin(omega))
    w0 = np.where(small, 1.0 - a, np.sin((1.0 - a) * omega) / s)
    w1 = np.where(small, a, np.sin(a * omega) / s)
    q = w0[:, None] * q0 + w1[:, None] * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


class TfTree:
    """The transforms of a bag's ``/tf_static`` and ``/tf``: a tree of frames, each with one parent.

    ``transforms`` rows ``(parent, child, stamp [ns], static, (x, y, z), (qx, qy, qz, qw), topic)``:
    ``T_parent_child``, a point of ``child`` is ``R p + t`` in ``parent``. A static transform holds at all
    times; the moving ones are interpolated at the asked stamps (linear, and spherical for the rotation)
    and held within the tolerance beyond their first and last stamp, as tf2 does between samples.
    """

    def __init__(self, where: str, transforms):
        self.where = where
        self.parent: dict[str, str] = {}
        self.static: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        moving: dict[str, list] = {}
        for parent, child, stamp, static, t, q, topic in transforms:
            if not parent or not child or parent == child:
                continue
            old = self.parent.get(child)
            if old is not None and old != parent:
                raise SequenceError(f"{where}: {topic}: frame {child!r} has two parents, {old!r} and {parent!r} "
                                    "(expected a tf tree: one parent per frame)")
            norm = math.sqrt(sum(v * v for v in q))
            if not (all(math.isfinite(v) for v in (*t, *q)) and abs(norm - 1.0) < 0.01):
                raise SequenceError(expected("a finite translation and a unit quaternion", [list(t), list(q)],
                                             where=f"{where}: {topic}: transform {parent}→{child} stamped "
                                                   f"{stamp / 1e9:.9f} s"))
            self.parent[child] = parent
            if static:
                self.static[child] = (np.array(t), np.array(q) / norm)
            else:
                moving.setdefault(child, []).append((stamp, t, np.array(q) / norm))
        self.moving: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for child, rows in moving.items():
            rows.sort(key=lambda r: r[0])
            stamps = np.array([r[0] for r in rows], dtype=np.int64)
            last = np.append(stamps[1:] != stamps[:-1], True)  # a repeated stamp: its last transform
            self.moving[child] = (stamps[last], np.array([r[1] for r in rows])[last],
                                  np.array([r[2] for r in rows])[last])

    def _ancestors(self, frame: str) -> list[str]:
        out = [frame]
        while out[-1] in self.parent:
            parent = self.parent[out[-1]]
            if parent in out:
                raise SequenceError(f"{self.where}: tf: the frames {' → '.join([*out, parent])} form a loop "
                                    "(expected a tree)")
            out.append(parent)
        return out

    def path(self, source: str, target: str) -> tuple[list[str], list[str]]:
        """The frames from ``source`` and from ``target`` up to (not including) their common ancestor; a
        :class:`SequenceError` naming both frames when the tree does not join them."""
        up, down = self._ancestors(source), self._ancestors(target)
        common = next((f for f in up if f in set(down)), None)
        if common is None:
            known = set(self.parent) | set(self.parent.values())
            missing = [f for f in (source, target) if f not in known]
            if missing:
                frames = ", ".join(sorted(known)) or "none"
                why = f"the tf tree has no frame {' and no frame '.join(repr(f) for f in missing)} (frames: {frames})"
            else:
                why = f"{source!r} hangs under {up[-1]!r} and {target!r} under {down[-1]!r}, not joined"
            raise SequenceError(f"{self.where}: no tf path from {source!r} to {target!r} (/tf_static, /tf): {why}")
        return up[: up.index(common)], down[: down.index(common)]

    def _edge(self, child: str, stamps_ns: np.ndarray, tolerance_ns: int):
        """``T_parent_child`` at the stamps: (n, 3, 3), (n, 3) and which stamps it covers (n,) bool."""
        n = len(stamps_ns)
        if child not in self.moving:
            t, q = self.static[child]
            return np.broadcast_to(_rotation(q), (n, 3, 3)), np.broadcast_to(t, (n, 3)), np.ones(n, bool)
        ts, t, q = self.moving[child]
        if len(ts) == 1:
            ok = np.abs(stamps_ns - ts[0]) <= tolerance_ns
            return np.broadcast_to(_rotation(q[0]), (n, 3, 3)), np.broadcast_to(t[0], (n, 3)), ok
        j = np.clip(np.searchsorted(ts, stamps_ns, side="right"), 1, len(ts) - 1)
        a = np.clip((stamps_ns - ts[j - 1]) / (ts[j] - ts[j - 1]).astype(float), 0.0, 1.0)
        ok = (stamps_ns >= ts[0] - tolerance_ns) & (stamps_ns <= ts[-1] + tolerance_ns)
        return _rotation(_slerp(q[j - 1], q[j], a)), t[j - 1] + a[:, None] * (t[j] - t[j - 1]), ok

    def _chain(self, frames: list[str], stamps_ns, tolerance_ns):
        n = len(stamps_ns)
        R, t, ok = np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)), np.ones(n, bool)
        for child in frames:  # T_ancestor_frame = T_parent_child @ ... , child first
            Re, te, oke = self._edge(child, stamps_ns, tolerance_ns)
            R, t, ok = Re @ R, np.einsum("nij,nj->ni", Re, t) + te, ok & oke
        return R, t, ok

    def transform(self, source: str, target: str, stamps, tolerance: float):
        """``T_source_target`` at ``stamps`` [s]: rotations (n, 3, 3), translations (n, 3), the stamps every
        transform of the chain covers (n,) bool, and whether any of them moves (is on ``/tf``)."""
        up, down = self.path(source, target)
        stamps_ns = np.round(np.asarray(stamps, dtype=float) * 1e9).astype(np.int64)
        tol = int(round(tolerance * 1e9))
        Ra, ta, oka = self._chain(up, stamps_ns, tol)    # T_common_source
        Rb, tb, okb = self._chain(down, stamps_ns, tol)  # T_common_target
        RaT = np.swapaxes(Ra, 1, 2)
        R = RaT @ Rb
        t = np.einsum("nij,nj->ni", RaT, tb - ta)
        return R, t, oka & okb, any(f in self.moving for f in up + down)

    def mount(self, base: str, frame: str | None, stamps, tolerance: float, image_topic: str):
        """The :class:`Mount` of the left optical frame ``frame`` (REP-103: z forward, x right, y down) on the
        robot frame ``base``: ``(mount, pans or None, keep (n,) bool, notes, description)``. The position and
        pan of the first kept frame make the mount; the pans of every frame when the chain moves."""
        if not frame:
            raise SequenceError(f"{self.where}: {image_topic}: the images have no header.frame_id, so the tf "
                                "chain to the camera is unknown: pass `mount`")
        R, t, keep, moving = self.transform(base, frame, stamps, tolerance)
        what = f"tf {base}→{frame}"
        notes = []
        if not keep.any():
            raise SequenceError(f"{self.where}: {what}: no frame within the time span of its /tf transforms")
        if not keep.all():
            notes.append(f"{int((~keep).sum())} of {len(keep)} frames left out: outside the time span of the /tf "
                         f"transforms of {what}")
        R, t = R[keep], t[keep]
        down = -R[:, 2, 1]  # the optical y axis (down) along −z of the base: cos of tilt/roll
        level = np.arccos(np.clip(down, -1.0, 1.0))
        k = int(np.argmax(level))
        if level[k] > MAX_MOUNT_TILT:
            raise SequenceError(
                f"{self.where}: {what}: the camera is {math.degrees(level[k]):.1f}° from level (its y axis should "
                f"point down: {frame!r} must be the optical frame, z forward, x right, y down: REP-103); the "
                f"method takes the head level, at most {math.degrees(MAX_MOUNT_TILT):g}°")
        height = float(t[0, 2])
        if not (math.isfinite(height) and height > 0):
            raise SequenceError(expected(f"the camera above {base!r}'s origin (on the floor), a positive height "
                                         "[m]", height, where=f"{self.where}: {what}: z"))
        pans = np.arctan2(R[:, 1, 2], R[:, 0, 2])
        drift = float(np.max(np.linalg.norm(t - t[0], axis=1)))
        if drift > MOUNT_DRIFT:
            notes.append(f"the left optical centre moves by up to {drift * 1e3:.0f} mm over the frames ({what}); "
                         "the mount is taken at the first frame (the method pans about the optical centre)")
        mount = Mount(mount_x=float(t[0, 0]), mount_y=float(t[0, 1]), mount_height=height, pan=float(pans[0]))
        return mount, (pans if moving else None), keep, notes, what


# ------------------------------------------------------------------ the start pose
def _initial_pose(messages, first_stamp: float, t_odom, poses_odom, odometry0, tolerance: float, where: str):
    """The start pose from the last ``/initialpose`` at or before ``first_stamp`` [s]: ``(pose (3,) or None,
    covariance (3, 3) or None, description, notes)``. The pose is moved by the odometry between its stamp and
    the first frame when the odometry covers its stamp; its covariance's x, y, yaw block is the start
    covariance (None when it is all zero)."""
    before = [m for m in messages if m[0] / 1e9 <= first_stamp + 1e-9]
    if not before:
        return None, None, "", [f"{len(messages)} {INITIAL_POSE_TOPIC} message(s), all after the first frame: "
                                "not used"]
    stamp, frame, pose, cov36 = max(before, key=lambda m: m[0])
    at = f"{where}: {INITIAL_POSE_TOPIC} stamped {stamp / 1e9:.9f} s"
    pose = np.array(pose)
    if not np.all(np.isfinite(pose) & (np.abs(pose) <= COORDINATE_LIMIT)):
        raise SequenceError(expected(f"a finite pose within ±{COORDINATE_LIMIT:g}", pose.tolist(), where=f"{at}: pose"))
    notes = []
    odo = poses_at(t_odom, poses_odom, [stamp / 1e9], tolerance)[0]
    if np.all(np.isfinite(odo)):
        pose = (SE2.from_array(pose) @ SE2.from_array(odo).between(SE2.from_array(odometry0))).as_array()
    else:
        notes.append(f"the odometry does not reach back to {INITIAL_POSE_TOPIC}'s stamp ({stamp / 1e9:.3f} s): "
                     "taken as the pose at the first frame")
    if frame not in ("map", ""):
        notes.append(f"{INITIAL_POSE_TOPIC} is in frame {frame!r}: taken as the map's frame")
    cov = None
    if cov36.size != 36 or not np.all(np.isfinite(cov36)):
        raise SequenceError(expected("36 finite numbers", cov36.size, where=f"{at}: pose.covariance"))
    block = cov36.reshape(6, 6)[np.ix_([0, 1, 5], [0, 1, 5])]
    if np.any(block):
        sym = 0.5 * (block + block.T)
        if not np.allclose(block, sym, rtol=1e-6, atol=1e-12) or np.linalg.eigvalsh(sym).min() <= 0:
            raise SequenceError(expected("a symmetric positive-definite x, y, yaw block", block.tolist(),
                                         where=f"{at}: pose.covariance"))
        cov = sym
    else:
        notes.append(f"{INITIAL_POSE_TOPIC} has no covariance (all zero): the start covariance is the default")
    return pose, cov, f"{INITIAL_POSE_TOPIC} (stamped {stamp / 1e9:.9f} s, frame {frame or 'none'})", notes


def open_bag(path: str | Path, *, left_topic=None, right_topic=None, odom_topic=None, pan_topic=None,
             pan_joint=None, calib=None, map=None, mount=None, tolerance: float = SYNC_TOLERANCE,
             start_pose=None, left_info_topic=None, right_info_topic=None, base_frame: str = BASE_FRAME,
             groundtruth_topic=None) -> BagSource:
    """Open a bag with the map file ``map``; the calibration ``calib`` (default: the bag's CameraInfo topics)
    and the mount file ``mount`` (default ``mount.yaml`` beside ``calib``, else the bag's tf from
    ``base_frame`` to the left image's frame); see :class:`BagSource` and
    :func:`~stablemarks.io.sources.open_sequence`.

    Everything is checked here, including the first stereo pair against the calibration's image size.
    """
    world_map = load_world_map(map, f"the bag {path}")
    calibration = load_calibration(calib) if calib is not None else None
    mount_path = None
    if mount is not None:
        mount_path = Path(mount)
    elif calib is not None:
        c = Path(calib)
        beside = (c if c.is_dir() else c.parent) / "mount.yaml"
        mount_path = beside if beside.is_file() else None
    source = BagSource(path, left_topic=left_topic, right_topic=right_topic, odom_topic=odom_topic,
                       world_map=world_map, calibration=calibration,
                       mount=load_mount(mount_path) if mount_path is not None else None, pan_topic=pan_topic,
                       pan_joint=pan_joint, tolerance=tolerance, start_pose=start_pose,
                       left_info_topic=left_info_topic, right_info_topic=right_info_topic, base_frame=base_frame,
                       groundtruth_topic=groundtruth_topic, calibration_source=f"file {calib}",
                       mount_source=f"file {mount_path}")
    try:
        source.pair(0)
    except BaseException:
        source.close()
        raise
    return source
