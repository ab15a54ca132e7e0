"""``stablemarks run``: the on-line loop on a recorded run: our sequence folder, a ROS bag, or a KITTI or
EuRoC dataset folder."""

from __future__ import annotations

import argparse
import contextlib
import re
from pathlib import Path

import numpy as np

from ._common import check_image_settings, check_out_dir, make_console, parse_sigmas, parse_triplet

NAME = "run"
HELP = "run on-line landmark selection and EKF localization on a recorded sequence, bag or dataset"
DESCRIPTION = (
    "Run the on-line loop (predict with odometry, segment stereo, associate and update, select new landmarks) "
    "on SOURCE: a sequence folder (sequence.yaml, as `stablemarks simulate` writes), a ROS 1 bag (.bag) or "
    "ROS 2 bag (folder with metadata.yaml, or a .db3/.mcap file) with --left-topic, --right-topic, --odom-topic, "
    "--calib and --map, a KITTI odometry sequence folder or a EuRoC MAV folder (with --map and odometry). "
    "Writes OUT/trajectory.tum (evo-ready, stamps as recorded), dead_reckoning.tum, landmarks.yaml, log.jsonl, "
    "config.yaml (the resolved configuration) and Figure 10."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="SOURCE",
                   help="sequence folder, bag (.bag, .db3, .mcap or ROS 2 bag folder), KITTI or EuRoC folder")
    p.add_argument("--out", metavar="OUT", help="output folder (default: results/<source name>)")
    p.add_argument("--config", metavar="FILE", help="thresholds (YAML, see README)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one setting on top of --config, e.g. --set ekf.max_updates_per_frame=4 (repeatable)")
    p.add_argument("--method", default="stablemarks",
                   choices=["stablemarks", "plane_no_selection", "all_segments", "dead_reckoning"],
                   help="which method to run (default: stablemarks, the full method)")
    p.add_argument("--pose", metavar="X,Y,THETA",
                   help="start pose in the map (default: the sequence's initial pose; for bags and datasets the "
                        "first odometry pose)")
    p.add_argument("--pose-sigma", default="0.05,0.05,1deg", metavar="SX,SY,STHETA",
                   help="standard deviations of the start pose (default 0.05,0.05,1deg)")
    p.add_argument("--prior-landmarks", metavar="landmarks.yaml",
                   help="a landmark map written by an earlier run, to start from")
    g = p.add_argument_group("recordings (bags and dataset folders)")
    g.add_argument("--calib", metavar="DIR|FILE",
                   help="calibration: folder with left.yaml and right.yaml (ROS camera_info) or an OpenCV file")
    g.add_argument("--camera", metavar="MOUNT.yaml",
                   help="the stereo head's mount on the robot (default: mount.yaml beside the calibration)")
    g.add_argument("--map", metavar="MAP", help="map of walls: our map YAML, a ROS map_server map.yaml, or GeoJSON")
    g.add_argument("--left-topic", metavar="TOPIC", help="bag: left image topic (sensor_msgs/Image or CompressedImage)")
    g.add_argument("--right-topic", metavar="TOPIC", help="bag: right image topic")
    g.add_argument("--odom-topic", metavar="TOPIC", help="bag: wheel odometry topic (nav_msgs/Odometry)")
    g.add_argument("--pan-topic", metavar="TOPIC",
                   help="bag: head pan topic (std_msgs/Float64 or sensor_msgs/JointState; default: the mount's pan)")
    g.add_argument("--pan-joint", metavar="NAME", help="bag: the pan joint's name in --pan-topic's joint states")
    g.add_argument("--odometry", metavar="CSV",
                   help="KITTI/EuRoC: odometry CSV (stamp,x,y,theta; default: odometry.csv in the folder)")
    g.add_argument("--sync-tolerance", type=float, default=0.005, metavar="SECONDS",
                   help="largest stamp difference within a stereo pair and to the odometry (default 0.005)")
    o = p.add_argument_group("outputs")
    o.add_argument("--kitti", action="store_true", help="also write trajectory.kitti (KITTI odometry format)")
    o.add_argument("--save-rrd", metavar="FILE",
                   help="also write a rerun recording (needs pip install 'stablemarks[rerun]')")
    o.add_argument("--no-figures", action="store_true", help="skip Figure 10")


def run(args) -> int:
    from ..io.results import LogWriter, write_run
    from ..io.sources import open_sequence
    from ..io.trajectory import write_kitti
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
    sigma = parse_sigmas(args.pose_sigma, "--pose-sigma")
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
        source = open_sequence(args.source, left_topic=args.left_topic, right_topic=args.right_topic,
                               odom_topic=args.odom_topic, pan_topic=args.pan_topic, pan_joint=args.pan_joint,
                               calib=args.calib, map=args.map, mount=args.camera, odometry=args.odometry,
                               tolerance=args.sync_tolerance, start_pose=start)
        stack.callback(source.close)
        config = load_run_config(args, source)
        for note in source.notes:
            console.print(f"note: {note}")
        default = re.sub(r"[^\w.-]", "_", source.name).lstrip(".") or "run"  # a name is no path
        out = check_out_dir(args.out if args.out else Path("results") / default, inputs=(source_dir,))
        camera = source.camera
        check_image_settings(config, camera.width, camera.height, f"the images of {source.name}")
        localizer = Localizer(source.world_map, source.camera, start_pose=source.initial_pose,
                              start_cov=np.diag(sigma**2), config=config, method=args.method, prior_landmarks=prior)
        rrd = None
        if args.save_rrd:
            from ..io.rerun_log import RerunRecorder

            rrd = stack.enter_context(RerunRecorder(args.save_rrd, source, config))
            observers.append(rrd)
        with frame_progress(console, f"{source.name}: {len(source)} frames", len(source)) as progress:
            log = stack.enter_context(LogWriter(out / "log.jsonl"))  # streamed: an interrupted run keeps its log
            result = run_online(source, localizer, observers=[*observers, log], progress=progress, keep="poses")
    paths = write_run(out, result, config, log=log.path)
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

    def summary(self) -> None:
        import sys

        from ..cli import FLAGS
        from ..errors import for_cli

        for name, (k, _, message) in self.first.items():
            print(f"warning: {name} held in {self.frames[name]} frame(s), first at frame {k}: "
                  f"{for_cli(message.split(': ', 1)[1], FLAGS)}", file=sys.stderr)
