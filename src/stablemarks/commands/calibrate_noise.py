"""``stablemarks calibrate-noise``: the noise models estimated from recordings with ground truth.

Prints the estimated line-column noise σ_img, the boundary's border noise and the odometry noise next to the
current configuration's, the filter's consistency (pose NEES, NIS, landmark NEES, with their bounds) with the
current values and with the estimated ones, and writes the estimates as a configuration file for
``--config`` (:mod:`stablemarks.noisefit`).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from ..errors import InputError, expected
from ._common import make_console, parse_triplet, preset_arg

NAME = "calibrate-noise"
HELP = "estimate σ_img, the boundary noise and the odometry noise from recordings with ground truth"
# noise.sigma_img is written as the smallest of 1, 2, 3, 5, 8 times the measured line noise with which the
# filter's pooled pose NEES is at most 3.75 (or the last tried)
DESCRIPTION = (
    "Estimate the noise models from SEQ (sequence folders with groundtruth.tum, e.g. from `stablemarks simulate`, "
    "or simulated scenarios by name or YAML file): the column noise of a line (noise.sigma_img), the noise of a "
    "boundary's column (noise.boundary_px when a segment marks the edge, noise.free_boundary_px when not) and "
    "the odometry noise per metre and per radian (odometry.*). Prints the filter's consistency with the current "
    "and with the estimated values and writes OUT (YAML, for --config)."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sources", nargs="+", metavar="SEQ",
                   help="a sequence folder with ground truth, or a built-in scenario name / scenario YAML file")
    p.add_argument("--out", required=True, metavar="noise.yaml", help="the configuration file to write")
    p.add_argument("--config", metavar="FILE", help="the current configuration (YAML, see README)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one setting of the current configuration (repeatable)")
    preset_arg(p)
    p.add_argument("--trials", type=int, default=2, metavar="N",
                   help="simulated runs per scenario given by name or file (default 2)")
    p.add_argument("--frames", type=int, default=None, metavar="N", help="only the first N frames of each run")
    p.add_argument("--every", type=int, default=2, metavar="K",
                   help="measure the images of every K-th frame (default 2; the odometry uses every frame)")
    p.add_argument("--pose-sigma", default="0.05,0.05,1deg", metavar="SX,SY,STHETA",
                   help="standard deviations of the start pose belief for the consistency runs")


def _sources(args):
    """(name, make_source(), start pose or None, truth-observer wanted) for every SEQ, checked up front."""
    from ..evaluation import start_belief, trial_seeds
    from ..io.sources import open_sequence
    from ..sim.run import simulate_run
    from ..sim.scenario import builtin_scenarios, load_scenario
    from ..sim.source import SimulatedSource

    sigma = parse_triplet(args.pose_sigma, "σx, σy, σθ", "--pose-sigma")
    if np.any(sigma <= 0):
        raise InputError(expected("positive standard deviations", args.pose_sigma, where="--pose-sigma"))
    cov0 = np.diag(sigma**2)
    out = []
    for item in args.sources:
        path = Path(item)
        if path.is_dir():
            seq = open_sequence(path)
            if getattr(seq, "sequence", None) is not None and seq.sequence.groundtruth is None:
                raise InputError(f"{path}: no groundtruth.tum: calibrate-noise needs the true poses")
            out.append((seq.name, lambda p=path: open_sequence(p), None))
            continue
        if item not in builtin_scenarios() and not path.is_file():
            raise InputError(expected(f"a sequence folder, a scenario file or one of {', '.join(builtin_scenarios())}",
                                      item, where="SEQ"))
        scenario = load_scenario(item)
        for seed in trial_seeds(scenario.seed, args.trials):
            run = simulate_run(scenario, seed)
            out.append((f"{scenario.name}#{seed}", lambda r=run: SimulatedSource(r, frames=args.frames),
                        start_belief(run, cov0)))
    return out, cov0


def run(args) -> int:
    import yaml

    from ..evaluation import TruthObserver
    from ..noisefit import NoiseSamples, collect, consistency, estimate
    from ..online import run_online
    from ._common import load_run_config
    from ._report import frame_progress

    console = make_console()
    for name in ("trials", "every"):
        if getattr(args, name) < 1:
            raise InputError(expected("a positive integer", getattr(args, name), where=f"--{name}"))
    if args.frames is not None and args.frames < 2:
        raise InputError(expected("at least 2 frames", args.frames, where="--frames"))
    out = Path(args.out)
    if out.is_dir():
        raise InputError(f"{out}: is a folder; --out names the YAML file to write")
    if not out.parent.exists():
        raise InputError(f"{out.parent}: no such folder for --out")
    current = load_run_config(args)
    sources, cov0 = _sources(args)

    samples = NoiseSamples()
    for name, make, _ in sources:
        source = make()
        config = current.with_source_defaults(getattr(source, "config_defaults", None) or {})
        with frame_progress(console, f"{name}: measuring", len(source)) as progress:
            samples.extend(collect(source, config, args.every, progress))
    doc = estimate(samples)
    if not doc:
        raise InputError("no noise could be measured: no plane, line or boundary was found in these recordings")
    estimated = current.with_overrides(doc, "estimate")

    def runs(config):
        results = []
        for name, make, start in sources:
            source = make()
            truth = TruthObserver()
            cfg = config.with_source_defaults(getattr(source, "config_defaults", None) or {})
            with frame_progress(console, f"{name}: filtering", len(source)) as progress:
                result = run_online(source, start_pose=start, start_cov=cov0, config=cfg, observers=[truth],
                                    progress=progress)
            results.append((truth.result(result), truth.edges or None))
        return consistency(results)

    before = runs(current)
    # The line noise measured frame by frame is a lower bound: the errors of one frame's lines and of one line
    # over frames are not independent. Take the smallest multiple of it with which the filter is consistent
    # (pooled pose NEES at most its 3 dof, with a quarter of slack).
    trials = []
    line_noise = doc.get("noise", {}).get("sigma_img")
    for factor in (1.0, 2.0, 3.0, 5.0, 8.0) if line_noise else (1.0,):
        if line_noise:
            doc["noise"]["sigma_img"] = round(line_noise * factor, 4)
        estimated = current.with_overrides(doc, "estimate")
        after = runs(estimated)
        trials.append((factor, after))
        if after.nees_pose <= 3.75:
            break
    _print(console, current, estimated, samples, before, after, line_noise, trials, doc)
    text = ("# stablemarks calibrate-noise: noise models estimated from " + ", ".join(args.sources) + "\n"
            + yaml.safe_dump(doc, sort_keys=False))
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(text)
    tmp.replace(out)
    console.print(f"wrote {out} (use it with --config {out})")
    return 0


def _print(console, current, estimated, samples, before, after, line_noise=None, trials=(), doc=None) -> None:
    from rich.table import Table

    t = Table(title=f"noise models from {samples.frames} frames: {len(samples.line_z)} lines on walls, "
                    f"{sum(len(v) for v in samples.boundary_err.values()) // 2} boundaries, "
                    f"{len(samples.odometry)} odometry steps")
    for col in ("setting", "current", "estimated"):
        t.add_column(col, justify="left" if col == "setting" else "right")

    def fmt(v):
        return "window/√12" if v is None else f"{v:.4g}"

    def row(section, key, unit=""):
        # a setting these recordings could not measure (no boundary found, no turn on the spot) is not in
        # the file written: the filter keeps its current value
        measured = doc is None or key in doc.get(section, {})
        now, new = getattr(getattr(current, section), key), getattr(getattr(estimated, section), key)
        t.add_row(f"{section}.{key}{unit}", fmt(now), fmt(new) if measured else "not measured")

    if line_noise:
        t.add_row("line noise per frame [px]", "", fmt(line_noise))
    for key in ("sigma_img", "boundary_px", "free_boundary_px"):
        row("noise", key, " [px]")
    for key in ("trans_per_m", "rot_per_m_deg", "rot_per_rad", "trans_per_rad"):
        row("odometry", key)
    console.print(t)
    c = Table(title=f"filter consistency over {before.runs} run(s), {before.frames} frames (pose NEES: mean over "
                    "all frames, inside: frames within one frame's 95 % bounds; NIS, landmark NEES: means and "
                    "their 95 % bounds)")
    for col in ("", "pose NEES", "bounds", "inside", "NIS", "bounds", "landmark NEES", "bounds", "ATE [m]"):
        c.add_column(col, justify="right")

    def row(label, r):
        def b(x):
            return f"[{x[0]:.2f}, {x[1]:.2f}]"

        lm = "n/a" if math.isnan(r.nees_landmark) else f"{r.nees_landmark:.2f}"
        c.add_row(label, f"{r.nees_pose:.2f}", b(r.nees_pose_bounds), f"{r.nees_pose_inside:.0%}", f"{r.nis:.2f}",
                  b(r.nis_bounds), lm, b(r.nees_landmark_bounds) if lm != "n/a" else "", f"{r.ate:.4f}")

    row("current", before)
    for factor, r in trials[:-1]:
        row(f"{factor:g} × line noise", r)
    row("estimated", after)
    console.print(c)
