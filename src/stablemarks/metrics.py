"""Figures of merit of a run: trajectory error, consistency (NEES/NIS) and landmark stability.

Definitions (also in the README):

- **ATE RMSE** — root mean square of the planar position error over all frames [m] (poses compared at the
  same stamps in the map frame, no alignment: the map fixes the frame).
- **NEES** — ``eᵀ P⁻¹ e`` of an estimate's error ``e`` against the truth with the filter's covariance ``P``
  (:func:`nees`). Of the pose: ``e_k`` the pose error (angle wrapped), ``P_k`` the 3×3 pose covariance;
  3 dof. Of a landmark *along the wall* (:func:`along_wall_nees`): ``e = tᵀ (p − p_true)``, ``var = tᵀ Σ t``
  with ``t`` the unit direction of the true feature's wall, ``p`` and ``Σ`` the landmark's map position and
  2×2 covariance; 1 dof. For a wall landmark this is exactly ``(s − s_true)² / var_s`` with ``s_true``
  measured from the same edge; for a point landmark (``all_segments``) it tests the same direction.
- **NIS** — ``νᵀ S⁻¹ ν`` of each landmark observation; 2 dof.
- **χ² bounds** for an average of ``N`` independent ``d``-dof values:
  ``[χ²⁻¹(0.025; N·d)/N, χ²⁻¹(0.975; N·d)/N]`` (d = 3, N = 50: [2.36, 3.72]). The pose NEES is averaged
  over the ``N`` runs at each time step and :func:`fraction_inside` counts the steps whose average lies
  inside the bounds, :func:`fraction_above` those above them (overconfident).
- **Re-observation rate** of a landmark — the fraction of the later frames in which its true feature is in
  view and unoccluded in both images where the landmark was associated with a segment pair.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from .geometry import wrap_angle


def position_errors(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(n,) planar position errors [m] of poses (n, 3) against the truth (n, 3)."""
    d = np.asarray(estimate, dtype=float)[:, :2] - np.asarray(truth, dtype=float)[:, :2]
    return np.hypot(d[:, 0], d[:, 1])


def ate_rmse(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Absolute trajectory error: RMS of the planar position errors [m]."""
    e = position_errors(estimate, truth)
    return float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")


def nees(errors: np.ndarray, covs: np.ndarray) -> np.ndarray:
    """(n,) normalized estimation errors squared ``eᵀ P⁻¹ e`` of errors (n, d) with covariances (n, d, d)."""
    e = np.asarray(errors, dtype=float)
    if len(e) == 0:
        return np.zeros(0)
    return np.einsum("ni,ni->n", e, np.linalg.solve(np.asarray(covs, dtype=float), e[..., None])[..., 0])


def pose_nees(estimate: np.ndarray, covs: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(n,) NEES of poses (n, 3) with covariances (n, 3, 3) against the truth (n, 3); 3 dof."""
    e = np.asarray(estimate, dtype=float) - np.asarray(truth, dtype=float)
    e[:, 2] = wrap_angle(e[:, 2])
    return nees(e, covs)


def along_wall_nees(positions: np.ndarray, covs: np.ndarray, truths: np.ndarray,
                    directions: np.ndarray) -> np.ndarray:
    """(n,) 1-dof NEES of landmark positions (n, 2) [m] with covariances (n, 2, 2) [m²] along the unit
    directions (n, 2) of their true walls, against the true positions (n, 2): ``(tᵀ e)² / tᵀ Σ t``."""
    t = np.asarray(directions, dtype=float).reshape(-1, 2)
    e = np.einsum("ni,ni->n", t, np.asarray(positions, dtype=float).reshape(-1, 2)
                  - np.asarray(truths, dtype=float).reshape(-1, 2))
    var = np.einsum("ni,nij,nj->n", t, np.asarray(covs, dtype=float).reshape(-1, 2, 2), t)
    return nees(e[:, None], var[:, None, None])


def chi2_bounds(n_runs: int, dof: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided bounds of the average of ``n_runs`` χ²(dof) values: ``[χ²⁻¹(α/2; N·d)/N, χ²⁻¹(1−α/2; N·d)/N]``."""
    a = (1.0 - probability) / 2.0
    nd = n_runs * dof
    return float(chi2.ppf(a, nd) / n_runs), float(chi2.ppf(1.0 - a, nd) / n_runs)


def fraction_above(values: np.ndarray, bound: float) -> float:
    """Fraction of ``values`` (n,) above ``bound`` (NaN when there are none)."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return float("nan")
    return float(np.mean(v > bound))


def fraction_inside(values: np.ndarray, bounds: tuple[float, float]) -> float:
    """Fraction of ``values`` (n,) inside the closed interval ``bounds`` (NaN when there are none)."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return float("nan")
    return float(np.mean((v >= bounds[0]) & (v <= bounds[1])))


def reobservation(result) -> dict:
    """Per landmark (with a known true feature): frames after its creation where the true feature was
    visible in both images, and how many of those the landmark was associated in. ``result`` is a run with
    its ground truth (``truth_of``, ``visible_truth``: :class:`stablemarks.evaluation.TruthObserver`).

    Returns ``{landmark id: (n_associated, n_visible)}``.
    """
    out = {}
    for lid, tid in result.truth_of.items():
        first = next((r.index for r in result.records if lid in r.new), None)
        if first is None:
            continue
        vis = [r for r in result.records if r.index > first and tid in result.visible_truth[r.index]]
        out[lid] = (sum(lid in r.associated for r in vis), len(vis))
    return out


def reobserved_at(result, frame: int) -> tuple[list[int], list[int]]:
    """Landmarks whose true feature is visible at ``frame``: (associated ids, missed ids)."""
    r = result.records[frame]
    seen, missed = [], []
    for lid, tid in result.truth_of.items():
        first = next((x.index for x in result.records if lid in x.new), None)
        if first is None or first >= frame or tid not in result.visible_truth[frame]:
            continue
        (seen if lid in r.associated else missed).append(lid)
    return seen, missed
