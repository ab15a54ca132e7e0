"""``stablemarks run`` on recordings: a ROS 2 bag with every output option, ``--set`` overrides, the rerun
recording, and the broken inputs, each a one-line error with no output written."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
import yaml

from stablemarks.cli import main
from stablemarks.io.calibration import save_camera_info_pair
from stablemarks.io.trajectory import kitti_camera_poses, read_tum

from .test_sources import N_FRAMES, lab_recording, lab_stamps, write_lab_inputs, write_lab_sequence

pytest.importorskip("rosbags")
from .test_bags import LEFT, ODOM, PAN, RIGHT, lab_messages, write_bag  # noqa: E402


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    root = tmp_path_factory.mktemp("lab")
    inputs = write_lab_inputs(root)
    inputs["bag"] = write_bag(root / "lab_bag", lab_messages())
    return inputs


def bag_args(lab, out, *extra) -> list[str]:
    return ["run", str(lab["bag"]), "--left-topic", LEFT, "--right-topic", RIGHT, "--odom-topic", ODOM,
            "--pan-topic", PAN, "--calib", str(lab["calib"]), "--map", str(lab["map"]), "--camera", str(lab["mount"]),
            "--out", str(out), "--no-figures", *extra]


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("stablemarks run: error: ")
    return err.strip()


def test_run_on_a_ros2_bag_writes_the_run_folder(lab, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(bag_args(lab, out, "--kitti", "--set", "ekf.max_updates_per_frame=4",
                         "--set", "landmarks.min_length_similarity=0.6")) == 0
    stdout = capsys.readouterr().out
    assert "note: 0 left and 1 right images have no partner within 5 ms" in stdout
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "dead_reckoning.tum", "landmarks.yaml",
                                                     "log.jsonl", "trajectory.kitti", "trajectory.tum"]
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["ekf"]["max_updates_per_frame"] == 4
    assert config["landmarks"]["min_length_similarity"] == 0.6
    stamps, poses = read_tum(out / "trajectory.tum")
    np.testing.assert_allclose(stamps, lab_stamps(), rtol=0, atol=1e-6)  # as recorded: evo matches them
    log = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    np.testing.assert_allclose(poses, [r["pose"] for r in log], atol=1e-6)
    kitti = np.loadtxt(out / "trajectory.kitti")
    assert kitti.shape == (N_FRAMES, 12)
    mount = yaml.safe_load(lab["mount"].read_text())["mount"]
    expected = kitti_camera_poses(poses, [r["pan"] for r in log], mount=(mount["x"], mount["y"]))
    np.testing.assert_allclose(kitti.reshape(-1, 3, 4), np.asarray(expected).reshape(-1, 3, 4), atol=1e-6)
    assert yaml.safe_load((out / "landmarks.yaml").read_text())["frame"] == "map"


def write_map_server_map(folder, resolution: float = 0.05, origin=(-3.0, 2.0), size=(5.0, 5.0)):
    """The lab's reference walls drawn one cell wide into a ROS map_server map (PGM + YAML)."""
    import cv2

    run, _ = lab_recording()
    W, H = int(size[0] / resolution), int(size[1] / resolution)
    img = np.full((H, W), 254, np.uint8)

    def cell(p):
        u = (p[0] - origin[0]) / resolution - 0.5
        v = H - 0.5 - (p[1] - origin[1]) / resolution
        return int(round(u)), int(round(v))

    for plane in run.scenario.map.planes:
        if plane.reference:
            cv2.line(img, cell(plane.P1), cell(plane.P2), 0, 1)
    cv2.imwrite(str(folder / "building.pgm"), img)
    (folder / "building.yaml").write_text(f"image: building.pgm\nresolution: {resolution}\norigin: [{origin[0]}, "
                                          f"{origin[1]}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return folder / "building.yaml"


def test_readme_command_calibration_pair_map_server_map_and_ros2_bag(lab, tmp_path, capsys):
    """The README's one command: a camera_info pair, a mount, a map_server map and a ROS 2 bag. The lab's head
    pans and this bag carries its pan on a topic, not on /tf, so it takes ``--pan-topic`` (without it the walls
    are seen turned together by the pan, edges_not_found holds and nothing is entered)."""
    building = write_map_server_map(tmp_path)
    out = tmp_path / "results" / "my_run"
    assert main(["run", str(lab["bag"]), "--left-topic", LEFT, "--right-topic", RIGHT, "--odom-topic", ODOM,
                 "--pan-topic", PAN, "--calib", str(lab["calib"]), "--camera", str(lab["mount"]),
                 "--map", str(building), "--out", str(out), "--no-figures"]) == 0
    assert "warning:" not in capsys.readouterr().err
    stamps, poses = read_tum(out / "trajectory.tum")
    assert len(stamps) == N_FRAMES
    landmarks = yaml.safe_load((out / "landmarks.yaml").read_text())["landmarks"]
    # walls extracted from the grid: each of the lab's two walls has two faces
    assert landmarks and {lm["plane"] for lm in landmarks} <= {"wall01", "wall02", "wall03", "wall04"}


def test_run_on_our_folder_keeps_its_behaviour(tmp_path, capsys):
    folder = write_lab_sequence(tmp_path / "lab")
    out = tmp_path / "out"
    assert main(["run", str(folder), "--out", str(out), "--method", "dead_reckoning", "--no-figures"]) == 0
    assert (out / "groundtruth.tum").is_file()
    stamps, poses = read_tum(out / "trajectory.tum")
    run, _ = lab_recording()
    np.testing.assert_allclose(poses[:, :2], [p.translation for p in run.dead_reckoning[:N_FRAMES]], atol=1e-6)


@pytest.mark.parametrize("option, message", [
    ("ekf.max_updates_per_frame", "--set: expected SECTION.KEY=VALUE, got 'ekf.max_updates_per_frame'"),
    ("ekf=3", "--set: expected SECTION.KEY=VALUE, got 'ekf=3'"),
    ("ekf.nope=3", "--set: ekf.nope: unknown setting"),
    ("ekf.max_updates_per_frame=many", "--set: ekf.max_updates_per_frame: expected a number, got 'many'"),
])
def test_bad_overrides(lab, tmp_path, capsys, option, message):
    out = tmp_path / "out"
    assert main(bag_args(lab, out, "--set", option)) == 1
    assert message in one_line_error(capsys)
    assert not out.exists()


def test_missing_topic_is_one_line_listing_the_topics(lab, tmp_path, capsys):
    out = tmp_path / "out"
    args = bag_args(lab, out)
    args[args.index(LEFT)] = "/camera/left/image_raw"
    assert main(args) == 1
    err = one_line_error(capsys)
    assert err.endswith("no topic '/camera/left/image_raw' (--left-topic); the bag has: /head/pan "
                        "(std_msgs/msg/Float64), /odom (nav_msgs/msg/Odometry), /stereo/left/image_rect "
                        "(sensor_msgs/msg/Image), /stereo/right/image_rect (sensor_msgs/msg/Image)")
    assert not out.exists()


def test_calibration_of_another_size_is_one_line(lab, tmp_path, capsys):
    run, _ = lab_recording()
    cam = run.scenario.camera
    save_camera_info_pair(tmp_path / "small", type(cam)(width=320, height=240, f=250.0, cu=159.5, cv=119.5))
    out = tmp_path / "out"
    args = bag_args(lab, out)
    args[args.index(str(lab["calib"]))] = str(tmp_path / "small")
    assert main(args) == 1
    assert "left image is 640×480 px but the calibration" in one_line_error(capsys)
    assert not out.exists()


def test_unsorted_stamps_are_one_line(lab, tmp_path, capsys):
    bag = write_bag(tmp_path / "unsorted", lab_messages(left_stamps=lab_stamps()[[0, 2, 1, 3]]))
    out = tmp_path / "out"
    args = bag_args(lab, out)
    args[1] = str(bag)
    assert main(args) == 1
    assert f"{LEFT}: timestamps out of order: message 2" in one_line_error(capsys)
    assert not out.exists()


def test_a_sequence_folder_refuses_bag_options(tmp_path, capsys):
    folder = write_lab_sequence(tmp_path / "lab")
    assert main(["run", str(folder), "--odom-topic", "/odom", "--out", str(tmp_path / "out")]) == 1
    assert "--odom-topic does not apply to a sequence folder" in one_line_error(capsys)
    assert not (tmp_path / "out").exists()


def test_save_rrd_without_rerun_names_the_extra(lab, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun → ImportError
    out = tmp_path / "out"
    assert main(bag_args(lab, out, "--save-rrd", str(tmp_path / "run.rrd"))) == 1
    assert one_line_error(capsys) == ("stablemarks run: error: --save-rrd needs the rerun-sdk package: "
                                      "pip install 'stablemarks[rerun]'")
    assert not out.exists() and not (tmp_path / "run.rrd").exists()


def test_save_rrd_writes_a_rerun_recording(lab, tmp_path):
    pytest.importorskip("rerun")
    rrd = tmp_path / "run.rrd"
    assert main(bag_args(lab, tmp_path / "out", "--save-rrd", str(rrd))) == 0
    data = rrd.read_bytes()
    assert data[:4] == b"RRF2" and len(data) > 100_000  # the images are in it
    for entity in (b"world/walls", b"world/landmarks", b"world/trajectory/estimate", b"camera/left/segments",
                   b"camera/right/landmarks"):
        assert entity in data
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left
