"""Figures of one frame: the paper's Figures 5, 6 and 7. Only the CLI imports this module."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _draw_pairs(ax, pairs, colour, lw=1.2):
    for k in range(len(pairs)):
        ax.plot([pairs.u_left[k]] * 2, [pairs.v_top[k], pairs.v_bottom[k]], color=colour, lw=lw)


def figure5(path: str | Path, left: np.ndarray, right: np.ndarray, front) -> Path:
    """Fig 5: segment pairs matched by the segment-based stereo (before the disparity filter),
    drawn on both images; pairs the disparity filter will drop are red."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    pairs = front.pairs
    for ax, img, key in ((axes[0], left, "u_left"), (axes[1], right, "u_right")):
        ax.imshow(img, cmap="gray", vmin=0, vmax=255)
        for k in range(len(pairs)):
            c = "#00c000" if front.kept[k] else "#ff2020"
            u = getattr(pairs, key)[k]
            ax.plot([u, u], [pairs.v_top[k], pairs.v_bottom[k]], color=c, lw=1.4)
        ax.set_axis_off()
    axes[0].set_title(f"left: {len(pairs)} matched pairs (red: rejected by the disparity check)")
    axes[1].set_title("right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def figure6(path: str | Path, left: np.ndarray, result) -> Path:
    """Fig 6: valid SAD disparity (gray), planar regions (tinted), the kept segment pairs (black), the
    selected ones (thick), and each fitted boundary with its ±σ as bars at top and bottom."""
    plt = _plt()
    front = result.front
    H, W = left.shape
    fig, ax = plt.subplots(figsize=(8, 6.2))
    base = np.full((H, W, 3), 1.0)
    valid = front.disparity.valid
    base[valid] = 0.72
    tints = [(0.55, 0.75, 1.0), (1.0, 0.75, 0.45), (0.6, 0.95, 0.6), (0.95, 0.6, 0.9)]
    for i, fit in enumerate(f for f in result.fits if f):
        base[fit.region] = tints[i % len(tints)]
    ax.imshow(base, interpolation="nearest")
    kept = front.kept_pairs
    _draw_pairs(ax, kept, "black", 0.9)
    for c in result.candidates:
        ax.plot([c.u_left] * 2, [c.v_top, c.v_bottom], color="black" if c.selected else "#888888",
                lw=3.0 if c.selected else 1.5)
    n_label = 0
    for model in result.planes:
        for b in model.boundaries:
            u, s = b.u[0], b.sigma_u[0]
            ax.axvline(u, color="#d00000", lw=1.2)
            for y in (6, H - 6):
                ax.plot([u - s, u + s], [y, y], color="#d00000", lw=3)
            ax.text(u + 3, 20 + 16 * (n_label % 3), f"{model.fit.plane.label} {b.edge} ±{s:.1f}px",
                    color="#d00000", fontsize=8)
            n_label += 1
    ax.set_xlim(-0.5, W - 0.5)
    ax.set_ylim(H - 0.5, -0.5)
    ax.set_title("SAD matches (gray), planar regions, kept pairs (black), selected (thick), boundaries (red)")
    ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def figure7(path: str | Path, result, world_map, camera, truth: dict | None = None) -> Path:
    """Fig 7: positional uncertainty of the features on the map: each candidate's map position with
    its 3σ interval along the wall (rank-1 covariance), plus the plane-constrained triangulated points
    with their 3σ ellipses; true feature positions when known."""
    plt = _plt()
    from matplotlib.patches import Ellipse

    fig, ax = plt.subplots(figsize=(8, 6.5))
    for plane in world_map:
        ls = "-" if plane.reference else ":"
        ax.plot([plane.P1[0], plane.P2[0]], [plane.P1[1], plane.P2[1]], ls, color="#444444", lw=2)
        for e in plane.free_edges:
            p = plane.edge(e)
            ax.plot(*p, marker="s", color="#d00000", ms=6)
    X = result.X
    ax.plot(*X[:2], marker=(3, 0, np.degrees(X[2]) - 90), ms=14, color="#2060c0")
    for c in result.candidates:
        colour = "#008000" if c.selected else "#c08000"
        t = c.cov @ np.ones(2)
        sd = np.sqrt(np.trace(c.cov))
        d = (t / np.linalg.norm(t)) if np.linalg.norm(t) > 0 else np.array([1.0, 0.0])
        a, b = c.P - 3 * sd * d, c.P + 3 * sd * d
        ax.plot([a[0], b[0]], [a[1], b[1]], color=colour, lw=2.5, alpha=0.7)
        ax.plot(*c.P, "o", color=colour, ms=4)
        w, v = np.linalg.eigh(c.cov_observed)
        ang = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
        ax.add_patch(Ellipse(c.P_observed, 6 * np.sqrt(max(w[1], 0)), 6 * np.sqrt(max(w[0], 0)), angle=ang,
                             fill=False, color=colour, lw=0.8, ls="--"))
    if truth:
        pts = np.array(truth.get("points", []))
        if len(pts):
            ax.plot(pts[:, 0], pts[:, 1], "x", color="black", ms=5, label="true features")
    ax.plot([], [], color="#008000", lw=2.5, label="selected: ±3σ along the wall")
    ax.plot([], [], color="#c08000", lw=2.5, label="rejected")
    ax.plot([], [], "s", color="#d00000", label="free edge")
    ax.set_aspect("equal")
    xs = [c.P[0] for c in result.candidates] + [X[0]]
    ys = [c.P[1] for c in result.candidates] + [X[1]]
    ax.set_xlim(min(xs) - 1.0, max(xs) + 1.0)
    ax.set_ylim(min(ys) - 0.5, max(ys) + 1.0)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("Positional uncertainty of the features (Fig 7)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def zoom_figure7(path: str | Path, result, planes: list[str]) -> Path:
    """Fig 7 per plane, stretched along the wall: each feature's 3σ interval (mm scale)."""
    plt = _plt()
    planes = [p for p in planes if any(c.plane_id == p for c in result.candidates)]
    fig, axes = plt.subplots(len(planes), 1, figsize=(9, 1.8 + 1.4 * len(planes)), squeeze=False)
    for ax, pid in zip(axes[:, 0], planes, strict=True):
        cands = [c for c in result.candidates if c.plane_id == pid]
        for c in cands:
            colour = "#008000" if c.selected else "#c08000"
            ax.errorbar(c.s, 0, xerr=3 * c.sigma_s, fmt="o", color=colour, capsize=3)
            ax.text(c.s, 0.25, str(c.index), ha="center", fontsize=8)
        ax.axvline(0, color="#d00000", lw=1)
        ax.set_yticks([])
        ax.set_ylim(-0.6, 0.6)
        ax.set_xlabel(f"{cands[0].plane_label}: distance from the free edge [m] "
                      "(bars: ±3σ; green selected, orange rejected)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def disparity_image(path: str | Path, disparity: np.ndarray, num_disparities: int) -> Path:
    """The disparity image coloured (turbo), invalid pixels black."""
    import cv2

    d = np.nan_to_num(np.asarray(disparity, dtype=np.float32), nan=0.0, posinf=0.0)
    img = cv2.applyColorMap(np.clip(d * (255.0 / max(num_disparities, 1)), 0, 255).astype(np.uint8),
                            cv2.COLORMAP_TURBO)
    img[~np.isfinite(disparity)] = 0
    cv2.imwrite(str(path), img)
    return Path(path)


def figure6_front(path: str | Path, left: np.ndarray, front) -> Path:
    """Fig 6 without planes: valid SAD matches (gray) and the segment pairs the disparity image confirms."""
    plt = _plt()
    H, W = left.shape
    fig, ax = plt.subplots(figsize=(8, 6.2))
    base = np.full((H, W), 1.0)
    base[front.disparity.valid] = 0.72
    ax.imshow(base, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    _draw_pairs(ax, front.kept_pairs, "black", 1.5)
    ax.set_title("SAD matches (gray) and the pairs the disparity check keeps (black)")
    ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
