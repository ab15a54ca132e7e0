"""``stablemarks calibrate``: stereo calibration from chessboard image pairs, written as ROS camera_info files."""

from __future__ import annotations

import argparse
import glob
import re
from pathlib import Path

from rich.console import Console
from rich.table import Table

from ..errors import InputError, expected
from ..io.calibration import calibrate_stereo, save_calibration

NAME = "calibrate"
HELP = "calibrate a stereo pair from chessboard images; write left.yaml and right.yaml (ROS camera_info)"
DESCRIPTION = (
    "Calibrate a stereo camera from pairs of chessboard images. Pairs are formed in sorted file-name "
    "order of the two globs, which must match as many files each. Pairs where the board is not found in "
    "both images are skipped with a warning. The result is written, only on success, as ROS camera_info "
    "files OUT/left.yaml and OUT/right.yaml (raw intrinsics, distortion, rectification and projection)."
)

_BOARD = re.compile(r"^\s*(\d+)\s*[xX×]\s*(\d+)\s*$")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--left", required=True, metavar="GLOB", help="left images, e.g. 'calib/left_*.png'")
    parser.add_argument("--right", required=True, metavar="GLOB", help="right images, e.g. 'calib/right_*.png'")
    parser.add_argument("--board", required=True, metavar="COLSxROWS",
                        help="inner corners of the chessboard, e.g. 9x6 (as OpenCV counts them)")
    parser.add_argument("--square", required=True, type=float, metavar="METERS", help="side of a square [m]")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` → ``(9, 6)``; at least 2 inner corners each way."""
    m = _BOARD.match(text)
    if not m or len(m[1]) > 4 or len(m[2]) > 4 or min(int(m[1]), int(m[2])) < 2 or max(int(m[1]), int(m[2])) > 100:
        raise InputError(expected("COLSxROWS inner corners, e.g. 9x6", text, where="--board"))
    return int(m[1]), int(m[2])


def _images(option: str, pattern: str) -> list[str]:
    files = sorted(glob.glob(str(Path(pattern).expanduser())))
    if not files:
        raise InputError(f"{option}: no file matches {pattern!r}")
    return files


def run(args: argparse.Namespace) -> int:
    import math

    from ._common import check_out_dir

    check_out_dir(args.out)
    board = parse_board(args.board)
    if not (math.isfinite(args.square) and args.square > 0):
        raise InputError(expected("a positive square size [m]", args.square, where="--square"))
    if args.square > 10.0:
        raise InputError(expected("a square size [m] of at most 10", args.square, where="--square"))
    left, right = _images("--left", args.left), _images("--right", args.right)
    if len(left) != len(right):
        raise InputError(f"--left matches {len(left)} files but --right matches {len(right)}; "
                         "pairs are formed in sorted order, so the counts must be equal")
    calib, report = calibrate_stereo(left, right, board, args.square)
    paths = save_calibration(calib, args.out)

    console = Console(soft_wrap=True, highlight=False)
    table = Table(title=f"Stereo pairs ({board[0]}x{board[1]} board, {args.square} m squares)")
    for column in ("#", "left", "right", "used"):
        table.add_column(column)
    skipped = {s.index for s in report.skipped}
    for i, (l_path, r_path) in enumerate(zip(left, right, strict=True)):
        table.add_row(str(i), Path(l_path).name, Path(r_path).name,
                      "[red]no[/red]" if i in skipped else "[green]yes[/green]")
    console.print(table)
    for line in report.warnings:
        console.print(f"[yellow]warning:[/yellow] {line}")
    cam = calib.stereo_camera()
    console.print(f"Calibrated from {len(report.used)} of {report.n_pairs} pairs")
    console.print(f"RMS reprojection error: {report.rms:.3f} px "
                  f"(each camera alone: left {report.rms_left:.3f} px, right {report.rms_right:.3f} px)")
    console.print(f"Rectified epipolar error: {report.epipolar_error:.3f} px (mean |v_left - v_right|)")
    console.print(f"Rectified camera: f = {cam.f:.2f} px, (cu, cv) = ({cam.cu:.2f}, {cam.cv:.2f}) px, "
                  f"baseline = {cam.baseline:.4f} m, {cam.width}x{cam.height} px")
    console.print(f"Wrote {' and '.join(str(p) for p in paths)}")
    return 0
