"""ROS bags: ROS 2 sqlite3 and MCAP and ROS 1 bags written with rosbags' own writers from a short simulated
lab run, read back frame for frame; the loop on a bag against the loop on our folder; image decoding; and
the broken bags (missing topic, unsorted or duplicate stamps, no pairs, a calibration of another size)."""

from __future__ import annotations

import functools
import re

import cv2
import numpy as np
import pytest

from stablemarks.errors import ImageError, InputError, SequenceError
from stablemarks.io.bags import BagSource, decode_image
from stablemarks.io.sources import open_source
from stablemarks.online import run_online

from .test_sources import (
    N_FRAMES,
    assert_same_frames,
    lab_odometry,
    lab_recording,
    lab_stamps,
    write_lab_inputs,
    write_lab_sequence,
)

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

LEFT, RIGHT, ODOM, PAN = "/stereo/left/image_rect", "/stereo/right/image_rect", "/odom", "/head/pan"


# ------------------------------------------------------------------ writing bags
def _ns(t: float) -> int:
    return int(round(t * 1e9))


class Messages:
    """Builds messages of one typestore (ROS 1 Noetic or ROS 2 Humble)."""

    def __init__(self, ros1: bool):
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in self.ts.types:  # ROS 1 Noetic's store lacks it
            from rosbags.typesys import get_types_from_msg

            self.ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                "tf2_msgs/msg/TFMessage"))
        self.T = self.ts.types
        self.ros1 = ros1

    def header(self, ns: int, frame="camera"):
        Time = self.T["builtin_interfaces/msg/Time"]
        extra = {"seq": 0} if self.ros1 else {}
        return self.T["std_msgs/msg/Header"](stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame, **extra)

    def image(self, ns: int, img: np.ndarray, encoding: str = "mono8", bigendian: bool = False, pad: int = 0,
              frame: str = "camera"):
        h, w = img.shape[:2]
        data = img.astype(img.dtype.newbyteorder(">" if bigendian else "<")).reshape(h, -1).view(np.uint8)
        step = data.shape[1] + pad
        rows = np.zeros((h, step), np.uint8)
        rows[:, : data.shape[1]] = data
        return self.T["sensor_msgs/msg/Image"](header=self.header(ns, frame), height=h, width=w, encoding=encoding,
                                               is_bigendian=int(bigendian), step=step, data=rows.ravel())

    def compressed(self, ns: int, img: np.ndarray, frame: str = "camera"):
        ok, buf = cv2.imencode(".png", img)
        assert ok
        return self.T["sensor_msgs/msg/CompressedImage"](header=self.header(ns, frame), format="mono8; png compressed ",
                                                         data=buf.ravel())

    def pose(self, pose):
        """A ``geometry_msgs/Pose`` of a planar pose ``(x, y, theta)``."""
        T = self.T
        x, y, theta = pose
        return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                           orientation=T["geometry_msgs/msg/Quaternion"](
                                               x=0.0, y=0.0, z=np.sin(theta / 2), w=np.cos(theta / 2)))

    def odometry(self, ns: int, pose, frame: str = "odom"):
        T = self.T
        p = self.pose(pose)
        zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return T["nav_msgs/msg/Odometry"](
            header=self.header(ns, frame), child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=p, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=T["geometry_msgs/msg/Twist"](linear=zero,
                                                                                                angular=zero),
                                                             covariance=np.zeros(36)))

    def pose_stamped(self, ns: int, pose, frame: str = "map"):
        return self.T["geometry_msgs/msg/PoseStamped"](header=self.header(ns, frame), pose=self.pose(pose))

    def pose_with_covariance(self, ns: int, pose, cov3=None, frame: str = "map"):
        """A ``PoseWithCovarianceStamped``; ``cov3`` (3, 3) over x, y, yaw goes into the 6×6 covariance."""
        cov = np.zeros((6, 6))
        if cov3 is not None:
            cov[np.ix_([0, 1, 5], [0, 1, 5])] = cov3
        return self.T["geometry_msgs/msg/PoseWithCovarianceStamped"](
            header=self.header(ns, frame),
            pose=self.T["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(pose), covariance=cov.ravel()))

    def camera_info(self, ns: int, K, D, R, P, size, frame: str = "camera", model: str = "plumb_bob"):
        T = self.T
        upper = self.ros1  # ROS 1 spells the matrices D, K, R, P
        mats = {k.upper() if upper else k: np.asarray(v, float).ravel()
                for k, v in (("d", D), ("k", K), ("r", R), ("p", P))}
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return T["sensor_msgs/msg/CameraInfo"](header=self.header(ns, frame), height=size[1], width=size[0],
                                               distortion_model=model, binning_x=0, binning_y=0, roi=roi, **mats)

    def transforms(self, ns: int, edges):
        """A ``tf2_msgs/TFMessage`` of ``(parent, child, (x, y, z), (qx, qy, qz, qw))`` transforms."""
        T = self.T
        out = []
        for parent, child, t, q in edges:
            out.append(T["geometry_msgs/msg/TransformStamped"](
                header=self.header(ns, parent), child_frame_id=child,
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=t[0], y=t[1], z=t[2]),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))))
        return T["tf2_msgs/msg/TFMessage"](transforms=out)

    def float64(self, value: float):
        return self.T["std_msgs/msg/Float64"](data=float(value))

    def joints(self, ns: int, names, positions):
        return self.T["sensor_msgs/msg/JointState"](header=self.header(ns), name=list(names),
                                                    position=np.array(positions, float), velocity=np.zeros(0),
                                                    effort=np.zeros(0))


