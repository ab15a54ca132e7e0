"""The ``stablemarks`` command: parse, call the library, report.

Sub-commands live in :mod:`stablemarks.commands` (one module each) and are discovered at start-up.
Every :class:`~stablemarks.errors.StablemarksError`, a malformed command line and a file the system will not
let us read or write become one line on stderr (control characters escaped, about 300 characters at most)
and exit code 1.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import re
import sys

from . import __version__, commands
from .errors import MAX_LINE, StablemarksError, for_cli, one_line


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line, ``stablemarks CMD: error: ...``, and exit code 1 like
    every other user error (argparse's default is the usage and exit code 2)."""

    def error(self, message: str):
        print(fit_line(f"{self.prog}: error: {message} (see {self.prog} --help)"), file=sys.stderr)
        sys.exit(1)


def _command_modules():
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        if hasattr(module, "NAME") and hasattr(module, "run"):
            yield module


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="stablemarks",
        description="Select stable visual landmarks on known walls from stereo images, and localize with them.",
    )
    parser.add_argument("--version", action="version", version=f"stablemarks {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
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
    "save_rrd": "--save-rrd", "left_info_topic": "--left-info-topic", "right_info_topic": "--right-info-topic",
    "base_frame": "--base-frame", "groundtruth_topic": "--groundtruth-topic",
}
"""The library's parameter names (as its error messages write them) → the command line's flags."""


_PATH = re.compile(r"(?<![\w.~])/[^\s:,;'\"()]+")
"""An absolute path in a message."""


def _on_disk(path: str) -> bool:
    """Whether ``path`` names a file or folder, or something in an existing folder (not ``/``)."""
    folder = os.path.dirname(path.rstrip("/"))
    try:
        return os.path.exists(path) or (folder not in ("", "/") and os.path.isdir(folder))
    except (OSError, ValueError):
        return False


def fit_line(text: str, limit: int = MAX_LINE) -> str:
    """``text`` as one printable line of at most ``limit`` characters: first the leading folders of long
    absolute paths give way (``…/left/000000.png``, then ``…/000000.png``), then the middle of the text."""
    text = one_line(text, None)
    for keep in (2, 1):
        if len(text) <= limit:
            return text

        def short(m: re.Match, keep: int = keep) -> str:
            path, parts = m.group(0), m.group(0).split("/")
            if len(parts) - 1 <= keep or not _on_disk(path):  # a ROS topic looks like a path too
                return path
            return "…/" + "/".join(parts[-keep:])

        text = _PATH.sub(short, text)
    return one_line(text, limit)


_NEGATIVE = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)
"""A value that starts like a negative number (``-1,-1,-1``, ``-0.5``, ``-90deg``), not an option."""


def _value_options(parser: argparse.ArgumentParser) -> set[str]:
    """The option strings of ``parser`` and its sub-commands that take exactly one value."""
    out: set[str] = set()
    for action in parser._actions:
        if action.option_strings and action.nargs is None:
            out.update(action.option_strings)
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                out |= _value_options(sub)
    return out


def _join_negative_values(argv: list[str], parser: argparse.ArgumentParser) -> list[str]:
    """``--pose-sigma -1,-1,-1`` → ``--pose-sigma=-1,-1,-1``: argparse takes a value starting with ``-`` that
    is no plain number for an option and fails with its usage; joined, the value reaches our own check."""
    takes_value = _value_options(parser)
    out: list[str] = []
    i = 0
    while i < len(argv):
        if argv[i] in takes_value and i + 1 < len(argv) and _NEGATIVE.match(argv[i + 1]):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(_join_negative_values(argv, parser))
    prefix = f"stablemarks {args.command}: error: "
    try:
        code = args._run(args)
    except StablemarksError as exc:
        print(prefix + fit_line(for_cli(str(exc), FLAGS), MAX_LINE - len(prefix)), file=sys.stderr)
        return 1
    except OSError as exc:  # the system refused a read or a write the checks could not foresee (disk full, ...)
        where = f"{exc.filename}: " if exc.filename else ""
        text = f"{where}{exc.strerror or exc.__class__.__name__}"
        print(prefix + fit_line(text, MAX_LINE - len(prefix)), file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"stablemarks {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
