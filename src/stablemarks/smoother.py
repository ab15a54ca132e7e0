"""Batch smoother over a run's records: the evaluation's accuracy reference ``gtsam_batch`` (issue 6).

The same data the on-line filter used (:class:`~stablemarks.online.FrameRecord`), as one nonlinear least
squares problem solved by GTSAM's Levenberg–Marquardt (the optional ``gtsam`` extra):

- a prior on the start pose ``X_0 ~ N(start, cov0)``;
- one ``BetweenFactorPose2`` per odometry increment ``U_k = X_{k-1}⁻¹ X_k`` (paper Eq 19: ``X_k = X_{k-1} ⊕ U_k``
  is :meth:`SE2.__matmul__ <stablemarks.geometry.SE2.__matmul__>` and gtsam's ``Pose2.compose``);
- one factor per group of landmarks entered together: the joint Gaussian prior over their ``s`` along the
  wall with the group's full covariance (the shared boundary error, DESIGN §4);
- one factor per observation the filter used: ``(u_l, u_r) = J(X_k, P(s_j))`` with the frame's pan and
  ``R = σ_img² I`` (Eqs 3 and 20), with the analytic Jacobians of
  :meth:`StereoCamera.project_columns <stablemarks.geometry.StereoCamera.project_columns>`;
- a weak prior (σ = :data:`WEAK_LANDMARK_SIGMA`) on every landmark at the filter's value, so that a landmark
  nothing else constrains does not make the system indeterminate.

The marginals come from GTSAM; where its factorization finds the system numerically indeterminate (turns on
the spot give the odometry an information of 10¹² across the track, a far landmark seen nearly along its wall
one near 1), from the dense information matrix scaled to unit diagonal (:func:`_marginals`). A landmark no
better known than its weak prior has no marginal (``var_s`` None).

The data associations are the filter's; only the estimation differs. The filter's covariances are over
world ``(x, y, theta)`` and additive increments, gtsam's over the tangent space of ``Pose2`` at the pose
(body frame): a covariance over ``(x, y)`` in the world is rotated by ``R(theta)ᵀ`` into gtsam's and back,
exactly to first order (``Pose2.retract(δ) = X ⊕ δ`` for small ``δ``). Only wall landmarks (one number ``s``
each, the ``stablemarks`` and ``plane_no_selection`` runs) are supported; landmarks loaded from a prior map
have no recorded prior and enter through their observations alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import Config
from .errors import InputError, expected
from .geometry import SE2, StereoCamera, rot2, wrap_angle
from .maps import ReferencePlane

GTSAM_HINT = "the gtsam_batch smoother needs the optional gtsam extra: pip install 'stablemarks[gtsam]'"

WEAK_LANDMARK_SIGMA = 100.0
"""σ [m] of the weak prior every landmark gets at the filter's value: it changes nothing a landmark's
observations or group prior determine (information 1e-4 m⁻² against ≥ 1 m⁻²), and keeps a landmark that
nothing else constrains (one seen along its wall, or loaded from a prior map and barely observed) from making
the system indeterminate. Such a landmark is left out of the marginals (``var_s`` None)."""

MAX_DENSE_VARIABLES = 4000
"""Largest number of scalar unknowns for which the marginals, when GTSAM's sparse factorization finds the
system numerically indeterminate, are computed from the dense, scaled information matrix instead."""

BEHIND_CAMERA_ERROR = 1e6
"""Residual [px] of an observation whose landmark falls behind the camera at a trial step: large and finite,
so Levenberg–Marquardt rejects the step instead of propagating NaN."""


def gtsam_available() -> bool:
    """Whether the optional ``gtsam`` package can be imported."""
    import importlib.util

    return importlib.util.find_spec("gtsam") is not None


def _gtsam():
    try:
        import gtsam
    except ImportError:
        raise InputError(GTSAM_HINT) from None
    return gtsam


@dataclass(frozen=True, eq=False)
class SmoothedLandmark:
    """One wall landmark after smoothing: ``s`` [m] along ``plane_id`` from ``edge``, its marginal variance
    ``var_s`` [m²] (None without marginals), ``position`` (2,) [m] in the map frame and ``cov2d`` (2, 2) [m²]
    (rank 1 along the wall, Eq 17; None without marginals)."""

    id: int
    plane_id: str
    edge: str
    s: float
    var_s: float | None
    position: np.ndarray
    cov2d: np.ndarray | None


@dataclass(frozen=True, eq=False)
class SmootherResult:
    """The batch estimate of a run.

    Attributes
    ----------
    poses : (K, 3) ``(x [m], y [m], theta [rad])`` per frame, map frame.
    cov_poses : (K, 3, 3) marginal covariances over world ``(x, y, theta)`` (None when not computed).
    landmarks : ``{id: SmoothedLandmark}``.
    iterations : Levenberg–Marquardt iterations.
    error_initial, error_final : the graph's cost ``½ Σ ‖whitened residual‖²`` at the filter's estimate and at
        the optimum.
    """

    poses: np.ndarray
    cov_poses: np.ndarray | None
    landmarks: dict[int, SmoothedLandmark]
    iterations: int
    error_initial: float
    error_final: float


# ----------------------------------------------------------------- frames
def _pose_to_world(theta: float) -> np.ndarray:
    """(3, 3) ``∂X/∂δ``: a ``Pose2`` tangent vector at heading ``theta`` (body frame) to world ``(x, y, theta)``."""
    A = np.eye(3)
    A[:2, :2] = rot2(theta)
    return A


def world_to_tangent_cov(cov_world: np.ndarray, theta: float) -> np.ndarray:
    """A (3, 3) covariance over world ``(x, y, theta)`` [m², rad²] as gtsam's over the tangent space of a
    ``Pose2`` with heading ``theta`` (body frame): ``A Σ Aᵀ`` with ``A = diag(R(theta)ᵀ, 1)``. An odometry
    covariance over the increment's ``(dx, dy, dtheta)`` becomes the ``BetweenFactorPose2`` noise with
    ``theta`` the increment's angle."""
    A = _pose_to_world(theta).T
    cov = A @ np.asarray(cov_world, dtype=float) @ A.T
    return 0.5 * (cov + cov.T)


