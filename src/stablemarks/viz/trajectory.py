"""The paper's Figure 10: the motion result on the map. Only the CLI imports this module."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _ellipse(ax, mean, cov, n_sigma=2.0, **kw):
    from matplotlib.patches import Ellipse

    w, v = np.linalg.eigh(cov)
    w = np.maximum(w, 0.0)
    ang = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
    ax.add_patch(Ellipse(mean, 2 * n_sigma * np.sqrt(w[1]), 2 * n_sigma * np.sqrt(w[0]), angle=ang, fill=False, **kw))


def figure10(path: str | Path, result, every: int = 2, zoom: bool = True) -> Path:
    """True path (when known), dead reckoning, the EKF estimate with 2σ ellipses, and the landmarks with
    their 2σ uncertainty along their walls, on the map. A second panel zooms on the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2 if zoom else 1, figsize=(13 if zoom else 7, 6.5), squeeze=False)
    P = result.poses
    C = result.covs
    D = result.dead_reckoning
    T = result.true_poses
    for n_ax, ax in enumerate(axes[0]):
        for plane in result.world_map:
            ax.plot([plane.P1[0], plane.P2[0]], [plane.P1[1], plane.P2[1]], "-" if plane.reference else ":",
                    color="#444444", lw=2)
            for e in plane.free_edges:
                ax.plot(*plane.edge(e), "s", color="#d00000", ms=5)
        if T is not None:
            ax.plot(T[:, 0], T[:, 1], "-", color="black", lw=1.5, label="true path")
        ax.plot(D[:, 0], D[:, 1], "--", color="#c06000", lw=1.5, label="dead reckoning")
        ax.plot(P[:, 0], P[:, 1], "-", color="#2060c0", lw=1.5, label="EKF estimate (2σ ellipses)")
        for k in range(0, len(P), every):
            _ellipse(ax, P[k, :2], C[k, :2, :2], color="#2060c0", lw=0.8)
        ekf = result.ekf
        for i in ekf.landmark_ids:
            lm = ekf.landmark(i)
            cov = lm.cov2d
            if lm.kind == "wall":
                sd = np.sqrt(np.trace(cov))
                t = np.linalg.eigh(cov)[1][:, 1]
                a, b = lm.position - 2 * sd * t, lm.position + 2 * sd * t
                ax.plot([a[0], b[0]], [a[1], b[1]], color="#008000", lw=3, alpha=0.7)
            else:
                _ellipse(ax, lm.position, cov, color="#008000", lw=0.8)
            ax.plot(*lm.position, "o", color="#008000", ms=3)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        if n_ax == 1:
            pts = np.concatenate([P[:, :2], D[:, :2]] + ([T[:, :2]] if T is not None else []))
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            pad = max(0.1, 0.15 * float(np.max(hi - lo)))
            ax.set_xlim(lo[0] - pad, hi[0] + pad)
            ax.set_ylim(lo[1] - pad, hi[1] + pad)
            ax.set_aspect("auto")
            ax.set_title("zoom on the path (axes scaled independently)")
        else:
            ax.plot([], [], color="#008000", lw=3, label="landmarks (±2σ along the wall)")
            ax.legend(loc="lower left", fontsize=8)
            ax.set_title(f"{result.name}: motion with on-line selected landmarks (Fig 10)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
