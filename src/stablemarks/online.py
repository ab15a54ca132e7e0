"""The on-line loop (paper Sec 5, DESIGN.md §1 and §5): for every frame, predict with odometry, run the
front end, associate segment pairs with the landmarks in view and update, then model and select new
landmarks on the planes now in view. The stereo head looks at the midpoint of the visible free edges.

The same loop runs on a simulated scenario (:class:`SimulatedSource`, rendered on the fly with the pan
the loop commands) and on a recorded sequence folder (:class:`SequenceSource`, with the pans it
recorded). Methods, for the evaluation's side-by-side comparison:

``stablemarks``          the full method: plane-constrained landmarks that pass the selection rules;
``plane_no_selection``   plane-constrained landmarks, every candidate (no selection rules);
``all_segments``         every kept segment pair as a 2-D point landmark (classic stereo EKF-SLAM);
``dead_reckoning``       odometry only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .config import Config
from .errors import InputError, expected
from .estimation import JointEKF, NewLandmark
from .geometry import SE2, StereoCamera
from .maps import Map
from .pipeline import FrameLandmarks, run_front_end, select_landmarks

METHODS = ("stablemarks", "plane_no_selection", "all_segments", "dead_reckoning")


# ---------------------------------------------------------------- sources
class SimulatedSource:
    """A scenario's run, rendered frame by frame with the pan the loop commands (truth available).

    The robot believes it starts at the true start, or — with ``initial_error_cov`` (3, 3) — at the true
    start plus an error drawn from that covariance (seeded by the run's seed), as a consistency test needs.
    """

    def __init__(self, run, renderer=None, stamp_step: float = 0.5, initial_error_cov=None):
        from .sim.render import renderer_for

        self.run = run
        self.scenario = run.scenario
        self.name = run.scenario.name
        self.camera: StereoCamera = run.scenario.camera
        self.world_map: Map = run.scenario.map
        self.start_pose = run.poses[0].as_array()
        if initial_error_cov is not None:
            rng = np.random.default_rng(np.random.SeedSequence(run.seed, spawn_key=(2,)))
            L = np.linalg.cholesky(np.asarray(initial_error_cov, dtype=float) + 1e-15 * np.eye(3))
            self.start_pose = SE2.from_array(self.start_pose + L @ rng.normal(size=3)).as_array()
        self.renderer = renderer or renderer_for(run.scenario)
        self.stamp_step = stamp_step
        self.recorded_pan = False

    def __len__(self) -> int:
        return len(self.run)

    def stamp(self, k: int) -> float:
        return k * self.stamp_step

    def odometry(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        U = self.run.odometry[k]
        return U.as_array(), self.scenario.robot.odometry.covariance(U)

    def pan(self, k: int, X_belief: np.ndarray, previous: float | None) -> float:
        from .motion import look_at_free_edges

        plan = self.scenario.robot.pan
        if plan.policy == "fixed":
            return float(np.clip(plan.angle, *self.scenario.pan_limits))
        return look_at_free_edges(self.world_map, self.camera, X_belief, limits=self.scenario.pan_limits,
                                  default=plan.angle if previous is None else previous)

    def images(self, k: int, pan: float):
        frame = self.renderer.render(self.run.poses[k].as_array(), pan, self.run.frame_rng(k))
        return frame.left, frame.right, frame.truth

    def true_pose(self, k: int) -> np.ndarray | None:
        return self.run.poses[k].as_array()


class SequenceSource:
    """A recorded sequence folder (see :mod:`stablemarks.io.sequence`); pans as recorded.

    ``noise``: the odometry noise model (default: the sequence's, else 5 % of distance and 2° per metre);
    ``start_pose``: overrides the sequence's initial pose (default: its ``initial_pose``, else the origin).
    """

    def __init__(self, sequence, noise=None, start_pose=None):
        from .motion import OdometryNoise

        self.sequence = sequence
        self.name = sequence.name
        self.camera = sequence.camera
        self.world_map = sequence.world_map
        self.noise = noise or getattr(sequence, "odometry_noise", None) or OdometryNoise()
        if start_pose is None:
            start_pose = sequence.initial_pose.as_array() if sequence.initial_pose is not None else np.zeros(3)
        self.start_pose = np.asarray(start_pose, dtype=float)
        self.recorded_pan = True

    def __len__(self) -> int:
        return len(self.sequence)

    def stamp(self, k: int) -> float:
        return float(self.sequence.stamps[k])

    def odometry(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        U = self.sequence.odometry_increment(k)
        return U.as_array(), self.noise.covariance(U)

    def pan(self, k: int, X_belief, previous) -> float:
        return float(self.sequence.pans[k])

    def images(self, k: int, pan: float):
        left, right = self.sequence.frame(k)
        return left, right, None

    def true_pose(self, k: int) -> np.ndarray | None:
        gt = self.sequence.groundtruth
        return None if gt is None else np.asarray(gt[k], dtype=float)


# ---------------------------------------------------------------- results
@dataclass
class FrameRecord:
    """What happened in one frame (one line of ``log.jsonl``)."""

    index: int
    stamp: float
    pan: float
    pose: np.ndarray
    cov_pose: np.ndarray
    dead_reckoning: np.ndarray
    true_pose: np.ndarray | None
    observed: list[int]
    nis: list[float]
    associated: list[int]
    new: list[int]
    n_landmarks: int
    n_pairs: int
    n_candidates: int
    n_selected: int
    warnings: list[str]
    timings: dict[str, float]
    visible_truth: list[str] = field(default_factory=list)
    odometry: np.ndarray | None = None
    """The odometry increment ``U`` (3,) that led to this frame (None for the first), in the robot frame."""
    cov_odometry: np.ndarray | None = None
    """Its covariance (3, 3)."""
    measurements: list[tuple[int, float, float]] = field(default_factory=list)
    """The update's observations: ``(landmark id, u_l, u_r)`` [px], each with noise ``ekf.sigma_img``."""
    landmark_priors: list[tuple[list[int], list[float], np.ndarray]] = field(default_factory=list)
    """Landmarks entered in this frame, in groups: ``(ids, initial state values, joint covariance)``; the
    cross-covariance with the pose is zero for wall landmarks (DESIGN §4)."""

    def to_dict(self) -> dict:
        return {
            "index": self.index, "stamp": self.stamp, "pan": self.pan, "pose": self.pose.tolist(),
            "cov_pose": self.cov_pose.tolist(), "dead_reckoning": self.dead_reckoning.tolist(),
            "true_pose": None if self.true_pose is None else self.true_pose.tolist(),
            "observed": self.observed, "nis": self.nis, "associated": self.associated, "new": self.new,
            "n_landmarks": self.n_landmarks, "n_pairs": self.n_pairs, "n_candidates": self.n_candidates,
            "n_selected": self.n_selected, "warnings": self.warnings, "timings": self.timings,
            "visible_truth": self.visible_truth,
            "odometry": None if self.odometry is None else self.odometry.tolist(),
            "cov_odometry": None if self.cov_odometry is None else self.cov_odometry.tolist(),
            "measurements": [list(m) for m in self.measurements],
            "landmark_priors": [{"ids": ids, "values": vals, "cov": cov.tolist()}
                                for ids, vals, cov in self.landmark_priors],
        }


@dataclass
class OnlineResult:
    """A whole run: per-frame records, the final filter, the first view's landmark model, and for
    simulated sources which true feature each landmark was modelled from (``truth_of``)."""

    name: str
    method: str
    records: list[FrameRecord]
    ekf: JointEKF
    world_map: Map
    first_view: FrameLandmarks | None
    truth_of: dict[int, str]
    rejected_truth: dict[str, str]
    cov0: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))

    @property
    def stamps(self) -> np.ndarray:
        return np.array([r.stamp for r in self.records])

    @property
    def poses(self) -> np.ndarray:
        return np.array([r.pose for r in self.records])

    @property
    def covs(self) -> np.ndarray:
        return np.array([r.cov_pose for r in self.records])

    @property
    def dead_reckoning(self) -> np.ndarray:
        return np.array([r.dead_reckoning for r in self.records])

    @property
    def true_poses(self) -> np.ndarray | None:
        if any(r.true_pose is None for r in self.records):
            return None
        return np.array([r.true_pose for r in self.records])


