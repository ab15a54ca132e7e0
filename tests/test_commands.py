"""Smoke and error tests of the sub-commands (select, demo, run) through the CLI entry point."""

import csv
import json

import numpy as np
import pytest
import yaml

from stablemarks.cli import main
from stablemarks.io.results import LANDMARK_COLUMNS


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("render")
    assert main(["render", "lab", "--out", str(out), "--frames", "0"]) == 0
    return out


def test_select_on_a_rendered_frame(rendered, tmp_path, capsys):
    out = tmp_path / "sel"
    pan = json.loads((rendered / "groundtruth.json").read_text())["frames"][0]["pan"]  # the head looked 5° left
    code = main(["select", str(rendered / "frame_000000_left.png"), str(rendered / "frame_000000_right.png"),
                 "--map", str(rendered / "map.yaml"), "--pose", "0,0,90deg", "--pose-sigma", "0.05,0.05,1deg",
                 "--pan", str(pan), "--calib", str(rendered / "calib"), "--out", str(out), "--mm"])
    assert code == 0
    with (out / "landmarks.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0].keys()) == LANDMARK_COLUMNS
    assert {r["plane"] for r in rows} == {"partition", "whiteboard"}
    assert sum(r["selected"] == "True" for r in rows) >= 8
    doc = json.loads((out / "landmarks.json").read_text())
    assert len(doc["landmarks"]) == len(rows)
    for name in ("fig5_segments.png", "fig6_planes.png", "fig7_uncertainty.png"):
        assert (out / name).stat().st_size > 10_000
    assert "Modelled features (mm)" in capsys.readouterr().out


@pytest.mark.parametrize(
    "change,message",
    [
        ({"--pose": "0,0"}, "--pose: expected"),
        ({"--pose-sigma": "0.1,-1,0"}, "--pose-sigma: expected non-negative"),
        ({"--map": "missing.yaml"}, "no such map file"),
    ],
)
def test_select_bad_input_is_one_line(rendered, tmp_path, capsys, change, message):
    args = {"--map": str(rendered / "map.yaml"), "--pose": "0,0,1.57", "--pose-sigma": "0.05,0.05,0.02",
            "--calib": str(rendered / "calib"), "--out": str(tmp_path / "o")}
    args.update(change)
    argv = ["select", str(rendered / "frame_000000_left.png"), str(rendered / "frame_000000_right.png")]
    for k, v in args.items():
        argv += [k, v]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "o").exists()


def test_select_pair_of_different_sizes(rendered, tmp_path, capsys):
    import cv2

    small = tmp_path / "small.png"
    img = cv2.imread(str(rendered / "frame_000000_right.png"))
    cv2.imwrite(str(small), img[:240, :320])
    code = main(["select", str(rendered / "frame_000000_left.png"), str(small), "--map", str(rendered / "map.yaml"),
                 "--pose", "0,0,1.57", "--pose-sigma", "0.05,0.05,0.02", "--calib", str(rendered / "calib"),
                 "--out", str(tmp_path / "o")])
    assert code == 1
    assert "sizes differ" in capsys.readouterr().err


def test_demo_first_view(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--no-motion"]) == 0
    text = capsys.readouterr().out
    assert "Table 1, paper vs stablemarks" in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["table1"]["found"] == 14 and summary["table1"]["decisions_agree"] == 14
    assert (out / "landmarks.csv").exists() and (out / "map.png").exists()


def test_simulate_then_run(tmp_path, capsys):
    seq = tmp_path / "seq"
    assert main(["simulate", "lab", "--out", str(seq), "--frames", "4"]) == 0
    out = tmp_path / "run"
    assert main(["run", str(seq), "--out", str(out)]) == 0
    for name in ("trajectory.tum", "dead_reckoning.tum", "groundtruth.tum", "landmarks.yaml", "log.jsonl",
                 "fig10_motion.png", "config.yaml"):
        assert (out / name).exists(), name
    lines = (out / "log.jsonl").read_text().splitlines()
    assert len(lines) == 4 and "timings" in json.loads(lines[0])
    landmarks = yaml.safe_load((out / "landmarks.yaml").read_text())
    assert landmarks["frame"] == "map" and landmarks["landmarks"]
    # a later run starts from this landmark map
    out2 = tmp_path / "run2"
    assert main(["run", str(seq), "--out", str(out2), "--prior-landmarks", str(out / "landmarks.yaml"),
                 "--no-figures"]) == 0


def test_run_on_a_broken_folder_writes_nothing(tmp_path, capsys):
    seq = tmp_path / "seq"
    assert main(["simulate", "lab", "--out", str(seq), "--frames", "2"]) == 0
    (seq / "odometry.csv").unlink()
    out = tmp_path / "run"
    assert main(["run", str(seq), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "odometry" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_stereo_writes_disparity_pairs_and_figures(rendered, tmp_path, capsys):
    from stablemarks.io.pfm import read_pfm

    out = tmp_path / "stereo"
    assert main(["stereo", str(rendered / "frame_000000_left.png"), str(rendered / "frame_000000_right.png"),
                 "--out", str(out)]) == 0
    d = read_pfm(out / "disparity.pfm")
    assert d.shape == (480, 640)
    finite = np.isfinite(d)
    assert 0.2 < finite.mean() < 0.95 and np.all(d[finite] >= 0) and np.all(d[finite] < 64)
    pairs = json.loads((out / "pairs.json").read_text())
    assert pairs and set(pairs[0]) == {"u_left", "u_right", "v_top", "v_bottom", "length_left", "length_right",
                                       "similarity", "length_similarity", "kept"}
    assert sum(p["kept"] for p in pairs) >= 14
    for name in ("disparity.png", "fig5_segments.png", "fig6_disparity.png"):
        assert (out / name).exists()
    # a bad block size is a one-line error
    assert main(["stereo", str(rendered / "frame_000000_left.png"), str(rendered / "frame_000000_right.png"),
                 "--block-size", "4", "--out", str(tmp_path / "bad")]) == 1
    assert "block_size" in capsys.readouterr().err
