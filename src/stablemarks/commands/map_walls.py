"""``stablemarks map-walls``: extract the walls of a ROS map_server occupancy map into a stablemarks map."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from rich.console import Console
from rich.table import Table

from ..errors import InputError, expected
from ..io.mapfiles import WallExtraction, load_occupancy_map, walls_from_occupancy

NAME = "map-walls"
HELP = "extract walls from a ROS map_server occupancy map (YAML + PGM/PNG); write them as a stablemarks map"
DESCRIPTION = (
    "Read a ROS map_server map (MAP.yaml with image, resolution, origin, negate, occupied_thresh, free_thresh) "
    "as map_server does, extract its walls (skeleton of the occupied cells, Hough segments, collinear pieces "
    "merged, corners joined) and place each one where a stereo camera sees it: on its face, half the wall's "
    "thickness from its centre line, measured on the grid to a fraction of a cell. A wall with free space on "
    "both sides gives one plane per side (visible_from: left or right of p1 → p2); a wall end is free when the "
    "cells just beyond it are free space. Writes WALLS.yaml in the stablemarks map format and a picture "
    "WALLS.png beside it (the grid with the walls, their ids and free edges, and a zoom on each free edge) to "
    "check them by eye. Edit the YAML to fix what the extraction got wrong. Nothing is written on error."
)


def parse_height(text: str) -> tuple[float, float]:
    """``"LOW,HIGH"`` [m] → ``(low, high)``: two finite numbers with ``low < high`` (one-line error)."""
    parts = [p.strip() for p in str(text).split(",")]
    what = "LOW,HIGH: the bottom and top of the walls in metres, e.g. 0,2.5"
    if len(parts) != 2:
        raise InputError(expected(what, text, where="--height"))
    try:
        low, high = (float(p) for p in parts)
    except ValueError:
        raise InputError(expected(what, text, where="--height")) from None
    if not (math.isfinite(low) and math.isfinite(high)):
        raise InputError(expected("finite heights [m]", text, where="--height"))
    if not low < high:
        raise InputError(expected("LOW < HIGH [m]", text, where="--height"))
    return low, high


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = WallExtraction()
    parser.add_argument("map", type=Path, metavar="MAP.yaml", help="ROS map_server map YAML")
    parser.add_argument("--out", required=True, type=Path, metavar="WALLS.yaml",
                        help="output map file (.yaml); the picture goes beside it as WALLS.png")
    parser.add_argument("--min-length", type=float, default=defaults.min_length, metavar="M",
                        help=f"shortest wall kept [m] (default {defaults.min_length:g})")
    parser.add_argument("--max-gap", type=float, default=defaults.max_gap, metavar="M",
                        help=f"collinear pieces closer than this are one wall; wider gaps, such as doorways, "
                             f"separate walls [m] (default {defaults.max_gap:g})")
    low, high = defaults.height
    parser.add_argument("--height", default=f"{low:g},{high:g}", metavar="LOW,HIGH",
                        help=f"bottom and top of every wall [m], written as each wall's z "
                             f"(default {low:g},{high:g})")


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise InputError(expected("a .yaml file name", str(out), where="--out"))
    if out.exists() and out.resolve() == args.map.resolve():
        raise InputError(f"--out: {out} is the input map; choose another file name")
    from ._common import check_out_file

    check_out_file(out, "--out")
    if not args.min_length > 0:
        raise InputError(expected("a positive length [m]", args.min_length, where="--min-length"))
    if not args.max_gap >= 0:
        raise InputError(expected("a non-negative length [m]", args.max_gap, where="--max-gap"))
    height = parse_height(args.height)
    params = WallExtraction(min_length=args.min_length, max_gap=args.max_gap, height=height)
    occupancy = load_occupancy_map(args.map)
    walls = walls_from_occupancy(occupancy.grid, occupancy.resolution, occupancy.origin, params,
                                 source=str(args.map))

    from ..viz.walls import save_walls_figure

    picture = out.with_suffix(".png")
    out.parent.mkdir(parents=True, exist_ok=True)
    walls.save(out)
    save_walls_figure(picture, occupancy, walls)

    console = Console(soft_wrap=True, highlight=False)
    H, W = occupancy.shape
    table = Table(title=f"Walls of {args.map} ({W}×{H} cells, {occupancy.resolution:g} m per cell)")
    for column in ("id", "p1 [m]", "p2 [m]", "length [m]", "seen from", "free edges"):
        table.add_column(column)
    for plane in walls:
        side = plane.visible_from if plane.reference else "occluder"
        table.add_row(plane.id, f"({plane.p1[0]:.3f}, {plane.p1[1]:.3f})", f"({plane.p2[0]:.3f}, {plane.p2[1]:.3f})",
                      f"{plane.length:.3f}", side, ", ".join(plane.free_edges) or "-")
    console.print(table)
    n_free = sum(len(p.free_edges) for p in walls)
    console.print(f"Found {len(walls)} walls and {n_free} free edges (walls of at least {params.min_length:g} m; "
                  f"one wall per face seen from free space; height {height[0]:g}–{height[1]:g} m)")
    if not len(walls):
        console.print("[yellow]warning:[/yellow] no walls found; check occupied_thresh, negate and --min-length")
    console.print(f"Wrote {out} and {picture}")
    return 0
