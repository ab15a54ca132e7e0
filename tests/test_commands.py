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


# ------------------------------------------------------------------ --preset (issue 14)
class _Stop(Exception):
    pass


def _capture_config(monkeypatch, module, name):
    """Replace ``module.name`` by a stand-in that keeps the configuration it is called with and stops the
    command there: the configuration the command resolved from its options."""
    import importlib

    seen = []

    def stand_in(*args, **kw):
        seen.append(kw.get("config", next((a for a in args if type(a).__name__ == "Config"), None)))
        raise _Stop

    monkeypatch.setattr(importlib.import_module(module), name, stand_in)
    return seen


def test_preset_paper_on_run_eval_and_select(rendered, tmp_path, capsys, monkeypatch):
    from stablemarks.config import Config

    paper = Config.preset("paper").noise.sigma_img
    assert paper == 0.5 and Config().noise.sigma_img != paper
    # run writes the resolved configuration
    from .test_sources import write_lab_sequence

    folder = write_lab_sequence(tmp_path / "lab")
    for extra, expected in (([], Config().noise.sigma_img), (["--preset", "paper"], paper)):
        out = tmp_path / f"run{len(extra)}"
        assert main(["run", str(folder), "--out", str(out), "--method", "dead_reckoning", "--no-figures",
                     *extra]) == 0
        assert yaml.safe_load((out / "config.yaml").read_text())["noise"]["sigma_img"] == expected
    # eval and select: the configuration they hand on
    seen = _capture_config(monkeypatch, "stablemarks.evaluation", "make_trials")
    with pytest.raises(_Stop):
        main(["eval", "lab", "--trials", "1", "--methods", "dead_reckoning", "--preset", "paper",
              "--out", str(tmp_path / "ev")])
    assert seen[-1].noise.sigma_img == paper and seen[-1].noise.boundary_px is None
    with pytest.raises(_Stop):  # --set on top of the preset, as for run
        main(["eval", "lab", "--trials", "1", "--methods", "dead_reckoning", "--preset", "paper",
              "--set", "noise.sigma_img=0.2", "--out", str(tmp_path / "ev")])
    assert seen[-1].noise.sigma_img == 0.2 and seen[-1].noise.boundary_px is None
    seen = _capture_config(monkeypatch, "stablemarks.pipeline", "process_frame")
    with pytest.raises(_Stop):
        main(["select", str(rendered / "frame_000000_left.png"), str(rendered / "frame_000000_right.png"),
              "--map", str(rendered / "map.yaml"), "--pose", "0,0,90deg", "--pose-sigma", "0.05,0.05,1deg",
              "--calib", str(rendered / "calib"), "--out", str(tmp_path / "sel"), "--preset", "paper"])
    assert seen[-1].noise.sigma_img == paper


def test_preset_narrow_is_the_narrow_noise_with_its_rules():
    """The ``narrow`` preset: line and boundary noise 0.06 px with the plane gates kept as the defaults' (the
    disparity noise they imply), a σ floor of 0.2 mm per metre of range (no fixed one), the missing-variance test,
    blind entries widened, lines 4 px apart; everything else the defaults'."""
    from stablemarks.config import Config

    narrow, default = Config.preset("narrow"), Config()
    assert (narrow.noise.sigma_img, narrow.noise.boundary_px) == (0.06, 0.06)
    assert narrow.noise.free_boundary_px == default.noise.free_boundary_px
    assert narrow.planes.disparity_noise_px == 0.354
    assert narrow.ekf.landmark_sigma_floor == 0.0 and narrow.ekf.inflation_p == 0.001
    assert narrow.ekf.landmark_sigma_floor_per_m == 0.0002
    assert narrow.ekf.widen_blind_entries and narrow.landmarks.min_line_gap_px == 4.0
    assert narrow.sad == default.sad and narrow.health == default.health and narrow.segments == default.segments


def test_preset_then_config_file_then_set(tmp_path, capsys):
    """Precedence: the preset, then what --config names, then --set."""
    from .test_sources import write_lab_sequence

    folder = write_lab_sequence(tmp_path / "lab")
    cfg = tmp_path / "noise.yaml"
    cfg.write_text("noise: {sigma_img: 0.3}\n")
    base = ["run", str(folder), "--method", "dead_reckoning", "--no-figures", "--preset", "paper"]
    for extra, sigma in ((["--config", str(cfg)], 0.3), (["--config", str(cfg), "--set", "noise.sigma_img=0.4"], 0.4)):
        out = tmp_path / f"o{len(extra)}"
        assert main([*base, *extra, "--out", str(out)]) == 0
        noise = yaml.safe_load((out / "config.yaml").read_text())["noise"]
        assert noise["sigma_img"] == sigma
        assert noise["boundary_px"] is None  # from the preset: the file does not name it


@pytest.mark.parametrize("command", ["run", "eval", "select", "calibrate-noise"])
def test_an_unknown_preset_is_argparse_s_one_line_error(command, tmp_path, capsys):
    argv = {"run": ["run", "somewhere"], "eval": ["eval", "lab"], "calibrate-noise": ["calibrate-noise", "lab"],
            "select": ["select", "l.png", "r.png", "--map", "m.yaml", "--pose", "0,0,0", "--pose-sigma", "1,1,1"]}
    with pytest.raises(SystemExit) as exc:
        main([*argv[command], "--out", str(tmp_path / "o"), "--preset", "nonesuch"])
    assert exc.value.code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--preset" in err[0] and "invalid choice: 'nonesuch'" in err[0] and "paper" in err[0], err
    assert not (tmp_path / "o").exists()
