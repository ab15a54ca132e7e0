"""The methods the localizer can run, one strategy object each (the evaluation compares them):

=======================  ==========================================================================
``stablemarks``          the full method: plane-constrained landmarks that pass the selection rules
``plane_no_selection``   plane-constrained landmarks, every candidate (no selection rules)
``all_segments``         every kept segment pair as a 2-D point landmark (classic stereo EKF-SLAM)
``dead_reckoning``       odometry only
=======================  ==========================================================================

A method answers three questions for one frame: what the frame's own landmark model is (:meth:`Method.model`,
Secs 2.3–4), which measurements are which landmarks (:meth:`Method.associate`, Sec 5) and which new
landmarks enter the filter (:meth:`Method.enter`). The loop that calls them is
:meth:`stablemarks.localizer.Localizer.step`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .config import Config
from .errors import InputError, expected
from .estimation import JointEKF, NewLandmark, associate_frame, is_duplicate, wall_polarity
from .geometry import StereoCamera
from .landmarks import REASON_OFF_WALL, Candidate
from .maps import Map
from .pipeline import FrameLandmarks, FrontEnd, select_landmarks


@dataclass
class Entered:
    """What :meth:`Method.enter` put into the filter in one frame.

    ``ids`` the new landmark ids in order; ``candidates`` the wall candidate each came from (None for point
    landmarks); ``priors`` the groups ``(ids, initial values, joint covariance)`` they entered with (wall
    landmarks; the cross-covariance with the pose is zero, DESIGN §4, unless the group is in ``couplings``).
    """

    ids: list[int] = field(default_factory=list)
    candidates: list[Candidate | None] = field(default_factory=list)
    priors: list[tuple[list[int], list[float], np.ndarray]] = field(default_factory=list)
    couplings: list[tuple[list[int], np.ndarray, np.ndarray]] = field(default_factory=list)
    """Groups entered tied to the pose (``enter(..., blind="tied")``): ``(ids, G (n, 3), X)``: their errors are
    ``G (X_true − X)`` plus the prior's, ``X`` the pose they were entered from."""