def tangent_to_world_cov(cov_tangent: np.ndarray, theta: float) -> np.ndarray:
    """Inverse of :func:`world_to_tangent_cov`: gtsam's ``Pose2`` marginal (body frame) over world ``(x, y, theta)``."""
    A = _pose_to_world(theta)
    cov = A @ np.asarray(cov_tangent, dtype=float) @ A.T
    return 0.5 * (cov + cov.T)


# ---------------------------------------------------------------- factors
def observation(camera: StereoCamera, plane: ReferencePlane, edge: str, X, s: float):
    """Predicted columns of a wall landmark and their Jacobians (Eqs 3 and 20, as the filter's).

    ``camera`` is already panned for the frame; ``X`` (3,) the robot pose; ``s`` [m] the distance along
    ``plane`` from ``edge``. Returns ``uv`` (2,) ``(u_l, u_r)`` [px] (NaN behind the camera), ``J_I_X`` (2, 3)
    over world ``(x, y, theta)`` and ``J_I_s`` (2,).
    """
    t = plane.direction if edge == "p1" else -plane.direction
    uv, J_I_X, J_I_p = camera.project_columns(X, plane.point_at(s, edge), jacobians=True)
    return uv, J_I_X, J_I_p @ t


def observation_factor(pose_key: int, landmark_key: int, camera: StereoCamera, plane: ReferencePlane,
                       edge: str, measured, sigma_img: float):
    """A gtsam ``CustomFactor`` on (``Pose2`` at ``pose_key``, 1-vector ``s`` at ``landmark_key``): residual
    ``J(X, P(s)) − (u_l, u_r)`` [px] with noise ``σ_img² I`` and Jacobians w.r.t. gtsam's tangent spaces."""
    gtsam = _gtsam()
    z = np.asarray(measured, dtype=float).reshape(2)

    def error(this, values, H):
        pose = values.atPose2(pose_key)
        X = np.array([pose.x(), pose.y(), pose.theta()])
        s = float(values.atVector(landmark_key)[0])
        uv, J_I_X, J_I_s = observation(camera, plane, edge, X, s)
        if not np.all(np.isfinite(uv)):
            if H is not None:
                H[0], H[1] = np.zeros((2, 3)), np.zeros((2, 1))
            return np.full(2, BEHIND_CAMERA_ERROR)
        if H is not None:
            H[0] = J_I_X @ _pose_to_world(X[2])
            H[1] = J_I_s.reshape(2, 1)
        return uv - z

    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(2, sigma_img), [pose_key, landmark_key], error)


