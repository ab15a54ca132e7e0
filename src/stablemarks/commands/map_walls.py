"""``stablemarks map-walls``: extract the walls of a ROS map_server occupancy map into a stablemarks map."""

from __future__ import annotations

import argparse
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
    "merged, corners joined) and write them in the stablemarks map format to WALLS.yaml, with a picture "
    "WALLS.png beside it (the grid with the walls, their ids and their free edges) to check them by eye. "
    "A wall end is free when the cells just beyond it are free space. Edit the YAML to fix what the "
    "extraction got wrong. Nothing is written on error."
)


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


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise InputError(expected("a .yaml file name", str(out), where="--out"))
    if out.exists() and out.resolve() == args.map.resolve():
        raise InputError(f"--out: {out} is the input map; choose another file name")
    if not args.min_length > 0:
        raise InputError(expected("a positive length [m]", args.min_length, where="--min-length"))
    if not args.max_gap >= 0:
        raise InputError(expected("a non-negative length [m]", args.max_gap, where="--max-gap"))
    params = WallExtraction(min_length=args.min_length, max_gap=args.max_gap)
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
    for column in ("id", "p1 [m]", "p2 [m]", "length [m]", "free edges"):
        table.add_column(column)
    for plane in walls:
        table.add_row(plane.id, f"({plane.p1[0]:.3f}, {plane.p1[1]:.3f})", f"({plane.p2[0]:.3f}, {plane.p2[1]:.3f})",
                      f"{plane.length:.3f}", ", ".join(plane.free_edges) or "-")
    console.print(table)
    n_free = sum(len(p.free_edges) for p in walls)
    console.print(f"Found {len(walls)} walls and {n_free} free edges (walls of at least {params.min_length:g} m)")
    if not len(walls):
        console.print("[yellow]warning:[/yellow] no walls found; check occupied_thresh, negate and --min-length")
    console.print(f"Wrote {out} and {picture}")
    return 0
