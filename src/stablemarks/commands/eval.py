"""``stablemarks eval``: Monte Carlo evaluation of the methods side by side on simulated scenarios.

Runs N trials per scenario (independent odometry, exposure and sensor noise, seeds from
``SeedSequence.spawn``), every method on the same trials, in parallel through joblib; writes
``trials.jsonl``, ``summary.json``, ``summary.csv``, ``report.md`` and its figures into DIR and prints the
summary table and the goals. Definitions of the metrics: :mod:`stablemarks.evaluation`.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from ..errors import InputError, expected
from ._common import check_image_settings, check_out_dir, make_console, parse_sigmas, preset_arg

MAX_TRIALS = 100_000
"""Most trials per scenario ``--trials`` takes."""

MAX_JOBS = 1024
"""Most parallel jobs ``--jobs`` takes."""

MAX_SEED = 2**63 - 1
"""Largest ``--seed``."""

NAME = "eval"
HELP = "Monte Carlo evaluation of the methods on simulated scenarios (NEES, NIS, ATE, selection, stability)"
DESCRIPTION = (
    "Run N trials of each SCENARIO (a built-in name such as 'lab', or a scenario YAML file), each with its own "
    "odometry, exposure and sensor noise, and every method on the same trials; write DIR/trials.jsonl (one line "
    "per trial and method), DIR/summary.json, DIR/summary.csv and DIR/report.md with its figures, and print "
    "the summary. The metrics are defined in the report and the README."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..evaluation import available_methods
    from ..sim.scenario import builtin_scenarios

    methods = available_methods()
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO",
                   help=f"built-in scenario ({', '.join(builtin_scenarios())}) or a scenario YAML file")
    p.add_argument("--trials", type=int, default=10, metavar="N", help="trials per scenario (default 10)")
    p.add_argument("--jobs", type=int, default=1, metavar="J", help="parallel jobs, -1 for all cores (default 1)")
    p.add_argument("--backend", default="loky", choices=["loky", "dask", "ray"],
                   help="joblib backend (default loky; dask and ray need the optional extras)")
    p.add_argument("--address", metavar="ADDR",
                   help="dask scheduler or ray cluster address (default: a local cluster of --jobs workers)")
    p.add_argument("--methods", default=",".join(methods), metavar="M1,M2",
                   help=f"comma-separated methods (default: all of {', '.join(methods)}; gtsam_batch, the batch "
                        "smoother reference, needs pip install 'stablemarks[gtsam]')")
    p.add_argument("--frames", type=int, default=None, metavar="N", help="only the first N frames of each run")
    p.add_argument("--seed", type=int, default=None, metavar="S",
                   help="base seed of the trials (default: each scenario's seed)")
    p.add_argument("--pose-sigma", default="0.05,0.05,1deg", metavar="SX,SY,STHETA",
                   help="standard deviations of the start pose belief (default 0.05,0.05,1deg)")
    preset_arg(p)
    p.add_argument("--config", metavar="FILE", help="thresholds (YAML, see README), on top of --preset")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one setting on top of --config, e.g. --set noise.sigma_img=0.1 (repeatable)")
    p.add_argument("--out", default="results/eval", metavar="DIR", help="output folder (default results/eval)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures (report.md without them)")
    p.add_argument("--pan-policy", metavar="P1,P2", default=None,
                   help="run every method with these pan policies (fixed, free_edges, information; default: the "
                        "scenario's); with more than one the methods are reported as METHOD@POLICY side by side")
    p.add_argument("--resume", action="store_true",
                   help="keep the tasks already in DIR/trials.jsonl (from an interrupted evaluation) and run the rest")


def run(args) -> int:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )
    from rich.table import Table

    from ..evaluation import (
        REPORT_COLUMNS,
        check_backend,
        check_goals,
        evaluate,
        failures,
        format_value,
        goals_caveats,
        make_trials,
        report_markdown,
        summarize,
        summary_csv,
        summary_json,
        trials_jsonl,
    )
    from ..sim.scenario import MAX_FRAMES, load_scenario
    from ._common import load_run_config

    console = make_console()
    # Validate everything before running or writing anything.
    out = check_out_dir(args.out)
    config = load_run_config(args)
    sigma = parse_sigmas(args.pose_sigma, "--pose-sigma")
    if args.seed is not None and not 0 <= args.seed <= MAX_SEED:
        raise InputError(expected(f"a non-negative seed up to {MAX_SEED}", args.seed, where="--seed"))
    if args.trials > MAX_TRIALS:
        raise InputError(expected(f"at most {MAX_TRIALS} trials", args.trials, where="--trials"))
    if args.frames is not None and args.frames > MAX_FRAMES:
        raise InputError(expected(f"at most {MAX_FRAMES} frames", args.frames, where="--frames"))
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    check_backend(args.backend)
    policies = None if args.pan_policy is None else [p.strip() for p in args.pan_policy.split(",") if p.strip()]
    try:
        trials = make_trials(args.scenarios, args.trials, methods, seed=args.seed, frames=args.frames,
                             cov0=np.diag(sigma**2), config=config, pan_policies=policies)
    except InputError as exc:
        raise InputError(str(exc).replace("pan_policies:", "--pan-policy:")) from None
    done: list[dict] = []
    if args.resume:
        done = _finished(out / "trials.jsonl")
        finished = {(r["scenario"], r["trial"], r["seed"], r["method"]) for r in done}
        names = {name: load_scenario(name).name for name in dict.fromkeys(args.scenarios)}
        trials = [t for t in trials if (names[t.scenario], t.index, t.seed, t.label) not in finished]
    for name in dict.fromkeys(args.scenarios):
        cam = load_scenario(name).camera
        check_image_settings(config, cam.width, cam.height, f"scenario {name}'s camera")
    if isinstance(args.jobs, int) and (args.jobs == 0 or args.jobs < -1):
        raise InputError(expected("a positive number of jobs (or -1 for all cores)", args.jobs, where="--jobs"))
    if args.jobs > MAX_JOBS:
        raise InputError(expected(f"at most {MAX_JOBS} jobs", args.jobs, where="--jobs"))

    import json
    import sys

    start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    plain = not sys.stdout.isatty()
    last = [start]
    with open(out / "trials.jsonl", "a" if args.resume else "w") as log, \
            Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                     TimeRemainingColumn(), console=console, disable=plain) as bar:
        task = bar.add_task(f"{len(trials)} runs ({args.trials} trials × {len(set(methods))} methods × "
                            f"{len(args.scenarios)} scenarios)", total=len(trials))

        def progress(done, total, res):
            # every finished task is kept at once: an interrupted evaluation continues with --resume
            log.write(json.dumps(res) + "\n")
            log.flush()
            state = "failed" if res.get("error") is not None else "done"
            bar.update(task, completed=done,
                       description=f"{res['scenario']} trial {res['trial']} {res['method']}: {state}")
            if plain:
                now = time.perf_counter()
                ate = "failed" if res.get("error") is not None else f"ATE {res['ate_rmse']:.4f} m"
                # the task's own time (the method's work on its frames, time_per_frame × frames, rendering left
                # out); with parallel jobs the time since the line before says nothing about it
                per_frame, frames = res.get("time_per_frame"), res.get("frames")
                secs = per_frame * frames if per_frame is not None and frames else now - last[0]
                print(f"{res['scenario']} {res['method']} trial {res['trial']}: {ate}, {secs:.1f} s "
                      f"({done}/{total})", flush=True)
                last[0] = now

        results = done + evaluate(trials, jobs=args.jobs, backend=args.backend, address=args.address,
                                  progress=progress) if trials else done
    wall = time.perf_counter() - start
    failed = failures(results)
    measured = [r for r in results if r.get("error") is None]
    summary = summarize(measured)
    goals = check_goals(summary)
    caveats = goals_caveats(summary, args.frames) if goals else []

    tmp = Path(tempfile.mkdtemp(prefix=".eval-", dir=out))
    try:
        (tmp / "trials.jsonl").write_text(trials_jsonl(results))
        (tmp / "summary.json").write_text(summary_json(summary))
        (tmp / "summary.csv").write_text(summary_csv(summary))
        figures = {}
        if not args.no_figures and measured:
            from ..viz.report import report_figures

            figures = {k: p.name for k, p in report_figures(tmp, summary, measured).items()}
        meta = {"scenarios": ", ".join(summary), "trials": args.trials, "methods": ", ".join(dict.fromkeys(methods)),
                "frames": args.frames or "all", "seed": "scenario's" if args.seed is None else args.seed,
                "start pose σ": args.pose_sigma, "jobs": args.jobs, "backend": args.backend,
                "wall time": f"{wall:.0f} s"}
        (tmp / "report.md").write_text(report_markdown(summary, goals, figures, meta, failed, caveats))
        for f in tmp.iterdir():
            os.replace(f, out / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    for scen, by_method in summary.items():
        first = next(iter(by_method.values()))
        lo, hi = first["nees_pose_bounds"]
        t = Table(title=f"{scen}: {first['trials']} trials × {first['frames']} frames "
                        f"(pose NEES bounds [{lo:.2f}, {hi:.2f}])")
        t.add_column("method", no_wrap=True)
        for _, heading, _ in REPORT_COLUMNS:
            # no heading word cut short ("precisi…") where the console is narrower than the table would like
            t.add_column(heading, justify="right", min_width=max(len(w) for w in heading.split()))
        for method, s in by_method.items():
            t.add_row(method, *(format_value(s[k], f) for k, _, f in REPORT_COLUMNS))
        console.print(t)
    if goals:
        t = Table(title="goals of the full method")
        for col in ("scenario", "goal", "value", "target", "met"):
            t.add_column(col, justify="right" if col == "value" else "left")
        for g in goals:
            met = "n/a" if g.met is None else ("[green]yes[/]" if g.met else "[red]no[/]")
            t.add_row(g.scenario, g.name, g.value, g.target, met)
        console.print(t)
        for c in caveats:
            console.print(f"note: {c}", highlight=False)
    console.print(f"{len(results)} runs in {wall:.1f} s wall time ({args.jobs} job(s), {args.backend}); wrote "
                  f"{out}/trials.jsonl, summary.json, summary.csv, report.md"
                  + (", nees_pose.png, ate.png, reobservation.png" if figures else ""))
    import sys

    from ..errors import one_line

    for r in failed:
        print(one_line(f"warning: {r['scenario']} trial {r['trial']} {r['method']} failed: {r['error']}", 300),
              file=sys.stderr)
    if failed and not measured:
        print(f"stablemarks eval: error: all {len(results)} runs failed (their messages are in "
              f"{out}/trials.jsonl and report.md)", file=sys.stderr)
        return 1
    return 0


def _finished(path: Path) -> list[dict]:
    """The tasks an earlier (interrupted) evaluation wrote to ``trials.jsonl``; a torn last line is dropped."""
    import json

    if not path.is_file():
        raise InputError(f"{path}: no trials.jsonl to resume")
    out = []
    for line in path.read_text().splitlines():
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(r, dict) and {"scenario", "trial", "seed", "method"} <= set(r):
            out.append(r)
    return out