def edge_factor(pose_key: int, camera: StereoCamera, point, measured, cov_uv, cov_point, X_lin):
    """A gtsam ``CustomFactor`` on the ``Pose2`` at ``pose_key``: a free edge of the map at ``point`` (2,) seen at
    ``measured`` ``(u_l, u_r)`` [px] (the filter's ``ekf.edge_updates``), noise ``cov_uv`` plus the map's
    accuracy ``cov_point`` projected at the frame's estimated pose ``X_lin`` (the filter projected it at its
    pose just before the edge update; the two differ by that update, nothing when the map is exact)."""
    gtsam = _gtsam()
    z = np.asarray(measured, dtype=float).reshape(2)
    p = np.asarray(point, dtype=float).reshape(1, 2)
    _, _, J_p = camera.project_columns(np.asarray(X_lin, dtype=float), p, jacobians=True)
    cov = np.asarray(cov_uv, dtype=float) + J_p[0] @ np.asarray(cov_point, dtype=float) @ J_p[0].T

    def error(this, values, H):
        pose = values.atPose2(pose_key)
        X = np.array([pose.x(), pose.y(), pose.theta()])
        uv, J_I_X, _ = camera.project_columns(X, p, jacobians=True)
        if not np.all(np.isfinite(uv)):
            if H is not None:
                H[0] = np.zeros((2, 3))
            return np.full(2, BEHIND_CAMERA_ERROR)
        if H is not None:
            H[0] = J_I_X[0] @ _pose_to_world(X[2])
        return uv[0] - z

    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(0.5 * (cov + cov.T)), [pose_key], error)


def wall_factor(pose_key: int, bias_key: int | None, nu, H_X, J_bias, R, X_lin):
    """A gtsam ``CustomFactor`` on the ``Pose2`` at ``pose_key`` (and the wall's shared disparity error, a
    1-vector at ``bias_key``, when ``J_bias`` is given): a wall fitted in a frame (the filter's ``ekf.wall_updates``,
    :attr:`~stablemarks.localizer.FrameRecord.wall_measurements`), linear about the pose ``X_lin`` of the filter's
    update: residual ``H_X (X − X_lin) + J_β β − ν`` [m, 1] with noise ``R``."""
    gtsam = _gtsam()
    nu = np.asarray(nu, dtype=float).reshape(2)
    H_X = np.asarray(H_X, dtype=float).reshape(2, 3)
    X_lin = np.asarray(X_lin, dtype=float).reshape(3)
    J_b = None if J_bias is None else np.asarray(J_bias, dtype=float).reshape(2, 1)
    keys = [pose_key] if J_b is None else [pose_key, bias_key]

    def error(this, values, H):
        pose = values.atPose2(pose_key)
        X = np.array([pose.x(), pose.y(), pose.theta()])
        d = X - X_lin
        d[2] = wrap_angle(d[2])
        r = H_X @ d - nu
        if J_b is not None:
            r = r + J_b[:, 0] * float(values.atVector(bias_key)[0])
        if H is not None:
            H[0] = H_X @ _pose_to_world(X[2])
            if J_b is not None:
                H[1] = J_b.copy()
        return r

    R = np.asarray(R, dtype=float).reshape(2, 2)
    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(0.5 * (R + R.T)), keys, error)


def tied_prior_factor(keys, pose_key: int, values, cov, G, X_lin):
    """A gtsam ``CustomFactor`` on the 1-vectors ``s`` at ``keys`` (n,) and the ``Pose2`` at ``pose_key``: the prior of
    landmarks entered tied to the pose (``ekf.tie_blind_entries``), ``s − values − G (X − X_lin) ~ N(0, cov)``."""
    gtsam = _gtsam()
    keys = [int(k) for k in keys]
    mean = np.asarray(values, dtype=float).reshape(len(keys))
    G = np.asarray(G, dtype=float).reshape(len(keys), 3)
    X_lin = np.asarray(X_lin, dtype=float).reshape(3)
    eye = np.eye(len(keys))

    def error(this, vals, H):
        pose = vals.atPose2(pose_key)
        X = np.array([pose.x(), pose.y(), pose.theta()])
        d = X - X_lin
        d[2] = wrap_angle(d[2])
        if H is not None:
            for j in range(len(keys)):
                H[j] = eye[:, j : j + 1].copy()
            H[len(keys)] = -G @ _pose_to_world(X[2])
        return np.array([float(vals.atVector(k)[0]) for k in keys]) - mean - G @ d

    noise = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=float).reshape(len(keys), len(keys)))
    return gtsam.CustomFactor(noise, [*keys, pose_key], error)


def group_prior_factor(keys, values, cov):
    """A gtsam ``CustomFactor`` on the 1-vectors ``s`` at ``keys`` (n,): the joint prior ``s ~ N(values, cov)``
    of landmarks entered together (cov (n, n), full: their shared boundary error, DESIGN §4)."""
    gtsam = _gtsam()
    keys = [int(k) for k in keys]
    mean = np.asarray(values, dtype=float).reshape(len(keys))
    eye = np.eye(len(keys))

    def error(this, vals, H):
        if H is not None:
            for j in range(len(keys)):
                H[j] = eye[:, j : j + 1].copy()
        return np.array([float(vals.atVector(k)[0]) for k in keys]) - mean

    noise = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=float).reshape(len(keys), len(keys)))
    return gtsam.CustomFactor(noise, keys, error)