# ------------------------------------------------------------------ loop
def _match_truth(truth, c, tol_px: float = 2.0) -> str | None:
    """Id of the true image edge that candidate ``c`` was measured from: on the same wall, within ``tol_px``
    of the candidate's columns in both images (nearest first), and within max(3σ, 5 cm) of its position."""
    best, best_d = None, 2.0 * tol_px
    for e in truth.edges:
        if e.wall != c.plane_id or not (e.visible_l and e.visible_r):
            continue
        du = abs(e.u_l - c.u_left) + abs(e.u_r - c.u_right)
        if du <= best_d and max(abs(e.u_l - c.u_left), abs(e.u_r - c.u_right)) <= tol_px:
            best, best_d = e, du
    if best is None or np.hypot(best.x - c.P[0], best.y - c.P[1]) > max(3.0 * c.sigma_s, 0.05):
        return None
    return best.id


def _new_wall_landmarks(ekf: JointEKF, world_map: Map, candidates, frame: int, priors: list | None = None,
                        polarity: dict[int, int] | None = None, boundary_sigma: str = "model") -> list[int]:
    """Enter candidates as wall landmarks, jointly per boundary: ``Σ = σ_b² 11ᵀ + diag(σ_f²)`` (DESIGN §4).
    Each group ``(ids, values, Σ)`` is appended to ``priors`` when given; ``polarity`` maps a candidate's pair
    index to its edge's polarity along the wall (:func:`wall_polarity`). ``boundary_sigma``: which σ_b
    (``landmarks.filter_boundary_sigma``)."""
    polarity = polarity or {}
    ids = []
    groups: dict[tuple[str, str], list] = {}
    for c in candidates:
        groups.setdefault((c.plane_id, c.edge), []).append(c)
    for (plane_id, edge), group in groups.items():
        plane = world_map[plane_id]
        sb = group[0].sigma_b
        if boundary_sigma == "measured" and np.isfinite(group[0].sigma_b_measured):
            sb = group[0].sigma_b_measured
        sf = np.array([c.sigma_f for c in group])
        cov = sb**2 * np.ones((len(group), len(group))) + np.diag(sf**2)
        new = [NewLandmark.wall(plane, c.s, edge, c.z_low, c.z_high, polarity.get(c.pair, 0)) for c in group]
        added = ekf.add_landmarks(new, cov, frame=frame)
        if priors is not None:
            priors.append((added, [float(c.s) for c in group], cov))
        ids += added
    return ids


