"""``stablemarks stereo``: the stereo front end on one pair (paper Sec 2.1-2.2, Figs 5-6)."""

from __future__ import annotations

import argparse
import json

import numpy as np

from ._common import check_image_settings, check_out_dir, make_console, out_dir_arg

NAME = "stereo"
HELP = "run the stereo front end on one pair: disparity.pfm/png, pairs.json, Figures 5 and 6"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("left", metavar="LEFT", help="left image (rectified, or raw with --calib)")
    p.add_argument("right", metavar="RIGHT", help="right image")
    p.add_argument("--calib", metavar="DIR", help="calibration (left.yaml/right.yaml pair or OpenCV file): "
                   "raw images are rectified with it")
    p.add_argument("--num-disparities", type=int, default=None, metavar="N", help="disparity range (default 64)")
    p.add_argument("--block-size", type=int, default=None, metavar="B", help="SAD window (odd, default 15)")
    p.add_argument("--config", metavar="FILE", help="thresholds (YAML, see README)")
    out_dir_arg(p)


def run(args) -> int:
    from ..config import load_config
    from ..io.calibration import load_calibration
    from ..io.images import load_stereo_pair
    from ..io.pfm import write_pfm
    from ..pipeline import run_front_end
    from ..viz.frames import disparity_image, figure5, figure6_front

    console = make_console()
    out = check_out_dir(args.out)
    config = load_config(args.config)
    sad = {}
    if args.num_disparities is not None:
        sad["num_disparities"] = args.num_disparities
    if args.block_size is not None:
        sad["block_size"] = args.block_size
    if sad:
        config = config.with_overrides({"sad": sad}, "command line")
    calibration = load_calibration(args.calib) if args.calib else None
    left, right = load_stereo_pair(args.left, args.right, calibration)
    check_image_settings(config, left.shape[1], left.shape[0], f"{args.left}")
    front = run_front_end(left, right, config)
    out.mkdir(parents=True, exist_ok=True)
    write_pfm(out / "disparity.pfm", front.disparity.left)
    disparity_image(out / "disparity.png", front.disparity.left, config.sad.num_disparities)
    p = front.pairs
    pairs = [
        {"u_left": float(p.u_left[k]), "u_right": float(p.u_right[k]), "v_top": float(p.v_top[k]),
         "v_bottom": float(p.v_bottom[k]), "length_left": float(p.length_left[k]),
         "length_right": float(p.length_right[k]), "similarity": float(p.similarity[k]),
         "length_similarity": float(p.length_similarity[k]), "kept": bool(front.kept[k])}
        for k in range(len(p))
    ]
    (out / "pairs.json").write_text(json.dumps(pairs, indent=1))
    figure5(out / "fig5_segments.png", left, right, front)
    figure6_front(out / "fig6_disparity.png", left, front)
    valid = float(np.mean(front.disparity.valid))
    console.print(
        f"{len(front.left_segments)} + {len(front.right_segments)} vertical segments, {len(p)} matched pairs, "
        f"{int(front.kept.sum())} kept by the disparity check; {valid:.1%} of the pixels have a valid disparity."
    )
    times = ", ".join(f"{k} {1000 * v:.1f}" for k, v in front.timings.items())
    console.print(f"timings (ms, the first call includes compiling): {times}")
    console.print(f"wrote {out}/disparity.pfm, disparity.png, pairs.json, fig5_segments.png, fig6_disparity.png")
    return 0
