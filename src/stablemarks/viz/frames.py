"""Figures of one frame: the paper's Figures 5, 6 and 7. Only the CLI imports this module.

Each figure has a builder returning a matplotlib ``Figure`` (``make_figure6`` …, to inspect or test) and a
function writing it to a PNG (``figure6`` …, what the commands call).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

SELECTED = "#008000"  # green: a selected feature, in Figures 6 and 7
REJECTED = "#e08000"  # orange: a rejected candidate
SEGMENT = "#1f4fd8"  # blue: a segment pair the disparity check keeps
BOUNDARY = "#d00000"  # red: a plane's free edge found in the image, with its ±σ
SAD = 0.78  # gray level of a pixel with a valid SAD match
PLANE_TINTS = [(0.55, 0.78, 1.0), (1.0, 0.72, 0.40), (0.62, 0.92, 0.55), (0.93, 0.62, 0.92), (0.98, 0.92, 0.45)]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _new_figure(figsize):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path, dpi: int = 110) -> Path:
    fig.savefig(str(path), dpi=dpi)
    return Path(path)


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


# ------------------------------------------------------------ Figure 6
def _sad_base(shape, valid) -> np.ndarray:
    base = np.ones(tuple(shape) + (3,))
    base[np.asarray(valid, dtype=bool)] = SAD
    return base


def _fig6_legend_handles(planes: list[tuple[str, tuple]], *, candidates: bool, boundaries: bool) -> list:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [
        Patch(fc=(SAD, SAD, SAD), ec="0.5", label="SAD match (valid disparity)"),
        Patch(fc="white", ec="0.5", label="no SAD match"),
    ]
    handles += [Patch(fc=tint, ec="0.5", label=f"planar region: {label}") for label, tint in planes]
    handles.append(Line2D([], [], color=SEGMENT, lw=1.5, label="segment pair kept by the disparity check"))
    if candidates:
        handles += [Line2D([], [], color=SELECTED, lw=4, label="feature selected as landmark"),
                    Line2D([], [], color=REJECTED, lw=4, label="feature rejected")]
    if boundaries:
        handles.append(Line2D([], [], color=BOUNDARY, lw=1.5, marker="|", ms=12, mew=2,
                              label="plane's free edge found, ±σ (bars, zooms)"))
    return handles


def make_figure6(left: np.ndarray, result):
    """Fig 6 as a ``Figure``: valid SAD matches (gray), each planar region tinted (legend), the segment
    pairs the disparity check keeps (blue), the features modelled on the planes (thick: green selected,
    orange rejected), and each free edge found (red line) with its ±σ as capped bars at the top and the
    bottom of the image and, below it, a zoom ±30 px around the edge where the ±σ band is visible."""
    from matplotlib.patches import Rectangle

    front = result.front
    H, W = left.shape[:2]
    boundaries = [(model.fit.plane.label, b) for model in result.planes for b in model.boundaries]
    n_zoom = min(len(boundaries), 4)
    fig = _new_figure((11.0, 6.4 + (2.9 if n_zoom else 0.0)))
    gs = fig.add_gridspec(2 if n_zoom else 1, max(n_zoom, 1), height_ratios=[6.4, 2.6] if n_zoom else [1.0],
                          left=0.02, right=0.70, top=0.93, bottom=0.05, hspace=0.3, wspace=0.3)
    ax = fig.add_subplot(gs[0, :])
    base = _sad_base((H, W), front.disparity.valid)
    planes = []
    for i, fit in enumerate(f for f in result.fits if f):
        tint = PLANE_TINTS[i % len(PLANE_TINTS)]
        base[fit.region] = tint
        planes.append((fit.plane.label, tint))
    ax.imshow(base, interpolation="nearest")
    _draw_pairs(ax, front.kept_pairs, SEGMENT, 1.0)
    for c in result.candidates:
        ax.plot([c.u_left] * 2, [c.v_top, c.v_bottom], color=SELECTED if c.selected else REJECTED, lw=3.0,
                solid_capstyle="butt")
    for k, (label, b) in enumerate(boundaries):
        u, s = float(b.u[0]), float(b.sigma_u[0])
        ax.axvline(u, color=BOUNDARY, lw=1.0)
        ax.axvspan(u - s, u + s, color=BOUNDARY, alpha=0.15, lw=0)
        for y in (14, H - 14):
            ax.errorbar([u], [y], xerr=[s], fmt="none", ecolor=BOUNDARY, elinewidth=2.5, capsize=7, capthick=2)
        tag = f"Z{k + 1}: " if k < n_zoom else ""
        ax.text(u + 4, 34 + 18 * (k % 4), f"{tag}{label} {b.edge}: σ = {s:.1f} px", color=BOUNDARY, fontsize=8,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
    ax.set_xlim(-0.5, W - 0.5)
    ax.set_ylim(H - 0.5, -0.5)
    ax.set_title("Fig 6: SAD matches, planar regions, kept segment pairs, features and the planes' free edges",
                 fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.legend(handles=_fig6_legend_handles(planes, candidates=True, boundaries=bool(boundaries)),
               loc="upper left", bbox_to_anchor=(0.71, 0.93), fontsize=8, frameon=False)
    # a zoom on each free edge: ±30 px around it in the middle rows of the image, the ±σ band visible
    for k, (label, b) in enumerate(boundaries[:n_zoom]):
        z = fig.add_subplot(gs[1, k])
        u, s = float(b.u[0]), float(b.sigma_u[0])
        u0, u1 = int(max(0, np.floor(u - 30))), int(min(W, np.ceil(u + 31)))
        v0, v1 = int(H * 0.3), int(H * 0.7)
        z.imshow(base[v0:v1, u0:u1], interpolation="nearest", extent=(u0 - 0.5, u1 - 0.5, v1 - 0.5, v0 - 0.5),
                 aspect="auto")
        z.add_patch(Rectangle((u - s, v0 - 0.5), 2 * s, v1 - v0, color=BOUNDARY, alpha=0.25, lw=0))
        z.axvline(u, color=BOUNDARY, lw=1.2)
        ym = 0.5 * (v0 + v1)
        z.errorbar([u], [ym], xerr=[s], fmt="none", ecolor=BOUNDARY, elinewidth=2.5, capsize=8, capthick=2)
        z.set_title(f"Z{k + 1}: {label} {b.edge}\nu = {u:.1f} ± {s:.1f} px (σ)", fontsize=8, color=BOUNDARY)
        z.set_xlabel("column u [px]", fontsize=7)
        z.tick_params(labelsize=6)
        z.set_yticks([])
    return fig


def figure6(path: str | Path, left: np.ndarray, result) -> Path:
    """Write Fig 6 (:func:`make_figure6`) to ``path``."""
    return _save(make_figure6(left, result), path)


def make_figure6_front(left: np.ndarray, front):
    """Fig 6 without planes as a ``Figure``: valid SAD matches (gray) and the segment pairs the
    disparity image confirms (blue), with a legend."""
    H, W = left.shape[:2]
    fig = _new_figure((11.0, 6.4))
    ax = fig.add_axes((0.02, 0.04, 0.68, 0.89))
    ax.imshow(_sad_base((H, W), front.disparity.valid), interpolation="nearest")
    _draw_pairs(ax, front.kept_pairs, SEGMENT, 1.5)
    ax.set_xlim(-0.5, W - 0.5)
    ax.set_ylim(H - 0.5, -0.5)
    ax.set_title(f"SAD matches and the {len(front.kept_pairs)} segment pairs the disparity check keeps", fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.legend(handles=_fig6_legend_handles([], candidates=False, boundaries=False), loc="upper left",
               bbox_to_anchor=(0.71, 0.93), fontsize=8, frameon=False)
    return fig


def figure6_front(path: str | Path, left: np.ndarray, front) -> Path:
    """Write :func:`make_figure6_front` to ``path``."""
    return _save(make_figure6_front(left, front), path)


# ------------------------------------------------------------ Figure 7
def _wall_interval(c, n_sigma: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """The ends of a candidate's ±nσ interval along its wall (the rank-1 covariance's direction)."""
    w, v = np.linalg.eigh(np.asarray(c.cov, dtype=float))
    d = v[:, 1]
    sd = float(np.sqrt(max(w[1], 0.0)))
    return c.P - n_sigma * sd * d, c.P + n_sigma * sd * d


def _ellipse(ax, mean, cov, n_sigma: float, **kw) -> None:
    from matplotlib.patches import Ellipse

    w, v = np.linalg.eigh(np.asarray(cov, dtype=float))
    w = np.maximum(w, 0.0)
    ang = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
    ax.add_patch(Ellipse(mean, 2 * n_sigma * np.sqrt(w[1]), 2 * n_sigma * np.sqrt(w[0]), angle=ang, fill=False, **kw))


def _draw_fig7(ax, result, world_map, truth, *, marker_size: float, lw: float, stagger: float = 0.0) -> None:
    """Walls, free edges, each candidate's ±3σ interval along its wall, its triangulated point's 3σ
    ellipse and the true features. ``stagger`` > 0 [m]: the intervals of each wall go on rows that far
    apart, toward the robot, so that overlapping ones can be told apart (a thin line joins each to its
    feature on the wall)."""
    for plane in world_map:
        ax.plot([plane.P1[0], plane.P2[0]], [plane.P1[1], plane.P2[1]], "-" if plane.reference else ":",
                color="#444444", lw=2)
        for e in plane.free_edges:
            ax.plot(*plane.edge(e), "s", color="#d00000", ms=marker_size + 1, zorder=4)
    shift = {}
    if stagger > 0:
        X = np.asarray(result.X[:2], dtype=float)
        for pid in {c.plane_id for c in result.candidates}:
            cands = [c for c in result.candidates if c.plane_id == pid]
            try:
                plane = world_map[pid]
                normal = plane.normal if plane.offset(X) > 0 else -plane.normal
            except KeyError:
                normal = np.array([0.0, -1.0])
            ends = [_wall_interval(c) for c in cands]
            t = (ends[0][1] - ends[0][0]) / max(np.linalg.norm(ends[0][1] - ends[0][0]), 1e-12)
            lanes = _lanes([tuple(sorted((float(a @ t), float(b @ t)))) for a, b in ends], 0.01)
            for c, lane in zip(cands, lanes, strict=True):
                shift[id(c)] = (lane + 1) * stagger * normal
    for c in result.candidates:
        colour = SELECTED if c.selected else REJECTED
        off = shift.get(id(c), np.zeros(2))
        a, b = (p + off for p in _wall_interval(c))
        ax.plot([a[0], b[0]], [a[1], b[1]], "-", color=colour, lw=lw, alpha=0.85, solid_capstyle="butt")
        d = (b - a) / max(np.linalg.norm(b - a), 1e-12)
        cap = (0.4 * stagger if stagger > 0 else 0.012) * np.array([-d[1], d[0]])
        for p in (a, b):
            ax.plot([p[0] - cap[0], p[0] + cap[0]], [p[1] - cap[1], p[1] + cap[1]], "-", color=colour, lw=1.2)
        if stagger > 0:
            ax.plot([c.P[0], c.P[0] + off[0]], [c.P[1], c.P[1] + off[1]], "-", color=colour, lw=0.6)
            ax.plot(*(c.P + off), "o", color=colour, ms=marker_size - 1, zorder=3)
        ax.plot(*c.P, "o", color=colour, ms=marker_size, zorder=3)
        _ellipse(ax, c.P_observed, c.cov_observed, 3.0, color=colour, lw=0.8, ls="--")
    if truth:
        pts = np.array(truth.get("points", []))
        if len(pts):
            ax.plot(pts[:, 0], pts[:, 1], "x", color="black", ms=marker_size + 1, zorder=5)


def make_figure7(result, world_map, camera=None, truth: dict | None = None):
    """Fig 7 as a ``Figure``: positional uncertainty of the features on the map.

    Left, the map: walls, free edges, the robot and the modelled features. Right, one zoom per plane with
    candidates, at its own scale (stated on each panel), where the ±3σ intervals along the wall (the
    rank-1 covariance of Eq 17, capped bars; green selected, orange rejected), the plane-constrained
    triangulated points with their 3σ ellipses (dashed) and the true features (×) can be told apart.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    by_plane: dict[str, list] = {}
    for c in result.candidates:
        by_plane.setdefault(c.plane_id, []).append(c)
    n = len(by_plane)
    fig = _new_figure((13.0, max(6.5, 3.2 * n)))
    gs = fig.add_gridspec(max(n, 1), 2, width_ratios=[1.0, 1.35], left=0.06, right=0.98, top=0.86, bottom=0.08,
                          wspace=0.18, hspace=0.45)
    ax = fig.add_subplot(gs[:, 0])
    _draw_fig7(ax, result, world_map, truth, marker_size=3, lw=2.0)
    X = result.X
    ax.plot(*X[:2], marker=(3, 0, np.degrees(X[2]) - 90), ms=14, color="#2060c0", ls="none")
    xs = [c.P[0] for c in result.candidates] + [X[0]]
    ys = [c.P[1] for c in result.candidates] + [X[1]]
    ax.set_xlim(min(xs) - 1.0, max(xs) + 1.0)
    ax.set_ylim(min(ys) - 0.5, max(ys) + 1.0)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.set_title("the map (zooms on the right)", fontsize=10)
    for k, cands in enumerate(by_plane.values()):
        z = fig.add_subplot(gs[k, 1])
        pts = np.array([p for c in cands for p in (*_wall_interval(c), c.P_observed)])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        step = 0.03 * max(float(np.max(hi - lo)), 0.05)  # rows of the intervals, 3 % of the zoom apart
        _draw_fig7(z, result, world_map, truth, marker_size=5, lw=3.0, stagger=step)
        rows = np.array([p for c in cands for p in _wall_interval(c)])
        X = np.asarray(result.X[:2], dtype=float)
        toward = np.sign(X - rows.mean(axis=0))
        t = rows[1] - rows[0]
        t = t / max(np.linalg.norm(t), 1e-12)
        lanes = max(_lanes([tuple(sorted((float(a @ t), float(b @ t)))) for a, b in
                            (_wall_interval(c) for c in cands)], 0.01)) + 1
        lo = np.minimum(lo, rows.min(axis=0) + np.minimum(toward, 0) * step * (lanes + 1))
        hi = np.maximum(hi, rows.max(axis=0) + np.maximum(toward, 0) * step * (lanes + 1))
        pad = 0.06 * max(float(np.max(hi - lo)), 0.05)
        lo, hi = lo - pad, hi + pad
        z.set_xlim(lo[0], hi[0])
        z.set_ylim(lo[1], hi[1])
        z.set_aspect("equal", adjustable="box")
        z.grid(alpha=0.3)
        z.tick_params(labelsize=7)
        span = float(np.max(hi - lo))
        z.set_title(f"{cands[0].plane_label}: zoom, {100 * span:.0f} cm across (equal axes); the ±3σ bars on "
                    "rows toward the robot", fontsize=9)
        ax.add_patch(Rectangle(lo, *(hi - lo), fill=False, ec="0.3", lw=0.8, ls="-"))
        ax.annotate(cands[0].plane_label, (lo[0], hi[1]), xytext=(0, 3), textcoords="offset points", fontsize=7,
                    color="0.3")
    handles = [
        Line2D([], [], color=SELECTED, lw=3, marker="|", ms=8, label="selected feature: ±3σ along the wall"),
        Line2D([], [], color=REJECTED, lw=3, marker="|", ms=8, label="rejected feature: ±3σ along the wall"),
        Line2D([], [], color="0.3", lw=0.8, ls="--", label="triangulated on the plane: 3σ ellipse"),
        Line2D([], [], color="black", marker="x", ls="none", label="true feature"),
        Line2D([], [], color="#d00000", marker="s", ls="none", label="free edge"),
        Line2D([], [], color="#444444", lw=2, label="wall (reference plane)"),
        Line2D([], [], color="#444444", lw=2, ls=":", label="wall (occluder only)"),
        Line2D([], [], color="#2060c0", marker=(3, 0, 0), ms=10, ls="none", label="robot"),
    ]
    if not (truth and len(truth.get("points", []))):
        handles.pop(3)
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.965), ncol=4, fontsize=8, frameon=False)
    fig.suptitle("Positional uncertainty of the features (Fig 7)", y=0.995, fontsize=11)
    return fig