def _new_point_landmarks(ekf: JointEKF, camera: StereoCamera, pairs, idx, frame: int) -> list[int]:
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


def run_online(
    source,
    *,
    cov0=None,
    config: Config = Config(),
    method: str = "stablemarks",
    prior_landmarks=None,
    progress: Callable[[int, int], None] | None = None,
) -> OnlineResult:
    """Run the loop over every frame of ``source``; see the module docstring for ``method``.

    ``cov0`` (3, 3): covariance of the start pose (default σ = 5 cm, 5 cm, 1°). ``prior_landmarks``: a
    landmark map saved by a previous run (``landmarks.yaml``). ``progress(k, n)`` is called after each frame.
    """
    if method not in METHODS:
        raise InputError(expected(f"one of {', '.join(METHODS)}", method, where="method"))
    cov0 = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2 if cov0 is None else np.asarray(cov0, dtype=float)
    camera = source.camera
    world_map = source.world_map
    ekf = JointEKF(camera, source.start_pose, cov0, config.ekf)
    if prior_landmarks is not None:
        ekf.load_prior_landmarks(prior_landmarks, world_map)
    dr = SE2.from_array(source.start_pose)
    records: list[FrameRecord] = []
    truth_of: dict[int, str] = {}
    rejected_truth: dict[str, str] = {}
    first_view = None
    pan = None
    n = len(source)
    for k in range(n):
        t0 = time.perf_counter()
        U = cov_U = None
        if k > 0:
            U, cov_U = source.odometry(k)
            ekf.predict(U, cov_U)
            dr = dr @ SE2.from_array(U)
        pan = source.pan(k, ekf.pose, pan)
        left, right, truth = source.images(k, pan)
        t1 = time.perf_counter()
        timings = {"predict": t1 - t0}
        observed, nis, associated, new_ids, warnings = [], [], [], [], []
        measurements, priors = [], []
        n_pairs = n_cand = n_sel = 0
        if method != "dead_reckoning":
            front = run_front_end(left, right, config)
            timings.update(front.timings)
            pairs = front.kept_pairs
            n_pairs = len(pairs)
            pol = front.left_segments.polarity[pairs.left_index]
            t2 = time.perf_counter()
            used_pairs: set[int] = set()
            cam_k = camera.with_pan(pan)
            sel = None
            if method != "all_segments":
                # the frame's own model first: positions along the walls, independent of the pose error
                sel = select_landmarks(front, cam_k, world_map, ekf.pose, ekf.cov_pose, config)
                if first_view is None:
                    first_view = sel
                warnings = sel.warnings
                n_cand = len(sel.candidates)
                n_sel = len(sel.selected)
            if ekf.n_landmarks and n_pairs:
                measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
                centre = cam_k.optical_centres(ekf.pose)[0]
                assoc = associate_frame(ekf, pairs, measured, pan, sel, pol, centre)
                associated = [int(i) for i, _ in assoc]
                used_pairs = {int(j) for _, j in assoc}
                chosen = ekf.select_for_update(assoc, pan)
                if chosen:
                    res = ekf.update([(i, measured[j]) for i, j in chosen], pan, frame=k)
                    measurements = [(int(i), float(measured[j][0]), float(measured[j][1])) for i, j in chosen]
                    observed = [int(i) for i in res.ids]
                    nis = [float(v) for v in res.nis]
            t3 = time.perf_counter()
            timings.update(associate_update=t3 - t2)
            if method == "all_segments":
                idx = [j for j in range(n_pairs) if j not in used_pairs]
                new_ids = _new_point_landmarks(ekf, cam_k, pairs, idx, k)
            else:
                take = sel.candidates if method == "plane_no_selection" else sel.selected
                fresh = [c for c in take if c.pair not in used_pairs and not _duplicate(ekf, c)]
                centre = cam_k.optical_centres(ekf.pose)[0]
                new_ids = _new_wall_landmarks(ekf, world_map, fresh, k, priors, {
                    c.pair: wall_polarity(int(pol[c.pair]), world_map[c.plane_id], centre) for c in fresh},
                    config.landmarks.filter_boundary_sigma)
                if truth is not None:
                    for c in sel.candidates:
                        tid = _match_truth(truth, c)
                        if tid is not None and not c.selected:
                            rejected_truth.setdefault(tid, c.reason)
                    for c, i in zip(fresh, new_ids, strict=True):
                        tid = _match_truth(truth, c)
                        if tid is not None:
                            truth_of[i] = tid
            if method == "all_segments" and truth is not None:
                for i in new_ids:
                    lm = ekf.landmark(i)
                    best, best_d = None, 0.1
                    for e in truth.edges:
                        if e.visible_l and e.visible_r:
                            d = float(np.hypot(e.x - lm.position[0], e.y - lm.position[1]))
                            if d < best_d:
                                best, best_d = e.id, d
                    if best is not None:
                        truth_of[i] = best
            timings.update(select=time.perf_counter() - t3)
        timings["total"] = time.perf_counter() - t0
        visible_truth = [] if truth is None else [e.id for e in truth.edges if e.visible_l and e.visible_r]
        records.append(FrameRecord(
            k, source.stamp(k), float(pan), ekf.pose, ekf.cov_pose, dr.as_array(), source.true_pose(k),
            observed, nis, associated, new_ids, ekf.n_landmarks, n_pairs, n_cand, n_sel, warnings, timings,
            visible_truth, None if U is None else np.asarray(U, dtype=float),
            None if cov_U is None else np.asarray(cov_U, dtype=float), measurements, priors,
        ))
        if progress is not None:
            progress(k + 1, n)
    return OnlineResult(source.name, method, records, ekf, world_map, first_view, truth_of, rejected_truth, cov0)


