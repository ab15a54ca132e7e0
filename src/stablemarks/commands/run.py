"""``stablemarks run``: the on-line loop on a recorded run: our sequence folder, a ROS bag, or a KITTI or
EuRoC dataset folder."""

from __future__ import annotations

import argparse
import contextlib
import re
from pathlib import Path

import numpy as np

from ._common import (
    add_recording_arguments,
    check_image_settings,
    check_out_dir,
    make_console,
    parse_sigmas,
    parse_triplet,
    preset_arg,
    recording_options,
)

NAME = "run"
DEFAULT_POSE_SIGMA = "0.05,0.05,1deg"
"""--pose-sigma's default, where the source gives no start covariance."""
HELP = "run on-line landmark selection and EKF localization on a recorded sequence, bag or dataset"
DESCRIPTION = (
    "Run the on-line loop (predict with odometry, segment stereo, associate and update, select new landmarks) "
    "on SOURCE: a sequence folder (sequence.yaml, as `stablemarks simulate` writes), a ROS 1 bag (.bag) or "
    "ROS 2 bag (folder with metadata.yaml, or a .db3/.mcap file) with --left-topic, --right-topic, --odom-topic "
    "and --map (calibration, mount, start pose from its camera_info, /tf_static and /initialpose topics, or "
    "--calib, --camera, --pose), a KITTI odometry sequence folder or a EuRoC MAV folder (with --map and odometry). "
    "Writes OUT/trajectory.tum (evo-ready, stamps as recorded), dead_reckoning.tum, landmarks.yaml, log.jsonl, "
    "config.yaml (the resolved configuration) and Figure 10."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="SOURCE",
                   help="sequence folder, bag (.bag, .db3, .mcap or ROS 2 bag folder), KITTI or EuRoC folder")
    p.add_argument("--out", metavar="OUT", help="output folder (default: results/<source name>)")
    preset_arg(p)
    p.add_argument("--config", metavar="FILE", help="thresholds (YAML, see README), on top of --preset")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one setting on top of --config, e.g. --set ekf.max_updates_per_frame=4 (repeatable)")
    p.add_argument("--method", default="stablemarks",
                   choices=["stablemarks", "plane_no_selection", "all_segments", "dead_reckoning"],
                   help="which method to run (default: stablemarks, the full method)")
    p.add_argument("--pose", metavar="X,Y,THETA",
                   help="start pose in the map (default: the sequence's initial pose; for bags the last "
                        "/initialpose before the first frame; else the first odometry pose)")
    p.add_argument("--pose-sigma", metavar="SX,SY,STHETA",
                   help="standard deviations of the start pose (default: a bag's /initialpose covariance when "
                        "its pose is used, else 0.05,0.05,1deg)")
    p.add_argument("--prior-landmarks", metavar="landmarks.yaml",
                   help="a landmark map written by an earlier run, to start from")
    add_recording_arguments(p)
    o = p.add_argument_group("outputs")
    o.add_argument("--kitti", action="store_true", help="also write trajectory.kitti (KITTI odometry format)")
    o.add_argument("--save-rrd", metavar="FILE",
                   help="also write a rerun recording (needs pip install 'stablemarks[rerun]')")
    o.add_argument("--no-figures", action="store_true", help="skip Figure 10")