class Method:
    """Base strategy: the full method's behaviour; subclasses change one decision each."""

    name = "stablemarks"
    uses_vision = True
    models_planes = True

    def model(self, front: FrontEnd, camera: StereoCamera, world_map: Map, X, cov_X,
              config: Config) -> FrameLandmarks | None:
        """The frame's own landmark model on the reference planes (Secs 2.3–4), from the prior belief."""
        return select_landmarks(front, camera, world_map, X, cov_X, config)

    def associate(self, ekf: JointEKF, front: FrontEnd, model: FrameLandmarks | None, pan: float,
                  camera: StereoCamera, report: dict | None = None, max_incidence: float | None = None
                  ) -> list[tuple[int, int]]:
        """``(landmark id, kept-pair index)`` of this frame (:func:`~stablemarks.estimation.associate_frame`,
        which fills ``report``); wall landmarks seen more obliquely than ``max_incidence`` [rad] are left out."""
        pairs = front.kept_pairs
        if not ekf.n_landmarks or not len(pairs):
            return []
        measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
        polarity = front.left_segments.polarity[pairs.left_index]
        centre = camera.optical_centres(ekf.pose)[0]
        return associate_frame(ekf, pairs, measured, pan, model, polarity, centre, report, max_incidence)

    def take(self, model: FrameLandmarks) -> list[Candidate]:
        """The candidates this method enters as landmarks."""
        return model.selected

    def recheck(self, ekf: JointEKF, model: FrameLandmarks | None, assoc: list[tuple[int, int]],
                sigma: float, camera: StereoCamera | None = None, off_wall_sigma: float | None = None
                ) -> tuple[list[tuple[int, int]], list[int]]:
        """Re-check each associated wall landmark against the frame's own model of the same line: positions
        along the wall (both pose-independent) must agree within ``sigma`` σ of their two variances. A landmark
        that does not is dropped from the filter (and the pair enters again as a new landmark from this frame's
        model): an error made from far away or at a slant is corrected when the line is seen better. So is a
        landmark whose line this frame finds off its wall (:data:`~stablemarks.landmarks.REASON_OFF_WALL`): an
        edge of something standing in front of the wall, let in by a frame whose test it passed by chance, is
        tested again in every frame that sees it.

        A pair the model did not place on the wall (its features not modelled in this frame, no free edge in
        view; or the pair not one of the wall's members) is tested against the wall as fitted in this frame, when
        ``camera`` (the frame's, panned) and ``off_wall_sigma`` are given: its triangulated point must lie on the
        fitted line within ``off_wall_sigma`` σ (Eq 12's innovation, as at entry; the pose cancels, both being
        placed from the same mean pose). One that does not is not associated in this frame, the landmark kept: the
        line may be another one in the gate (storeroom: after a blind turn, a landmark entered at the junction of a
        cabinet with its wall was associated with the cabinet's front edge, 0.4 m nearer, and pulled the pose
        0.16 m off). A fit the map gates (shifted or turned from it) counts too: after a blind stretch the pose,
        not the fit, is usually what is off, and the test does not depend on the pose. Returns the associations
        kept and the ids dropped."""
        if model is None:
            return assoc, []
        by_pair = {c.pair: c for c in model.candidates}
        test = camera is not None and off_wall_sigma is not None
        fits = {pm.fit.plane.id: pm.fit for pm in model.planes} if test else {}
        keep, dropped = [], []
        for i, j in assoc:
            c = by_pair.get(j)
            lm = ekf.landmark(i)
            if c is None:  # a point landmark, or a pair the model did not place on a wall
                fit = fits.get(lm.plane_id) if lm.kind == "wall" else None
                if fit is None or _on_fitted_wall(camera, fit, model.X, model.front.kept_pairs, j, off_wall_sigma):
                    keep.append((i, j))
                continue
            if lm.kind != "wall" or lm.plane_id != c.plane_id:
                keep.append((i, j))
                continue
            if c.reason == REASON_OFF_WALL:
                dropped.append(i)
                continue
            plane = ekf.landmark_plane(i)
            gap = float(plane.along(c.P) - plane.along(lm.position))
            if abs(gap) > sigma * np.sqrt(float(lm.cov[0, 0]) + c.sigma_relative**2):
                dropped.append(i)
            else:
                keep.append((i, j))
        return keep, dropped

    def enter(self, ekf: JointEKF, front: FrontEnd, model: FrameLandmarks | None, used_pairs: set[int],
              camera: StereoCamera, world_map: Map, frame: int, config: Config, *,
              closed_planes: frozenset[str] = frozenset(), blind: str | None = None) -> Entered:
        """Enter the frame's new wall landmarks, jointly per boundary (:func:`enter_wall_landmarks`), on every wall
        but ``closed_planes`` (ids of walls whose landmarks in view this frame did not find). ``blind``: a frame that
        found none of the filter's landmarks, whose boundaries were told from other lines by the pose alone, enters
        them ``"tied"`` (with the cross-covariance to the pose their image positions imply) or ``"widened"`` (with
        the pose's variance along the wall, uncorrelated); None: as the map's."""
        fresh = [c for c in self.take(model) if c.pair not in used_pairs and c.plane_id not in closed_planes
                 and not is_duplicate(ekf, c)]
        pairs = front.kept_pairs
        polarity = front.left_segments.polarity[pairs.left_index]
        centre = camera.optical_centres(ekf.pose)[0]
        along = {c.pair: int(wall_polarity(int(polarity[c.pair]), world_map[c.plane_id], centre)) for c in fresh}
        return enter_wall_landmarks(ekf, world_map, fresh, frame, along, config.landmarks.filter_boundary_sigma,
                                    tied_camera=camera if blind else None, widen=blind == "widened")


class PlaneNoSelection(Method):
    """Plane-constrained landmarks without the selection rules: every candidate enters."""

    name = "plane_no_selection"

    def take(self, model: FrameLandmarks) -> list[Candidate]:
        return model.candidates


class AllSegments(Method):
    """Every kept segment pair becomes a 2-D point landmark (no planes, no selection)."""

    name = "all_segments"
    models_planes = False

    def model(self, front, camera, world_map, X, cov_X, config) -> None:
        return None

    def enter(self, ekf, front, model, used_pairs, camera, world_map, frame, config, *,
              closed_planes=frozenset(), blind=None) -> Entered:
        pairs = front.kept_pairs
        idx = [j for j in range(len(pairs)) if j not in used_pairs]
        ids = enter_point_landmarks(ekf, camera, pairs, idx, frame)
        return Entered(ids, [None] * len(ids))


class DeadReckoning(Method):
    """Odometry only: no image is looked at."""

    name = "dead_reckoning"
    uses_vision = False
    models_planes = False