def associate_frame(ekf: JointEKF, pairs, measured: np.ndarray, pan: float, model=None,
                    polarity: np.ndarray | None = None, centre=None) -> list[tuple[int, int]]:
    """Pairs (landmark id, segment-pair index) for this frame's update.

    Wall landmarks are found by the *pattern* of this frame's candidates along each wall (their positions
    relative to the wall's edge do not depend on the pose error, and the offsets between features on one
    wall are known to a few mm): :func:`match_along_wall`, kept if jointly compatible. Point landmarks, and
    wall landmarks the pattern leaves unmatched, go through the image-space association with joint
    compatibility and the vertical-extent cost; each such pair is added only if the whole set stays
    jointly compatible. ``polarity`` (M,): the sign of each pair's brightness step in the left image, seen from
    the camera centre ``centre`` (2,); a wall landmark never matches an edge whose step along its wall is the
    opposite (a bar's two edges, equally long and a bar's width apart, differ only in it).
    """
    if polarity is None or centre is None:
        polarity, centre = np.zeros(len(measured), dtype=int), np.zeros(2)
    polarity = np.asarray(polarity, dtype=int)
    in_view = set(ekf.visible(pan))
    walls: list[list[tuple[int, int]]] = []
    if model is not None:
        for plane_model in model.planes:
            plane = plane_model.fit.plane
            matched = [(i, c) for i, c in match_along_wall(ekf, plane, plane_model.candidates,
                                                           polarity=wall_polarity(polarity, plane, centre))
                       if i in in_view]
            if matched:
                walls.append(matched)
    # Wall by wall, most features first: one wall's wrong pattern must not throw out the others' right ones.
    chosen: list[tuple[int, int]] = []
    for matched in sorted(walls, key=len, reverse=True):
        if ekf.joint_compatible(chosen + matched, measured, pan):
            chosen += matched
    taken_l = {i for i, _ in chosen}
    taken_p = {j for _, j in chosen}
    rest = [i for i in ekf.landmark_ids if i not in taken_l]
    free = [j for j in range(len(measured)) if j not in taken_p]
    if rest and free:
        cost = _height_cost(ekf, pairs, pan) + _polarity_cost(ekf, polarity, centre)
        rows = [ekf.landmark_ids.index(i) for i in rest]
        sub = ekf.associate_joint(measured[free], pan, candidates=rest, extra_cost=cost[np.ix_(rows, free)])
        for i, j in sub:
            trial = chosen + [(i, free[j])]
            if ekf.joint_compatible(trial, measured, pan):
                chosen = trial
    return sorted(chosen, key=lambda q: q[1])


