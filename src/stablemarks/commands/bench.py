"""``stablemarks bench``: per-stage speed against OpenCV's StereoBM and the EKF against filterpy."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from rich.table import Table

from ._common import make_console

MAX_LANDMARKS = 10_000
"""Largest landmark count of the EKF comparison (``--sizes``)."""

MAX_REPEATS = 1000
"""Most timed runs per stage (``--repeats``)."""

NAME = "bench"
HELP = "time every stage against OpenCV StereoBM, the EKF update against filterpy, and memory per frame"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    p.add_argument("--repeats", type=int, default=15, help="timed runs per stage (median; default 15)")
    p.add_argument("--sizes", default="10,100,500,1000,2000", help="landmark counts of the EKF comparison")
    p.add_argument("--memory-frames", type=int, default=0, metavar="N",
                   help="also soak: N frames of the `loop` scenario lap after lap, time and memory per frame in the "
                        "first and last 1000 (10000 take about half an hour; default: skip)")


def _plain(v):
    """``v`` with every non-finite float as None (strict JSON: a soak too short for a slope has NaN there)."""
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_plain(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def soak_table(mem: dict) -> Table:
    """The soak's figures (:func:`stablemarks.bench.memory_profile`) in the first and the last window."""
    first, last = mem["first"], mem["last"]
    t = Table(title=f"soak: {mem['frames']} frames of `{mem['scenario']}` lap after lap, streamed (no record kept)")
    t.add_column("")
    for w in (first, last):
        t.add_column(f"frames {w['frames'][0]}–{w['frames'][1] - 1}", justify="right")

    def row(label, fmt, *keys):
        t.add_row(label, *(fmt.format(*(w[k] for k in keys)) for w in (first, last)))

    row("localizer step, median ms/frame (untraced half)", "{:.1f}", "step_ms")
    row("with rendering the frame, median ms/frame", "{:.1f}", "frame_ms")
    row("resident memory (RSS), median MB (untraced half)", "{:.1f}", "rss_mb")
    row("traced peak per frame, median (max) MB (traced half)", "{:.1f} ({:.1f})", "traced_peak_mb",
        "traced_peak_mb_max")
    row("memory held between frames grows, kB/frame (traced)", "{:.2f}", "held_kb_per_frame")
    row("landmarks in the filter, median (max)", "{:.0f} ({})", "landmarks", "landmarks_max")
    return t