METHODS: dict[str, type[Method]] = {m.name: m for m in (Method, PlaneNoSelection, AllSegments, DeadReckoning)}
"""The methods by name, in the evaluation's order."""


def method_named(name: str) -> Method:
    """A new strategy object for ``name`` (one of :data:`METHODS`)."""
    if name not in METHODS:
        raise InputError(expected(f"one of {', '.join(METHODS)}", name, where="method"))
    return METHODS[name]()


# ------------------------------------------------------------------ entering landmarks
def along_wall_jacobian(camera: StereoCamera, X, plane, edge: str, u_left) -> np.ndarray:
    """``G = ∂s/∂X`` (n, 3): how the point where the left camera's ray through column ``u_left`` (n,) meets the
    wall moves along it (``s`` from ``edge``) with the pose, by central differences (:func:`ray_on_wall`)."""
    G = np.empty((len(np.atleast_1d(u_left)), 3))
    for i, h in enumerate((1e-4, 1e-4, 1e-5)):
        e = np.zeros(3)
        e[i] = h
        G[:, i] = (ray_on_wall(camera, np.asarray(X, dtype=float) + e, plane, edge, u_left)
                   - ray_on_wall(camera, np.asarray(X, dtype=float) - e, plane, edge, u_left)) / (2 * h)
    return G


def ray_on_wall(camera: StereoCamera, X, plane, edge: str, u_left) -> np.ndarray:
    """``s`` (n,) [m from ``edge``] where the left camera's ray through column ``u_left`` (n,), from the pose
    ``X``, meets the wall's line."""
    t = plane.direction if edge == "p1" else -plane.direction
    u = np.atleast_1d(np.asarray(u_left, dtype=float))
    c = camera.from_camera(X, np.zeros_like(u), np.zeros_like(u))
    d = camera.from_camera(X, (u - camera.cu) / camera.f, np.ones_like(u)) - c
    n = plane.normal
    lam = ((np.asarray(plane.P1) - c) @ n) / (d @ n)  # c + λ d on the wall's line
    return (c + lam[:, None] * d - plane.point_at(0.0, edge)) @ t


