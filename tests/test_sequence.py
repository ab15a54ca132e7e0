"""Recorded-sequence folders: the simulator's round trip, raw images, ground truth, every broken folder,
atomic writing, and the ``simulate`` command."""

from __future__ import annotations

import json
import math
import re
import shutil
from dataclasses import replace

import cv2
import numpy as np
import pytest
import yaml

from stablemarks.cli import main
from stablemarks.errors import InputError, SequenceError
from stablemarks.geometry import SE2, StereoCamera, wrap_angle
from stablemarks.io.calibration import StereoCalibration
from stablemarks.io.sequence import FRAME_PERIOD, load_sequence, write_sequence
from stablemarks.io.trajectory import write_tum
from stablemarks.maps import Map, ReferencePlane
from stablemarks.sim import parse_scenario, simulate_run
from stablemarks.sim.export import write_simulated_sequence
from stablemarks.sim.scenario import SCENARIO_DIR


def tiny_scenario_data() -> dict:
    """The lab at 160×120 px, driving 0.3 m and turning right 25°: 7 frames, fast to render."""
    data = yaml.safe_load((SCENARIO_DIR / "lab.yaml").read_text())
    data["name"] = "tiny"
    data["camera"].update(width=160, height=120, f=125.0, cu=79.5, cv=59.5)
    data["robot"].update(path=[{"forward": 0.3}, {"turn_deg": -25}], frame_spacing=0.1, frame_turn_deg=10)
    return data


@pytest.fixture(scope="module")
def sim_run():
    return simulate_run(parse_scenario(tiny_scenario_data(), "tiny.yaml", default_name="tiny"))


@pytest.fixture(scope="module")
def sim_folder(sim_run, tmp_path_factory):
    calls = []
    out = write_simulated_sequence(sim_run, tmp_path_factory.mktemp("sim") / "tiny", on_frame=calls.append)
    assert calls == list(range(len(sim_run)))
    return out


# ------------------------------------------------------------------ round trips
def test_simulated_sequence_round_trip(sim_run, sim_folder):
    seq = load_sequence(sim_folder)
    n = len(sim_run)
    sc = sim_run.scenario
    assert len(seq) == n == 7 and seq.name == "tiny"
    np.testing.assert_array_equal(seq.stamps, FRAME_PERIOD * np.arange(n))
    np.testing.assert_array_equal(seq.indices, np.arange(n))
    assert seq.camera == sc.camera
    assert seq.world_map == sc.map
    assert seq.calibration.is_rectified
    assert seq.initial_pose == sc.robot.start
    np.testing.assert_array_equal(seq.pans, sim_run.pans)
    assert seq.camera_at(3) == sc.camera.with_pan(sim_run.pans[3])
    assert seq.odometry_increment(0) == SE2()
    for k in range(1, n):
        np.testing.assert_allclose(seq.odometry_increment(k).as_array(), sim_run.odometry[k].as_array(),
                                   rtol=0, atol=1e-12)
    truth = np.array([p.as_array() for p in sim_run.poses])
    np.testing.assert_allclose(seq.groundtruth[:, :2], truth[:, :2], rtol=0, atol=1e-6)
    assert np.all(np.abs(wrap_angle(seq.groundtruth[:, 2] - truth[:, 2])) < 1e-8)
    for k in (0, n - 1):
        frame = sim_run.render(k)
        left, right = seq.frame(k)
        np.testing.assert_array_equal(left, frame.left)
        np.testing.assert_array_equal(right, frame.right)
    doc = json.loads(seq.truth_path.read_text())
    assert doc["scenario"] == "tiny" and doc["n_frames"] == n and len(doc["frames"]) == n
    assert doc["frames"][2]["stamp"] == 2 * FRAME_PERIOD and doc["frames"][2]["left"] == "left/000002.png"
    assert doc["frames"][2]["pose"] == truth[2].tolist()
    with pytest.raises(IndexError):
        seq.frame(n)
    with pytest.raises(ValueError, match="read-only"):
        seq.stamps[0] = 1.0


def test_the_turn_is_in_the_odometry(sim_folder):
    seq = load_sequence(sim_folder)
    turn = sum(seq.odometry_increment(k).theta for k in range(4, len(seq)))
    assert turn == pytest.approx(math.radians(-25), abs=math.radians(3))