def write_bag(path, messages, storage: str = "sqlite3"):
    """Write ``(topic, bag time [ns], message)`` rows with rosbags' writer: ``storage`` sqlite3, mcap or ros1."""
    ros1 = storage == "ros1"
    m = Messages(ros1)
    if ros1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer(path, version=8, storage_plugin=plugin)
    conns = {}
    with writer:
        for topic, t, msg in sorted(messages, key=lambda row: row[1]):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=m.ts)
            data = m.ts.serialize_ros1(msg, msg.__msgtype__) if ros1 else m.ts.serialize_cdr(msg, msg.__msgtype__)
            writer.write(conns[topic], int(t), data)
    return path


def lab_messages(storage: str = "sqlite3", *, compressed: bool = False, pan: str | None = "float64",
                 left_stamps=None, odom_stamps=None, frame: str = "camera"):
    """The lab recording as bag messages: images (right 1 ms after left, one extra right image) received 2 ms
    after their stamps (``left_stamps``: other header stamps, same bag times) in the tf frame ``frame``,
    odometry at the frame stamps and halfway between (``odom_stamps``: at these stamps only), the pan at the
    frame stamps."""
    run, frames = lab_recording()
    m = Messages(storage == "ros1")
    stamps = lab_stamps() if left_stamps is None else np.asarray(left_stamps)
    image = functools.partial(m.compressed if compressed else m.image, frame=frame)
    rows = []
    received = _ns(lab_stamps()[0]) + np.arange(N_FRAMES) * 500_000_000 + 2_000_000  # bag times, in order
    for k, f in enumerate(frames):
        tl, tr = _ns(stamps[k]), _ns(stamps[k] + 0.001)
        rows += [(LEFT, received[k], image(tl, f.left)), (RIGHT, received[k] + 1_000_000, image(tr, f.right))]
        if pan == "float64":
            rows.append((PAN, tl, m.float64(run.pans[k])))
        elif pan == "joint":
            rows.append((PAN, tl + 100, m.joints(tl, ["tilt", "pan"], [0.3, run.pans[k]])))
    rows.append((RIGHT, _ns(stamps[-1] + 0.25), image(_ns(stamps[-1] + 0.25), frames[-1].right)))
    odo = lab_odometry()
    t_odo = lab_stamps()
    if odom_stamps is None:
        for k in range(N_FRAMES):
            rows.append((ODOM, _ns(t_odo[k]) + 500, m.odometry(_ns(t_odo[k]), odo[k])))
            if k + 1 < N_FRAMES:  # halfway, interpolated: must not change the poses at the frames
                mid = 0.5 * (odo[k] + odo[k + 1])
                rows.append((ODOM, _ns(t_odo[k] + 0.25) + 500, m.odometry(_ns(t_odo[k] + 0.25), mid)))
    else:
        for k, t in enumerate(odom_stamps):
            rows.append((ODOM, _ns(t_odo[k]) + 500, m.odometry(_ns(t), odo[k])))
    return rows


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return write_lab_inputs(tmp_path_factory.mktemp("inputs"))


