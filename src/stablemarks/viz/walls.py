"""The picture of walls extracted from an occupancy map: the grid in gray, the walls on top, in map metres."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.mapfiles import OCCUPIED, OccupancyMap
from ..maps import Map


def save_walls_figure(path: str | Path, occupancy: OccupancyMap, walls: Map) -> None:
    """Draw ``walls`` over ``occupancy`` into ``path`` (PNG), both in map coordinates [m].

    Occupied cells are black, free cells white, unknown cells gray (the grid is placed by its origin,
    rotation included); each wall is a coloured line labelled with its id at its middle, free edges are
    red circles.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.transforms import Affine2D

    grid = occupancy.grid
    H, W = grid.shape
    res = occupancy.resolution
    x0, y0, yaw = (float(v) for v in occupancy.origin)
    shade = np.where(grid >= OCCUPIED, 0.0, np.where(grid < 0, 0.75, 1.0 - grid / (2.0 * OCCUPIED)))

    fig = Figure(figsize=(8.0, 8.0 * min(1.5, max(0.5, H / W))))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    place = Affine2D().rotate(yaw).translate(x0, y0)
    ax.imshow(shade, cmap="gray", vmin=0.0, vmax=1.0, origin="upper", extent=(0.0, W * res, 0.0, H * res),
              interpolation="nearest", transform=place + ax.transData)
    corners = place.transform(np.array([[0.0, 0.0], [W * res, 0.0], [W * res, H * res], [0.0, H * res]]))
    ax.set_xlim(corners[:, 0].min(), corners[:, 0].max())
    ax.set_ylim(corners[:, 1].min(), corners[:, 1].max())

    colours = ["tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:cyan", "tab:olive",
               "tab:pink"]
    n_free = 0
    for i, plane in enumerate(walls.planes):
        P = np.array([plane.P1, plane.P2])
        ax.plot(P[:, 0], P[:, 1], "-", color=colours[i % len(colours)], lw=2.5, solid_capstyle="butt")
        mid = P.mean(axis=0)
        ax.annotate(plane.id, mid, textcoords="offset points", xytext=(3, 3), fontsize=7,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
        for e in plane.free_edges:
            ax.plot(*plane.edge(e), "o", ms=8, mfc="none", mec="red", mew=2)
            n_free += 1
    ax.plot([], [], "-", color="tab:blue", lw=2.5, label="extracted wall (id at its middle)")
    ax.plot([], [], "o", ms=8, mfc="none", mec="red", mew=2, label="free edge")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{len(walls)} walls, {n_free} free edges\n{occupancy.source}", fontsize=9)
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    fig.savefig(str(path), dpi=110, bbox_inches="tight")
