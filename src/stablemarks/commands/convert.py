"""``stablemarks convert``: a recording (a ROS bag, or a KITTI or EuRoC folder) written as a sequence folder."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..errors import InputError
from ._common import add_recording_arguments, check_out_dir, make_console, parse_triplet, recording_options

NAME = "convert"
HELP = "write a ROS bag (or a KITTI or EuRoC folder) as a sequence folder that can be inspected, edited and shared"
DESCRIPTION = (
    "Read SOURCE as `stablemarks run` does (same options: a bag's topics, its camera_info, /tf_static, /tf and "
    "/initialpose, or --calib, --camera, --pose) and write DIR as a recorded-sequence folder: sequence.yaml, "
    "calib/left.yaml and calib/right.yaml (ROS camera_info), calib/mount.yaml, map.yaml, left/ and right/ "
    "PNGs (the images as recorded, lossless), frames.csv (stamps and the head's pan), odometry.csv (the "
    "odometry at the frames) and groundtruth.tum (with --groundtruth-topic). `stablemarks run DIR` then gives "
    "the trajectory of `stablemarks run SOURCE`. DIR is written under a temporary name and appears only when "
    "complete."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="SOURCE",
                   help="bag (.bag, .db3, .mcap or ROS 2 bag folder), KITTI or EuRoC folder")
    p.add_argument("--out", required=True, metavar="DIR", help="sequence folder to write")
    p.add_argument("--force", action="store_true", help="replace DIR if it is an existing sequence folder")
    p.add_argument("--pose", metavar="X,Y,THETA",
                   help="start pose in the map, written as the folder's initial_pose (default: a bag's last "
                        "/initialpose before the first frame; else the first odometry pose)")
    add_recording_arguments(p)


def run(args: argparse.Namespace) -> int:
    from ..geometry import SE2
    from ..io.recorded import RecordedSource
    from ..io.sequence import check_target, write_sequence
    from ..io.sources import open_sequence
    from ._report import frame_progress

    start = parse_triplet(args.pose, "x, y, theta", "--pose") if args.pose else None
    source_dir = args.source if Path(args.source).is_dir() else None
    out = check_out_dir(args.out, inputs=(source_dir,), replaces=args.force)
    check_target(out.resolve(), args.force)
    console = make_console()
    source = open_sequence(args.source, **recording_options(args), start_pose=start)
    if not isinstance(source, RecordedSource):
        source.close()
        raise InputError(f"{args.source}: already a sequence folder (convert reads bags and KITTI or EuRoC "
                         "folders)")
    with source:
        for note in source.notes:
            console.print(f"note: {note}")
        n = len(source)
        truth = source.groundtruth
        if truth is not None and np.isnan(truth).any():
            missing = int(np.isnan(truth[:, 0]).sum())
            console.print(f"note: {missing} of {n} frames have no ground truth: groundtruth.tum is not written "
                          "(a sequence folder's ground truth covers every frame)")
            truth = None
        with frame_progress(console, f"{source.name}: {n} frames", n) as progress:

            def images():
                for k in range(n):
                    yield source.raw_pair(k)
                    progress(k + 1, n)

            written = write_sequence(
                out, name=source.name, description=f"converted by stablemarks convert from {args.source}",
                camera=source.camera, calibration=source.calibration, world_map=source.world_map,
                stamps=source.stamps, odometry=source.odometry_poses,
                pans=source.pans if getattr(source, "pan_recorded", True) else None, images=images(),
                groundtruth=truth, initial_pose=SE2.from_array(source.initial_pose), force=args.force,
                initial_cov=getattr(source, "initial_cov", None))
    files = ["sequence.yaml", "calib/", "map.yaml", "left/", "right/", "frames.csv", "odometry.csv"]
    if truth is not None:
        files.append("groundtruth.tum")
    console.print(f"wrote {written}/ ({', '.join(files)}): {n} frames; run it with: stablemarks run {args.out}")
    return 0
