"""``stablemarks simulate``: render a scenario's run as a recorded-sequence folder, with its ground truth."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from ..errors import InputError, expected
from ..io.sequence import FRAME_PERIOD
from ..sim import builtin_scenarios, load_scenario, simulate_run, steered_by_method
from ..sim.export import write_simulated_sequence

NAME = "simulate"
HELP = "simulate a scenario and write it as a sequence folder (images, calibration, map, odometry, ground truth)"
DESCRIPTION = (
    "Simulate the robot's run through SCENARIO (a built-in name such as 'lab', or a scenario YAML file), "
    "render every stereo frame, and write DIR as a recorded-sequence folder that `stablemarks run DIR` "
    "reads: sequence.yaml, calib/ (ROS camera_info pair and mount), map.yaml, left/ and right/ PNGs, "
    f"frames.csv (stamps {FRAME_PERIOD:g} s apart, head pans: by default those the method's pan policy "
    "commands while the run is simulated, see --head), odometry.csv (the noisy wheel odometry, "
    "integrated), and beside them the ground truth: groundtruth.tum (true poses, for evo) and "
    "groundtruth.json (per-frame truth of every image edge). The seed fixes odometry and image noise. "
    "DIR is written under a temporary name and appears only when complete."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", metavar="SCENARIO",
                        help=f"built-in scenario ({', '.join(builtin_scenarios())}) or a scenario YAML file")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="sequence folder to write")
    parser.add_argument("--seed", type=int, default=None, metavar="N",
                        help="seed of the run (default: the scenario's seed)")
    parser.add_argument("--frames", default="all", metavar="N|all",
                        help="write the first N frames of the run, or all of them (default)")
    parser.add_argument("--head", choices=("method", "scenario"), default="method",
                        help="who points the stereo head: 'method' (default) runs the localizer while simulating "
                             "and records the pans its pan policy commands, as on a robot whose localizer steers "
                             "its head; 'scenario' applies the scenario's pan rule to the dead-reckoning pose "
                             "(the drifting belief of a robot without a localizer)")
    parser.add_argument("--force", action="store_true", help="replace DIR if it is an existing sequence folder")


def parse_count(text: str, n: int) -> int:
    """``"all"`` → ``n``; ``"N"`` → N, in ``[1, n]``."""
    if text.strip().lower() == "all":
        return n
    try:
        count = int(text)
    except ValueError:
        raise InputError(expected("'all' or a number of frames", text, where="--frames")) from None
    if not 1 <= count <= n:
        raise InputError(expected(f"a number of frames in [1, {n}] (this run has {n})", count, where="--frames"))
    return count


def run(args: argparse.Namespace) -> int:
    from ..io.sequence import check_target
    from ._common import check_out_dir

    if args.seed is not None and not 0 <= args.seed < 2**63:
        raise InputError(expected("a non-negative seed below 2**63", args.seed, where="--seed"))
    check_out_dir(args.out, inputs=(args.scenario if Path(args.scenario).exists() else None,), replaces=args.force)
    check_target(Path(args.out).resolve(), args.force)
    scenario = load_scenario(args.scenario)
    sim = simulate_run(scenario, args.seed)
    n = parse_count(args.frames, len(sim))

    console = Console(soft_wrap=True, highlight=False)
    start = time.perf_counter()
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  console=console, transient=True) as progress:
        if args.head == "method":
            steer = progress.add_task("steering the head", total=n)
            sim = steered_by_method(sim, n, progress=lambda k, _n: progress.update(steer, completed=k))
        task = progress.add_task("rendering", total=n)
        out = write_simulated_sequence(sim, args.out, n_frames=n, force=args.force,
                                       on_frame=lambda _k: progress.advance(task))
    elapsed = time.perf_counter() - start

    true = np.array([p.translation for p in sim.poses[:n]])
    length = float(np.linalg.norm(np.diff(true, axis=0), axis=1).sum())
    drift = float(np.linalg.norm(sim.dead_reckoning[n - 1].translation - sim.poses[n - 1].translation))
    cam = scenario.camera
    console.print(
        f"Scenario [bold]{scenario.name}[/bold] ({scenario.source}), seed {sim.seed}: {n} of {len(sim)} stereo "
        f"frames ({cam.width}x{cam.height} px) rendered in {elapsed:.1f} s (the head pointed by the "
        f"{'method' if args.head == 'method' else 'scenario rule on dead reckoning'}), {FRAME_PERIOD:g} s apart; "
        f"the robot drives {length:.2f} m and its odometry drifts {drift:.3f} m by the last frame. "
        f"Wrote the sequence folder {out}/ (sequence.yaml, calib/, map.yaml, left/, right/, frames.csv, "
        f"odometry.csv) with its ground truth (groundtruth.tum, groundtruth.json); "
        f"run it with: stablemarks run {args.out} --out RESULTS"
    )
    return 0
