"""``stablemarks select``: landmark modeling and selection on one stereo frame (Table 1, Figs 5–7)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ._common import (
    check_image_settings,
    check_out_dir,
    load_camera,
    load_world_map,
    make_console,
    mount_source,
    out_dir_arg,
    parse_pan,
    pose_prior,
    preset_arg,
)

NAME = "select"
HELP = "model and select landmarks on one stereo frame (prints Table 1, writes landmarks.csv/json, Figs 5-7)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("left", metavar="LEFT", help="left image (rectified, or raw with --calib)")
    p.add_argument("right", metavar="RIGHT", help="right image")
    p.add_argument("--map", required=True, metavar="MAP",
                   help="map of walls: our map YAML (see README), a ROS map_server map.yaml or GeoJSON")
    p.add_argument("--pose", required=True, metavar="X,Y,THETA",
                   help="robot pose prior in the map: metres and radians (or e.g. 90deg)")
    p.add_argument("--pose-sigma", required=True, metavar="SX,SY,STHETA",
                   help="standard deviations of the pose prior (metres, radians or e.g. 2deg)")
    p.add_argument("--calib", metavar="DIR", help="calibration: left.yaml/right.yaml pair or OpenCV file "
                   "(default: a pair next to LEFT)")
    p.add_argument("--camera", metavar="MOUNT.yaml", help="camera mounting on the robot (offset, height, pan)")
    p.add_argument("--pan", type=float, default=None, metavar="RAD", help="head pan for this frame [rad]")
    preset_arg(p)
    p.add_argument("--config", metavar="FILE", help="thresholds (YAML, see README), on top of --preset")
    p.add_argument("--mm", action="store_true", help="print the table in millimetres like the paper")
    p.add_argument("--no-figures", action="store_true", help="skip the pictures")
    out_dir_arg(p)


def run(args) -> int:
    from ..io.images import load_stereo_pair
    from ..io.results import write_landmarks
    from ..pipeline import process_frame
    from ._common import load_run_config
    from ._tables import landmark_table

    console = make_console()
    out = check_out_dir(args.out)
    config = load_run_config(args)
    X, cov_X = pose_prior(args.pose, args.pose_sigma)
    pan = parse_pan(args.pan)
    world_map = load_world_map(args.map)
    camera, calibration = load_camera(args.calib, args.camera, args.left)
    console.print(f"mount: {mount_source(args.calib, args.camera, args.left)}")
    if pan is not None:
        camera = camera.with_pan(pan)
    left, right = load_stereo_pair(args.left, args.right, calibration)
    check_image_settings(config, left.shape[1], left.shape[0], f"{args.left}")
    result = process_frame(left, right, camera, world_map, X, cov_X, config, dense=True)  # Fig 6 shows all
    write_landmarks(out, result.candidates, extra={"pose": X.tolist(), "cov_pose": cov_X.tolist(),
                                                    "warnings": result.warnings})
    for w in result.warnings:
        console.print(f"[yellow]warning:[/] {w}")
    console.print(landmark_table(result.candidates, mm=args.mm))
    if not args.no_figures:
        write_frame_figures(out, left, right, result, world_map, camera)
    (out / "timings.json").write_text(json.dumps({**result.front.timings, **result.timings}, indent=2))
    figures = [] if args.no_figures else frame_figure_names(result)
    console.print(f"wrote {out / 'landmarks.csv'}, " + ", ".join(["landmarks.json", "timings.json", *figures]))
    return 0


def frame_figure_names(result) -> list[str]:
    """The files :func:`write_frame_figures` writes for ``result``."""
    names = ["fig5_segments.png", "fig6_planes.png", "fig7_uncertainty.png"]
    return names + (["fig7_along_walls.png"] if result.candidates else [])


def write_frame_figures(out: Path, left, right, result, world_map, camera, truth=None, matches=None) -> None:
    """Figs 5–7 of one frame; ``matches`` (Table 1's rows against our candidates) numbers the features along the
    walls as the paper does."""
    from ..viz.frames import figure5, figure6, figure7, zoom_figure7

    figure5(out / "fig5_segments.png", left, right, result.front)
    figure6(out / "fig6_planes.png", left, result)
    figure7(out / "fig7_uncertainty.png", result, world_map, camera, truth)
    if result.candidates:
        zoom_figure7(out / "fig7_along_walls.png", result, sorted({c.plane_id for c in result.candidates}), matches)