# ----------------------------------------------------------------- smooth
def batch_smooth(result, camera: StereoCamera, config: Config = Config(), *, marginals: bool = True,
                 max_iterations: int = 100) -> SmootherResult:
    """Smooth a run of the on-line loop (:class:`~stablemarks.online.OnlineResult`) in one batch.

    ``camera``: the stereo head of the run (unpanned; each frame's pan is in its record); ``config``: the
    run's configuration (``config.noise.sigma_img`` is the observation noise). The start pose prior is
    ``N(records[0].dead_reckoning, result.cov0)``; the initial values are the filter's per-frame poses and
    final landmark values. ``marginals``: also compute the marginal covariances of every pose and landmark.
    Raises :class:`InputError` when gtsam is not installed or the run holds point landmarks.
    """
    gtsam = _gtsam()
    from gtsam.symbol_shorthand import B, L, X

    records = result.records
    if not records:
        raise InputError(expected("a run of at least one frame", "no records", where="batch_smooth.result"))
    sigma_img = float(config.noise.sigma_img)
    graph = gtsam.NonlinearFactorGraph()
    initial = gtsam.Values()
    start = records[0].dead_reckoning
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*start),
                                     gtsam.noiseModel.Gaussian.Covariance(world_to_tangent_cov(result.cov0, start[2]))))
    walls: dict[int, tuple[ReferencePlane, str]] = {}
    biases: dict[str, int] = {}  # each wall's shared disparity error (ekf.wall_updates)

    def wall(lid: int) -> tuple[ReferencePlane, str]:
        if lid not in walls:
            lm = result.landmark(lid)  # in the final filter, or as it was when dropped
            if lm.kind != "wall":
                raise InputError(expected("wall landmarks (a stablemarks or plane_no_selection run)",
                                          f"a {lm.kind} landmark (id {lid})", where="batch_smooth"))
            walls[lid] = (result.world_map[lm.plane_id], lm.edge)
            value = np.array([float(lm.value[0])])
            initial.insert(L(lid), value)
            graph.add(gtsam.PriorFactorVector(L(lid), value, gtsam.noiseModel.Isotropic.Sigma(1, WEAK_LANDMARK_SIGMA)))
        return walls[lid]

    for rec in records:
        k = rec.index
        initial.insert(X(k), gtsam.Pose2(*rec.pose))
        if rec.odometry is not None:
            U = rec.odometry
            # A turn on the spot has no sideways error in the odometry model: its covariance is singular, which
            # the filter takes but a factor's information matrix cannot. A floor of 1 µm and 1 µrad changes
            # nothing measurable and keeps the system determinate.
            cov_U = world_to_tangent_cov(rec.cov_odometry, U[2]) + np.diag([1e-12, 1e-12, 1e-12])
            graph.add(gtsam.BetweenFactorPose2(X(k - 1), X(k), gtsam.Pose2(*U),
                                               gtsam.noiseModel.Gaussian.Covariance(cov_U)))
        cam_k = camera.with_pan(rec.pan)
        for lid, u_l, u_r in rec.measurements:
            plane, edge = wall(int(lid))
            graph.add(observation_factor(X(k), L(int(lid)), cam_k, plane, edge, (u_l, u_r), sigma_img))
        tied = {tuple(int(i) for i in ids): (G, X_lin) for ids, G, X_lin in getattr(rec, "landmark_couplings", [])}
        for ids, values, cov in rec.landmark_priors:
            for lid in ids:
                wall(int(lid))
            key = tuple(int(i) for i in ids)
            if key in tied:
                graph.add(tied_prior_factor([L(i) for i in key], X(k), values, cov, *tied[key]))
            else:
                graph.add(group_prior_factor([L(int(i)) for i in ids], values, cov))
        for plane_id, edge, u_l, u_r, cov_uv in getattr(rec, "edge_measurements", []):
            graph.add(edge_factor(X(k), cam_k, result.world_map[plane_id].edge(edge), (u_l, u_r), cov_uv,
                                  result.world_map.edge_cov(plane_id, edge), rec.pose))
        for plane_id, nu, H_X, J_bias, R, var_beta, X_lin in getattr(rec, "wall_measurements", []):
            if J_bias is not None and plane_id not in biases:
                biases[plane_id] = B(len(biases))
                initial.insert(biases[plane_id], np.zeros(1))
                graph.add(gtsam.PriorFactorVector(biases[plane_id], np.zeros(1),
                                                  gtsam.noiseModel.Isotropic.Sigma(1, float(np.sqrt(var_beta)))))
            graph.add(wall_factor(X(k), biases.get(plane_id), nu, H_X, J_bias, R, X_lin))

    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(int(max_iterations))
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-12)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
    estimate = optimizer.optimize()

    K = len(records)
    poses = np.array([SE2(p.x(), p.y(), p.theta()).as_array()
                      for p in (estimate.atPose2(X(r.index)) for r in records)])
    cov_poses = None
    var_s: dict[int, float | None] = dict.fromkeys(walls)
    if marginals:
        pose_keys = [X(r.index) for r in records]
        tangent, var_s = _marginals(graph, estimate, pose_keys, {lid: L(lid) for lid in walls})
        cov_poses = np.array([tangent_to_world_cov(c, poses[i, 2]) for i, c in enumerate(tangent)]).reshape(K, 3, 3)
    landmarks = {}
    for lid, (plane, edge) in sorted(walls.items()):
        s = float(estimate.atVector(L(lid))[0])
        t = plane.direction if edge == "p1" else -plane.direction
        v = var_s[lid]
        landmarks[lid] = SmoothedLandmark(lid, plane.id, edge, s, v, plane.point_at(s, edge),
                                          None if v is None else v * np.outer(t, t))
    return SmootherResult(poses, cov_poses, landmarks, int(optimizer.iterations()),
                          float(graph.error(initial)), float(graph.error(estimate)))