def open_lab_bag(path, inputs, **kw):
    options = dict(left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, pan_topic=PAN, calib=inputs["calib"],
                   map=inputs["map"], mount=inputs["mount"])
    options.update(kw)
    return open_source(path, **options)


# ------------------------------------------------------------------ reading back
@pytest.mark.parametrize("storage, compressed, name", [("sqlite3", False, "lab_db3"), ("mcap", True, "lab_mcap"),
                                                       ("ros1", False, "lab.bag")])
def test_bag_gives_the_recordings_frames(tmp_path, inputs, storage, compressed, name):
    path = write_bag(tmp_path / name, lab_messages(storage, compressed=compressed), storage)
    with open_lab_bag(path, inputs) as source:
        assert isinstance(source, BagSource)
        assert source.name == name.removesuffix(".bag")
        assert source.notes == ["0 left and 1 right images have no partner within 5 ms"]
        assert_same_frames(source)
        run, _ = lab_recording()
        assert source.camera == run.scenario.camera
        assert source.world_map == run.scenario.map
        assert source.true_pose(0) is None


def test_images_are_decoded_on_demand(tmp_path, inputs, monkeypatch):
    import stablemarks.io.bags as bags

    calls = []
    decode = bags.decode_image

    def counting(msg, msgtype, where):
        calls.append(where)
        return decode(msg, msgtype, where)

    monkeypatch.setattr(bags, "decode_image", counting)
    path = write_bag(tmp_path / "lab", lab_messages())
    source = open_lab_bag(path, inputs)
    assert len(calls) == 2  # opening checks the first pair against the calibration, nothing else
    _, frames = lab_recording()
    source.close()  # reopened when a frame is read again
    left, _ = source.pair(2)
    np.testing.assert_array_equal(left, frames[2].left)
    assert len(calls) == 4 and "stamped 1700000001.000000000 s" in calls[-2]
    source.close()


def test_a_storage_file_inside_a_bag_folder_opens_the_folder(tmp_path, inputs):
    path = write_bag(tmp_path / "lab", lab_messages("mcap"), "mcap")
    (storage_file,) = path.glob("*.mcap")
    with open_lab_bag(storage_file, inputs) as source:
        assert len(source) == N_FRAMES and source.name == "lab"


def test_pan_from_joint_states_and_the_mounts_pan_without_a_topic(tmp_path, inputs):
    run, _ = lab_recording()
    path = write_bag(tmp_path / "joints", lab_messages(pan="joint"))
    with open_lab_bag(path, inputs, pan_joint="pan") as source:
        np.testing.assert_allclose(source.pans, run.pans[:N_FRAMES], atol=1e-12)
        assert source.pan_recorded
    with pytest.raises(SequenceError, match=r"/head/pan: joint states of several joints \(tilt, pan\): pass "
                                            r"`pan_joint`"):
        open_lab_bag(path, inputs)
    with pytest.raises(SequenceError, match=r"/head/pan: no pan values \(no joint 'yaw'; the joints are pan, tilt\)"):
        open_lab_bag(path, inputs, pan_joint="yaw")
    path = write_bag(tmp_path / "nopan", lab_messages(pan=None))
    with open_lab_bag(path, inputs, pan_topic=None) as source:
        assert list(source.pans) == [0.0] * N_FRAMES
        assert not source.pan_recorded  # `stablemarks run` warns (unless pan.policy is fixed)


def test_run_on_a_bag_equals_the_run_on_our_folder(tmp_path, inputs):
    """Same images, same odometry, same pans ⇒ the same trajectory and landmarks."""
    folder = open_source(write_lab_sequence(tmp_path / "lab"))
    bag = write_bag(tmp_path / "lab.mcap.d", lab_messages("mcap"), "mcap")
    with open_lab_bag(bag, inputs) as source:
        from_bag = run_online(source)
    from_folder = run_online(folder)
    np.testing.assert_allclose(from_bag.poses, from_folder.poses, rtol=0, atol=1e-9)
    np.testing.assert_allclose(from_bag.covs, from_folder.covs, rtol=0, atol=1e-9)
    np.testing.assert_allclose(from_bag.stamps, from_folder.stamps, rtol=0, atol=1e-6)
    assert from_bag.ekf.landmark_ids == from_folder.ekf.landmark_ids
    assert from_bag.ekf.n_landmarks > 0 and any(r.observed for r in from_bag.records)  # the loop did work


