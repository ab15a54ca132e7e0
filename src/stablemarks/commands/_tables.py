"""Rich tables printed by the commands (the library returns data; this formats it)."""

from __future__ import annotations

import numpy as np
from rich.table import Table

from ..io.results import candidate_row
from ..reference import TABLE1


def landmark_table(candidates, mm: bool = False, title: str = "Modelled features") -> Table:
    """The layout of the paper's Table 1: plane, index, x, y, l, σx, σy, ℓs, selected, reason."""
    k, unit = (1000.0, "mm") if mm else (1.0, "m")
    fmt = "{:.1f}" if mm else "{:.4f}"
    t = Table(title=f"{title} ({unit})")
    for col in ("plane", "index", "x", "y", "l", "σx", "σy", "ℓs", "selected", "reason"):
        t.add_column(col, justify="left" if col in ("plane", "reason", "selected") else "right")
    for c in candidates:
        r = candidate_row(c)
        t.add_row(
            c.plane_label, str(r["index"]), fmt.format(k * r["x"]), fmt.format(k * r["y"]),
            fmt.format(k * r["length"]), fmt.format(k * r["sigma_x"]), fmt.format(k * r["sigma_y"]),
            f"{r['length_similarity']:.2f}", "Yes" if r["selected"] else "No", r["reason"],
        )
    return t


def match_table1(candidates, plane_ids: dict[str, str], tolerance: float = 0.04):
    """Pair each row of the paper's Table 1 with our candidate nearest along the same wall.

    ``plane_ids`` maps Table 1's plane names ("partition", "whiteboard") to our plane ids. Returns a list of
    ``(paper_row, candidate or None)``; a candidate is used once, within ``tolerance`` [m] of the paper's x.
    """
    used = set()
    out = []
    for row in TABLE1:
        pid = plane_ids.get(row.plane)
        best, best_d = None, tolerance
        for i, c in enumerate(candidates):
            if c.plane_id != pid or i in used:
                continue
            d = abs(c.P[0] - row.x / 1000.0)
            if d <= best_d:
                best, best_d = i, d
        if best is not None:
            used.add(best)
        out.append((row, candidates[best] if best is not None else None))
    return out, [c for i, c in enumerate(candidates) if i not in used]


def table1_comparison(matches, truth_x: dict | None = None) -> Table:
    """Paper's Table 1 beside ours, row by row [mm]."""
    t = Table(title="Table 1, paper vs stablemarks (mm)")
    for col in ("plane", "idx", "x paper", "x ours", "σx paper", "σx ours", "σy ours", "l paper", "l ours",
                "ℓs paper", "ℓs ours", "paper", "ours", "agree"):
        t.add_column(col, justify="right" if col not in ("plane", "paper", "ours", "agree") else "left")
    for row, c in matches:
        paper_dec = "Yes" if row.selected else f"No ({row.reason})"
        if c is None:
            t.add_row(row.plane, str(row.index), f"{row.x:.1f}", "—", f"{row.sigma_x:.1f}", "—", "—",
                      f"{row.length:.0f}", "—", f"{row.length_similarity:.1f}", "—", paper_dec, "not found", "✗")
            continue
        r = candidate_row(c)
        ours = "Yes" if c.selected else f"No ({c.reason})"
        agree = "✓" if c.selected == row.selected else "✗"
        t.add_row(
            row.plane, str(row.index), f"{row.x:.1f}", f"{1000 * r['x']:.1f}", f"{row.sigma_x:.1f}",
            f"{1000 * r['sigma_x']:.1f}", f"{1000 * r['sigma_y']:.1f}", f"{row.length:.0f}",
            f"{1000 * r['length']:.0f}", f"{row.length_similarity:.1f}", f"{r['length_similarity']:.2f}",
            paper_dec, ours, agree,
        )
    return t


def summary_counts(matches) -> dict:
    found = [(r, c) for r, c in matches if c is not None]
    return {
        "rows": len(matches),
        "found": len(found),
        "decisions_agree": sum(c.selected == r.selected for r, c in found),
        "sigma_y_max": max((float(np.sqrt(max(c.cov[1, 1], 0))) for _, c in found), default=0.0),
    }
