"""The map picture of a scenario: walls, free edges, features, clutter, the robot's path and its view."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geometry import SE2
from ..sim.run import Run
from ..sim.scenario import Scenario


def save_scene_figure(path: str | Path, scenario: Scenario, run: Run | None = None, *, fov_range: float = 6.0) -> Path:
    """Draw the scenario seen from above (:func:`scene_figure`) into ``path`` (PNG)."""
    fig = scene_figure(scenario, run, fov_range=fov_range)
    fig.savefig(str(path), dpi=100, bbox_inches="tight")
    return Path(path)


def scene_figure(scenario: Scenario, run: Run | None = None, *, fov_range: float = 6.0):
    """The scenario seen from above as a matplotlib ``Figure``.

    Reference planes of the map are drawn thick and coloured, other walls of the map black, walls in the
    world only gray and dashed; free edges are red circles labelled with their wall and end, feature edges
    small ticks, clutter gray. With a ``run``: the true path (poses and headings), the dead-reckoning path,
    and the camera's field of view at the first frame (``fov_range`` [m] long). Labels are placed where
    they overlap no other label and no marked point; the legend sits beside the map.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Polygon

    fig = Figure(figsize=(7.5, 7.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    labels = []  # (annotation, anchor point [m])
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
                labels.append((ax.annotate(f"{w.name or w.id} {e}", p, textcoords="offset points", xytext=(6, 6),
                                           fontsize=8, color="red"), p))
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
        labels += _draw_run(ax, run, fov_range)
    ax.plot([], [], "o", mfc="none", mec="red", mew=2, label="free edge (wall and end beside it)")
    ax.set_aspect("equal")
    ax.grid(True, lw=0.3)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"scenario {scenario.name}")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0.0)
    place_labels(ax, labels)
    return fig


def place_labels(ax, labels, gap: float = 2.0) -> None:
    """Move each annotation of ``labels`` (``(annotation, anchor)`` pairs, offsets in points) to the first of
    a ring of offsets around its anchor where its box overlaps no label placed before it, no anchor and
    stays inside the axes (else where it overlaps least)."""
    if not labels:
        return
    fig = ax.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    to_px = fig.dpi / 72.0
    anchors = ax.transData.transform(np.array([np.asarray(p, float) for _, p in labels]))
    box_ax = ax.get_window_extent(renderer)
    placed = []
    for ann, anchor in labels:
        extent = ann.get_window_extent(renderer)
        w, h = extent.width, extent.height
        a = ax.transData.transform(np.asarray(anchor, float))
        best, best_cost = None, np.inf
        for dx, dy in ((6, 6), (6, -6 - h / to_px), (-6 - w / to_px, 6), (-6 - w / to_px, -6 - h / to_px),
                       (-w / to_px / 2, 10), (-w / to_px / 2, -10 - h / to_px), (10, -h / to_px / 2),
                       (-10 - w / to_px, -h / to_px / 2), (6, 18), (6, -18 - h / to_px), (-6 - w / to_px, 18),
                       (-6 - w / to_px, -18 - h / to_px)):
            x0, y0 = a[0] + dx * to_px, a[1] + dy * to_px
            box = (x0 - gap, y0 - gap, x0 + w + gap, y0 + h + gap)
            cost = sum(_overlap(box, other) for other in placed)
            cost += sum(_overlap(box, (q[0] - 5, q[1] - 5, q[0] + 5, q[1] + 5)) for q in anchors)
            inside = (box[0] >= box_ax.x0 and box[2] <= box_ax.x1 and box[1] >= box_ax.y0 and box[3] <= box_ax.y1)
            cost += 0 if inside else 1e6
            if cost < best_cost:
                best, best_cost = (dx, dy, box), cost
            if cost == 0:
                break
        dx, dy, box = best
        ann.set_position((dx, dy))
        ann.set_horizontalalignment("left")
        ann.set_verticalalignment("bottom")
        placed.append(box)


def _overlap(a, b) -> float:
    """Area [px²] where boxes ``(x0, y0, x1, y1)`` overlap."""
    return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))


def _draw_run(ax, run: Run, fov_range: float) -> list:
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
    return [(ax.annotate(f"frame {len(true) - 1}", end.translation, textcoords="offset points", xytext=(6, -10),
                         fontsize=8), end.translation)]
