"""Helpers shared by the sub-commands: argument parsing of poses, checking the output before any work,
loading the camera and the map, and the limits of the stereo settings for an image."""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..errors import InputError, expected
from ..maps import COORDINATE_LIMIT


def parse_triplet(text: str, what: str, option: str) -> np.ndarray:
    """``"X,Y,THETA"`` → (3,) floats; the angle in radians, or in degrees with a ``deg`` suffix. Each value
    finite and within ±:data:`~stablemarks.maps.COORDINATE_LIMIT` (metres or radians)."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 3:
        raise InputError(expected(f"{what} as three comma-separated numbers", text, where=option))
    out = []
    for i, p in enumerate(parts):
        scale = 1.0
        if i == 2 and p.lower().endswith("deg"):
            p, scale = p[:-3], np.pi / 180.0
        try:
            v = float(p) * scale
        except ValueError:
            raise InputError(expected(f"{what} as three comma-separated numbers", text, where=option)) from None
        if not np.isfinite(v):
            raise InputError(expected("finite numbers", text, where=option))
        if abs(v) > COORDINATE_LIMIT:
            raise InputError(expected(f"numbers within ±{COORDINATE_LIMIT:g}", text, where=option))
        out.append(v)
    return np.array(out)


def parse_sigmas(text: str, option: str = "--pose-sigma") -> np.ndarray:
    """``"SX,SY,STHETA"`` → (3,) standard deviations, each positive (a zero σ makes the covariance singular)."""
    s = parse_triplet(text, "σx [m], σy [m], σθ [rad, or e.g. 2deg]", option)
    if np.any(s < 0):
        raise InputError(expected("non-negative standard deviations", text, where=option))
    if np.any(s == 0):
        raise InputError(expected("positive standard deviations (a zero σ makes the covariance singular)", text,
                                  where=option))
    return s


def pose_prior(pose: str, sigma: str) -> tuple[np.ndarray, np.ndarray]:
    """``--pose`` and ``--pose-sigma`` → pose (3,) and its diagonal covariance (3, 3)."""
    X = parse_triplet(pose, "x [m], y [m], theta [rad, or e.g. 90deg]", "--pose")
    s = parse_sigmas(sigma, "--pose-sigma")
    return X, np.diag(s**2)


def parse_pan(value: float | None, option: str = "--pan") -> float | None:
    """A head pan [rad] from the command line: finite and within ±:data:`~stablemarks.maps.COORDINATE_LIMIT`."""
    if value is None:
        return None
    if not (np.isfinite(value) and abs(value) <= COORDINATE_LIMIT):
        raise InputError(expected(f"a finite angle [rad] within ±{COORDINATE_LIMIT:g}", value, where=option))
    return float(value)


# ------------------------------------------------------------------ the output, before any work
def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except OSError:  # e.g. a parent we may not search
        return False


def check_out_dir(path: str | Path, *, option: str = "--out", inputs: Iterable[str | Path | None] = (),
                  replaces: bool = False) -> Path:
    """Check an output folder before any work: it is a folder or can be made one (not an existing file, not
    under a file), we can write there (a probe file is created and removed: nothing is left), and it is not
    an input folder nor inside one (``inputs``; with ``replaces``, the output folder may be replaced as a whole,
    so no input may be inside it either). Returns the path; :class:`InputError` naming ``option`` otherwise."""
    out = Path(path)
    if _exists(out) and not out.is_dir():
        raise InputError(f"{option}: {out} exists and is not a folder")
    probe = out
    while not _exists(probe) and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(f"{option}: {out}: {probe} is a file, so no folder can be made under it")
    try:
        fd, name = tempfile.mkstemp(prefix=".stablemarks-probe-", dir=probe)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        raise InputError(f"{option}: {out}: cannot write in {probe} ({exc.strerror or exc.__class__.__name__})") \
            from None
    here = out.resolve()
    for item in inputs:
        if item is None:
            continue
        src = Path(item).resolve()
        if src.is_dir() and (here == src or src in here.parents):
            raise InputError(f"{option}: {out} is the input {item} or inside it; write the results elsewhere")
        if replaces and (src == here or here in src.parents):
            raise InputError(f"{option}: {out} holds the input {item}; write the results elsewhere")
    return out


def check_out_file(path: str | Path, option: str) -> Path:
    """Check an output file before any work: not a folder, its folder exists (or can be made) and is writable."""
    out = Path(path)
    if out.is_dir():
        raise InputError(f"{option}: {out} is a folder; {option} names the file to write")
    check_out_dir(out.parent if str(out.parent) else Path("."), option=option)
    return out


# ------------------------------------------------------------------ the stereo settings
def check_image_settings(config, width: int, height: int, what: str) -> None:
    """The SAD settings must fit the images (``width`` × ``height`` px, ``what`` names them): the block at
    most the smaller image side, the disparity range inside the image width."""
    sad = config.sad
    if sad.block_size > min(width, height):
        raise InputError(f"sad.block_size: expected an odd window of at most {min(width, height)} px (the smaller "
                         f"side of {what}, {width}×{height} px), got {sad.block_size}")
    top = sad.min_disparity + sad.num_disparities
    if top > width or sad.min_disparity <= -width:
        raise InputError(f"sad.num_disparities: expected a disparity range inside the image width ({what} is "
                         f"{width} px wide), got {sad.min_disparity} to {top - 1} px "
                         f"(sad.min_disparity {sad.min_disparity}, sad.num_disparities {sad.num_disparities})")


def load_world_map(path: str | Path, what: str = "the command line"):
    """The map of walls ``--map``: our map YAML, a ROS map_server map or GeoJSON walls, with at least one wall."""
    from ..io.recorded import load_world_map as load

    return load(path, what)


def load_camera(calib: str | None, mount_path: str | None, near: str | Path):
    """The StereoCamera and the calibration: from ``--calib DIR|FILE`` (or a ``left.yaml``/``right.yaml``
    pair next to the images) and the mount from ``--camera MOUNT.yaml`` (or ``mount.yaml`` beside the
    calibration; otherwise the default mount)."""
    from ..io.calibration import Mount, load_calibration, load_mount

    if calib is None:
        here = Path(near).parent
        found = [d for d in (here, here / "calib") if (d / "left.yaml").exists() and (d / "right.yaml").exists()]
        if found:
            calib = str(found[0])
        else:
            raise InputError(
                f"no calibration: pass --calib DIR (a left.yaml/right.yaml camera_info pair or an OpenCV "
                f"stereo file); none found next to {near}"
            )
    calibration = load_calibration(calib)
    if mount_path is None:
        beside = Path(calib) / "mount.yaml" if Path(calib).is_dir() else Path(calib).parent / "mount.yaml"
        mount = load_mount(beside) if beside.exists() else Mount()
    else:
        mount = load_mount(mount_path)
    return calibration.stereo_camera(mount), calibration


def mount_source(calib: str | None, mount_path: str | None, near: str | Path) -> str:
    """Where :func:`load_camera` takes the mount from, as a phrase for the console."""
    if mount_path is not None:
        return f"{mount_path} (--camera)"
    if calib is None:
        here = Path(near).parent
        calib = str(next((d for d in (here, here / "calib") if (d / "left.yaml").exists()), here))
    beside = Path(calib) / "mount.yaml" if Path(calib).is_dir() else Path(calib).parent / "mount.yaml"
    if beside.exists():
        return f"{beside} (beside the calibration)"
    return ("the default, x 0 m, y 0 m, height 1 m, pan 0 (no mount.yaml beside the calibration; "
            "pass --camera MOUNT.yaml)")


def out_dir_arg(parser: argparse.ArgumentParser, default: str | None = None) -> None:
    parser.add_argument("--out", required=default is None, default=default, metavar="DIR",
                        help="output folder (created if missing)")


def make_console():
    """A rich console; when the output is not a terminal (a log, CI, `make demo | tee`), wide enough for
    the tables instead of rich's 80 columns."""
    import sys

    from rich.console import Console

    return Console(width=None if sys.stdout.isatty() else 160)