def test_frames_outside_the_odometry_are_left_out(tmp_path, inputs):
    late = lab_stamps() + np.array([0.6, 0.6, 0.6, 0.6])  # odometry starts after frame 1
    path = write_bag(tmp_path / "late", lab_messages(odom_stamps=late))
    with open_lab_bag(path, inputs) as source:
        assert len(source) == 2
        assert source.notes[-1].startswith("2 of 4 frames left out: outside the odometry's time span")
        np.testing.assert_allclose(source.stamps[0], lab_stamps()[2], atol=1e-6)


# ------------------------------------------------------------------ decoding
@pytest.mark.parametrize("encoding", ["mono8", "rgb8", "bgr8", "rgba8", "mono16"])
def test_decode_image_encodings(encoding):
    rng = np.random.default_rng(1)
    m = Messages(ros1=False)
    bgr = rng.integers(0, 256, (5, 7, 3), dtype=np.uint8)
    if encoding == "mono8":
        img, want = bgr[..., 0], bgr[..., 0]
    elif encoding == "mono16":
        img = want = rng.integers(0, 65536, (5, 7), dtype=np.uint16)
    elif encoding == "bgr8":
        img = want = bgr
    elif encoding == "rgb8":
        img, want = bgr[..., ::-1], bgr
    else:
        alpha = np.full((5, 7, 1), 200, np.uint8)
        img, want = np.concatenate([bgr[..., ::-1], alpha], axis=2), np.concatenate([bgr, alpha], axis=2)
    for bigendian in (False, True):
        msg = m.image(7, np.ascontiguousarray(img), encoding, bigendian=bigendian, pad=3)
        np.testing.assert_array_equal(decode_image(msg, "sensor_msgs/msg/Image", "x"), want)


def test_decode_image_errors():
    m = Messages(ros1=False)
    msg = m.image(0, np.zeros((4, 4), np.uint8), "yuv422")
    with pytest.raises(ImageError, match=r"^cam: unsupported image encoding 'yuv422' \(expected one of mono8"):
        decode_image(msg, "sensor_msgs/msg/Image", "cam")
    msg = m.image(0, np.zeros((4, 4), np.uint8))
    msg.step = 2
    with pytest.raises(ImageError, match=r"a 4×4 mono8 image needs rows of at least 4 bytes"):
        decode_image(msg, "sensor_msgs/msg/Image", "cam")
    bad = m.compressed(0, np.zeros((4, 4), np.uint8))
    bad.data = np.frombuffer(b"not a png", np.uint8)
    with pytest.raises(ImageError, match=r"cannot decode the compressed image \(format 'mono8; png compressed '\)"):
        decode_image(bad, "sensor_msgs/msg/CompressedImage", "cam")


# ------------------------------------------------------------------ broken bags
def test_missing_topic_lists_the_bags_topics(tmp_path, inputs):
    path = write_bag(tmp_path / "lab", lab_messages())
    with pytest.raises(SequenceError) as err:
        open_lab_bag(path, inputs, left_topic="/camera/left")
    msg = str(err.value)
    assert "\n" not in msg
    assert msg == (f"{path}: no topic '/camera/left' (`left_topic`); the bag has: /head/pan (std_msgs/msg/Float64), "
                   "/odom (nav_msgs/msg/Odometry), /stereo/left/image_rect (sensor_msgs/msg/Image), "
                   "/stereo/right/image_rect (sensor_msgs/msg/Image)")
    with pytest.raises(SequenceError, match=re.escape("/odom (`left_topic`) is nav_msgs/msg/Odometry, expected "
                                                      "sensor_msgs/msg/Image or sensor_msgs/msg/CompressedImage")):
        open_lab_bag(path, inputs, left_topic=ODOM)
    with pytest.raises(InputError, match=r"a bag needs `odom_topic`, a topic of nav_msgs/msg/Odometry"):
        open_lab_bag(path, inputs, odom_topic=None)
    with pytest.raises(InputError, match=r"carries no calibration: no topic /stereo/left/camera_info \(the "
                                         r"sensor_msgs/CameraInfo beside /stereo/left/image_rect\): pass `calib` "
                                         r"or `left_info_topic`$"):
        open_lab_bag(path, inputs, calib=None)
    with pytest.raises(InputError, match=r"carries no map of walls: pass `map`"):
        open_lab_bag(path, inputs, map=None)


