"""The map picture of a scenario: walls, free edges, features, clutter, the robot's path and its view."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geometry import SE2
from ..sim.run import Run
from ..sim.scenario import Scenario


def save_scene_figure(path: str | Path, scenario: Scenario, run: Run | None = None, *, fov_range: float = 6.0) -> None:
    """Draw the scenario seen from above into ``path`` (PNG).

    Reference planes of the map are drawn thick and coloured, other walls of the map black, walls in the
    world only gray and dashed; free edges are red circles, feature edges small ticks, clutter gray. With a
    ``run``: the true path (poses and headings), the dead-reckoning path, and the camera's field of view at
    the first frame (``fov_range`` [m] long).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Polygon

    fig = Figure(figsize=(7.5, 7.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    colours = iter(["tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:cyan", "tab:olive"])
    wall_colour = {}
    labelled: set[str] = set()

    def once(label: str) -> str | None:
        if label in labelled:
            return None
        labelled.add(label)
        return label

    for w in scenario.walls:
        P = np.array([w.p1, w.p2])
        if w.in_map and w.reference:
            c = wall_colour[w.id] = next(colours, "tab:blue")
            ax.plot(P[:, 0], P[:, 1], "-", color=c, lw=4, solid_capstyle="butt", label=f"{w.name or w.id} (reference)")
        elif w.in_map:
            wall_colour[w.id] = "black"
            ax.plot(P[:, 0], P[:, 1], "-", color="black", lw=2, solid_capstyle="butt", label=once("map wall"))
        else:
            wall_colour[w.id] = "0.5"
            ax.plot(P[:, 0], P[:, 1], "--", color="0.5", lw=2, label=once("wall not in the map"))
        if w.in_map:
            for e in w.free_edges:
                p = w.plane.edge(e)
                ax.plot(*p, "o", ms=9, mfc="none", mec="red", mew=2)
                ax.annotate(f"{w.id}.{e}", p, textcoords="offset points", xytext=(6, 6), fontsize=8, color="red")
    for feat in scenario.features:
        plane = scenario.wall(feat.wall).plane
        for _, s, _ in feat.edges():
            p = plane.point_at(s)
            tick = np.array([p - 0.08 * plane.normal, p + 0.08 * plane.normal])
            ax.plot(tick[:, 0], tick[:, 1], "-", color=wall_colour[feat.wall], lw=1)
    for b in scenario.boxes:
        ax.add_patch(Polygon(b.corners(), closed=True, fc="0.8", ec="0.3", hatch="//", label=once("clutter")))
    for p in scenario.poles:
        ax.add_patch(Circle(p.center, p.radius, fc="0.8", ec="0.3", label=once("clutter")))
    if run is not None:
        _draw_run(ax, run, fov_range)
    ax.plot([], [], "o", mfc="none", mec="red", mew=2, label="free edge")
    ax.set_aspect("equal")
    ax.grid(True, lw=0.3)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"scenario {scenario.name}")
    ax.legend(loc="lower left", fontsize=8)
    fig.savefig(str(path), dpi=100, bbox_inches="tight")


def _draw_run(ax, run: Run, fov_range: float) -> None:
    from matplotlib.patches import Polygon

    true = np.array([p.as_array() for p in run.poses])
    dead = np.array([p.as_array() for p in run.dead_reckoning])
    ax.plot(true[:, 0], true[:, 1], ".-", color="k", ms=3, lw=1, label="true path")
    ax.plot(dead[:, 0], dead[:, 1], ".--", color="tab:red", ms=3, lw=1, label="dead reckoning")
    step = max(1, len(true) // 10)
    ax.quiver(true[::step, 0], true[::step, 1], np.cos(true[::step, 2]), np.sin(true[::step, 2]),
              angles="xy", scale_units="xy", scale=4, width=0.004, color="k")
    camera = run.scenario.camera.with_pan(run.pans[0])
    cam = camera.camera_pose(true[0])
    half = camera.half_fov
    corners = [cam.translation] + [
        cam.translation + fov_range * np.array([np.cos(cam.theta + a), np.sin(cam.theta + a)]) for a in (half, -half)
    ]
    ax.add_patch(Polygon(np.array(corners), closed=True, fc="gold", alpha=0.2, ec="goldenrod", zorder=0,
                         label="field of view (frame 0)"))
    end = SE2.from_array(true[-1])
    ax.annotate(f"frame {len(true) - 1}", end.translation, textcoords="offset points", xytext=(6, -10), fontsize=8)