def run(args) -> int:
    from ..bench import ekf_vs_filterpy, memory_profile, stage_times
    from ..errors import InputError, expected
    from ..sim.scenario import MAX_FRAMES
    from ._common import check_out_file

    console = make_console()
    # Validate everything before the first (long) measurement.
    try:
        sizes = tuple(int(v) for v in args.sizes.split(","))
    except ValueError:
        raise InputError(expected("comma-separated landmark counts", args.sizes, where="--sizes")) from None
    if not all(1 <= n <= MAX_LANDMARKS for n in sizes):
        raise InputError(expected(f"landmark counts from 1 to {MAX_LANDMARKS}", args.sizes, where="--sizes"))
    if not 1 <= args.repeats <= MAX_REPEATS:
        raise InputError(expected(f"a positive number of runs, at most {MAX_REPEATS}", args.repeats,
                                  where="--repeats"))
    if args.memory_frames != 0 and not 4 <= args.memory_frames <= MAX_FRAMES:
        raise InputError(expected(f"0 (skip) or a number of frames from 4 to {MAX_FRAMES}", args.memory_frames,
                                  where="--memory-frames"))
    if args.json:
        check_out_file(args.json, "--json")
    console.print("single-threaded (BLAS, OpenCV, numba), median of repeated runs on a rendered 640×480 lab pair; "
                  "the pipeline as the localizer runs it: SAD only where the method reads it")
    stages = stage_times(args.repeats)
    t = Table(title="per-frame time, 640×480, 64 disparities")
    t.add_column("stage")
    t.add_column("ms", justify="right")
    t.add_column("× one StereoBM call", justify="right")
    for key, label in (("stereobm", "OpenCV StereoBM (15×15, 64 disp.), reference"),
                       ("regions", "planes' disparity regions from the prior"),
                       ("segments", "vertical segments, both images"), ("matching", "segment matching (DP)"),
                       ("disparity", "SAD both directions + L-R check, in regions"), ("filter", "disparity filter"),
                       ("planes", "plane prediction + fit"), ("landmarks", "boundary, model, selection"),
                       ("ekf", "EKF association + update"), ("front_end", "front end (first five)"),
                       ("pipeline", "whole per-frame pipeline"),
                       ("disparity_alone", "SAD in regions, alone (as StereoBM)"),
                       ("disparity_dense", "SAD both directions + L-R check, dense, alone"),
                       ("disparity_dense_in_pipeline", "the same inside the pipeline"),
                       ("pipeline_dense", "whole pipeline with dense SAD")):
        if f"paired_{key}_ms" in stages:  # timed alternating with StereoBM calls: their own reference
            ref, ms = stages[f"paired_{key}_ms"]
            t.add_row(label + " *", f"{ms:.1f}", f"{ms / ref:.2f}")
            continue
        ms = stages[f"{key}_ms"]
        t.add_row(label, f"{ms:.1f}", f"{ms / stages['stereobm_ms']:.2f}")
    if "run_pipeline_ms" in stages:
        for key, label in (("pipeline", "whole pipeline, lab frames " + ", ".join(map(str, stages["run_frames"]))),
                           ("pipeline_dense", "the same with dense SAD")):
            ms = stages[f"run_{key}_ms"]
            t.add_row(label, f"{ms:.1f}", f"{ms / stages['run_stereobm_ms']:.2f}")
    console.print(t)
    console.print("* timed in short blocks alternating with StereoBM calls on the same pair, the ratio to their "
                  "median (a burst of load on a shared machine falls on both); the other rows in blocks of their own")
    console.print(f"whole pipeline: {stages['pipeline_fps']:.0f} frames/s "
                  f"(with dense SAD {stages['pipeline_dense_fps']:.0f} frames/s)")
    out = {"stages": stages, **{k: v for k, v in stages.items() if k.startswith(("ratio_", "pipeline_fps"))}}
    ekf = ekf_vs_filterpy(sizes)
    if "skipped" in ekf:
        console.print(f"[yellow]EKF comparison skipped:[/] {ekf['skipped']}")
    else:
        t = Table(title="EKF update (6 observations) vs filterpy's ExtendedKalmanFilter, same numbers")
        for col in ("landmarks", "ours ms", "filterpy ms", "speed-up", "max |difference|"):
            t.add_column(col, justify="right")
        for r in ekf["rows"]:
            t.add_row(str(r["landmarks"]), f"{r['ours_ms']:.2f}", f"{r['filterpy_ms']:.2f}", f"{r['ratio']:.1f}×",
                      f"{r['max_abs_diff']:.1e}")
        console.print(t)
        out["ekf"] = ekf
        if "ratio_ekf_vs_filterpy_1000" in ekf:
            out["ratio_ekf_vs_filterpy_1000"] = ekf["ratio_ekf_vs_filterpy_1000"]
        out["max_abs_diff"] = ekf["max_abs_diff"]
    if args.memory_frames:
        from ._report import frame_progress

        with frame_progress(console, f"soak: {args.memory_frames} frames of `loop`", args.memory_frames) as progress:
            mem = memory_profile(args.memory_frames, progress=progress)
        out["memory"] = mem
        console.print(soak_table(mem))
        console.print(
            f"resident memory grows {mem['rss_growth_kb_per_frame']:.1f} kB/frame from the first window to the last "
            f"({mem['rss_mb_end']:.0f} MB at the end); {mem['landmarks_final']} landmarks in the filter at the end, "
            f"{mem['landmarks_dropped']} dropped on the way; {mem['frames']} frames in {mem['seconds'] / 60:.1f} min "
            f"({1000 * mem['seconds_per_frame']:.0f} ms/frame with rendering and the traced frames)"
        )
    console.print(f"ratio_pipeline_vs_stereobm = {stages['ratio_pipeline_vs_stereobm']:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(_plain(out), indent=2, allow_nan=False))
        console.print(f"wrote {args.json}")
    return 0
