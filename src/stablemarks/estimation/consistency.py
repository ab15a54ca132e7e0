"""Landmark errors larger than their covariance says, found from the frame's innovations and given their variance.

A wall landmark's covariance comes from its entry model: the boundary it was measured from (shared by the group
entered with it) and its own line. Both are heavy-tailed: a boundary snapped onto a line a few pixels inside the
edge, or a line that sits on texture next to the edge, errs far more than the Gaussian σ that suits the rest.
Widening every σ to cover those cases makes the filter cautious on every scene; keeping them narrow makes it
overconfident where one of them is wrong.

Here the variance is added where the data show it is missing. Before an update, for each direction ``v`` of the
landmark state that an entry error moves (a group's common shift along its wall: the boundary's error; one
landmark alone: its line's persistent error), the innovations ``ν`` (stacked, covariance ``S``) are tested for a
component along ``h = H v`` that no pose explains: with the pose profiled out (its prior left aside, so that a
slip of the odometry is not taken for a landmark error), the score statistic

    t = (hᵀ W ν)² / (hᵀ W h),   W = S⁻¹ − S⁻¹ A (Aᵀ S⁻¹ A)⁻¹ Aᵀ S⁻¹,   A = H_X (the pose's columns of H),

is χ²₁ when the model holds. Where ``t`` exceeds its ``1 − p`` quantile, the variance along ``v`` is raised by
the maximum-likelihood amount ``α = ((hᵀWν)² − hᵀWh) / (hᵀWh)²`` (``P ← P + α v vᵀ``: PSD, and the update then
moves those landmarks rather than the pose), largest ``t`` first, ``S`` updated after each. Nothing is ever made
more certain. A direction that a pose change explains as well (one wall's group seen alone) has ``hᵀWh ≈ 0``
and is not tested: those cases are the health rules' (module :mod:`stablemarks.health`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri

from .ekf import JointEKF


@dataclass(frozen=True)
class Inflation:
    """One direction whose variance was raised: the landmark ids it moves, ``t`` its score statistic before, ``alpha``
    the variance added along the unit-per-landmark shift [m²]."""

    ids: tuple[int, ...]
    t: float
    alpha: float
    group: bool


def inflate_inconsistent(ekf: JointEKF, observations: Sequence[tuple[int, Sequence[float]]], pan: float,
                         groups: Mapping[int, int], p: float, *, min_info: float = 1e-9,
                         max_rounds: int = 8) -> list[Inflation]:
    """Raise the variance of landmark directions the frame's observations contradict (module docstring).

    ``observations``: ``(landmark id, (u_l, u_r))`` as for :meth:`JointEKF.update`; ``groups`` maps a landmark id
    to the id of the group it was entered with (landmarks without one are tested alone only); ``p``: the test's
    false-alarm probability per direction (0: nothing is done). Returns what was inflated, in order.
    """
    if p <= 0 or len(observations) < 3:  # the pose takes 3 of the 2m dimensions
        return []
    ids = [int(i) for i, _ in observations]
    z = np.asarray([np.asarray(u, dtype=float) for _, u in observations]).reshape(-1)
    h_fn, H = ekf.observation_model(ids, pan)
    nu = z - h_fn(ekf.state)
    S = H @ ekf.cov @ H.T + ekf.camera.sigma_img**2 * np.eye(len(z))
    A = H[:, :3]
    # the directions: each group and each wall with at least two observed members, and each landmark alone
    members: dict[int, list[int]] = {}
    for i in ids:
        if i in groups:
            members.setdefault(groups[i], []).append(i)
    directions: list[tuple[tuple[int, ...], bool]] = [(tuple(m), True) for m in members.values() if len(m) >= 2]
    walls: dict[str, list[int]] = {}
    for i in ids:
        plane = ekf.landmark_plane(i)
        if plane is not None:
            walls.setdefault(plane.id, []).append(i)
    directions += [(tuple(m), True) for m in walls.values()
                   if len(m) >= 2 and tuple(m) not in {d for d, _ in directions}]
    directions += [((i,), False) for i in ids if ekf.landmark_plane(i) is not None]
    V = np.zeros((len(ekf.state), len(directions)))
    for k, (d_ids, _) in enumerate(directions):
        for i in d_ids:
            V[ekf.state_slice(i), k] = 1.0
    Hv = H @ V  # (2m, K)
    threshold = float(chdtri(1, p))
    out: list[Inflation] = []
    done: set[int] = set()
    for _ in range(max_rounds):
        Si = np.linalg.inv(S)
        SiA = Si @ A
        W = Si - SiA @ np.linalg.solve(A.T @ SiA, SiA.T)
        q = Hv.T @ W @ nu  # (K,)
        info = np.einsum("ik,ij,jk->k", Hv, W, Hv)
        t = np.where(info > min_info, q**2 / np.maximum(info, min_info), 0.0)
        for k in done:
            t[k] = 0.0
        k = int(np.argmax(t))
        if t[k] <= threshold:
            break
        alpha = float((q[k] ** 2 - info[k]) / info[k] ** 2)
        if not alpha > 0:  # t ≤ 1: nothing is missing (only with p near 1)
            break
        ekf.add_landmark_variance(directions[k][0], alpha)
        S = S + alpha * np.outer(Hv[:, k], Hv[:, k])
        done.add(k)
        out.append(Inflation(directions[k][0], float(t[k]), alpha, directions[k][1]))
    return out
