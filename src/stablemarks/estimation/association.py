"""Data association of one frame's segment pairs with the landmarks of the filter (paper Sec 5).

Everything that decides which measured line is which landmark lives here; the gating and joint
compatibility primitives it builds on are methods of :class:`~stablemarks.estimation.ekf.JointEKF`
(:meth:`~JointEKF.associate_joint`, :meth:`~JointEKF.joint_compatible`). The cues, strongest first:

- the *pattern* along a wall (:func:`match_along_wall`): this frame's candidates and the wall's
  landmarks are both positions along the wall from its edge, so they differ by one common offset (the
  two boundary errors) whatever the pose error;
- image-space gating with joint compatibility (all landmarks share the pose error);
- the vertical extent (:func:`height_cost`): lines of other heights or lengths cost more;
- the polarity of the brightness step along the wall (:func:`wall_polarity`, :func:`polarity_cost`):
  an edge never matches one of the opposite step.

Units: image columns in pixels, positions in metres in the map frame.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from .ekf import JointEKF

__all__ = ["associate_frame", "height_cost", "is_duplicate", "match_along_wall", "merged_with_edges", "polarity_cost",
           "wall_polarity"]


def associate_frame(ekf: JointEKF, pairs, measured: np.ndarray, pan: float, model=None,
                    polarity: np.ndarray | None = None, centre=None, report: dict | None = None,
                    max_incidence: float | None = None) -> list[tuple[int, int]]:
    """Pairs (landmark id, segment-pair index) for this frame's update.

    Wall landmarks are found by the *pattern* of this frame's candidates along each wall (their positions
    relative to the wall's edge do not depend on the pose error, and the offsets between features on one
    wall are known to a few mm): :func:`match_along_wall`, kept if jointly compatible. Point landmarks, and
    wall landmarks the pattern leaves unmatched, go through the image-space association with joint
    compatibility and the vertical-extent cost; each such pair is added only if the whole set stays
    jointly compatible. ``polarity`` (M,): the sign of each pair's brightness step in the left image, seen from
    the camera centre ``centre`` (2,); a wall landmark never matches an edge whose step along its wall is the
    opposite (a bar's two edges, equally long and a bar's width apart, differ only in it).

    ``max_incidence`` [rad]: wall landmarks seen at a more grazing angle than this are not associated
    (:meth:`JointEKF.visible`; the limit of entry, ``landmarks.max_incidence_deg``, by default).

    ``report`` (a dict, filled when given): ``"compatible"`` the wall patterns kept, ``"incompatible"`` those
    matched along their wall but jointly incompatible with the predicted pose (evidence that the odometry and
    the images disagree), ``"ambiguous"`` the matchings left out because another one fits as well (two
    offsets of a wall's pattern, or another line or landmark in an image gate, jointly compatible with the
    rest: the pose is too uncertain to tell them apart).
    """
    if polarity is None or centre is None:
        polarity, centre = np.zeros(len(measured), dtype=int), np.zeros(2)
    polarity = np.asarray(polarity, dtype=int)
    in_view = set(ekf.visible(pan, max_incidence))
    if ekf.config.merge_px > 0 and model is not None and in_view:
        in_view -= merged_with_edges(ekf, sorted(in_view), pan, model.predictions, ekf.config.merge_px)
    walls: list[list[tuple[int, int]]] = []
    if model is not None:
        for plane_model in model.planes:
            plane = plane_model.fit.plane
            options = [[(i, c) for i, c in m if i in in_view]
                       for m in match_along_wall(ekf, plane, plane_model.candidates,
                                                 polarity=wall_polarity(polarity, plane, centre), every=True)]
            options = [m for m in options if m]
            if options:
                walls.append(options)
    # Wall by wall, most features first: one wall's wrong pattern must not throw out the others' right ones.
    # Regularly spaced features match at several offsets along the wall; the first (best-scoring) offset whose
    # matching is jointly compatible with the predicted pose is taken. Only when none is, the wall's pattern
    # disagrees with the prediction (its best offset is reported): a pattern aliased by one feature spacing
    # is not evidence against the odometry.
    chosen: list[tuple[int, int]] = []
    kept, rejected = [], []
    ambiguous: list[list[tuple[int, int]]] = []
    for options in sorted(walls, key=lambda o: len(o[0]), reverse=True):
        fits = [m for m in options if len(m) >= len(options[0]) - 1  # far fewer features: not an alternative
                and ekf.joint_compatible(chosen + m, measured, pan)]
        if not fits:
            rejected.append(options[0])
        elif any(_conflict(fits[0], m) for m in fits[1:]):
            # two offsets that pair a landmark with different lines both fit the prediction: the pose is too
            # uncertain to tell them apart (after a blind stretch), and the wrong one would pull it a whole
            # feature spacing off with a collapsed covariance. Neither is taken.
            ambiguous.append(fits[0])
        else:
            chosen += fits[0]
            kept.append(fits[0])
    taken_l = {i for i, _ in chosen}
    taken_p = {j for _, j in chosen}
    # A wall whose pattern of two or more features was matched places every feature on it to a few mm: a wall
    # landmark there that the pattern leaves out does not sit where its line is (a line standing a few cm in
    # front of the wall shifts along it with the viewing angle), so the image gates do not get to take it.
    patterned = {ekf.landmark_plane(m[0][0]).id for m in kept if len(m) >= 2}
    rest = [i for i in ekf.landmark_ids if i in in_view and i not in taken_l and not (
        ekf.landmark(i).kind == "wall" and ekf.landmark_plane(i).id in patterned)]
    free = [j for j in range(len(measured)) if j not in taken_p]
    if rest and free:
        cost = height_cost(ekf, pairs, pan) + polarity_cost(ekf, polarity, centre)
        rows = [ekf.landmark_ids.index(i) for i in rest]
        extra = cost[np.ix_(rows, free)]
        gates = ekf.association_costs(measured[free], pan, rest, extra)
        sub = ekf.associate_joint(measured[free], pan, candidates=rest, extra_cost=extra, costs=gates)
        taken = []
        for i, j in sub:
            trial = chosen + [(i, free[j])]
            if ekf.joint_compatible(trial, measured, pan):
                chosen = trial
                taken.append((i, free[j]))
        if taken:
            alone = _ambiguous_in_gates(ekf, measured, pan, free, gates, chosen, taken)
            if alone:
                ambiguous.append(alone)
                chosen = [q for q in chosen if q not in alone]
    if report is not None:
        report["compatible"], report["incompatible"], report["ambiguous"] = kept, rejected, ambiguous
    return sorted(chosen, key=lambda q: q[1])


def merged_with_edges(ekf: JointEKF, ids, pan: float, predictions, merge_px: float) -> set[int]:
    """Landmarks ``ids`` whose predicted line lies within ``merge_px`` of the predicted image of a free edge
    (:class:`~stablemarks.planes.EdgePrediction` of ``predictions``, at the same prior mean) in the left or
    the right image: the detector finds the two as one line (:attr:`EKFConfig.merge_px`)."""
    edges = np.array([e.u for pred in (predictions or []) for e in pred.edges.values()
                      if e.free and np.isfinite(e.u).all()], dtype=float).reshape(-1, 2)
    if not len(edges) or not len(ids):
        return set()
    uv = ekf.predict_observation(ids, pan).uv
    near = (np.abs(uv[:, None, :] - edges[None, :, :]) < merge_px).any(axis=(1, 2))
    return {int(i) for i, n in zip(ids, near, strict=True) if n}


def lone_gate_px(ekf: JointEKF, pairs: list[tuple[int, int]], pan: float, columns=None, within: float = 0.0) -> float:
    """Half-width [px] of the widest 3σ gate of the left columns of a frame's associations when they amount to
    one line: a single pair, or (with the lines' left ``columns`` indexed by pair) pairs whose lines all lie
    within ``within`` px of each other (the two edges of one narrow bar, or one edge found twice); 0 otherwise.
    One line cannot be checked against anything (a 2-D measurement, a 3-D pose: joint compatibility accepts
    whatever lies in the gate), and lines closer than a SAD window are measured from overlapping windows and move
    together with a shift of the pattern, so the wider that gate, the likelier it holds a neighbour of a line
    that was not found."""
    if not pairs:
        return 0.0
    if len(pairs) > 1:
        if columns is None:
            return 0.0
        u = [float(columns[j]) for _, j in pairs]
        if max(u) - min(u) > within:
            return 0.0
    S = ekf.predict_observation([i for i, _ in pairs], pan).S
    return 3.0 * float(np.sqrt(np.max(S[:, 0, 0])))


def _conflict(a: list[tuple[int, int]], b: list[tuple[int, int]]) -> bool:
    """Whether two matchings pair one landmark with different lines, or one line with different landmarks."""
    la, pa = dict(a), {j: i for i, j in a}
    return any((i in la and la[i] != j) or (j in pa and pa[j] != i) for i, j in b)


def _ambiguous_in_gates(ekf: JointEKF, measured: np.ndarray, pan: float, free: list[int], gates,
                        chosen: list[tuple[int, int]], taken: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The image-gated pairs of ``taken`` (a part of ``chosen``) that another pairing would explain as well:
    another free line in the landmark's gate, or another landmark whose gate holds the line, with which the
    whole set stays jointly compatible. While the pose is well known the gates are a few pixels wide and hold
    one line; after a blind stretch they span several, and the nearest is as likely another feature of the
    same wall, whose update would pull the pose a feature spacing off with a collapsed covariance. ``gates``:
    :meth:`JointEKF.association_costs` of the free lines and the landmarks left to the image gates."""
    ids, _, d2, cost = gates
    row = {int(i): r for r, i in enumerate(ids)}
    col = {j: c for c, j in enumerate(free)}
    ok = (d2 <= ekf.config.gate) & np.isfinite(cost)
    used_l = {i for i, _ in chosen}
    used_p = {j for _, j in chosen}
    out = []
    for i, j in taken:
        others = [q for q in chosen if q != (i, j)]
        r, c = row.get(int(i)), col.get(j)
        if r is None or c is None:
            continue
        alts = [(i, free[c2]) for c2 in np.flatnonzero(ok[r]) if free[c2] not in used_p]
        alts += [(int(ids[r2]), j) for r2 in np.flatnonzero(ok[:, c]) if int(ids[r2]) not in used_l]
        if any(ekf.joint_compatible(others + [q], measured, pan) for q in alts):
            out.append((i, j))
    return out


def match_along_wall(ekf: JointEKF, plane, candidates, tol: float = 3.0,
                     polarity: np.ndarray | None = None, every: bool = False):
    """Match this frame's candidates on ``plane`` with the wall landmarks on it, by their pattern.

    Candidates and landmarks are placed along the wall (from ``p1``). The two sets differ by one common
    offset — the difference of the boundary errors, ``σ_δ² = σ_b,now² + var_landmark`` — and by each
    feature's own small error. Every candidate-landmark pair proposes an offset within ``3σ_δ``; the offset
    that matches the most features (ties: least squared residual) wins, and features are then paired
    one-to-one within ``tol`` σ of their own errors. Features whose vertical extents disagree never match;
    among offsets that match equally many, the likeliest one (its own prior and the residuals) wins.
    Returns ``(landmark id, segment-pair index)``; with ``every``, the matchings of all distinct offsets, best
    first (a list of such lists).
    """
    lms = [ekf.landmark(i) for i in ekf.landmark_ids]
    lms = [lm for lm in lms if lm.kind == "wall" and lm.plane_id == plane.id]
    if not lms or not candidates:
        return []
    a = np.array([float(plane.along(lm.position)) for lm in lms])
    var_a = np.array([float(lm.cov[0, 0]) for lm in lms])
    c = np.array([float(plane.along(cd.P)) for cd in candidates])
    sf = np.array([cd.sigma_f for cd in candidates])
    sb = max(cd.sigma_b for cd in candidates)
    # heights must agree: one vertical extent (mostly) inside the other (a segment may be seen in part)
    zl = np.array([[lm.z_low if lm.z_low is not None else -np.inf for lm in lms]])
    zh = np.array([[lm.z_high if lm.z_high is not None else np.inf for lm in lms]])
    cl = np.array([[cd.z_low] for cd in candidates])
    ch = np.array([[cd.z_high] for cd in candidates])
    inter = np.clip(np.minimum(zh, ch) - np.maximum(zl, cl), 0.0, None)
    shorter = np.maximum(np.minimum(zh - zl, ch - cl), 1e-3)
    same_height = inter / shorter >= 0.5
    if polarity is not None:  # an edge never matches one of the opposite brightness step along the wall
        lp = np.array([[lm.polarity for lm in lms]])
        cp = np.array([[polarity[cd.pair]] for cd in candidates])
        same_height &= (lp * cp) >= 0
    found = []
    for i in range(len(c)):
        for j in range(len(a)):
            delta = a[j] - c[i]
            if abs(delta) > 3.0 * np.sqrt(sb**2 + var_a[j]):
                continue
            resid = (c[:, None] + delta) - a[None, :]
            # a feature's own error against its landmark's: the landmark's spread beyond the shared offset
            # is not known apart from var_a, so allow the candidate's σ_f and a few mm of the landmark's
            scale = tol * np.sqrt(sf[:, None] ** 2 + np.minimum(var_a[None, :], (2 * sf[:, None]) ** 2) + 1e-6)
            ok = (np.abs(resid) <= scale) & same_height
            # most features matched; then the likeliest offset and residuals
            prior = delta**2 / (sb**2 + float(np.mean(var_a)))
            score = (int(ok.any(axis=1).sum()), -prior - float(np.sum(np.where(ok, (resid / scale) ** 2, 0.0))))
            if ok.any():
                found.append((score, delta, resid, ok))
    if not found:
        return []
    found.sort(key=lambda f: f[0], reverse=True)
    out, seen = [], set()
    for _, _, resid, ok in found if every else found[:1]:
        rows, cols = linear_sum_assignment(np.where(ok, resid**2, 1e6))
        m = tuple((int(lms[j].id), int(candidates[i].pair)) for i, j in zip(rows, cols, strict=True) if ok[i, j])
        if m and m not in seen:
            seen.add(m)
            out.append(list(m))
    return out if every else (out[0] if out else [])


def height_cost(ekf: JointEKF, pairs, pan: float, weight: float = 9.0) -> np.ndarray:
    """(n_landmarks, n_pairs) association cost from the vertical extents: ``weight·(1 − IoU)`` of a pair's
    rows and the rows of the landmark's ends at its predicted depth (clipped to the image). Lines of other
    heights or lengths cost up to ``weight`` more: regularly spaced features are told apart by their extents
    when the pose error alone cannot (a whole group matched one feature over is jointly compatible)."""
    ids = ekf.landmark_ids
    cost = np.zeros((len(ids), len(pairs)))
    if not ids or not len(pairs):
        return cost
    cam = ekf.camera
    pred = ekf.predict_observation(ids, pan)
    d = pred.uv[:, 0] - pred.uv[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        Z = cam.f * cam.baseline / d
    for j, i in enumerate(ids):
        lm = ekf.landmark(i)
        if lm.z_low is None or lm.z_high is None or not np.isfinite(Z[j]) or Z[j] <= 0:
            continue
        vt = np.clip(cam.cv + cam.f * (cam.mount_height - lm.z_high) / Z[j], 0.0, cam.height - 1.0)
        vb = np.clip(cam.cv + cam.f * (cam.mount_height - lm.z_low) / Z[j], 0.0, cam.height - 1.0)
        inter = np.clip(np.minimum(vb, pairs.v_bottom) - np.maximum(vt, pairs.v_top), 0.0, None)
        union = np.maximum(np.maximum(vb, pairs.v_bottom) - np.minimum(vt, pairs.v_top), 1.0)
        cost[j] = weight * (1.0 - inter / union)
    return cost


def wall_polarity(polarity, plane, centre):
    """Image polarity (+1: brighter to the right in the left image) → polarity along the wall (+1: brighter
    towards ``p2``), for a camera centre ``centre`` (2,) [m]. ``p1 → p2`` runs left to right in the image when
    the camera is on the wall's right side (opposite its normal); from the other face the sign flips. A
    painted edge keeps its polarity along the wall from both faces of a partition."""
    side = float(plane.normal @ (np.asarray(centre, dtype=float) - plane.P1))
    return np.asarray(polarity, dtype=int) * (1 if side < 0 else -1)


def polarity_cost(ekf: JointEKF, polarity: np.ndarray, centre, cost: float = np.inf) -> np.ndarray:
    """(n_landmarks, n_pairs): ``cost`` (default: forbidden) where a wall landmark's polarity along its wall
    and a pair's, seen from ``centre``, are known and differ; else 0."""
    out = np.zeros((ekf.n_landmarks, len(polarity)))
    for r, i in enumerate(ekf.landmark_ids):
        lm = ekf.landmark(i)
        if lm.kind == "wall" and lm.polarity:
            pair_pol = wall_polarity(polarity, ekf.landmark_plane(i), centre)
            out[r] = np.where(lm.polarity * pair_pol < 0, cost, 0.0)
    return out


def is_duplicate(ekf: JointEKF, c) -> bool:
    """Whether a wall landmark on the same plane (measured from either edge) already explains candidate
    ``c``: their positions along the wall agree within 3σ."""
    for i in ekf.landmark_ids:
        lm = ekf.landmark(i)
        if lm.kind != "wall" or lm.plane_id != c.plane_id:
            continue
        gap = float(np.linalg.norm(lm.position - c.P))
        if gap <= 3.0 * np.sqrt(float(lm.cov[0, 0]) + c.sigma_s**2):
            return True
    return False
