import json
import re

import cv2
import numpy as np
import pytest
import yaml

from stablemarks.cli import main
from stablemarks.io.calibration import load_camera_info_pair
from stablemarks.maps import load_map
from stablemarks.sim import load_scenario, simulate_run
from stablemarks.sim.scenario import SCENARIO_DIR


def test_render_lab_frames(tmp_path, capsys):
    out = tmp_path / "lab"
    assert main(["render", "lab", "--out", str(out), "--frames", "0,20", "--seed", "3"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted([
        "frame_000000_left.png", "frame_000000_right.png", "frame_000020_left.png", "frame_000020_right.png",
        "map.yaml", "calib", "groundtruth.json", "map.png",
    ])
    assert sorted(p.name for p in (out / "calib").iterdir()) == ["left.yaml", "mount.yaml", "right.yaml"]
    assert yaml.safe_load((out / "calib" / "mount.yaml").read_text())["mount"]["height"] == pytest.approx(1.0)
    truth = json.loads((out / "groundtruth.json").read_text())
    assert truth["scenario"] == "lab" and truth["seed"] == 3 and truth["n_frames"] == 21
    assert [f["index"] for f in truth["frames"]] == [0, 20]
    last = truth["frames"][1]
    assert last["pose"] == pytest.approx([0.0, 2.0, np.pi / 2])
    assert len(last["odometry"]) == 3 and np.array(last["cov_odometry"]).shape == (3, 3)
    boundaries = {e["id"] for e in last["edges"] if e["boundary"]}
    assert boundaries == {"partition-p1", "partition-p2", "whiteboard-p1", "whiteboard-p2"}
    # The images on disk are the run's frames.
    left = cv2.imread(str(out / "frame_000020_left.png"), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(left, simulate_run(load_scenario("lab"), 3).render(20).left)
    # The map and the calibration read back.
    assert load_map(out / "map.yaml") == load_scenario("lab").map
    calib = load_camera_info_pair(out / "calib")
    cam = calib.stereo_camera()
    assert cam.f == pytest.approx(500.0) and cam.baseline == pytest.approx(0.12)
    assert "2 of 21 frames rendered" in capsys.readouterr().out


def test_bad_scenario_is_one_line_and_writes_nothing(tmp_path, capsys):
    data = yaml.safe_load((SCENARIO_DIR / "lab.yaml").read_text())
    data["walls"][1]["texture"]["scale"] = -2
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    assert main(["render", str(path), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"stablemarks render: error: {path}: walls[1].texture.scale: expected a positive number, got -2"
    assert not out.exists()


@pytest.mark.parametrize("frames, message", [("0,99", r"--frames: expected frame indices in \[0, 20\], got 99"),
                                             ("1;2", r"--frames: expected 'all' or comma-separated")])
def test_bad_frames_are_rejected_before_writing(tmp_path, capsys, frames, message):
    out = tmp_path / "out"
    assert main(["render", "lab", "--out", str(out), "--frames", frames]) == 1
    assert re.search(message, capsys.readouterr().err)
    assert not out.exists()