def parse_overrides(items: list[str]) -> dict:
    """``["ekf.max_updates_per_frame=4", …]`` → ``{"ekf": {"max_updates_per_frame": 4}}`` (values read as YAML,
    strictly: :func:`~stablemarks.maps.load_yaml_text`)."""
    import yaml

    from ..maps import load_yaml_text, yaml_error_text

    out: dict = {}
    for item in items:
        key, sep, text = item.partition("=")
        section, dot, name = key.strip().partition(".")
        if not (sep and dot and section and name and text.strip()):
            raise InputError(expected("SECTION.KEY=VALUE", item, where="--set"))
        try:
            value = load_yaml_text(text)
        except yaml.YAMLError as exc:
            raise InputError(f"--set: expected a YAML value after '=' in {item!r}{yaml_error_text(exc)}") from None
        out.setdefault(section, {})[name] = value
    return out


def preset_arg(parser: argparse.ArgumentParser) -> None:
    """``--preset NAME``, one of :data:`~stablemarks.config.PRESETS`, read by :func:`load_run_config`."""
    from ..config import PRESETS

    parser.add_argument("--preset", choices=list(PRESETS), default=None,
                        help="start from a named configuration (paper: the paper's noise values, σ_img 0.5 px; "
                             "narrow: line noise 0.06 px and the rules that go with it, see the README); "
                             "--config and --set change it further")