CAMERA = StereoCamera(width=64, height=48, f=60.0, cu=31.5, cv=23.5, baseline=0.1, mount_x=0.05,
                      mount_height=0.9, pan=0.2)
MAP = Map((ReferencePlane("w", (0.0, 2.0), (1.0, 2.0), free_edges=("p1",)),))


def synthetic(n=4, seed=0, **kwargs) -> dict:
    rng = np.random.default_rng(seed)
    images = [tuple(rng.integers(0, 256, (CAMERA.height, CAMERA.width), dtype=np.uint8) for _ in range(2))
              for _ in range(n)]
    odometry = np.column_stack([np.arange(n) * 0.1, np.zeros(n), wrap_angle(3.0 + 0.1 * np.arange(n))])
    args = dict(name="synthetic", camera=CAMERA, world_map=MAP, stamps=100.0 + 0.25 * np.arange(n),
                odometry=odometry, pans=np.linspace(-0.3, 0.3, n), images=images)
    args.update(kwargs)
    return args


def test_raw_images_are_rectified_through_the_calibration(tmp_path):
    ideal = StereoCalibration.from_stereo_camera(CAMERA)
    D = np.array([-0.2, 0.05, 0.001, -0.001, 0.0])
    raw = StereoCalibration(ideal.image_size, ideal.K1, D, ideal.K2, D, ideal.R, ideal.T, ideal.R1, ideal.R2,
                            ideal.P1, ideal.P2)
    args = synthetic()
    seq = load_sequence(write_sequence(tmp_path / "raw", calibration=raw, **args))
    assert not seq.calibration.is_rectified
    left, right = seq.frame(1)
    expected_l, expected_r = raw.rectify(*args["images"][1])
    np.testing.assert_array_equal(left, expected_l)
    np.testing.assert_array_equal(right, expected_r)
    assert not np.array_equal(left, args["images"][1][0])
    # The mount round trips with the calibration; its pan goes through degrees.
    assert replace(seq.camera, pan=CAMERA.pan) == CAMERA and seq.camera.pan == pytest.approx(CAMERA.pan, abs=1e-15)
    # Heading crossing ±π: the increment is the small turn, not a full circle.
    assert seq.odometry_increment(2).theta == pytest.approx(0.1, abs=1e-12)


def test_groundtruth_at_other_stamps_is_interpolated(tmp_path):
    out = write_sequence(tmp_path / "s", **synthetic(n=4))
    # Ground truth from 100.1 s to 100.6 s, turning through ±π; the frames are at 100, 100.25, 100.5, 100.75.
    gt_t = np.array([100.1, 100.35, 100.6])
    gt = np.array([[0.0, 0.0, 3.1], [1.0, 2.0, -3.1], [2.0, 4.0, -3.0]])
    write_tum(out / "groundtruth.tum", gt_t, gt)
    edit_yaml(out / "sequence.yaml", groundtruth="groundtruth.tum")
    seq = load_sequence(out)
    assert np.all(np.isnan(seq.groundtruth[[0, 3]]))
    expected_theta = 3.1 + 0.6 * (2 * np.pi - 6.2)  # 0.15/0.25 of the way along the short arc
    np.testing.assert_allclose(seq.groundtruth[1, :2], [0.6, 1.2], atol=1e-6)
    assert wrap_angle(seq.groundtruth[1, 2] - expected_theta) == pytest.approx(0.0, abs=1e-8)
    np.testing.assert_allclose(seq.groundtruth[2], [1.6, 3.2, -3.04], atol=1e-6)


def test_without_a_pan_column_every_frame_has_the_mount_pan(tmp_path):
    out = write_sequence(tmp_path / "s", **synthetic(n=3))
    frames = (out / "frames.csv").read_text().splitlines()
    # Saved by a spreadsheet: with a byte-order mark.
    (out / "frames.csv").write_text("\ufeff" + "\n".join(",".join(line.split(",")[:4]) for line in frames) + "\n",
                                    encoding="utf-8")
    np.testing.assert_allclose(load_sequence(out).pans, [CAMERA.pan] * 3, rtol=0, atol=1e-15)


# ------------------------------------------------------------------ broken folders
def edit_yaml(path, **changes):
    data = yaml.safe_load(path.read_text())
    for key, value in changes.items():
        if value is None:
            data.pop(key)
        else:
            data[key] = value
    path.write_text(yaml.safe_dump(data))


