"""The ``stablemarks`` command: parse, call the library, report.

Sub-commands live in :mod:`stablemarks.commands` (one module each) and are discovered at start-up.
Every :class:`~stablemarks.errors.StablemarksError` becomes one line on stderr and exit code 1.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from . import __version__, commands
from .errors import StablemarksError, for_cli


def _command_modules():
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        if hasattr(module, "NAME") and hasattr(module, "run"):
            yield module


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="stablemarks",
        description="Select stable visual landmarks on known walls from stereo images, and localize with them.",
    )
    parser.add_argument("--version", action="version", version=f"stablemarks {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for module in _command_modules():
        p = sub.add_parser(module.NAME, help=module.HELP, description=getattr(module, "DESCRIPTION", module.HELP))
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


FLAGS = {
    "left_topic": "--left-topic", "right_topic": "--right-topic", "odom_topic": "--odom-topic",
    "pan_topic": "--pan-topic", "pan_joint": "--pan-joint", "calib": "--calib", "map": "--map", "mount": "--camera",
    "odometry": "--odometry", "tolerance": "--sync-tolerance", "start_pose": "--pose", "force": "--force",
    "save_rrd": "--save-rrd",
}
"""The library's parameter names (as its error messages write them) → the command line's flags."""


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args._run(args)
    except StablemarksError as exc:
        print(f"stablemarks {args.command}: error: {for_cli(str(exc), FLAGS)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"stablemarks {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