def match_along_wall(ekf: JointEKF, plane, candidates, tol: float = 3.0,
                     polarity: np.ndarray | None = None) -> list[tuple[int, int]]:
    """Match this frame's candidates on ``plane`` with the wall landmarks on it, by their pattern.

    Candidates and landmarks are placed along the wall (from ``p1``). The two sets differ by one common
    offset — the difference of the boundary errors, ``σ_δ² = σ_b,now² + var_landmark`` — and by each
    feature's own small error. Every candidate-landmark pair proposes an offset within ``3σ_δ``; the offset
    that matches the most features (ties: least squared residual) wins, and features are then paired
    one-to-one within ``tol`` σ of their own errors. Features whose vertical extents disagree never match;
    among offsets that match equally many, the likeliest one (its own prior and the residuals) wins.
    Returns ``(landmark id, segment-pair index)``.
    """
    from scipy.optimize import linear_sum_assignment

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
    best = None
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
            if best is None or score > best[0]:
                best = (score, delta, resid, ok)
    if best is None:
        return []
    _, delta, resid, ok = best
    big = 1e6
    rows, cols = linear_sum_assignment(np.where(ok, resid**2, big))
    return [(int(lms[j].id), int(candidates[i].pair)) for i, j in zip(rows, cols, strict=True) if ok[i, j]]


def _height_cost(ekf: JointEKF, pairs, pan: float, weight: float = 9.0) -> np.ndarray:
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


def _polarity_cost(ekf: JointEKF, polarity: np.ndarray, centre, cost: float = np.inf) -> np.ndarray:
    """(n_landmarks, n_pairs): ``cost`` (default: forbidden) where a wall landmark's polarity along its wall
    and a pair's, seen from ``centre``, are known and differ; else 0."""
    out = np.zeros((ekf.n_landmarks, len(polarity)))
    for r, i in enumerate(ekf.landmark_ids):
        lm = ekf.landmark(i)
        if lm.kind == "wall" and lm.polarity:
            pair_pol = wall_polarity(polarity, ekf.landmark_plane(i), centre)
            out[r] = np.where(lm.polarity * pair_pol < 0, cost, 0.0)
    return out


def _duplicate(ekf: JointEKF, c) -> bool:
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