def replace_line(path, number, text):
    lines = path.read_text().splitlines()
    lines[number - 1] = text
    path.write_text("\n".join(lines) + "\n")


def delete_line(path, number):
    lines = path.read_text().splitlines()
    del lines[number - 1]
    path.write_text("\n".join(lines) + "\n")


BROKEN = {
    "no sequence.yaml": (lambda d: (d / "sequence.yaml").unlink(), r"seq: not a sequence folder: no sequence\.yaml"),
    "yaml syntax": (lambda d: (d / "sequence.yaml").write_text("format: [\n"),
                    r"sequence\.yaml: invalid YAML at line 2"),
    "wrong format": (lambda d: edit_yaml(d / "sequence.yaml", format="tum"),
                     r"sequence\.yaml: format: expected 'stablemarks-sequence', got 'tum'"),
    "wrong version": (lambda d: edit_yaml(d / "sequence.yaml", version=2),
                      r"sequence\.yaml: version: expected version 1, got 2"),
    "unknown field": (lambda d: edit_yaml(d / "sequence.yaml", images="left"),
                      r"sequence\.yaml: images: unknown field"),
    "no frames field": (lambda d: edit_yaml(d / "sequence.yaml", frames=None),
                        r"sequence\.yaml: missing field 'frames'"),
    "no calibration folder": (lambda d: shutil.rmtree(d / "calib"),
                              r"seq/calib: no such calibration folder or file"),
    "no right.yaml": (lambda d: (d / "calib" / "right.yaml").unlink(),
                      r"calib/right\.yaml: no such camera_info file"),
    "bad camera_info": (lambda d: (d / "calib" / "left.yaml").write_text("image_width: 64\n"),
                        r"calib/left\.yaml"),
    "no mount": (lambda d: (d / "calib" / "mount.yaml").unlink(), r"calib/mount\.yaml: no such mount file"),
    "bad mount": (lambda d: (d / "calib" / "mount.yaml").write_text("mount: {x: 0}\n"),
                  r"calib/mount\.yaml: missing field mount\.height"),
    "no map": (lambda d: (d / "map.yaml").unlink(), r"seq/map\.yaml: no such map file"),
    "bad map": (lambda d: (d / "map.yaml").write_text("planes: [{id: w, p1: [0, 0]}]\n"),
                r"map\.yaml: planes\[0\]: missing field 'p2'"),
    "no frames.csv": (lambda d: (d / "frames.csv").unlink(), r"frames\.csv: no such frames file"),
    "bad header": (lambda d: replace_line(d / "frames.csv", 1, "index,time,left,right"),
                   r"frames\.csv line 1: expected a header line with the columns index,stamp,left,right\[,pan\]"),
    "no rows": (lambda d: (d / "frames.csv").write_text("index,stamp,left,right\n"),
                r"frames\.csv: no rows after the header line"),
    "short row": (lambda d: replace_line(d / "frames.csv", 3, "1,100.25,left/000001.png"),
                  r"frames\.csv line 3: expected 5 fields \(index,stamp,left,right,pan\), got 3"),
    "text stamp": (lambda d: replace_line(d / "frames.csv", 3, "1,abc,left/000001.png,right/000001.png,0"),
                   r"frames\.csv line 3: stamp: expected a number, got 'abc'"),
    "nan pan": (lambda d: replace_line(d / "frames.csv", 3, "1,100.25,left/000001.png,right/000001.png,nan"),
                r"frames\.csv line 3: pan: expected a finite number, got 'nan'"),
    "float index": (lambda d: replace_line(d / "frames.csv", 3, "1.5,100.25,left/000001.png,right/000001.png,0"),
                    r"frames\.csv line 3: index: expected an integer, got '1\.5'"),
    "duplicate stamp": (lambda d: replace_line(d / "frames.csv", 4, "2,100.25,left/000002.png,right/000002.png,0"),
                        r"frames\.csv line 4: stamp: expected more than the previous row's 100\.25"),
    "unsorted stamps": (lambda d: replace_line(d / "frames.csv", 4, "2,99,left/000002.png,right/000002.png,0"),
                        r"frames\.csv line 4: stamp: expected more than the previous row's 100\.25 .*got 99\.0"),
    "missing image": (lambda d: (d / "left" / "000002.png").unlink(),
                      r"frames\.csv line 4: left image .*left/000002\.png: no such file"),
    "corrupt image": (lambda d: (d / "right" / "000000.png").write_bytes(b"not a png"),
                      r"right/000000\.png: cannot read image"),
    "wrong image size": (lambda d: [cv2.imwrite(str(d / side / "000000.png"), np.zeros((10, 10), np.uint8))
                                    for side in ("left", "right")],
                         r"left/000000\.png.*10×10 px but the calibration .* is for 64×48 px"),
    "pair sizes differ": (lambda d: cv2.imwrite(str(d / "left" / "000000.png"), np.zeros((10, 10), np.uint8)),
                          r"stereo pair sizes differ: .*left/000000\.png is 10×10 px"),
    "no odometry.csv": (lambda d: (d / "odometry.csv").unlink(), r"odometry\.csv: no such odometry file"),
    "odometry row missing": (lambda d: delete_line(d / "odometry.csv", 5),
                             r"odometry\.csv: 3 rows, but .*frames\.csv has 4 frames"),
    "odometry stamp": (lambda d: replace_line(d / "odometry.csv", 3, "100.3,0.1,0,3"),
                       r"odometry\.csv line 3: stamp: expected 100\.25, the stamp of frame 1 "
                       r"\(.*frames\.csv line 3\), got 100\.3"),
    "odometry value": (lambda d: replace_line(d / "odometry.csv", 3, "100.25,0.1,,3"),
                       r"odometry\.csv line 3: y: expected a number, got ''"),
    "odometry columns": (lambda d: replace_line(d / "odometry.csv", 1, "stamp,x,y,yaw"),
                         r"odometry\.csv line 1: expected a header line with the columns stamp,x,y,theta"),
    "no groundtruth": (lambda d: (d / "groundtruth.tum").unlink(), r"groundtruth\.tum: no such ground-truth file"),
    "bad groundtruth": (lambda d: replace_line(d / "groundtruth.tum", 3, "100.25 0.1 0 0 0 0 1"),
                        r"groundtruth\.tum line 3: expected 8 numbers"),
    "groundtruth order": (lambda d: replace_line(d / "groundtruth.tum", 3, "99 0 0 0 0 0 0 1"),
                          r"groundtruth\.tum: stamps must increase strictly"),
    "no truth": (lambda d: (d / "groundtruth.json").unlink(), r"groundtruth\.json: no such truth file"),
    "bad initial pose": (lambda d: edit_yaml(d / "sequence.yaml", initial_pose={"x": 0, "theta": 1}),
                         r"sequence\.yaml: initial_pose: expected a mapping \{x: m, y: m, theta_deg: deg\}"),
    "initial cov not 3x3": (lambda d: edit_yaml(d / "sequence.yaml", initial_cov=[[1, 0], [0, 1]]),
                            r"sequence\.yaml: initial_cov: expected a 3×3 list of numbers"),
    "initial cov indefinite": (lambda d: edit_yaml(d / "sequence.yaml", initial_cov=[[1, 2, 0], [2, 1, 0], [0, 0, 1]]),
                               r"sequence\.yaml: initial_cov: expected a symmetric positive semi-definite matrix"),
}