def figure7(path: str | Path, result, world_map, camera=None, truth: dict | None = None) -> Path:
    """Write Fig 7 (:func:`make_figure7`) to ``path``."""
    return _save(make_figure7(result, world_map, camera, truth), path)


def _lanes(intervals: list[tuple[float, float]], gap: float) -> list[int]:
    """A row for each interval ``(lo, hi)`` so that intervals in a row are ``gap`` apart (greedy, by ``lo``)."""
    order = sorted(range(len(intervals)), key=lambda i: intervals[i][0])
    ends: list[float] = []
    lane = [0] * len(intervals)
    for i in order:
        lo, hi = intervals[i]
        for k, end in enumerate(ends):
            if lo > end + gap:
                lane[i], ends[k] = k, hi
                break
        else:
            lane[i] = len(ends)
            ends.append(hi)
    return lane


def _plane_geometry(result) -> dict:
    out = {}
    for model in getattr(result, "planes", []) or []:
        out[model.fit.plane.id] = model.fit.plane
    for fit in getattr(result, "fits", []) or []:
        if fit:
            out.setdefault(fit.plane.id, fit.plane)
    return out


def make_zoom_figure7(result, planes: list[str], matches=None):
    """Fig 7 along the walls as a ``Figure``: per plane, each feature's ±3σ interval along the wall [m
    from the free edge the features are counted from], on rows of their own where intervals would overlap.

    Numbering: with ``matches`` (the ``(paper_row, candidate or None)`` pairs of
    :func:`stablemarks.commands._tables.match_table1`), as Table 1 does: a feature matched to a row of the
    paper's table carries that row's index (counted from the plane's free edge among the paper's features)
    and the axis runs from the free edge nearest the paper's first feature; candidates the paper does not
    list are drawn hollow and marked ``+``, not counted. Without ``matches``, our own index (counted among
    all our candidates from the edge each was modelled from).
    """
    from matplotlib.lines import Line2D

    label_of: dict[int, str] = {}
    first_of: dict[str, np.ndarray] = {}  # the candidate matched to the lowest paper index, per plane
    if matches is not None:
        best: dict[str, int] = {}
        for row, c in matches:
            if c is None:
                continue
            label_of[id(c)] = str(row.index)
            if row.index < best.get(c.plane_id, 10**9):
                best[c.plane_id] = row.index
                first_of[c.plane_id] = np.asarray(c.P, dtype=float)
    geometry = _plane_geometry(result)
    planes = [p for p in planes if any(c.plane_id == p for c in result.candidates)]
    rows_per_plane = []
    for pid in planes:
        cands = [c for c in result.candidates if c.plane_id == pid]
        plane = geometry.get(pid)
        edges = [c.edge for c in cands]
        edge = max(set(edges), key=edges.count)
        if plane is not None and pid in first_of:  # the edge Table 1 counts from: nearest its first feature
            first = first_of[pid]
            edge = min(plane.free_edges or ("p1", "p2"), key=lambda e: float(np.linalg.norm(plane.edge(e) - first)))
        pos = [float(plane.along(c.P, edge)) if plane is not None else float(c.s) for c in cands]
        rows_per_plane.append((pid, cands, edge, pos))
    heights = []
    lanes_per_plane = []
    for _, cands, _, pos in rows_per_plane:
        span = max(max(p + 3 * c.sigma_s for p, c in zip(pos, cands, strict=True)) -
                   min(p - 3 * c.sigma_s for p, c in zip(pos, cands, strict=True)), 0.1)
        lanes = _lanes([(p - 3 * c.sigma_s, p + 3 * c.sigma_s) for p, c in zip(pos, cands, strict=True)],
                       0.015 * span)
        lanes_per_plane.append(lanes)
        heights.append(0.5 + 0.45 * (max(lanes) + 1))  # [in]
    top, gap, bottom = 1.0, 0.85, 0.6  # [in]: legend and numbering; x label and ticks; the last x label
    total = top + sum(heights) + gap * max(len(heights) - 1, 0) + bottom
    fig = _new_figure((11.0, total))
    y = total - top  # [in] from the bottom
    for k, ((_, cands, edge, pos), lanes) in enumerate(zip(rows_per_plane, lanes_per_plane, strict=True)):
        y -= heights[k]
        ax = fig.add_axes((0.05, y / total, 0.93, heights[k] / total))
        y -= gap
        for c, p, lane in zip(cands, pos, lanes, strict=True):
            colour = SELECTED if c.selected else REJECTED
            extra = matches is not None and id(c) not in label_of
            row = -lane
            ax.errorbar(p, row, xerr=3 * c.sigma_s, fmt="o", color=colour, ms=6, capsize=4, elinewidth=1.6,
                        mfc="white" if extra else colour, mew=1.5)
            label = "+" if extra else (label_of.get(id(c), str(c.index)))
            ax.annotate(label, (p, row), xytext=(0, 7), textcoords="offset points", ha="center", va="bottom",
                        fontsize=9, weight="bold", color="0.15")
        ax.axvline(0, color="#d00000", lw=1.2)
        ax.set_yticks([])
        ax.set_ylim(-max(lanes) - 0.7, 0.9)
        ax.grid(axis="x", alpha=0.3)
        ax.set_xlabel(f"{cands[0].plane_label}: distance along the wall from its free edge {edge} (red line) [m]",
                      fontsize=9)
    handles = [
        Line2D([], [], color=SELECTED, marker="o", lw=1.6, label="selected: ±3σ along the wall"),
        Line2D([], [], color=REJECTED, marker="o", lw=1.6, label="rejected: ±3σ along the wall"),
    ]
    if matches is not None:
        handles.append(Line2D([], [], color="0.4", marker="o", mfc="white", lw=1.6,
                              label="+ : a candidate not in the paper's Table 1 (not numbered)"))
        numbering = "numbers: Table 1's index, counted from the free edge among the paper's features"
    else:
        numbering = "numbers: our index, counted from the free edge each feature is modelled from"
    fig.legend(handles=handles, loc="upper center", ncol=len(handles), fontsize=8, frameon=False)
    fig.text(0.5, 1.0 - 0.62 / total, numbering, ha="center", fontsize=8, color="0.3")
    return fig


def zoom_figure7(path: str | Path, result, planes: list[str], matches=None) -> Path:
    """Write Fig 7 along the walls (:func:`make_zoom_figure7`) to ``path``."""
    return _save(make_zoom_figure7(result, planes, matches), path)


def disparity_image(path: str | Path, disparity: np.ndarray, num_disparities: int) -> Path:
    """The disparity image coloured (turbo), invalid pixels black."""
    import cv2

    d = np.nan_to_num(np.asarray(disparity, dtype=np.float32), nan=0.0, posinf=0.0)
    img = cv2.applyColorMap(np.clip(d * (255.0 / max(num_disparities, 1)), 0, 255).astype(np.uint8),
                            cv2.COLORMAP_TURBO)
    img[~np.isfinite(disparity)] = 0
    cv2.imwrite(str(path), img)
    return Path(path)
