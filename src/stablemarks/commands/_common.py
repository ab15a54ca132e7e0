"""Helpers shared by the sub-commands: argument parsing of poses and loading the camera."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..errors import InputError, expected


def parse_triplet(text: str, what: str, option: str) -> np.ndarray:
    """``"X,Y,THETA"`` → (3,) floats; the angle in radians, or in degrees with a ``deg`` suffix."""
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
        out.append(v)
    return np.array(out)


def pose_prior(pose: str, sigma: str) -> tuple[np.ndarray, np.ndarray]:
    """``--pose`` and ``--pose-sigma`` → pose (3,) and its diagonal covariance (3, 3)."""
    X = parse_triplet(pose, "x [m], y [m], theta [rad, or e.g. 90deg]", "--pose")
    s = parse_triplet(sigma, "σx [m], σy [m], σθ [rad, or e.g. 2deg]", "--pose-sigma")
    if np.any(s < 0):
        raise InputError(expected("non-negative standard deviations", sigma, where="--pose-sigma"))
    return X, np.diag(np.maximum(s, 1e-9) ** 2)


def load_camera(calib: str | None, mount_path: str | None, near: str | Path):
    """The StereoCamera and the calibration: from ``--calib DIR|FILE`` (or a ``left.yaml``/``right.yaml``
    pair next to the images) and the mount from ``--camera MOUNT.yaml`` (or ``mount.yaml`` beside the
    calibration; otherwise the default mount)."""
    from ..io.calibration import Mount, load_calibration, load_mount

    if calib is None:
        here = Path(near).parent
        if (here / "left.yaml").exists() and (here / "right.yaml").exists():
            calib = str(here)
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
    """``["ekf.max_updates_per_frame=4", …]`` → ``{"ekf": {"max_updates_per_frame": 4}}`` (values read as YAML)."""
    import yaml

    out: dict = {}
    for item in items:
        key, sep, text = item.partition("=")
        section, dot, name = key.strip().partition(".")
        if not (sep and dot and section and name and text.strip()):
            raise InputError(expected("SECTION.KEY=VALUE", item, where="--set"))
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            raise InputError(expected("a YAML value after '='", item, where="--set")) from None
        out.setdefault(section, {})[name] = value
    return out


def load_run_config(args, source=None, base=None):
    """The resolved configuration: ``base`` (default ``--preset NAME`` or the defaults), ``--config FILE``,
    then every ``--set SECTION.KEY=VALUE``, then the
    settings ``source`` describes (its ``config_defaults``: a simulated robot's odometry noise and pan
    policy) where the user left the default."""
    from ..config import Config, load_config, parse_config
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