def run(args) -> int:
    from ..io.recorded import note_sources
    from ..io.results import LogWriter, write_run
    from ..io.sources import open_sequence
    from ..io.trajectory import write_kitti, write_tum
    from ..localizer import Localizer
    from ..maps import read_yaml
    from ..online import run_online
    from ._common import load_run_config
    from ._report import frame_progress, print_motion_summary

    console = make_console()
    if args.save_rrd:
        from ..io.rerun_log import require_rerun

        require_rerun()
    start = parse_triplet(args.pose, "x, y, theta", "--pose") if args.pose else None
    sigma = parse_sigmas(args.pose_sigma, "--pose-sigma") if args.pose_sigma else None
    source_dir = args.source if Path(args.source).is_dir() else None
    if args.out is not None:
        check_out_dir(args.out, inputs=(source_dir,))
    if args.save_rrd:
        from ._common import check_out_file

        check_out_file(args.save_rrd, "--save-rrd")
    prior = read_yaml(args.prior_landmarks, "landmark map") if args.prior_landmarks else None
    warned = HealthWarnings()
    observers = [warned]
    with contextlib.ExitStack() as stack:
        source = open_sequence(args.source, **recording_options(args), start_pose=start)
        stack.callback(source.close)
        start_cov = getattr(source, "initial_cov", None) if sigma is None else np.diag(sigma**2)
        if start_cov is None:
            start_cov = np.diag(parse_sigmas(DEFAULT_POSE_SIGMA) ** 2)
        config = load_run_config(args, source)
        for note in source.notes:
            console.print(f"note: {note}")
        default = re.sub(r"[^\w.-]", "_", source.name).lstrip(".") or "run"  # a name is no path
        out = check_out_dir(args.out if args.out else Path("results") / default, inputs=(source_dir,))
        camera = source.camera
        check_image_settings(config, camera.width, camera.height, f"the images of {source.name}")
        if not getattr(source, "pan_recorded", True) and config.pan.policy != "fixed":  # after the input checks
            warned.unrecorded_pan(source)
        localizer = Localizer(source.world_map, source.camera, start_pose=source.initial_pose,
                              start_cov=start_cov, config=config, method=args.method, prior_landmarks=prior)
        rrd = None
        if args.save_rrd:
            from ..io.rerun_log import RerunRecorder

            rrd = stack.enter_context(RerunRecorder(args.save_rrd, source, config))
            observers.append(rrd)
        with frame_progress(console, f"{source.name}: {len(source)} frames", len(source)) as progress:
            log = stack.enter_context(LogWriter(out / "log.jsonl"))  # streamed: an interrupted run keeps its log
            result = run_online(source, localizer, observers=[*observers, log], progress=progress, keep="poses")
    paths = write_run(out, result, config, log=log.path)
    sources = getattr(source, "sources", {})
    if sources:  # where a recording's inputs came from: comment lines atop config.yaml
        from ..cli import FLAGS
        from ..errors import for_cli

        cov = f"--pose-sigma {args.pose_sigma}" if sigma is not None else sources.get(
            "start_covariance", f"the default --pose-sigma {DEFAULT_POSE_SIGMA}")
        note_sources(paths.get("config"), {**{k: for_cli(v, FLAGS) for k, v in sources.items()},
                                           "start_covariance": cov})
    truth = getattr(source, "groundtruth", None)
    if truth is not None and "groundtruth" not in paths and not np.isnan(truth[:, 0]).all():
        known = ~np.isnan(truth[:, 0])  # a ground-truth topic that misses some frames: the frames it covers
        paths["groundtruth"] = write_tum(out / "groundtruth.tum", source.stamps[known], truth[known])
    if args.kitti:
        cam = source.camera
        paths["kitti"] = write_kitti(out / "trajectory.kitti", result.poses, [r.pan for r in result.records],
                                     mount=(cam.mount_x, cam.mount_y))
    if rrd is not None:
        paths["rrd"] = rrd.path
    if not args.no_figures:
        from ..viz.trajectory import figure10

        paths["figure"] = figure10(out / "fig10_motion.png", result)
    print_motion_summary(console, result, config.odometry)
    console.print("wrote " + ", ".join(str(p) for p in paths.values()))
    warned.summary()
    return 0


class HealthWarnings:
    """An observer printing one ``warning:`` line on stderr the first time each health condition holds (frame
    and stamp), and at the end of the run how many frames each held."""

    def __init__(self) -> None:
        self.first: dict[str, tuple[int, float, str]] = {}
        self.frames: dict[str, int] = {}

    def __call__(self, frame, est, localizer) -> None:
        import sys

        from ..cli import FLAGS
        from ..errors import for_cli

        for message in est.health:
            name = message.split(":", 1)[0]
            self.frames[name] = self.frames.get(name, 0) + 1
            if name not in self.first:
                self.first[name] = (frame.index, frame.stamp, message)
                print(f"warning: frame {frame.index} (stamp {frame.stamp:.3f} s): {for_cli(message, FLAGS)}",
                      file=sys.stderr, flush=True)

    def unrecorded_pan(self, source) -> None:
        """Warn, before the first frame, that ``source`` gives no pan for its frames (``pan_recorded`` False)
        while the configuration's pan policy says the head moves: a head that panned unrecorded turns every wall
        in the image, and the run then follows the odometry."""
        import math
        import sys

        message = (f"{source.name}: no pan recorded for the frames (a frames.csv without its pan column, or a bag "
                   "without --pan-topic and without a moving joint on /tf): every frame is taken at the mount's "
                   f"pan, {math.degrees(source.camera.pan):.1f} deg. If the head panned, give each frame's pan (the "
                   "pan column of frames.csv, or --pan-topic for a bag): with a wrong pan the walls are not found "
                   "where the pan puts them and the run follows the odometry. If the head does not pan, say so with "
                   "--set pan.policy=fixed")
        self.first["pan_unrecorded"] = (0, math.nan, f"pan_unrecorded: {message}")
        self.frames["pan_unrecorded"] = len(source)
        print(f"warning: {message}", file=sys.stderr, flush=True)

    def summary(self) -> None:
        import sys

        from ..cli import FLAGS
        from ..errors import for_cli

        for name, (k, _, message) in self.first.items():
            print(f"warning: {name} held in {self.frames[name]} frame(s), first at frame {k}: "
                  f"{for_cli(message.split(': ', 1)[1], FLAGS)}", file=sys.stderr)
