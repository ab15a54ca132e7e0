"""Noise models estimated from data (``stablemarks calibrate-noise``)."""

import math

import numpy as np
import pytest
import yaml

from stablemarks.cli import main
from stablemarks.config import load_config
from stablemarks.geometry import SE2
from stablemarks.motion import OdometryNoise
from stablemarks.noisefit import NoiseSamples, _odometry_sample, clipped_rms, estimate


def test_clipped_rms_keeps_the_tails_and_drops_gross_outliers():
    rng = np.random.default_rng(0)
    z = rng.normal(0, 0.2, 5000)
    assert clipped_rms(z) == pytest.approx(0.2, rel=0.05)
    dirty = np.concatenate([z, rng.uniform(5, 10, 250)])  # 5 % lines of clutter
    assert clipped_rms(dirty) == pytest.approx(0.2, rel=0.06)
    assert np.sqrt(np.mean(dirty**2)) > 1.0  # the plain RMS would not


def test_the_odometry_noise_model_is_recovered_from_its_own_samples():
    truth = OdometryNoise(trans_per_m=0.08, rot_per_m_deg=3.0, rot_per_rad=0.04, trans_per_rad=0.01)
    rng = np.random.default_rng(1)
    samples = NoiseSamples()
    pose = SE2()
    for k in range(3000):
        step = SE2(0.1, 0.0, 0.0) if k % 2 else SE2(0.0, 0.0, math.radians(10))
        odo = truth.sample(step, rng)
        new = pose @ step
        samples.odometry.append(_odometry_sample((pose.as_array(), pose.as_array()), (new.as_array(),
                                                                                       (pose @ odo).as_array())))
        pose = new
    doc = estimate(samples)["odometry"]
    assert doc["trans_per_m"] == pytest.approx(0.08, rel=0.1)
    assert doc["rot_per_m_deg"] == pytest.approx(3.0, rel=0.1)
    assert doc["rot_per_rad"] == pytest.approx(0.04, rel=0.1)
    assert doc["trans_per_rad"] == pytest.approx(0.01, rel=0.1)


def test_straight_driving_leaves_the_turn_terms_alone():
    rng = np.random.default_rng(2)
    noise = OdometryNoise()
    samples = NoiseSamples()
    pose = SE2()
    for _ in range(50):
        step = SE2(0.1, 0.0, 0.0)
        odo = noise.sample(step, rng)
        samples.odometry.append(_odometry_sample((pose.as_array(), pose.as_array()),
                                                 ((pose @ step).as_array(), (pose @ odo).as_array())))
        pose = pose @ step
    doc = estimate(samples)["odometry"]
    assert set(doc) == {"trans_per_m", "rot_per_m_deg"}


def test_calibrate_noise_on_a_simulated_run_writes_a_config(tmp_path, capsys):
    out = tmp_path / "noise.yaml"
    assert main(["calibrate-noise", "lab", "--trials", "1", "--frames", "6", "--every", "3", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "filter consistency" in text and "estimated" in text
    doc = yaml.safe_load(out.read_text())
    assert 0.0 < doc["noise"]["sigma_img"] < 0.5
    config = load_config(out)
    assert config.noise.sigma_img == doc["noise"]["sigma_img"]
    # the lab's robot never turns on the spot: the per-radian odometry terms are not measured, not written,
    # and the table says so instead of repeating the current value as an estimate
    assert "rot_per_rad" not in doc.get("odometry", {})
    row = next(line for line in text.splitlines() if "odometry.rot_per_rad" in line)
    assert "not measured" in row


@pytest.mark.parametrize(("argv", "message"), [
    (["calibrate-noise", "nowhere", "--out", "x.yaml"], "SEQ: expected a sequence folder"),
    (["calibrate-noise", "lab", "--trials", "0", "--out", "x.yaml"], "--trials: expected a positive integer"),
    (["calibrate-noise", "lab", "--frames", "1", "--out", "x.yaml"], "--frames: expected at least 2 frames"),
    (["calibrate-noise", "lab", "--out", "missing/x.yaml"], "missing: no such folder for --out"),
])
def test_bad_arguments_are_one_line_errors(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not (tmp_path / "x.yaml").exists()
