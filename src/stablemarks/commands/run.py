"""``stablemarks run``: the on-line loop on a recorded sequence (or any supported recording)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ._common import make_console, parse_triplet

NAME = "run"
HELP = "run on-line landmark selection and EKF localization on a recorded sequence"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="DIR", help="recorded sequence folder (see README)")
    p.add_argument("--out", metavar="OUT", help="output folder (default: results/<sequence name>)")
    p.add_argument("--config", metavar="FILE", help="thresholds (YAML, see README)")
    p.add_argument("--method", default="stablemarks",
                   choices=["stablemarks", "plane_no_selection", "all_segments", "dead_reckoning"],
                   help="which method to run (default: stablemarks, the full method)")
    p.add_argument("--pose", metavar="X,Y,THETA", help="start pose (default: the sequence's initial pose)")
    p.add_argument("--pose-sigma", default="0.05,0.05,1deg", metavar="SX,SY,STHETA",
                   help="standard deviations of the start pose (default 0.05,0.05,1deg)")
    p.add_argument("--prior-landmarks", metavar="landmarks.yaml",
                   help="a landmark map written by an earlier run, to start from")
    p.add_argument("--no-figures", action="store_true", help="skip Figure 10")


def run(args) -> int:
    from ..config import load_config
    from ..io.results import write_run
    from ..io.sources import open_source
    from ..maps import read_yaml
    from ..online import run_online
    from ._report import frame_progress, print_motion_summary

    console = make_console()
    config = load_config(args.config)
    start = parse_triplet(args.pose, "x, y, theta", "--pose") if args.pose else None
    sigma = parse_triplet(args.pose_sigma, "σx, σy, σθ", "--pose-sigma")
    prior = read_yaml(args.prior_landmarks, "landmark map") if args.prior_landmarks else None
    source = open_source(args.source, start_pose=start)
    out = Path(args.out) if args.out else Path("results") / source.name
    with frame_progress(console, f"{source.name}: {len(source)} frames", len(source)) as progress:
        result = run_online(source, cov0=np.diag(sigma**2), config=config, method=args.method,
                            prior_landmarks=prior, progress=progress)
    paths = write_run(out, result, config)
    if not args.no_figures:
        from ..viz.trajectory import figure10

        paths["figure"] = figure10(out / "fig10_motion.png", result)
    print_motion_summary(console, result, getattr(source, "noise", None))
    console.print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0