@pytest.fixture(scope="module")
def good_folder(tmp_path_factory):
    args = synthetic(n=4, pans=np.zeros(4), groundtruth=np.zeros((4, 3)), truth=lambda: {"frames": []},
                     initial_pose=SE2(0.0, 0.0, 1.0))
    return write_sequence(tmp_path_factory.mktemp("good") / "seq", **args)


def test_the_good_folder_loads(good_folder):
    seq = load_sequence(good_folder)
    assert len(seq) == 4 and seq.initial_pose.theta == pytest.approx(1.0)


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_folders_name_what_is_wrong(good_folder, tmp_path, case):
    edit, message = BROKEN[case]
    folder = shutil.copytree(good_folder, tmp_path / "seq")
    edit(folder)
    with pytest.raises(SequenceError, match=message):
        load_sequence(folder)


def test_missing_folder(tmp_path):
    with pytest.raises(SequenceError, match=r"nowhere: no such sequence folder"):
        load_sequence(tmp_path / "nowhere")


# ------------------------------------------------------------------ atomic writing
def test_a_failure_while_writing_leaves_nothing(tmp_path):
    def images():
        yield from synthetic(n=2)["images"]
        raise RuntimeError("renderer crashed")

    with pytest.raises(RuntimeError, match="renderer crashed"):
        write_sequence(tmp_path / "s", **synthetic(n=4, images=images()))
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(InputError, match=r"images: expected 4 stereo pairs, one per stamp, got 3"):
        write_sequence(tmp_path / "s", **synthetic(n=4, images=synthetic(n=3)["images"]))
    with pytest.raises(InputError, match=r"images: expected 2 stereo pairs, one per stamp, got more"):
        write_sequence(tmp_path / "s", **synthetic(n=2, images=synthetic(n=3)["images"]))
    assert list(tmp_path.iterdir()) == []


