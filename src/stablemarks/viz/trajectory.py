"""The paper's Figure 10: the motion result on the map. Only the CLI imports this module."""

from __future__ import annotations

from pathlib import Path

import numpy as np

EKF = "#2060c0"
DEAD = "#c06000"
LANDMARK = "#008000"
FREE_EDGE = "#d00000"
WALL = "#444444"


def _ellipse(ax, mean, cov, n_sigma=2.0, **kw):
    from matplotlib.patches import Ellipse

    w, v = np.linalg.eigh(cov)
    w = np.maximum(w, 0.0)
    ang = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
    ax.add_patch(Ellipse(mean, 2 * n_sigma * np.sqrt(w[1]), 2 * n_sigma * np.sqrt(w[0]), angle=ang, fill=False, **kw))


def _draw_map(ax, world_map) -> tuple[bool, bool, bool]:
    """Walls (reference planes solid, occluders dotted) and free edges; which of them were drawn."""
    drawn = [False, False, False]
    for plane in world_map:
        ax.plot([plane.P1[0], plane.P2[0]], [plane.P1[1], plane.P2[1]], "-" if plane.reference else ":",
                color=WALL, lw=2)
        drawn[0 if plane.reference else 1] = True
        for e in plane.free_edges:
            ax.plot(*plane.edge(e), "s", color=FREE_EDGE, ms=5, zorder=4)
            drawn[2] = True
    return drawn[0], drawn[1], drawn[2]


def _draw_landmarks(ax, ekf, n_sigma: float = 2.0) -> int:
    n = 0
    for i in ekf.landmark_ids:
        lm = ekf.landmark(i)
        pos = np.asarray(lm.position, dtype=float)
        cov = np.asarray(lm.cov2d, dtype=float)
        if lm.plane_id is not None:  # a landmark on a wall: rank-1 covariance along the wall
            w, v = np.linalg.eigh(cov)
            sd = float(np.sqrt(max(w[1], 0.0)))
            t = v[:, 1]
            a, b = pos - n_sigma * sd * t, pos + n_sigma * sd * t
            ax.plot([a[0], b[0]], [a[1], b[1]], color=LANDMARK, lw=3, alpha=0.7, solid_capstyle="butt")
        else:
            _ellipse(ax, pos, cov, n_sigma, color=LANDMARK, lw=0.8)
        ax.plot(*pos, "o", color=LANDMARK, ms=3)
        n += 1
    return n


def make_figure10(result, every: int = 2, zoom: bool = True):
    """Figure 10 as a matplotlib ``Figure``.

    Left, the map: walls (reference planes solid, walls in the map only as occluders dotted), free edges
    (red squares), the true path (when known), dead reckoning, the EKF estimate with 2σ ellipses every
    ``every`` frames, and the landmarks with their 2σ interval along their walls. Right (``zoom``), the
    path alone at a larger scale, with equal axes so that the ellipses keep their shape, and its own
    legend.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    P = np.asarray(result.poses, dtype=float)
    C = np.asarray(result.covs, dtype=float)
    D = np.asarray(result.dead_reckoning, dtype=float)
    T = result.true_poses
    T = None if T is None else np.asarray(T, dtype=float)
    lo = hi = None
    if zoom:  # the zoom's extent: the paths and their ellipses
        ext = [P[:, :2], D[:, :2]] + ([T[:, :2]] if T is not None else [])
        for k in range(0, len(P), max(1, every)):
            w, v = np.linalg.eigh(C[k, :2, :2])
            r = 2.0 * np.sqrt(np.maximum(w, 0.0))
            ext.append(P[k, :2] + np.array([s1 * r[0] * v[:, 0] + s2 * r[1] * v[:, 1]
                                            for s1 in (-1, 1) for s2 in (-1, 1)]))
        allp = np.concatenate(ext)
        lo, hi = allp.min(axis=0), allp.max(axis=0)
        pad = max(0.05, 0.08 * float(np.max(hi - lo)))
        lo, hi = lo - pad, hi + pad
    ratio = float(np.clip((hi[0] - lo[0]) / (hi[1] - lo[1]), 0.45, 1.2)) if zoom else 0.0
    fig = Figure(figsize=(7.5 + 6.5 * ratio if zoom else 7.5, 7.4))
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(1, 2 if zoom else 1, width_ratios=[1.0, ratio] if zoom else [1.0])
    axes = [fig.add_subplot(gs[0, k]) for k in range(2 if zoom else 1)]

    def paths(ax):
        if T is not None:
            ax.plot(T[:, 0], T[:, 1], "-", color="black", lw=1.5)
        ax.plot(D[:, 0], D[:, 1], "--", color=DEAD, lw=1.5)
        ax.plot(P[:, 0], P[:, 1], "-", color=EKF, lw=1.5)
        for k in range(0, len(P), max(1, every)):
            _ellipse(ax, P[k, :2], C[k, :2, :2], color=EKF, lw=0.8)

    ax = axes[0]
    reference, occluder, free = _draw_map(ax, result.world_map)
    paths(ax)
    n_landmarks = _draw_landmarks(ax, result.ekf)
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{result.name}: motion with on-line selected landmarks (Fig 10)", fontsize=10)
    path_handles = ([Line2D([], [], color="black", lw=1.5, label="true path")] if T is not None else []) + [
        Line2D([], [], color=DEAD, lw=1.5, ls="--", label="dead reckoning"),
        Line2D([], [], color=EKF, lw=1.5, label=f"EKF estimate ({result.method})"),
        Line2D([], [], color=EKF, marker="o", ms=11, mfc="none", ls="none", mew=0.8,
               label=f"EKF 2σ position ellipse (every {every} frames)"),
    ]
    map_handles = []
    if reference:
        map_handles.append(Line2D([], [], color=WALL, lw=2, label="wall: reference plane"))
    if occluder:
        map_handles.append(Line2D([], [], color=WALL, lw=2, ls=":", label="wall in the map only as occluder"))
    if free:
        map_handles.append(Line2D([], [], color=FREE_EDGE, marker="s", ls="none", ms=6, label="free edge"))
    if n_landmarks:
        map_handles.append(Line2D([], [], color=LANDMARK, lw=3, marker="o", ms=3,
                                  label=f"landmark ±2σ along its wall ({n_landmarks})"))
    ax.legend(handles=map_handles + path_handles, loc="upper left", bbox_to_anchor=(0.0, -0.09), ncol=2,
              fontsize=8, frameon=False)

    if zoom:
        z = axes[1]
        paths(z)
        z.set_xlim(lo[0], hi[0])
        z.set_ylim(lo[1], hi[1])
        z.set_aspect("equal", adjustable="box")
        z.grid(alpha=0.3)
        z.set_xlabel("x [m]")
        z.set_ylabel("y [m]")
        z.set_title("zoom on the path (equal axes)", fontsize=10)
        z.legend(handles=path_handles, loc="upper right", bbox_to_anchor=(1.0, -0.09), fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.07, right=0.98, top=0.94, bottom=0.2, wspace=0.25)
    return fig


def figure10(path: str | Path, result, every: int = 2, zoom: bool = True) -> Path:
    """Write Figure 10 (:func:`make_figure10`) to ``path``."""
    fig = make_figure10(result, every, zoom)
    fig.savefig(str(path), dpi=110)
    return Path(path)
