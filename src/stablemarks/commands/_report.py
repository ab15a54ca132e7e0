"""Reporting an on-line run: progress bar, motion summary table, output files."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table

from ..metrics import ate_rmse, position_errors, reobservation, reobserved_at


@contextmanager
def frame_progress(console, description: str, total: int):
    """A rich progress bar over frames; yields ``progress(k, n)`` for :func:`stablemarks.online.run_online`."""
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  console=console, transient=False) as bar:
        task = bar.add_task(description, total=total)
        yield lambda k, n: bar.update(task, completed=k)


def motion_summary(result) -> dict:
    """Final position error and 2σ uncertainty of the EKF and dead reckoning, ATE RMSE, re-observation."""
    T = result.true_poses
    P, D, C = result.poses, result.dead_reckoning, result.covs
    out = {
        "frames": len(result.records),
        "landmarks": result.ekf.n_landmarks,
        "final_2sigma_ekf": float(2 * np.sqrt(np.trace(C[-1][:2, :2]))),
    }
    if T is not None:
        e_ekf, e_dr = position_errors(P, T), position_errors(D, T)
        out.update(
            ate_rmse_ekf=ate_rmse(P, T), ate_rmse_dead_reckoning=ate_rmse(D, T),
            final_error_ekf=float(e_ekf[-1]), final_error_dead_reckoning=float(e_dr[-1]),
        )
    if result.truth_of:  # which true feature each landmark is: known in simulation only
        reobs = reobservation(result)
        n_assoc = sum(a for a, _ in reobs.values())
        n_vis = sum(v for _, v in reobs.values())
        out["reobservation_rate"] = n_assoc / n_vis if n_vis else float("nan")
        for name, k in (("1m", 10), ("2m", 20)):
            if k < len(result.records):
                seen, missed = reobserved_at(result, k)
                out[f"reobserved_at_{name}"] = [len(seen), len(seen) + len(missed)]
    return out


def dead_reckoning_2sigma(result, noise) -> float:
    """2σ position uncertainty of odometry alone at the end (the same noise model, propagated)."""
    from ..estimation import motion
    from ..geometry import SE2

    cov = np.asarray(result.cov0, dtype=float).copy()
    D = result.dead_reckoning  # built once: the property makes the (K, 3) array from the records each time
    X = D[0]
    for k in range(1, len(D)):
        U = SE2.from_array(D[k - 1]).between(SE2.from_array(D[k]))
        X, F, J_U = motion(X, U.as_array(), jacobians=True)
        cov = F @ cov @ F.T + J_U @ noise.covariance(U) @ J_U.T
    return float(2 * np.sqrt(np.trace(cov[:2, :2])))


def print_motion_summary(console, result, noise=None) -> dict:
    s = motion_summary(result)
    if noise is not None:
        s["final_2sigma_dead_reckoning"] = dead_reckoning_2sigma(result, noise)
    t = Table(title=f"{result.name}: {s['frames']} frames, {s['landmarks']} landmarks (mm)")
    t.add_column("")
    t.add_column("EKF (stablemarks)", justify="right")
    t.add_column("dead reckoning", justify="right")
    t.add_column("ratio", justify="right")

    def row(label, a, b):
        if a is None or b is None:
            return
        t.add_row(label, f"{1000 * a:.1f}", f"{1000 * b:.1f}", f"{a / b:.2f}" if b else "—")

    row("trajectory RMSE (ATE)", s.get("ate_rmse_ekf"), s.get("ate_rmse_dead_reckoning"))
    row("final position error", s.get("final_error_ekf"), s.get("final_error_dead_reckoning"))
    row("final 2σ position uncertainty", s.get("final_2sigma_ekf"), s.get("final_2sigma_dead_reckoning"))
    console.print(t)
    for name in ("1m", "2m"):
        if f"reobserved_at_{name}" in s:
            a, b = s[f"reobserved_at_{name}"]
            console.print(f"at {name}: re-observed {a} of the {b} landmarks whose feature is in view")
    if np.isfinite(s.get("reobservation_rate", float("nan"))):
        console.print(f"re-observation rate of the landmarks over the run: {s['reobservation_rate']:.1%}")
    return s
