"""ROS bags that carry their own calibration (``sensor_msgs/CameraInfo``), mount (``/tf_static``, ``/tf``),
start pose (``/initialpose``) and ground truth: written with rosbags' writers from the short simulated lab run
of test_bags, run with only the topic flags and ``--map``, against the same run with the calibration, mount
and pose files; ``convert`` to a sequence folder and back; and the one-line errors."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
import yaml

from stablemarks.cli import main
from stablemarks.errors import InputError, SequenceError
from stablemarks.io.calibration import StereoCalibration, load_camera_info_pair, save_calibration
from stablemarks.io.sources import open_sequence
from stablemarks.io.trajectory import read_tum

from .test_bags import LEFT, ODOM, PAN, RIGHT, Messages, _ns, lab_messages, write_bag
from .test_sources import N_FRAMES, lab_recording, lab_stamps, lab_truth, write_lab_inputs

pytest.importorskip("rosbags")

LEFT_INFO, RIGHT_INFO = "/stereo/left/camera_info", "/stereo/right/camera_info"
GT = "/groundtruth"
OPTICAL = "left_optical"
LINK_TO_OPTICAL = (-0.5, 0.5, -0.5, 0.5)
"""``camera_link`` (x forward, y left, z up) → its optical frame (z forward, x right, y down): REP-103."""
SIGMA = "0.1,0.08,2deg"
"""The start pose's σ in the bags' /initialpose (and given as --pose-sigma to the runs from files)."""


def _yaw(theta: float):
    return (0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2))


def _sigma_cov():
    from stablemarks.commands._common import parse_sigmas

    return np.diag(parse_sigmas(SIGMA) ** 2)


def ros_messages(storage: str = "sqlite3", *, info: bool = True, tf: str | None = "static",
                 initial_pose: bool = True, groundtruth: str | None = "odometry", pan: str | None = None):
    """The lab recording with what a robot's bag carries beside the images and odometry: the CameraInfo of
    each camera, the tf tree (``tf``: ``"static"`` base_link → mast → camera_link → left_optical, all on
    /tf_static, with an odom → base_link on /tf; ``"pan"``: base_link → pan_link on /tf turning by the run's
    pans; ``"broken"``: no link from base_link to the camera), /initialpose (one before the first frame, the
    true start; one after it, to be ignored) and the true poses on /groundtruth."""
    run, _ = lab_recording()
    cam = run.scenario.camera
    m = Messages(storage == "ros1")
    rows = lab_messages(storage, pan=pan, frame=OPTICAL)
    stamps = lab_stamps()
    if info:
        calib = StereoCalibration.from_stereo_camera(cam)
        for k, t in enumerate(stamps):
            for topic, K, D, R, P, dt in ((LEFT_INFO, calib.K1, calib.D1, calib.R1, calib.P1, 0.0),
                                          (RIGHT_INFO, calib.K2, calib.D2, calib.R2, calib.P2, 0.001)):
                rows.append((topic, _ns(t + dt) + 3_000_000 + k, m.camera_info(_ns(t + dt), K, D, R, P,
                                                                               calib.image_size, OPTICAL)))
    t0 = _ns(stamps[0]) - 2_000_000_000
    optical = ("camera_link", OPTICAL, (0.0, 0.0, 0.0), LINK_TO_OPTICAL)
    if tf == "static":
        # base_link → mast (0.1, −0.05, 0.6 m; yaw 0.3) → camera_link: the mount's position, pan 0.
        mast = np.array([0.1, -0.05, 0.6])
        c, s = math.cos(0.3), math.sin(0.3)
        offset = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ (
            np.array([cam.mount_x, cam.mount_y, cam.mount_height]) - mast)
        static = [("base_link", "mast", tuple(mast), _yaw(0.3)), ("mast", "camera_link", tuple(offset), _yaw(-0.3)),
                  optical]
        rows.append(("/tf_static", t0, m.transforms(t0, static)))
        for k, t in enumerate(stamps):  # the robot in odom: on /tf, above base_link in the tree
            rows.append(("/tf", _ns(t) + 700, m.transforms(_ns(t), [("odom", "base_link", (k * 0.1, 0.0, 0.0),
                                                                     _yaw(0.0))])))
    elif tf == "pan":
        static = [("pan_link", "camera_link", (0.0, 0.0, 0.0), _yaw(0.0)), optical]
        rows.append(("/tf_static", t0, m.transforms(t0, static)))
        for k, t in enumerate(stamps):
            edge = ("base_link", "pan_link", (cam.mount_x, cam.mount_y, cam.mount_height), _yaw(run.pans[k]))
            rows.append(("/tf", _ns(t) + 800, m.transforms(_ns(t), [edge])))
    elif tf == "broken":
        rows.append(("/tf_static", t0, m.transforms(t0, [("odom", "base_link", (0.0, 0.0, 0.0), _yaw(0.0)),
                                                         optical])))
    if initial_pose:
        rows.append(("/initialpose", t0, m.pose_with_covariance(t0, run.poses[0].as_array(), _sigma_cov())))
        later = _ns(stamps[1])
        rows.append(("/initialpose", later, m.pose_with_covariance(later, (5.0, 5.0, 0.0), np.eye(3))))
    truth = lab_truth()
    for k, t in enumerate(stamps):
        if groundtruth == "odometry":
            rows.append((GT, _ns(t) + 900, m.odometry(_ns(t), truth[k], frame="map")))
        elif groundtruth == "pose":
            rows.append((GT, _ns(t) + 900, m.pose_stamped(_ns(t), truth[k])))
    return rows


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return write_lab_inputs(tmp_path_factory.mktemp("inputs"))


TOPICS = ["--left-topic", LEFT, "--right-topic", RIGHT, "--odom-topic", ODOM]


def run_cli(tmp_path, name, *args):
    out = tmp_path / name
    assert main(["run", *map(str, args), "--out", str(out), "--no-figures"]) == 0
    return out


def cli_error(capsys, *args) -> str:
    assert main([*map(str, args)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    return err.strip()


def _trajectory(out):
    return read_tum(out / "trajectory.tum")


# ------------------------------------------------------------------ run BAG with the bag's own inputs
@pytest.mark.parametrize("storage", ["sqlite3", "ros1"])
def test_a_bag_with_its_own_calibration_mount_and_start_runs_as_with_the_files(tmp_path, inputs, storage):
    """Only the topic flags and --map: the CameraInfo, the tf tree and /initialpose give what --calib, --camera,
    --pose and --pose-sigma give; the ground-truth topic is written at the frame stamps."""
    run, _ = lab_recording()
    name = "lab.bag" if storage == "ros1" else "lab"
    bag = write_bag(tmp_path / name, ros_messages(storage, groundtruth="odometry" if storage == "ros1" else "pose"),
                    storage)
    own = run_cli(tmp_path, "own", bag, *TOPICS, "--map", inputs["map"], "--groundtruth-topic", GT)
    start = ",".join(repr(float(v)) for v in run.poses[0].as_array())
    files = run_cli(tmp_path, "files", bag, *TOPICS, "--map", inputs["map"], "--calib", inputs["calib"],
                    "--camera", inputs["mount"], f"--pose={start}", "--pose-sigma", SIGMA)
    (t_own, p_own), (t_files, p_files) = _trajectory(own), _trajectory(files)
    np.testing.assert_array_equal(t_own, t_files)
    np.testing.assert_allclose(p_own, p_files, rtol=0, atol=1e-9)
    t_gt, p_gt = read_tum(own / "groundtruth.tum")
    np.testing.assert_allclose(t_gt, lab_stamps(), rtol=0, atol=1e-6)
    np.testing.assert_allclose(p_gt, lab_truth(), rtol=0, atol=1e-9)
    assert not (files / "groundtruth.tum").exists()
    text = (own / "config.yaml").read_text()
    sources = yaml.safe_load("\n".join(line[2:] for line in text.splitlines() if line.startswith("# ")))["sources"]
    assert sources["calibration"] == f"camera_info {LEFT_INFO}, {RIGHT_INFO} (images rectified: their P)"
    assert sources["mount"] == f"tf base_link→{OPTICAL}"
    assert sources["start_pose"].startswith("/initialpose (stamped 1699999998.000000000 s, frame map)")
    assert sources["start_covariance"] == "/initialpose" and sources["groundtruth"] == f"topic {GT}"
    assert yaml.safe_load(text)["ekf"]  # still a configuration: the sources are comments
    files_sources = yaml.safe_load("\n".join(line[2:] for line in (files / "config.yaml").read_text().splitlines()
                                             if line.startswith("# ")))["sources"]
    assert files_sources["calibration"] == f"file {inputs['calib']}"
    assert files_sources["start_pose"] == "given (--pose)"
    assert files_sources["start_covariance"] == f"--pose-sigma {SIGMA}"


def test_the_bags_inputs_on_the_source(tmp_path, inputs):
    run, _ = lab_recording()
    bag = write_bag(tmp_path / "lab", ros_messages(groundtruth="odometry"))
    with open_sequence(bag, left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, map=inputs["map"],
                       groundtruth_topic=GT) as source:
        cam, want = source.camera, run.scenario.camera  # the mount through three tf links
        for field in ("f", "cu", "cv", "baseline", "width", "height"):
            assert getattr(cam, field) == getattr(want, field)
        for field in ("mount_x", "mount_y", "mount_height", "pan"):
            assert getattr(cam, field) == pytest.approx(getattr(want, field), abs=1e-12)
        assert source.calibration.is_rectified
        np.testing.assert_allclose(source.initial_pose, run.poses[0].as_array(), rtol=0, atol=1e-12)
        np.testing.assert_allclose(source.initial_cov, _sigma_cov(), rtol=0, atol=0)
        np.testing.assert_allclose(source.groundtruth, lab_truth(), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(source.true_pose(2), source.groundtruth[2])
        np.testing.assert_allclose(source.pans, 0.0, rtol=0, atol=1e-12)
    # Given ones win: the start pose (without /initialpose's covariance), the calibration, the mount.
    with open_sequence(bag, left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, map=inputs["map"],
                       start_pose=(1.0, 2.0, 0.5), calib=inputs["calib"]) as source:
        assert source.initial_cov is None and list(source.initial_pose) == [1.0, 2.0, 0.5]
        assert source.sources["calibration"] == f"file {inputs['calib']}"
        assert source.sources["mount"] == f"tf base_link→{OPTICAL}"  # no mount.yaml beside the calibration
        assert source.sources["start_pose"] == "given (`start_pose`)"
    with open_sequence(bag, left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, map=inputs["map"],
                       mount=inputs["mount"]) as source:
        assert source.camera == run.scenario.camera and source.sources["mount"] == f"file {inputs['mount']}"


def test_a_pan_joint_on_tf_gives_the_pan_of_each_frame(tmp_path, inputs):
    run, _ = lab_recording()
    bag = write_bag(tmp_path / "pan", ros_messages(tf="pan", pan="float64"))
    options = dict(left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, map=inputs["map"])
    with open_sequence(bag, **options) as source:
        np.testing.assert_allclose(source.pans, run.pans[:N_FRAMES], rtol=0, atol=1e-12)
        assert source.camera.pan == pytest.approx(run.pans[0], abs=1e-12)
        assert (source.camera.mount_x, source.camera.mount_y) == pytest.approx((0.0, 0.0), abs=1e-12)
        assert source.camera.mount_height == pytest.approx(1.0, abs=1e-12)
        assert source.sources["pan"] == f"tf base_link→{OPTICAL} (per frame, /tf)"
    with open_sequence(bag, **options, pan_topic=PAN) as source:  # --pan-topic wins
        np.testing.assert_allclose(source.pans, run.pans[:N_FRAMES], rtol=0, atol=0)
        assert source.sources["pan"] == f"topic {PAN}"
    # The same run as with the pan topic and the files.
    own = run_cli(tmp_path, "own", bag, *TOPICS, "--map", inputs["map"])
    start = ",".join(repr(float(v)) for v in run.poses[0].as_array())
    files = run_cli(tmp_path, "files", bag, *TOPICS, "--pan-topic", PAN, "--map", inputs["map"], "--calib",
                    inputs["calib"], "--camera", inputs["mount"], f"--pose={start}", "--pose-sigma", SIGMA)
    np.testing.assert_allclose(_trajectory(own)[1], _trajectory(files)[1], rtol=0, atol=1e-9)


# ------------------------------------------------------------------ convert
def test_convert_then_run_the_folder_equals_run_on_the_bag(tmp_path, inputs, capsys):
    bag = write_bag(tmp_path / "lab.mcap.d", ros_messages("mcap"), "mcap")
    folder = tmp_path / "lab_seq"
    assert main(["convert", str(bag), *TOPICS, "--map", str(inputs["map"]), "--groundtruth-topic", GT,
                 "--out", str(folder)]) == 0
    printed = capsys.readouterr().out
    assert "wrote" in printed
    # the start pose's covariance (/initialpose) is kept in sequence.yaml: the folder runs as the bag, no flag
    import yaml as _yaml

    np.testing.assert_allclose(_yaml.safe_load((folder / "sequence.yaml").read_text())["initial_cov"], _sigma_cov(),
                               rtol=0, atol=0)
    assert sorted(p.name for p in folder.iterdir()) == ["calib", "frames.csv", "groundtruth.tum", "left", "map.yaml",
                                                        "odometry.csv", "right", "sequence.yaml"]
    assert sorted(p.name for p in (folder / "calib").iterdir()) == ["left.yaml", "mount.yaml", "right.yaml"]
    assert len(list((folder / "left").iterdir())) == N_FRAMES
    from_bag = run_cli(tmp_path, "bag", bag, *TOPICS, "--map", inputs["map"], "--groundtruth-topic", GT)
    from_folder = run_cli(tmp_path, "folder", folder)
    (t_bag, p_bag), (t_dir, p_dir) = _trajectory(from_bag), _trajectory(from_folder)
    np.testing.assert_array_equal(t_bag, t_dir)
    np.testing.assert_allclose(p_bag, p_dir, rtol=0, atol=1e-9)
    np.testing.assert_allclose(read_tum(from_folder / "groundtruth.tum")[1], lab_truth(), rtol=0, atol=1e-9)
    # the bag gives no pan (no --pan-topic): the folder says so too (no pan column), and both runs warn of it
    assert "pan" not in (folder / "frames.csv").read_text().splitlines()[0].split(",")
    assert capsys.readouterr().err.count("warning: pan_unrecorded held") == 2
    # --out is checked before any work, and an existing folder is not replaced without --force.
    err = cli_error(capsys, "convert", bag, *TOPICS, "--map", inputs["map"], "--out", folder)
    assert err.startswith("stablemarks convert: error: ") and "not empty" in err
    (tmp_path / "file").write_text("x")
    err = cli_error(capsys, "convert", bag, *TOPICS, "--map", inputs["map"], "--out", tmp_path / "file")
    assert err == f"stablemarks convert: error: --out: {tmp_path / 'file'} exists and is not a folder"


# ------------------------------------------------------------------ errors
def test_a_bag_without_camera_info_needs_calib(tmp_path, inputs, capsys):
    bag = write_bag(tmp_path / "lab", ros_messages(info=False))
    err = cli_error(capsys, "run", bag, *TOPICS, "--map", inputs["map"], "--out", tmp_path / "out")
    assert err == (f"stablemarks run: error: the bag {bag} carries no calibration: no topic {LEFT_INFO} (the "
                   f"sensor_msgs/CameraInfo beside {LEFT}): pass --calib or --left-info-topic")
    err = cli_error(capsys, "run", bag, *TOPICS, "--map", inputs["map"], "--left-info-topic", "/nope",
                    "--out", tmp_path / "out")
    assert re.match(r"stablemarks run: error: \S*/lab: no topic '/nope' \(--left-info-topic\); the bag has: ", err)


def test_a_tf_tree_without_a_path_to_the_camera(tmp_path, inputs, capsys):
    bag = write_bag(tmp_path / "lab", ros_messages(tf="broken"))
    err = cli_error(capsys, "run", bag, *TOPICS, "--map", inputs["map"], "--out", tmp_path / "out")
    assert err == (f"stablemarks run: error: {bag}: no tf path from 'base_link' to '{OPTICAL}' (/tf_static, /tf): "
                   f"'base_link' hangs under 'odom' and '{OPTICAL}' under 'camera_link', not joined")
    err = cli_error(capsys, "run", bag, *TOPICS, "--map", inputs["map"], "--base-frame", "base_footprint",
                    "--out", tmp_path / "out")
    assert err.endswith("no tf path from 'base_footprint' to 'left_optical' (/tf_static, /tf): the tf tree has no "
                        "frame 'base_footprint' (frames: base_link, camera_link, left_optical, odom)")
    with pytest.raises(InputError, match=r"carries no camera mount: no /tf_static or /tf topic"):
        open_sequence(write_bag(tmp_path / "notf", ros_messages(tf=None)), left_topic=LEFT, right_topic=RIGHT,
                      odom_topic=ODOM, map=inputs["map"])


def test_bad_camera_info_is_a_one_line_error_naming_the_topic_and_field(tmp_path, inputs, monkeypatch):
    run, _ = lab_recording()
    calib = StereoCalibration.from_stereo_camera(run.scenario.camera)
    m = Messages(ros1=False)

    def bag_with(name, left_K=calib.K1, left_P=calib.P1, right_size=calib.image_size, right_P=calib.P2):
        rows = [r for r in ros_messages() if r[0] not in (LEFT_INFO, RIGHT_INFO)]
        t = _ns(lab_stamps()[0])
        rows += [(LEFT_INFO, t, m.camera_info(t, left_K, calib.D1, calib.R1, left_P, calib.image_size)),
                 (RIGHT_INFO, t, m.camera_info(t, calib.K2, calib.D2, calib.R2, right_P, right_size))]
        return write_bag(tmp_path / name, rows)

    options = dict(left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, map=inputs["map"])
    zero = calib.P1.copy()
    zero[0, 0] = 0.0
    with pytest.raises(InputError, match=rf"{LEFT_INFO}: P\[0,0\]: expected a positive focal length fx, got 0\.0$"):
        open_sequence(bag_with("zero", left_P=zero), **options)
    from stablemarks.io import bags

    monkeypatch.setattr(bags, "_is_rectified_topic", lambda topic: False)  # raw images: K is read
    with pytest.raises(InputError, match=rf"{LEFT_INFO}: K\[0,0\]: expected a positive focal length fx, got 0\.0$"):
        open_sequence(bag_with("zeroK", left_K=np.zeros((3, 3))), **options)
    monkeypatch.undo()
    with pytest.raises(SequenceError, match=rf"image sizes differ: {LEFT_INFO} width/height is 640×480, "
                                            rf"{RIGHT_INFO} is 320×480"):
        open_sequence(bag_with("size", right_size=(320, 480)), **options)
    swapped = calib.P2.copy()
    swapped[0, 3] = -swapped[0, 3]
    with pytest.raises(InputError, match=rf"{RIGHT_INFO}: P: expected Tx = P\[0,3\] = −f·baseline < 0"):
        open_sequence(bag_with("swapped", right_P=swapped), **options)


# ------------------------------------------------------------------ the pieces
def test_camera_info_gives_the_calibration_the_files_give(tmp_path):
    """A raw calibration (distortion, rectifying rotations) through CameraInfo messages equals it through
    left.yaml/right.yaml: the same checks and assembly."""
    from stablemarks.io.bags import _camera_info_fields, calibration_from_camera_info

    K1 = np.array([[510.0, 0.0, 322.0], [0.0, 508.0, 241.0], [0.0, 0.0, 1.0]])
    K2 = np.array([[505.0, 0.0, 318.0], [0.0, 506.0, 238.0], [0.0, 0.0, 1.0]])
    D1, D2 = np.array([-0.1, 0.02, 0.001, -0.002, 0.0]), np.array([-0.09, 0.01, 0.0, 0.001, 0.0])
    c, s = math.cos(0.01), math.sin(0.01)
    R1, R2 = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]), np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    P1 = np.array([[480.0, 0.0, 320.0, 0.0], [0.0, 480.0, 240.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    P2 = P1.copy()
    P2[0, 3] = -480.0 * 0.12
    files = StereoCalibration((640, 480), K1, D1, K2, D2, R2.T @ R1, R2.T @ np.array([-0.12, 0, 0]), R1, R2, P1, P2)
    save_calibration(files, tmp_path / "calib")
    from_files = load_camera_info_pair(tmp_path / "calib")
    m = Messages(ros1=True)
    infos = [{**_camera_info_fields(m.camera_info(0, K, D, R, P, (640, 480), "cam"))} | {"topic": t}
             for K, D, R, P, t in ((K1, D1, R1, P1, "/l/camera_info"), (K2, D2, R2, P2, "/r/camera_info"))]
    from_msgs = calibration_from_camera_info(infos, "bag")
    for name in ("K1", "D1", "K2", "D2", "R", "T", "R1", "R2", "P1", "P2"):
        np.testing.assert_array_equal(getattr(from_msgs, name), getattr(from_files, name), err_msg=name)
    assert from_msgs.stereo_camera() == from_files.stereo_camera()
    assert not from_msgs.is_rectified
    rect = calibration_from_camera_info(infos, "bag", rectified=True)  # image_rect topics: P's camera
    assert rect.is_rectified and rect.stereo_camera() == from_files.stereo_camera()


@pytest.mark.parametrize("topic, msgtype, info", [
    ("/ns/left/image_raw", "sensor_msgs/msg/Image", "/ns/left/camera_info"),
    ("/ns/left/image_rect/compressed", "sensor_msgs/msg/CompressedImage", "/ns/left/camera_info"),
    ("/image", "sensor_msgs/msg/Image", "/camera_info"),
])
def test_the_camera_info_beside_an_image_topic(topic, msgtype, info):
    from stablemarks.io.bags import camera_info_topic

    assert camera_info_topic(topic, msgtype) == info


def test_initial_pose_is_the_last_before_the_first_frame_moved_by_the_odometry():
    from stablemarks.io.bags import _initial_pose

    t_odom = np.array([0.0, 1.0, 2.0])
    odom = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    cov = np.zeros(36)
    msgs = [(0, "map", (5.0, 5.0, math.pi / 2), cov), (int(1e9), "map", (10.0, 0.0, math.pi / 2), cov),
            (int(3e9), "map", (0.0, 0.0, 0.0), cov)]
    pose, c, where, notes = _initial_pose(msgs, 2.0, t_odom, odom, odom[2], 0.005, "bag")
    np.testing.assert_allclose(pose, [10.0, 1.0, math.pi / 2], atol=1e-12)  # 1 m forward, heading +y
    assert c is None and where.startswith("/initialpose (stamped 1.000000000 s")
    assert notes == ["/initialpose has no covariance (all zero): the start covariance is the default"]
    bad = np.zeros((6, 6))
    bad[0, 0], bad[1, 1], bad[5, 5] = 1.0, -1.0, 1.0
    with pytest.raises(SequenceError, match=r"bag: /initialpose stamped 1\.000000000 s: pose\.covariance: expected "
                                            r"a symmetric positive-definite x, y, yaw block"):
        _initial_pose([(int(1e9), "map", (0.0, 0.0, 0.0), bad.ravel())], 2.0, t_odom, odom, odom[2], 0.005, "bag")
    assert _initial_pose(msgs[2:], 2.0, t_odom, odom, odom[2], 0.005, "bag")[0] is None


def test_a_tilted_camera_is_refused(tmp_path, inputs):
    run, _ = lab_recording()
    m = Messages(ros1=False)
    rows = [r for r in ros_messages(tf=None)]
    tilt = (math.sin(math.radians(5) / 2), 0.0, 0.0, math.cos(math.radians(5) / 2))  # roll 5° about x
    rows.append(("/tf_static", 0, m.transforms(0, [("base_link", "camera_link", (0.0, 0.0, 1.0), tilt),
                                                   ("camera_link", OPTICAL, (0.0, 0.0, 0.0), LINK_TO_OPTICAL)])))
    bag = write_bag(tmp_path / "tilted", rows)
    with pytest.raises(SequenceError, match=re.escape(f"tf base_link→{OPTICAL}: the camera is 5.0° from level")):
        open_sequence(bag, left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, map=inputs["map"])


def test_ground_truth_that_misses_frames_is_written_for_the_frames_it_covers(tmp_path, inputs, capsys):
    first = _ns(lab_stamps()[0])
    rows = [r for r in ros_messages() if not (r[0] == GT and r[1] < first + 1_000_000)]  # none at frame 0
    bag = write_bag(tmp_path / "lab", rows)
    with open_sequence(bag, left_topic=LEFT, right_topic=RIGHT, odom_topic=ODOM, map=inputs["map"],
                       groundtruth_topic=GT) as source:
        assert np.isnan(source.groundtruth[0]).all() and source.true_pose(0) is None
        np.testing.assert_allclose(source.groundtruth[1:], lab_truth()[1:], rtol=0, atol=1e-12)
        assert source.notes[-1].startswith(f"1 of {N_FRAMES} frames have no ground truth: outside the time span "
                                           f"of {GT}")
    out = run_cli(tmp_path, "out", bag, *TOPICS, "--map", inputs["map"], "--groundtruth-topic", GT)
    stamps, poses = read_tum(out / "groundtruth.tum")
    np.testing.assert_allclose(stamps, lab_stamps()[1:], rtol=0, atol=1e-6)
    np.testing.assert_allclose(poses, lab_truth()[1:], rtol=0, atol=1e-9)
    # convert keeps no partial ground truth (a folder's covers every frame), and says so.
    capsys.readouterr()
    assert main(["convert", str(bag), *TOPICS, "--map", str(inputs["map"]), "--groundtruth-topic", GT,
                 "--out", str(tmp_path / "seq")]) == 0
    assert "1 of 4 frames have no ground truth: groundtruth.tum is not written" in capsys.readouterr().out
    assert not (tmp_path / "seq" / "groundtruth.tum").exists()
    err = cli_error(capsys, "convert", tmp_path / "seq", "--out", tmp_path / "again")
    assert err.endswith("seq: already a sequence folder (convert reads bags and KITTI or EuRoC folders)")