def enter_wall_landmarks(ekf: JointEKF, world_map: Map, candidates, frame: int,
                         polarity: dict[int, int] | None = None, boundary_sigma: str = "model",
                         tied_camera: StereoCamera | None = None, widen: bool = False) -> Entered:
    """Enter candidates as wall landmarks, jointly per boundary: ``Σ = J Σ_shared Jᵀ + diag(σ_own²)`` from each
    candidate's error model (the fitted line and the boundary shared; see :class:`~stablemarks.landmarks.Candidate`),
    or ``σ_b² 11ᵀ + diag(σ_f²)`` for candidates without one (DESIGN §4).

    With ``tied_camera`` (the frame's panned camera) the group is entered as a SLAM filter enters what it measures
    from an uncertain pose: each landmark where its line's ray from the pose meets the mapped wall
    (:func:`ray_on_wall`), its error the pose's carried along the rays, ``G δX`` (:func:`along_wall_jacobian`), and
    the column's, ``σ_img ∂s/∂u``: the filter holds ``diag(σ²) + G P_XX Gᵀ`` with cross-covariance ``P_XX Gᵀ``.
    Seen again from about the same place such landmarks then tell the pose little until a
    landmark entered otherwise is seen with them; entered independent of the pose, two landmarks modelled from a
    wrong boundary would pull the pose onto it with the confidence of a right one.

    ``polarity`` maps a candidate's pair index to its edge's polarity along the wall
    (:func:`~stablemarks.estimation.wall_polarity`); ``boundary_sigma``: which σ_b
    (``landmarks.filter_boundary_sigma``). Returns what entered, group by group.
    """
    polarity = polarity or {}
    out = Entered()
    groups: dict[tuple[str, str], list] = {}
    for c in candidates:
        groups.setdefault((c.plane_id, c.edge), []).append(c)
    for (plane_id, edge), group in groups.items():
        plane = world_map[plane_id]
        if all(c.shared_jacobian is not None for c in group):
            # the joint error model: the fitted line and the boundary shared, the columns each its own
            J = np.stack([c.shared_jacobian for c in group])
            own = np.array([c.sigma_own for c in group])
            cov = J @ group[0].shared_cov @ J.T + np.diag(own**2)
            cov = 0.5 * (cov + cov.T)
        else:
            sb = group[0].sigma_b
            if boundary_sigma == "measured" and np.isfinite(group[0].sigma_b_measured):
                sb = group[0].sigma_b_measured
            sf = np.array([c.sigma_f for c in group])
            cov = sb**2 * np.ones((len(group), len(group))) + np.diag(sf**2)
        values = [float(c.s) for c in group]
        if tied_camera is not None and widen:
            # the boundary was told from the lines beside it by the pose alone: it may be any of them, so the
            # group's place along the wall is as uncertain as the pose is along it (G P_XX Gᵀ), but its error does
            # not follow the pose's (no cross-covariance): where it was right, it carries no pose error
            u = np.array([c.u_left for c in group], dtype=float)
            G = along_wall_jacobian(tied_camera, ekf.pose, plane, edge, u)
            cov = cov + G @ ekf.cov_pose @ G.T
            new = [NewLandmark.wall(plane, c.s, edge, c.z_low, c.z_high, polarity.get(c.pair, 0)) for c in group]
            added = ekf.add_landmarks(new, 0.5 * (cov + cov.T), frame=frame)
        elif tied_camera is not None:
            # measured from the pose, as SLAM does: where the line's ray meets the mapped wall, with the pose's
            # error G δX and the column's (σ_img along the ray) — not from the boundary, which the pose alone chose
            X = ekf.pose
            u = np.array([c.u_left for c in group], dtype=float)
            values = ray_on_wall(tied_camera, X, plane, edge, u).tolist()
            G = along_wall_jacobian(tied_camera, X, plane, edge, u)
            du = (ray_on_wall(tied_camera, X, plane, edge, u + 0.5) - ray_on_wall(tied_camera, X, plane, edge, u - 0.5))
            cov = np.diag((du * float(tied_camera.sigma_img)) ** 2)
            new = [NewLandmark.wall(plane, v, edge, c.z_low, c.z_high, polarity.get(c.pair, 0))
                   for v, c in zip(values, group, strict=True)]
            P_XX = ekf.cov_pose
            added = ekf.add_landmarks(new, cov + G @ P_XX @ G.T, cov_pose_new=P_XX @ G.T, frame=frame)
            out.couplings.append((added, G, X))
        else:
            new = [NewLandmark.wall(plane, c.s, edge, c.z_low, c.z_high, polarity.get(c.pair, 0)) for c in group]
            added = ekf.add_landmarks(new, cov, frame=frame)
        out.priors.append((added, values, cov))
        out.ids += added
        out.candidates += group
    return out


def enter_point_landmarks(ekf: JointEKF, camera: StereoCamera, pairs, idx, frame: int) -> list[int]:
    """Classic stereo EKF-SLAM initialisation of 2-D point landmarks: ``p = g(X, z)`` with
    ``Σ_pp = G_X P_XX G_Xᵀ + G_z R G_zᵀ`` (points triangulated from one pose share its error) and
    ``Σ_Xp = P_XX G_Xᵀ``."""
    X = ekf.pose
    new, cov_z, J_X = [], [], []
    for k in idx:
        p, cov = camera.triangulate(pairs.u_left[k], pairs.u_right[k], X)
        if not np.all(np.isfinite(p)):
            continue
        Xc, Zc = camera.to_camera(X, p)
        new.append(NewLandmark.point(p))
        cov_z.append(cov)
        J_X.append(camera.triangulation_jacobian_pose(X, Xc, Zc))
    if not new:
        return []
    G = np.concatenate(J_X, axis=0)  # (2n, 3)
    C = G @ ekf.cov_pose @ G.T
    for i, cz in enumerate(cov_z):
        C[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] += cz
    return ekf.add_landmarks(new, C, cov_pose_new=ekf.cov_pose @ G.T, frame=frame)


def _on_fitted_wall(camera: StereoCamera, fit, X, pairs, j: int, k: float) -> bool:
    """Whether segment pair ``j``'s line, triangulated from the mean pose ``X``, lies on the wall ``fit`` within
    ``k`` σ: Eq 12's innovation against its variance from the line's columns (``camera.sigma_img``) and the fitted
    line's covariance (:meth:`~stablemarks.planes.PlaneFit.innovation`, as the entry's off-wall test)."""
    P, cov = camera.triangulate(pairs.u_left[j : j + 1], pairs.u_right[j : j + 1], X)
    if not np.all(np.isfinite(P)):
        return False
    G, var_G, _ = fit.innovation(P, cov)
    return bool(abs(float(G[0])) <= k * np.sqrt(float(var_G[0])))