def test_existing_folders_are_replaced_only_when_safe(tmp_path):
    out = write_sequence(tmp_path / "s", **synthetic(n=2, seed=1))
    with pytest.raises(InputError, match=r"s: folder exists and is not empty \(`force` replaces"):
        write_sequence(out, **synthetic(n=3))
    assert len(load_sequence(out)) == 2
    write_sequence(out, force=True, **synthetic(n=3))
    assert len(load_sequence(out)) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]  # no temporary or old folders left

    other = tmp_path / "photos"
    other.mkdir()
    (other / "holiday.png").write_bytes(b"x")
    with pytest.raises(InputError, match=r"photos: not a sequence folder \(no sequence\.yaml\); refusing"):
        write_sequence(other, force=True, **synthetic(n=2))
    assert [p.name for p in other.iterdir()] == ["holiday.png"]

    empty = tmp_path / "empty"
    empty.mkdir()
    assert len(load_sequence(write_sequence(empty, **synthetic(n=2)))) == 2
    (tmp_path / "file").write_text("")
    with pytest.raises(InputError, match=r"file: exists and is not a folder"):
        write_sequence(tmp_path / "file", **synthetic(n=2))


def test_write_sequence_checks_its_arrays(tmp_path):
    with pytest.raises(InputError, match=r"stamps: expected \(n,\) finite, strictly increasing"):
        write_sequence(tmp_path / "s", **synthetic(n=3, stamps=[0.0, 1.0, 1.0]))
    with pytest.raises(InputError, match=r"odometry: expected finite numbers of shape \(3, 3\), got \(3, 2\)"):
        write_sequence(tmp_path / "s", **synthetic(n=3, odometry=np.zeros((3, 2))))
    assert not (tmp_path / "s").exists()


# ------------------------------------------------------------------ the command
@pytest.fixture()
def tiny_yaml(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_scenario_data()))
    return path


def test_simulate_command_writes_a_loadable_sequence(tiny_yaml, tmp_path, capsys):
    out = tmp_path / "out" / "seq"
    assert main(["simulate", str(tiny_yaml), "--out", str(out), "--frames", "3", "--seed", "5"]) == 0
    text = capsys.readouterr().out
    assert "3 of 7 stereo frames" in text and "drives 0.20 m" in text and str(out) in text
    seq = load_sequence(out)
    assert len(seq) == 3 and seq.name == "tiny"
    assert sorted(p.name for p in out.iterdir()) == [
        "calib", "frames.csv", "groundtruth.json", "groundtruth.tum", "left", "map.yaml", "odometry.csv",
        "right", "sequence.yaml"]
    assert json.loads(seq.truth_path.read_text())["seed"] == 5

    # An existing sequence is kept without --force and replaced with it.
    assert main(["simulate", str(tiny_yaml), "--out", str(out), "--frames", "2"]) == 1
    assert "folder exists and is not empty" in capsys.readouterr().err
    assert len(load_sequence(out)) == 3
    assert main(["simulate", str(tiny_yaml), "--out", str(out), "--frames", "2", "--force"]) == 0
    assert len(load_sequence(out)) == 2


@pytest.mark.parametrize("argv, message", [
    (["no-such-scenario"], r"scenario: expected a scenario file or a built-in name"),
    (["{tiny}", "--frames", "0"], r"--frames: expected a number of frames in \[1, 7\]"),
    (["{tiny}", "--frames", "some"], r"--frames: expected 'all' or a number of frames, got 'some'"),
    (["{tiny}", "--seed", "-1"], r"--seed: expected a non-negative seed"),
])
def test_simulate_command_errors_leave_nothing(tiny_yaml, tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    argv = [a.format(tiny=tiny_yaml) for a in argv]
    assert main(["simulate", *argv, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("stablemarks simulate: error: ") and len(err.strip().splitlines()) == 1
    assert re.search(message, err)
    assert not out.exists()