def _marginals(graph, estimate, pose_keys: list[int], landmark_keys: dict[int, int]):
    """Marginal covariances of the poses (tangent space, (3, 3) each) and variances of the landmarks (``{id:
    var_s or None}``).

    GTSAM's sparse marginals first. When it finds the system numerically indeterminate (a turn on the spot
    has an odometry information of 10¹² across its track, a far landmark seen nearly along its wall one of 1:
    a condition number beyond what its Cholesky factorization accepts), the same marginals come from the dense
    information matrix at the optimum, scaled to unit diagonal and inverted through its eigenvalues. A landmark
    whose marginal is no tighter than its weak prior (:data:`WEAK_LANDMARK_SIGMA`) is left out (None).
    """
    gtsam = _gtsam()
    weak = 0.25 * WEAK_LANDMARK_SIGMA**2
    try:
        m = gtsam.Marginals(graph, estimate)
        covs = [np.asarray(m.marginalCovariance(k)) for k in pose_keys]
        var = {lid: float(m.marginalCovariance(k)[0, 0]) for lid, k in landmark_keys.items()}
    except RuntimeError:
        covs, var = _dense_marginals(graph, estimate, pose_keys, landmark_keys)
    return covs, {lid: (v if np.isfinite(v) and 0.0 < v < weak else None) for lid, v in var.items()}


def _dense_marginals(graph, estimate, pose_keys: list[int], landmark_keys: dict[int, int]):
    """The fallback of :func:`_marginals`: the inverse of the scaled dense information matrix."""
    gtsam = _gtsam()
    n = 3 * len(pose_keys) + len(landmark_keys)
    if n > MAX_DENSE_VARIABLES:
        raise RuntimeError(f"the smoother's marginals: GTSAM found the system indeterminate and it has {n} "
                           f"unknowns, more than the {MAX_DENSE_VARIABLES} the dense fallback takes")
    ordering = gtsam.Ordering()
    for k in [*pose_keys, *landmark_keys.values()]:
        ordering.push_back(k)
    H, _ = graph.linearize(estimate).hessian(ordering)
    H = 0.5 * (H + H.T)
    d = np.sqrt(np.clip(np.diag(H), 1e-300, None))
    w, V = np.linalg.eigh(H / np.outer(d, d))
    if not w[-1] > 0:
        raise RuntimeError("the smoother's marginals: the information matrix has no positive eigenvalue")
    floor = w[-1] * 1e-14  # directions below it are undetermined: a huge, finite variance
    inv = 1.0 / np.maximum(w, floor)
    cov = (V * inv) @ V.T
    cov = cov / np.outer(d, d)
    covs = [cov[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] for i in range(len(pose_keys))]
    if not all(np.all(np.isfinite(c)) and np.all(np.linalg.eigvalsh(0.5 * (c + c.T)) > 0) for c in covs):
        raise RuntimeError("the smoother's marginals: a pose is not determined by the data")
    base = 3 * len(pose_keys)
    var = {lid: float(cov[base + j, base + j]) for j, lid in enumerate(landmark_keys)}
    return covs, var
