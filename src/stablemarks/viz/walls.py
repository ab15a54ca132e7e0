"""The picture of walls extracted from an occupancy map: the grid in gray, the walls on top, in map metres,
with a zoom on every free edge to check it cell by cell."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.mapfiles import OCCUPIED, OccupancyMap
from ..maps import Map

COLOURS = ["tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:cyan", "tab:olive", "tab:pink"]
MAX_ZOOMS = 30
"""At most this many free edges get a zoom panel (the others are listed in the title)."""


def _shade(occupancy: OccupancyMap) -> np.ndarray:
    grid = occupancy.grid
    return np.where(grid >= OCCUPIED, 0.0, np.where(grid < 0, 0.75, 1.0 - grid / (2.0 * OCCUPIED)))


def _draw_grid(ax, occupancy: OccupancyMap, shade: np.ndarray):
    """The grid placed by its origin (rotation included) in map metres; returns the corners of the grid."""
    from matplotlib.transforms import Affine2D

    H, W = occupancy.grid.shape
    res = occupancy.resolution
    x0, y0, yaw = (float(v) for v in occupancy.origin)
    place = Affine2D().rotate(yaw).translate(x0, y0)
    ax.imshow(shade, cmap="gray", vmin=0.0, vmax=1.0, origin="upper", extent=(0.0, W * res, 0.0, H * res),
              interpolation="nearest", transform=place + ax.transData)
    return place.transform(np.array([[0.0, 0.0], [W * res, 0.0], [W * res, H * res], [0.0, H * res]]))


def _visible_normal(plane) -> np.ndarray | None:
    """Unit normal toward the side the wall is seen from, None when seen from both."""
    if plane.visible_from == "left":
        return plane.normal
    if plane.visible_from == "right":
        return -plane.normal
    return None


def _draw_walls(ax, walls: Map, colours: dict, *, lw: float, tick: float, labels: bool, fontsize: float = 7):
    for plane in walls.planes:
        c = colours[plane.id]
        P = np.array([plane.P1, plane.P2])
        ax.plot(P[:, 0], P[:, 1], "-" if plane.reference else ":", color=c, lw=lw, solid_capstyle="butt")
        n = _visible_normal(plane)
        mid = P.mean(axis=0)
        if n is not None and tick > 0:  # a short tick toward the free space the face is seen from
            ax.plot([mid[0], mid[0] + tick * n[0]], [mid[1], mid[1] + tick * n[1]], "-", color=c, lw=max(1.0, lw / 2))
        if labels:
            away = n if n is not None else plane.normal
            ax.annotate(plane.id, mid, xytext=(14 * away[0], 14 * away[1]), textcoords="offset points",
                        ha="center", va="center", fontsize=fontsize, color=c,
                        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": c, "lw": 0.6, "alpha": 0.85})


def walls_figure(occupancy: OccupancyMap, walls: Map):
    """The figure of :func:`save_walls_figure` (a matplotlib ``Figure``, not yet saved)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    shade = _shade(occupancy)
    res = occupancy.resolution
    H, W = occupancy.grid.shape
    edges = [(plane, e) for plane in walls.planes for e in plane.free_edges]
    zooms = edges[:MAX_ZOOMS]
    colours = {plane.id: COLOURS[i % len(COLOURS)] for i, plane in enumerate(walls.planes)}

    # the overview: about 6 px per cell, between 10 and 30 inches wide at 100 dpi
    width = float(np.clip(W * 6 / 100.0, 10.0, 30.0))
    aspect = float(np.clip(H / W, 0.4, 2.0))
    cols = 5
    rows = int(np.ceil(len(zooms) / cols))
    zoom_h = width / cols
    total = width * aspect + rows * zoom_h + 1.6  # inches: the map, the zooms, the title and legend
    fig = Figure(figsize=(width, total))
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(1 + rows, cols, height_ratios=[width * aspect] + [zoom_h] * rows, hspace=0.35,
                          wspace=0.25, top=1.0 - 1.3 / total, bottom=0.4 / total, left=0.05, right=0.98)
    ax = fig.add_subplot(gs[0, :])
    corners = _draw_grid(ax, occupancy, shade)
    ax.set_xlim(corners[:, 0].min(), corners[:, 0].max())
    ax.set_ylim(corners[:, 1].min(), corners[:, 1].max())
    _draw_walls(ax, walls, colours, lw=2.0, tick=4 * res, labels=True, fontsize=8)
    for k, (plane, e) in enumerate(zooms):
        p = plane.edge(e)
        ax.plot(*p, "o", ms=10, mfc="none", mec="red", mew=2)
        # the label beyond the edge, on the side the face is seen from: two faces' labels part
        out = plane.direction if e == "p2" else -plane.direction
        side = _visible_normal(plane)
        off = 14 * out + (10 * side if side is not None else 0)
        ax.annotate(f"Z{k + 1}", p, xytext=(off[0], off[1]), textcoords="offset points", ha="center",
                    va="center", fontsize=8, color="red", weight="bold")
    for plane, e in edges[MAX_ZOOMS:]:
        ax.plot(*plane.edge(e), "o", ms=10, mfc="none", mec="red", mew=2)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    more = f"; {len(edges) - MAX_ZOOMS} free edges without a zoom" if len(edges) > MAX_ZOOMS else ""
    fig.suptitle(f"{occupancy.source}: {len(walls)} wall faces, {len(edges)} free edges "
                 f"({W}×{H} cells of {100 * res:g} cm){more}", fontsize=11)
    handles = [
        Line2D([], [], color="tab:blue", lw=2.5, label="wall face (plane), id beside it"),
        Line2D([], [], color="tab:blue", lw=1.5, marker="|", ls="none", ms=8,
               label="tick: the side it is seen from (visible_from)"),
        Line2D([], [], color="0.3", lw=2.0, ls=":", label="occluder only (reference: false)"),
        Line2D([], [], ls="none", marker="o", ms=9, mfc="none", mec="red", mew=2,
               label="free edge (Zn: its zoom below)"),
        Line2D([], [], ls="none", marker="s", ms=9, mfc="black", mec="0.5", label="occupied cell"),
        Line2D([], [], ls="none", marker="s", ms=9, mfc="0.75", mec="0.5", label="unknown cell"),
    ]
    ax.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.02), ncol=3, fontsize=8, frameon=False)

    # one zoom per free edge: 0.6 m around it, the cells' boundaries drawn
    half = max(0.3, 6 * res)
    for k, (plane, e) in enumerate(zooms):
        z = fig.add_subplot(gs[1 + k // cols, k % cols])
        _draw_grid(z, occupancy, shade)
        p = plane.edge(e)
        z.set_xlim(p[0] - half, p[0] + half)
        z.set_ylim(p[1] - half, p[1] + half)
        _cell_lines(z, occupancy, p, half)
        _draw_walls(z, walls, colours, lw=2.0, tick=2 * res, labels=False)
        z.plot(*p, "+", color="red", ms=14, mew=1.5)
        z.set_aspect("equal")
        z.tick_params(labelsize=6)
        z.set_title(f"Z{k + 1}: {plane.id}.{e} ({p[0]:.3f}, {p[1]:.3f})", fontsize=8, color=colours[plane.id])
    return fig


def _cell_lines(ax, occupancy: OccupancyMap, centre, half: float) -> None:
    """Thin lines on the cells' boundaries around ``centre`` (map frame, rotated with the grid)."""
    res = occupancy.resolution
    x0, y0, yaw = (float(v) for v in occupancy.origin)
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    local = R.T @ (np.asarray(centre, float) - [x0, y0])
    reach = half * 1.5
    lo = np.floor((local - reach) / res) * res
    hi = np.ceil((local + reach) / res) * res
    segs = []
    for x in np.arange(lo[0], hi[0] + res / 2, res):
        segs.append([[x, lo[1]], [x, hi[1]]])
    for y in np.arange(lo[1], hi[1] + res / 2, res):
        segs.append([[lo[0], y], [hi[0], y]])
    from matplotlib.collections import LineCollection

    segs = np.array(segs) @ R.T + [x0, y0]
    ax.add_collection(LineCollection(segs, colors="0.55", linewidths=0.3))


def save_walls_figure(path: str | Path, occupancy: OccupancyMap, walls: Map) -> Path:
    """Draw ``walls`` over ``occupancy`` into ``path`` (PNG), both in map coordinates [m].

    Occupied cells are black, free cells white, unknown cells gray (the grid is placed by its origin,
    rotation included). Each wall face is a coloured line with its id on the side it is seen from and a
    short tick toward that side; free edges are red circles, each with a zoom panel below the map
    (0.6 m around it, every cell's boundary drawn, the edge a red cross) to check it to the centimetre.
    """
    fig = walls_figure(occupancy, walls)
    fig.savefig(str(path), dpi=100)
    return Path(path)