def load_run_config(args, source=None, base=None):
    """The resolved configuration, each step on top of the one before: ``base`` (default ``--preset NAME`` or the
    defaults), ``--config FILE`` (the settings it names), then every ``--set SECTION.KEY=VALUE``, then the
    settings ``source`` describes (its ``config_defaults``: a simulated robot's odometry noise and pan
    policy) where the steps before left the default: preset < file < command line."""
    from ..config import Config, parse_config
    from ..maps import read_yaml

    preset = getattr(args, "preset", None)
    if base is None:
        base = Config.preset(preset) if preset else Config()
    config = base if getattr(args, "config", None) is None else parse_config(
        read_yaml(args.config, "configuration file"), str(args.config), base=base)
    if getattr(args, "set", None):
        config = config.with_overrides(parse_overrides(args.set), "--set")
    if source is not None:
        config = config.with_source_defaults(getattr(source, "config_defaults", None) or {})
    return config


# ------------------------------------------------------------------ recordings: run's and convert's inputs
def add_recording_arguments(p: argparse.ArgumentParser) -> None:
    """The options that say how to read a recording (a bag's topics, the calibration, mount and map files, a
    dataset's odometry, the stamp tolerance): shared by ``run`` and ``convert``, passed on to
    :func:`~stablemarks.io.sources.open_sequence` by :func:`recording_options`."""
    g = p.add_argument_group("recordings (bags and dataset folders)")
    g.add_argument("--calib", metavar="DIR|FILE",
                   help="calibration: folder with left.yaml and right.yaml (ROS camera_info) or an OpenCV file "
                        "(bags: default their camera_info topics)")
    g.add_argument("--camera", metavar="MOUNT.yaml",
                   help="the stereo head's mount on the robot (default: mount.yaml beside the calibration; bags "
                        "without one: the tf from --base-frame to the left image's frame)")
    g.add_argument("--map", metavar="MAP", help="map of walls: our map YAML, a ROS map_server map.yaml, or GeoJSON")
    g.add_argument("--left-topic", metavar="TOPIC", help="bag: left image topic (sensor_msgs/Image or CompressedImage)")
    g.add_argument("--right-topic", metavar="TOPIC", help="bag: right image topic")
    g.add_argument("--odom-topic", metavar="TOPIC", help="bag: wheel odometry topic (nav_msgs/Odometry)")
    g.add_argument("--pan-topic", metavar="TOPIC",
                   help="bag: head pan topic (std_msgs/Float64 or sensor_msgs/JointState; default: the mount's pan)")
    g.add_argument("--pan-joint", metavar="NAME", help="bag: the pan joint's name in --pan-topic's joint states")
    g.add_argument("--left-info-topic", metavar="TOPIC",
                   help="bag: left sensor_msgs/CameraInfo (default: camera_info beside --left-topic)")
    g.add_argument("--right-info-topic", metavar="TOPIC",
                   help="bag: right sensor_msgs/CameraInfo (default: camera_info beside --right-topic)")
    g.add_argument("--base-frame", metavar="FRAME",
                   help="bag: the robot's tf frame, origin on the floor, for the mount from /tf_static and /tf "
                        "(default base_link)")
    g.add_argument("--groundtruth-topic", metavar="TOPIC",
                   help="bag: true poses (nav_msgs/Odometry, geometry_msgs/PoseStamped or "
                        "PoseWithCovarianceStamped), written as OUT/groundtruth.tum at the frame stamps")
    g.add_argument("--odometry", metavar="CSV",
                   help="KITTI/EuRoC: odometry CSV (stamp,x,y,theta; default: odometry.csv in the folder)")
    g.add_argument("--sync-tolerance", type=float, default=0.005, metavar="SECONDS",
                   help="largest stamp difference within a stereo pair and to the odometry (default 0.005)")


def recording_options(args) -> dict:
    """The keyword arguments of :func:`~stablemarks.io.sources.open_sequence` that the options of
    :func:`add_recording_arguments` give (all but the source and the start pose)."""
    return dict(left_topic=args.left_topic, right_topic=args.right_topic, odom_topic=args.odom_topic,
                pan_topic=args.pan_topic, pan_joint=args.pan_joint, calib=args.calib, map=args.map,
                mount=args.camera, odometry=args.odometry, tolerance=args.sync_tolerance,
                left_info_topic=args.left_info_topic, right_info_topic=args.right_info_topic,
                base_frame=args.base_frame, groundtruth_topic=args.groundtruth_topic)
