"""Where the robot is when the pose prediction has lost it: a pose from two of the frame's lines.

After a kidnap or a wheel slip the predicted pose is wrong by more than the filter's gates, so none of the
landmarks is found where it is predicted; the walls, too, may be fitted away from where the pose puts them, or
not at all. The landmarks themselves still say where the robot is: every pair of landmarks is a known distance
apart, and every pair of the frame's stereo lines, triangulated in the camera, is a measured distance apart.
Two landmarks matched with two lines fix the camera's pose in the plane (a rigid 2-D transform from two point
correspondences); the pose that puts most of the filter's landmarks on a line of the frame wins
(:func:`pose_from_lines`, a RANSAC over all pairs that fit, without random sampling: the landmarks and lines of
one frame are few).

The winner is only a hypothesis: the caller re-initialises a copy of the filter's pose there with a wide
covariance and keeps it only if the ordinary association then finds a jointly compatible pattern of
landmarks (``Localizer._relocalize``).

Units: metres, radians, pixels; poses ``(x, y, theta)`` in the map frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import StereoCamera, wrap_angle

__all__ = ["LineRelocation", "pose_from_lines", "resection_cov"]


@dataclass(frozen=True)
class LineRelocation:
    """The pose :func:`pose_from_lines` found.

    Attributes
    ----------
    pose : (3,) robot pose ``(x, y, theta)`` [m, m, rad].
    inliers : the landmark ids predicted on one of the frame's lines at ``pose`` (within the tolerance).
    runner_up : how many landmarks the best hypothesis elsewhere (farther than ``distinct`` from ``pose``) put on
        a line: the margin by which the winner won.
    """

    pose: np.ndarray
    inliers: tuple[int, ...]
    runner_up: int


def pose_from_lines(camera: StereoCamera, landmarks: np.ndarray, ids, u_left, u_right, prior_pose, *,
                    radius: float, heading: float, tol_px: float, tight_px: float, sigma_img: float,
                    refine: int = 30, min_distance: float = 0.15,
                    distinct: tuple[float, float] = (0.10, np.radians(2.0)),
                    max_hypotheses: int = 20000) -> LineRelocation | None:
    """The robot pose that puts the most landmarks on the frame's lines, from pairs of landmarks matched with
    pairs of lines a consistent distance apart.

    Parameters
    ----------
    camera : the stereo head at the frame's pan.
    landmarks : (n, 2) map positions of the landmarks [m]; ``ids`` (n,) their ids.
    u_left, u_right : (m,) the columns of the frame's line pairs [px].
    prior_pose : (3,) the predicted pose; hypotheses farther than ``radius`` [m] from it, or with a heading
        more than ``heading`` [rad] from its heading, are not considered.
    tol_px : a landmark is on a line when both its predicted columns are within this of the line's [px], for a
        pose from two lines (whose error, mostly the triangulated depth's, moves every prediction).
    tight_px : the same after the pose is refitted to all the landmarks it puts on a line (``refine`` best).
    sigma_img : the lines' column σ [px], for the tolerance on the distance between two triangulated lines
        (3 σ of its first-order error).
    min_distance : landmark pairs closer than this [m] fix the heading too poorly to be used.
    distinct : ``(metres, radians)``: a hypothesis this far from the winner in position or heading counts as
        another place (``runner_up``).
    max_hypotheses : at most this many pairings are scored (those whose distances agree best).

    Returns None when no pairing fits within the prior's region.
    """
    P = np.asarray(landmarks, dtype=float).reshape(-1, 2)
    ids = np.asarray(ids, dtype=int)
    u_l, u_r = np.asarray(u_left, dtype=float), np.asarray(u_right, dtype=float)
    if len(P) < 2 or len(u_l) < 2:
        return None
    # the lines in the camera's plane: forward Z, left -X (so that world = C + R(psi) q)
    cam, cov = camera.triangulate(u_l, u_r, sigma_img=sigma_img)
    ok = np.isfinite(cam).all(axis=1) & (cam[:, 1] > 0)
    if ok.sum() < 2:
        return None
    lines = np.flatnonzero(ok)
    q = np.stack([cam[lines, 1], -cam[lines, 0]], axis=1)
    cq = cov[lines][:, ::-1, ::-1] * np.array([[1.0, -1.0], [-1.0, 1.0]])  # cov of (Z, -X)
    # every ordered pair of lines (a, b), every pair of landmarks (i, j), i < j, whose distances agree
    a, b = np.nonzero(~np.eye(len(q), dtype=bool))
    dq = q[b] - q[a]
    d_line = np.linalg.norm(dq, axis=1)
    unit = dq / np.maximum(d_line, 1e-12)[:, None]
    var_d = np.einsum("ki,kij,kj->k", unit, cq[a] + cq[b], unit)
    i, j = np.triu_indices(len(P), 1)
    d_lm = np.linalg.norm(P[j] - P[i], axis=1)
    use = d_lm >= min_distance
    i, j, d_lm = i[use], j[use], d_lm[use]
    if not len(i):
        return None
    gap = np.abs(d_line[:, None] - d_lm[None, :])
    fits = gap <= 3.0 * np.sqrt(var_d)[:, None]
    kl, kp = np.nonzero(fits)
    if not len(kl):
        return None
    if len(kl) > max_hypotheses:
        order = np.argsort(gap[kl, kp] / np.sqrt(var_d[kl]))[:max_hypotheses]
        kl, kp = kl[order], kp[order]
    # camera heading psi rotates q(b) - q(a) onto P(j) - P(i); the centre puts their midpoints together
    vl = P[j[kp]] - P[i[kp]]
    vq = dq[kl]
    psi = np.arctan2(vl[:, 1], vl[:, 0]) - np.arctan2(vq[:, 1], vq[:, 0])
    centre = 0.5 * (P[i[kp]] + P[j[kp]]) - _rotate(psi, 0.5 * (q[a[kl]] + q[b[kl]]))
    theta = wrap_angle(psi - camera.pan)
    xy = centre - _rotate(theta, np.array([camera.mount_x, camera.mount_y]))
    prior = np.asarray(prior_pose, dtype=float)
    near = (np.linalg.norm(xy - prior[:2], axis=1) <= radius) & (np.abs(wrap_angle(theta - prior[2])) <= heading)
    if not near.any():
        return None
    poses = np.column_stack([xy[near], theta[near]])
    ul, ur = u_l[lines], u_r[lines]
    counts, _ = _score(camera, poses, P, ul, ur, tol_px)
    # the best pairings, each refitted to the landmarks it puts on a line, then scored again with the tight
    # tolerance (two landmarks a few decimetres apart fix the heading to a few degrees only)
    top = np.argsort(-counts, kind="stable")[:refine]
    refined = np.array([_refine(camera, poses[t], P, ul, ur, tol_px, tight_px) for t in top])
    inside = (np.linalg.norm(refined[:, :2] - prior[:2], axis=1) <= radius) & \
        (np.abs(wrap_angle(refined[:, 2] - prior[2])) <= heading)
    if not inside.any():
        return None
    refined = refined[inside]
    counts, matched = _score(camera, refined, P, ul, ur, tight_px)
    best = int(np.argmax(counts))
    far = (np.linalg.norm(refined[:, :2] - refined[best, :2], axis=1) > distinct[0]) | \
        (np.abs(wrap_angle(refined[:, 2] - refined[best, 2])) > distinct[1])
    runner_up = int(counts[far].max()) if far.any() else 0
    inliers = tuple(int(v) for v in ids[matched[best]])
    return LineRelocation(refined[best].copy(), inliers, runner_up)


def resection_cov(camera: StereoCamera, pose, points: np.ndarray, point_covs: np.ndarray, sigma_px: float, *,
                  radius: float, heading: float) -> np.ndarray:
    """(3, 3) covariance of a robot pose resected from the columns of ``points`` (m, 2) [m] seen from ``pose``:
    each point's two columns good to ``sigma_px`` and uncertain by its own position's covariance ``point_covs``
    (m, 2, 2) [m²] seen through the camera (``R_i = σ² I + J_p Σ_p J_pᵀ``), ``(Σ J_Xᵀ R_i⁻¹ J_X)⁻¹``, with the
    directions they do not fix bounded by the region searched (``radius`` [m] for the position, ``heading``
    [rad], each as one σ). Landmarks on one wall a few decimetres apart at 4 m fix the pose's position along
    their line of sight and little else: a shift across it with a turn that keeps every column where it is is
    as likely as the place found. Lab, narrow noise (trial 11 of 20, frame 5): six landmarks over 0.55 m of a
    partition, good to a millimetre, and four of a white board 40 mm uncertain; the place found 35 mm and 10 mrad
    off along that direction fitted all ten, and an isotropic σ (4 mm, 1 mrad) held it there with NEES 175."""
    _, J_X, J_p = camera.project_columns(np.asarray(pose, dtype=float), np.asarray(points, dtype=float),
                                         jacobians=True)
    R = sigma_px**2 * np.eye(2) + J_p @ np.asarray(point_covs, dtype=float) @ np.swapaxes(J_p, 1, 2)
    info = np.einsum("mji,mjk->ik", J_X, np.linalg.solve(R, J_X))
    cov = np.linalg.inv(info + np.diag([radius**-2, radius**-2, heading**-2]))
    return 0.5 * (cov + cov.T)


def lines_score(camera: StereoCamera, pose, landmarks: np.ndarray, u_left, u_right, tol_px: float) -> int:
    """How many of ``landmarks`` (n, 2) robot pose ``pose`` (3,) puts within ``tol_px`` of one of the frame's lines
    ``(u_left, u_right)`` in both images (:func:`pose_from_lines`'s score of a pose, except that every line counts
    here, also those it leaves out for not triangulating in front of the camera)."""
    P = np.asarray(landmarks, dtype=float).reshape(-1, 2)
    u_l, u_r = np.asarray(u_left, dtype=float), np.asarray(u_right, dtype=float)
    if not len(P) or not len(u_l):
        return 0
    counts, _ = _score(camera, np.asarray(pose, dtype=float).reshape(1, 3), P, u_l, u_r, tol_px)
    return int(counts[0])


def _rotate(angle, v) -> np.ndarray:
    """Vectors ``v`` (h, 2) or one vector (2,) turned by ``angle`` (h,) [rad]: (h, 2)."""
    c, s = np.cos(angle), np.sin(angle)
    v = np.broadcast_to(v, np.shape(angle) + (2,))
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def _camera_centre(camera: StereoCamera, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Left optical centres (h, 2) and camera headings (h,) of robot poses (h, 3)."""
    th = poses[:, 2]
    return poses[:, :2] + _rotate(th, np.array([camera.mount_x, camera.mount_y])), th + camera.pan


def _refine(camera: StereoCamera, pose: np.ndarray, P: np.ndarray, u_l: np.ndarray, u_r: np.ndarray,
            tol_px: float, tight_px: float, rounds: int = 4) -> np.ndarray:
    """``pose`` refitted to the landmarks it puts on a line, each with its nearest line: Gauss–Newton on the
    columns (the same projection the filter uses, :meth:`StereoCamera.project_columns`), ``rounds`` times, the
    tolerance narrowing from ``tol_px`` to ``tight_px`` (the triangulated points themselves are a few cm off in
    depth at 3 m; their columns are good to a fraction of a pixel)."""
    pose = np.asarray(pose, dtype=float).copy()
    measured = np.stack([u_l, u_r], axis=1)
    for k in range(rounds):
        nearest, matched = _nearest_lines(camera, pose[None], P, u_l, u_r, tol_px if k == 0 else tight_px)
        w = np.flatnonzero(matched[0])
        if len(w) < 2:
            return pose
        uv, J, _ = camera.project_columns(pose, P[w], jacobians=True)
        r = (measured[nearest[0, w]] - uv).reshape(-1)
        step = np.linalg.lstsq(J.reshape(-1, 3), r, rcond=None)[0]
        if not np.all(np.isfinite(step)):
            return pose
        pose += step
        pose[2] = float(wrap_angle(pose[2]))
    return pose


def _nearest_lines(camera: StereoCamera, poses: np.ndarray, P: np.ndarray, u_l: np.ndarray, u_r: np.ndarray,
                   tol_px: float) -> tuple[np.ndarray, np.ndarray]:
    """For each pose (h, 3) and landmark (n, 2): the nearest line (h, n) by the larger of the two columns'
    differences, and whether the landmark is predicted in both images within ``tol_px`` of it (h, n)."""
    centre, psi = _camera_centre(camera, poses)
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    dx = P[None, :, 0] - centre[:, None, 0]
    dy = P[None, :, 1] - centre[:, None, 1]
    Xc, Zc = s * dx - c * dy, c * dx + s * dy
    Zs = np.where(Zc > 0.1, Zc, np.nan)
    ul = camera.cu + camera.f * Xc / Zs
    ur = ul - camera.f * camera.baseline / Zs
    seen = np.isfinite(Zs) & (ul >= 0) & (ul <= camera.width - 1) & (ur >= 0) & (ur <= camera.width - 1)
    err = np.maximum(np.abs(ul[:, :, None] - u_l[None, None, :]), np.abs(ur[:, :, None] - u_r[None, None, :]))
    err = np.where(np.isfinite(err), err, np.inf)
    nearest = np.argmin(err, axis=2)
    close = np.take_along_axis(err, nearest[:, :, None], axis=2)[:, :, 0] <= tol_px
    return nearest, seen & close


def _score(camera: StereoCamera, poses: np.ndarray, P: np.ndarray, u_l: np.ndarray, u_r: np.ndarray,
           tol_px: float, chunk: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """For each pose (h, 3): how many landmarks (n, 2) are predicted in both images within ``tol_px`` of a line
    ``(u_l, u_r)`` (m,), and which (h, n) bool; in chunks of ``chunk`` poses (memory ``chunk · n · m``)."""
    matched = np.zeros((len(poses), len(P)), dtype=bool)
    for k in range(0, len(poses), chunk):
        matched[k:k + chunk] = _nearest_lines(camera, poses[k:k + chunk], P, u_l, u_r, tol_px)[1]
    return matched.sum(axis=1), matched