@pytest.mark.parametrize("stamps, what", [([0.0, 0.5, 0.5, 1.5], "duplicate timestamp: message 2"),
                                          ([0.0, 1.0, 0.5, 1.5], "timestamps out of order: message 2")])
def test_unsorted_or_duplicate_image_stamps(tmp_path, inputs, stamps, what):
    path = write_bag(tmp_path / "bad", lab_messages(left_stamps=1_700_000_000.0 + np.array(stamps)))
    with pytest.raises(SequenceError, match=rf"^{re.escape(str(path))}: {LEFT}: {what} is stamped"):
        open_lab_bag(path, inputs)


def test_duplicate_odometry_stamps(tmp_path, inputs):
    t = lab_stamps()
    path = write_bag(tmp_path / "bad", lab_messages(odom_stamps=[t[0], t[1], t[1], t[3]]))
    with pytest.raises(SequenceError, match=rf"{ODOM}: duplicate timestamp: message 2"):
        open_lab_bag(path, inputs)


def test_no_pairs_and_no_odometry_overlap(tmp_path, inputs):
    path = write_bag(tmp_path / "lab", lab_messages())
    with pytest.raises(SequenceError, match=r"no stereo pairs: no image on /stereo/left/image_rect \(4, stamped "
                                            r"1700000000\.000 to 1700000001\.500 s\) has one on "
                                            r"/stereo/right/image_rect \(5, .*\) within 0\.5 ms"):
        open_lab_bag(path, inputs, tolerance=0.0005)
    path = write_bag(tmp_path / "far", lab_messages(odom_stamps=lab_stamps() + 100.0))
    with pytest.raises(SequenceError, match=r"/odom: no frame within the odometry's time span"):
        open_lab_bag(path, inputs)


def test_calibration_of_another_size_fails_at_open(tmp_path, inputs):
    from stablemarks.io.calibration import save_camera_info_pair

    run, _ = lab_recording()
    cam = run.scenario.camera
    small = type(cam)(width=320, height=240, f=250.0, cu=159.5, cv=119.5, baseline=cam.baseline)
    save_camera_info_pair(tmp_path / "small", small)
    path = write_bag(tmp_path / "lab", lab_messages())
    with pytest.raises(ImageError, match=r"frame 0 \(/stereo/left/image_rect and /stereo/right/image_rect at "
                                         r"1700000000\.000000000 s\): left image is 640×480 px but the calibration "
                                         r".*small is for 320×240 px"):
        open_lab_bag(path, inputs, calib=tmp_path / "small")


def test_not_a_bag(tmp_path, inputs):
    path = tmp_path / "junk.bag"
    path.write_bytes(b"#ROSBAG V9.9\nnonsense")
    with pytest.raises(SequenceError, match=r"junk\.bag: cannot read the bag: "):
        open_lab_bag(path, inputs)


def test_the_streaming_api_on_a_ros2_bag_gives_the_trajectory_of_run(tmp_path, inputs):
    """``sm.open_sequence`` + ``sm.Localizer.step`` over a ROS 2 bag equals ``stablemarks run`` on it (1e-9)."""
    import stablemarks as sm
    from stablemarks.cli import main
    from stablemarks.io.trajectory import read_tum

    bag = write_bag(tmp_path / "lab", lab_messages())
    seq = sm.open_sequence(bag, left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, pan_topic=PAN,
                           calib=inputs["calib"], map=inputs["map"], mount=inputs["mount"])
    loc = sm.Localizer(seq.world_map, seq.camera, start_pose=seq.initial_pose, config=sm.Config())
    poses = [loc.step(f.stamp, f.left, f.right, odometry=f.odometry, pan=f.pan).pose for f in seq]
    seq.close()
    assert main(["run", str(bag), "--left-topic", LEFT, "--right-topic", RIGHT, "--odom-topic", ODOM,
                 "--pan-topic", PAN, "--calib", str(inputs["calib"]), "--map", str(inputs["map"]),
                 "--camera", str(inputs["mount"]), "--out", str(tmp_path / "out"), "--no-figures"]) == 0
    _, from_run = read_tum(tmp_path / "out" / "trajectory.tum")
    np.testing.assert_allclose(from_run, poses, rtol=0, atol=1e-9)
    assert loc.landmarks()
