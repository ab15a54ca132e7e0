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
  the mount's pan.

Stereo pairs are matched by header stamp: a left and a right image that are each other's nearest within
the tolerance (default 5 ms) form a frame, stamped by the left image. The odometry poses and pans are
interpolated linearly at the frame stamps (heading on the shortest arc); frames before the first or after
the last odometry message (beyond the tolerance) are left out, with a note. Each stream's header stamps
must increase strictly in the bag; a duplicate or out-of-order stamp is an error naming the topic.

Opening a bag reads it once to index the messages (bag time and header stamp of every image); the
images are decoded only when the loop asks for a frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from ..errors import ImageError, InputError, SequenceError
from ..geometry import StereoCamera
from ..maps import COORDINATE_LIMIT, Map
from .calibration import StereoCalibration
from .images import MAX_IMAGE_SIDE, check_image_size, imdecode_quietly
from .recorded import (
    BAG_SUFFIXES,
    SYNC_TOLERANCE,
    RecordedSource,
    check_stamps,
    frames_with_odometry,
    load_mount_near,
    load_stereo_calibration,
    load_world_map,
    match_stamps,
    yaw_of_quaternion,
)

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
ODOMETRY_TYPES = ("nav_msgs/msg/Odometry",)
PAN_TYPES = ("std_msgs/msg/Float64", "sensor_msgs/msg/JointState")

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

    ``path`` the bag; the topics as in the module docstring; ``calibration`` of the images and ``camera``
    the rectified head on its mount; ``world_map`` the walls; ``tolerance`` [s] for pairing and odometry;
    ``start_pose`` (3,) in the map, default the first odometry pose. Use it as a context manager (or call
    :meth:`close`) to close the bag.
    """

    def __init__(self, path: str | Path, *, left_topic: str, right_topic: str, odom_topic: str,
                 calibration: StereoCalibration, camera: StereoCamera, world_map: Map,
                 pan_topic: str | None = None, pan_joint: str | None = None, tolerance: float = SYNC_TOLERANCE,
                 start_pose=None):
        self.path = Path(path)
        self._AnyReader, self._errors, self._typestore = _rosbags()
        self.topics = {"left": left_topic, "right": right_topic}
        self._reader = None
        self._connections: dict[str, list] = {}
        index = self._index(left_topic, right_topic, odom_topic, pan_topic, pan_joint)
        (t_left, bag_left), (t_right, bag_right), (t_odom, poses), pan_samples = index
        pairs = match_stamps(t_left, t_right, int(round(tolerance * 1e9)))
        name = self.path.stem if self.path.is_file() else self.path.name
        if not len(pairs):
            raise SequenceError(
                f"{self.path}: no stereo pairs: no image on {left_topic} ({len(t_left)}, stamped "
                f"{_span(t_left)}) has one on {right_topic} ({len(t_right)}, stamped {_span(t_right)}) within "
                f"{tolerance * 1e3:g} ms")
        notes = []
        unpaired = len(t_left) + len(t_right) - 2 * len(pairs)
        if unpaired:
            notes.append(f"{len(t_left) - len(pairs)} left and {len(t_right) - len(pairs)} right images have no "
                         f"partner within {tolerance * 1e3:g} ms")
        stamps = t_left[pairs[:, 0]] / 1e9
        keep, odometry, more = frames_with_odometry(stamps, t_odom / 1e9, poses, tolerance,
                                                    f"{self.path}: {odom_topic}")
        notes += more
        pairs, stamps = pairs[keep], stamps[keep]
        if pan_samples is None:
            pans = np.full(len(stamps), camera.pan)
        else:
            t_pan, values = pan_samples
            pans = np.interp(stamps, t_pan / 1e9, values)
        # What raw_pair fetches: (bag time, header stamp) of each frame's left and right message.
        self._left = [(int(bag_left[i]), int(t_left[i])) for i in pairs[:, 0]]
        self._right = [(int(bag_right[j]), int(t_right[j])) for j in pairs[:, 1]]
        super().__init__(name, calibration, camera, world_map, stamps, odometry, pans, start_pose=start_pose,
                         notes=notes)

    # -- reading
    def _open(self):
        try:
            reader = self._AnyReader(bag_paths(self.path), default_typestore=self._typestore)
            reader.open()
        except (*self._errors, OSError) as exc:
            raise SequenceError(f"{self.path}: cannot read the bag: {_reason(exc)}") from None
        return reader

    def _index(self, left_topic, right_topic, odom_topic, pan_topic, pan_joint):
        """One pass over the bag: image stamps and bag times, odometry poses, pan samples."""
        reader = self._open()
        try:
            topics = reader.topics
            wanted = {"left_topic": (left_topic, IMAGE_TYPES), "right_topic": (right_topic, IMAGE_TYPES),
                      "odom_topic": (odom_topic, ODOMETRY_TYPES)}
            if pan_topic is not None:
                wanted["pan_topic"] = (pan_topic, PAN_TYPES)
            for option, (topic, types) in wanted.items():
                self._check_topic(topics, option, topic, types)
            images = {left_topic: ([], []), right_topic: ([], [])}
            odom: list[tuple[int, float, float, float]] = []
            pan: list[tuple[int, float]] = []
            pan_names: set[tuple[str, ...]] = set()
            conns = [c for c in reader.connections if c.topic in {t for t, _ in wanted.values()}]
            for conn, t_bag, raw in reader.messages(connections=conns):
                topic = conn.topic
                if topic in images:
                    msg = reader.deserialize(raw, conn.msgtype)
                    images[topic][0].append(stamp_ns(msg))
                    images[topic][1].append(t_bag)
                if topic == odom_topic:
                    msg = reader.deserialize(raw, conn.msgtype)
                    p, q = msg.pose.pose.position, msg.pose.pose.orientation
                    odom.append((stamp_ns(msg), float(p.x), float(p.y), float(yaw_of_quaternion(q.x, q.y, q.z, q.w))))
                if topic == pan_topic:
                    msg = reader.deserialize(raw, conn.msgtype)
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
        out = []
        for topic in (left_topic, right_topic):
            t, bag_t = (np.array(v, dtype=np.int64) for v in images[topic])
            if not len(t):
                raise SequenceError(f"{self.path}: {topic}: no messages")
            check_stamps(t, f"{self.path}: {topic}")
            out.append((t, bag_t))
        if not odom:
            raise SequenceError(f"{self.path}: {odom_topic}: no messages")
        t_odom = np.array([o[0] for o in odom], dtype=np.int64)
        check_stamps(t_odom, f"{self.path}: {odom_topic}")
        poses = np.array([o[1:] for o in odom], dtype=float)
        _check_values(poses, t_odom, f"{self.path}: {odom_topic}", "pose")
        out.append((t_odom, poses))
        if pan_topic is None:
            out.append(None)
            return out
        if not pan:
            known = ", ".join(sorted({n for names in pan_names for n in names}))
            raise SequenceError(f"{self.path}: {pan_topic}: no pan values"
                                + (f" (no joint {pan_joint!r}; the joints are {known})" if known else ""))
        t_pan = np.array([p[0] for p in pan], dtype=np.int64)
        check_stamps(t_pan, f"{self.path}: {pan_topic}")
        values = np.array([p[1] for p in pan], dtype=float)
        _check_values(values, t_pan, f"{self.path}: {pan_topic}", "pan")
        out.append((t_pan, values))
        return out

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


def open_bag(path: str | Path, *, left_topic=None, right_topic=None, odom_topic=None, pan_topic=None,
             pan_joint=None, calib=None, map=None, mount=None, tolerance: float = SYNC_TOLERANCE,
             start_pose=None) -> BagSource:
    """Open a bag with the calibration ``calib``, the map file ``map`` and the mount file ``mount`` (default
    ``mount.yaml`` beside the calibration); see :class:`BagSource` and :func:`~stablemarks.io.sources.open_source`.

    Everything is checked here, including the first stereo pair against the calibration's image size.
    """
    what = f"the bag {path}"
    calibration = load_stereo_calibration(calib, what)
    camera = calibration.stereo_camera(load_mount_near(mount, calib, what=what))
    world_map = load_world_map(map, what)
    source = BagSource(path, left_topic=left_topic, right_topic=right_topic, odom_topic=odom_topic,
                       calibration=calibration, camera=camera, world_map=world_map, pan_topic=pan_topic,
                       pan_joint=pan_joint, tolerance=tolerance, start_pose=start_pose)
    try:
        source.pair(0)
    except BaseException:
        source.close()
        raise
    return source
