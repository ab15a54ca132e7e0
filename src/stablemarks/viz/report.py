"""Figures of the evaluation report (``stablemarks eval``). Only the CLI imports this module."""

from __future__ import annotations

from pathlib import Path

import numpy as np

COLORS = {"stablemarks": "#1f77b4", "plane_no_selection": "#2ca02c", "all_segments": "#d62728",
          "dead_reckoning": "#ff7f0e", "gtsam_batch": "#9467bd"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _panels(plt, n: int, width: float = 5.0, height: float = 3.8):
    fig, axes = plt.subplots(1, n, figsize=(width * n, height), squeeze=False)
    return fig, axes[0]


def make_nees_figure(summary: dict):
    """The figure of :func:`nees_figure` (a matplotlib ``Figure``, not yet saved)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    n_panels = max(len(summary), 1)
    fig = Figure(figsize=(5.0 * n_panels, 3.8))
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(1, n_panels, k + 1) for k in range(n_panels)]
    for ax, (scen, by_method) in zip(axes, summary.items(), strict=False):
        for method, s in by_method.items():
            v = np.maximum(np.asarray(s["nees_pose_time"], dtype=float), 1e-3)
            ax.semilogy(np.arange(len(v)), v, color=COLORS.get(method), lw=1.4, label=method)
        lo, hi = next(iter(by_method.values()))["nees_pose_bounds"]
        ax.axhspan(lo, hi, color="0.85", zorder=0, label="95 % bounds")
        ax.axhline(3.0, color="0.5", lw=0.8, ls=":")
        n = next(iter(by_method.values()))["trials"]
        ax.set(title=f"{scen}: pose NEES, average of {n} trials", xlabel="frame", ylabel="NEES (3 dof)")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # frames are whole numbers
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return fig


def nees_figure(path: str | Path, summary: dict) -> Path:
    """Per scenario: the N-trial average pose NEES of each method over the frames (log scale, frames on
    integer ticks) with the 95 % bounds of an N-trial average of a 3-dof χ² value."""
    make_nees_figure(summary).savefig(str(path), dpi=110)
    return Path(path)


def ate_figure(path: str | Path, results: list[dict]) -> Path:
    """Per scenario: each trial's ATE RMSE [m] per method (dots) and their mean (bar)."""
    plt = _pyplot()
    scenarios = list(dict.fromkeys(r["scenario"] for r in results))
    fig, axes = _panels(plt, len(scenarios))
    for ax, scen in zip(axes, scenarios, strict=True):
        methods = list(dict.fromkeys(r["method"] for r in results if r["scenario"] == scen))
        for i, m in enumerate(methods):
            v = np.array([r["ate_rmse"] for r in results if r["scenario"] == scen and r["method"] == m])
            ax.bar(i, v.mean(), color=COLORS.get(m), alpha=0.35, width=0.6)
            jitter = np.linspace(-0.15, 0.15, len(v)) if len(v) > 1 else np.zeros(1)
            ax.plot(i + jitter, v, "o", color=COLORS.get(m), ms=3)
        ax.set_xticks(range(len(methods)), methods, rotation=20, fontsize=8)
        ax.set(title=f"{scen}: trajectory RMSE per trial", ylabel="ATE RMSE [m]")
        ax.set_yscale("log")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def reobservation_figure(path: str | Path, summary: dict) -> Path:
    """Per scenario and method: re-observation rate of the landmarks whose true feature the full method
    selected, next to those it rejected."""
    plt = _pyplot()
    fig, axes = _panels(plt, len(summary))
    for ax, (scen, by_method) in zip(axes, summary.items(), strict=True):
        methods = [m for m in by_method if m not in ("dead_reckoning", "gtsam_batch")]  # no re-observation of their own
        x = np.arange(len(methods))
        sel = [by_method[m]["reobservation_selected"] for m in methods]
        rej = [by_method[m]["reobservation_rejected"] for m in methods]
        ax.bar(x - 0.2, np.nan_to_num(sel), width=0.4, color="#1f77b4", label="selected by the full method")
        ax.bar(x + 0.2, np.nan_to_num(rej), width=0.4, color="#d62728", label="rejected by the full method")
        ax.axhline(0.95, color="0.4", lw=0.8, ls="--")
        ax.set_xticks(x, methods, rotation=20, fontsize=8)
        ax.set(title=f"{scen}: re-observation rate", ylabel="associated / frames in view", ylim=(0, 1.3))
        ax.legend(fontsize=7, loc="upper center", ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def report_figures(out: str | Path, summary: dict, results: list[dict]) -> dict[str, Path]:
    """All figures of the report in folder ``out``: ``{name: path}``."""
    out = Path(out)
    return {
        "nees": nees_figure(out / "nees_pose.png", summary),
        "ate": ate_figure(out / "ate.png", results),
        "reobservation": reobservation_figure(out / "reobservation.png", summary),
    }
