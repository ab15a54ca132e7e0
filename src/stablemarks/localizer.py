"""The step-by-step localizer: one stereo frame in, the pose estimate out (paper Secs 2–5).

::

    import stablemarks as sm
    seq = sm.open_sequence("results/lab-seq")
    loc = sm.Localizer(seq.world_map, seq.camera, start_pose=seq.initial_pose, config=sm.Config())
    for frame in seq:
        est = loc.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        print(est.pose, est.cov, est.pan_command, est.health)
    loc.save_landmarks("landmarks.yaml")

Each :meth:`Localizer.step` predicts with the odometry since the last frame (Eq 19), runs the stereo
front end (Secs 2.1–2.2), models the frame's features on the reference planes in view (Secs 2.3–4),
associates and updates the joint EKF with the re-observed landmarks (Sec 5, Eq 20) and enters the new
stable ones. What it does is decided by the method, a strategy object (:mod:`stablemarks.methods`).

Frames and units: poses ``(x [m], y [m], theta [rad])`` in the map frame; odometry poses in the odometry
frame (only their differences are used); pans [rad] relative to the robot's heading; stamps [s].
"""

from __future__ import annotations

import collections
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.linalg
from scipy.special import chdtri
from scipy.stats import binom

from .config import Config
from .errors import GeometryError, InputError, expected
from .estimation import JointEKF, LandmarkEstimate, motion
from .estimation.association import lone_gate_px, merged_with_edges
from .estimation.consistency import inflate_inconsistent
from .estimation.relocalize import lines_score, pose_from_lines, resection_cov
from .geometry import SE2, StereoCamera, wrap_angle
from .health import HealthMonitor
from .landmarks import SLOPE_GATE_CHI2, common_turn, fit_disagreements, seen_wall_jacobian
from .maps import Map
from .methods import Entered, Method, method_named
from .pipeline import FrameLandmarks, FrontEnd, Regions, check_pair, disparity_limits, plane_regions, run_front_end
from .viewing import choose_pan

DEFAULT_START_COV = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
"""Covariance of the start pose when none is given: σ = 5 cm, 5 cm, 1° over ``(x, y, theta)``."""
POSE_GATE_CHI2 = float(chdtri(3, 0.001))
"""99.9 % bound of a pose difference's Mahalanobis² (3 dof): a pose the frame's lines give beyond it is elsewhere."""
FOUND_PRIOR = (8.5, 1.5)
"""Pseudo-counts (found, missed) of the rate at which a landmark predicted in view is found, before the run has
found any (Beta prior, weight of ten landmarks): 85 %, as measured on clean runs of loop, office and hall."""
REASON_BOUNDARY_RECHECK = "its boundary does not fit the map's free edge at the updated pose"
"""Why a candidate selected from the prior's model is not entered after all (:meth:`Localizer._recheck_boundaries`):
a reason of the on-line loop only, beside those of one frame's selection (``landmarks.REASON_*``)."""


def _rounded(v, digits: int):
    """A finite number rounded for the log (None for NaN or an infinity: strict JSON)."""
    v = float(v)
    return round(v, digits) if math.isfinite(v) else None


def model_log(model: FrameLandmarks | None, rechecked: dict | None = None) -> tuple[list[dict], list[dict]]:
    """The frame's candidates and boundaries as :attr:`FrameRecord.candidates` and :attr:`FrameRecord.boundaries`.

    Candidates: one object per modelled feature, ``plane`` (its id, as ``landmarks.csv`` names it), ``index``
    (from the free edge, Table 1's), ``pair`` (the segment pair's index in the frame's kept pairs), ``u_left``,
    ``u_right`` [px], ``s`` along the wall from the free edge ``edge`` [m], ``selected`` and ``reason`` (None
    when selected). Boundaries: every free edge found in the images, used or not: ``plane``, ``edge``,
    ``u_left``, ``u_right`` [px], ``offset`` its distance along the wall from the map's free edge, positive into
    the wall [m], ``sigma`` its σ along the wall [m], ``snapped``, ``used`` and ``reason`` (a sentence; None when
    used). ``rechecked``: ``{(plane id, edge): NIS}`` of boundaries that did not fit the map at the updated pose.
    Rounded to 0.01 px and 0.1 mm: a line of a frame with fifty candidates stays a few kilobytes."""
    if model is None:
        return [], []
    rechecked = rechecked or {}
    cands = [{"plane": c.plane_id, "index": int(c.index), "pair": int(c.pair), "u_left": _rounded(c.u_left, 2),
              "u_right": _rounded(c.u_right, 2), "edge": c.edge, "s": _rounded(c.s, 4), "selected": bool(c.selected),
              "reason": None if c.selected else (c.reason or None)} for c in model.candidates]
    bounds = []

    def entry(pm, b, used, reason):
        plane = pm.fit.plane
        offset = float((np.asarray(b.P) - plane.edge(b.edge)) @ np.asarray(b.inward))
        bounds.append({"plane": b.plane_id, "edge": b.edge, "u_left": _rounded(b.u[0], 2),
                       "u_right": _rounded(b.u[1], 2), "offset": _rounded(offset, 4),
                       "sigma": _rounded(b.sigma_along, 4), "snapped": bool(b.snapped), "used": used,
                       "reason": reason})

    for pm in model.planes:
        for b in pm.boundaries:
            nis = rechecked.get((b.plane_id, b.edge))
            if nis is None:
                entry(pm, b, True, None)
            else:
                entry(pm, b, False, f"plane {pm.fit.plane.label!r}: the boundary found at {b.edge} does not fit the "
                                    f"map's free edge at the updated pose (NIS {nis:.0f}): nothing is entered from it")
        for b, why in pm.rejected_boundaries:
            if b is not None:
                entry(pm, b, False, why)
    return cands, bounds


@dataclass(kw_only=True)
class FrameRecord:
    """What happened in one frame (one line of ``log.jsonl``).

    Poses are ``(x [m], y [m], theta [rad])`` in the map frame, covariances over them; ids are landmark ids.
    """

    index: int
    """Frame number from 0."""
    stamp: float
    """Time [s]."""
    pan: float
    """The pan the frame was taken with [rad]."""
    pan_command: float
    """The pan the method asks for next [rad]."""
    pose: np.ndarray
    """(3,) the estimate after the frame."""
    cov_pose: np.ndarray
    """(3, 3) its covariance."""
    dead_reckoning: np.ndarray
    """(3,) odometry alone from the start pose."""
    true_pose: np.ndarray | None = None
    """(3,) the true pose when the source knows it."""
    observed: list[int] = field(default_factory=list)
    """Landmarks that updated the filter."""
    nis: list[float] = field(default_factory=list)
    """Their normalised innovations squared (2 dof each)."""
    associated: list[int] = field(default_factory=list)
    """Landmarks associated with a segment pair (a superset of ``observed``)."""
    new: list[int] = field(default_factory=list)
    """Landmarks entered in this frame."""
    inflation: float = 1.0
    """Factor the pose covariance was widened by before the update (1: not widened; see
    :mod:`stablemarks.health`, ``odometry_disagrees``)."""
    dropped: list[int] = field(default_factory=list)
    """Landmarks dropped from the filter in this frame (re-check failed, or missed too often), before the
    update: they are marginalised out."""
    n_landmarks: int = 0
    n_pairs: int = 0
    """Segment pairs kept by the disparity filter."""
    n_candidates: int = 0
    n_selected: int = 0
    warnings: list[str] = field(default_factory=list)
    """Plain sentences about this frame (a plane not found, no free edge in view)."""
    health: list[str] = field(default_factory=list)
    """Warnings about the filter's state (empty when all is well)."""
    timings: dict[str, float] = field(default_factory=dict)
    """Wall time of each stage [s]."""
    odometry: np.ndarray | None = None
    """The odometry increment ``U`` (3,) that led to this frame (None for the first), in the robot frame."""
    cov_odometry: np.ndarray | None = None
    """Its covariance (3, 3)."""
    measurements: list[tuple[int, float, float]] = field(default_factory=list)
    """The update's observations: ``(landmark id, u_l, u_r)`` [px], each with noise ``noise.sigma_img``."""
    landmark_priors: list[tuple[list[int], list[float], np.ndarray]] = field(default_factory=list)
    """Landmarks entered in this frame, in groups: ``(ids, initial state values, joint covariance)``; the
    cross-covariance with the pose is zero for wall landmarks (DESIGN §4) unless the group is tied to the pose
    (:attr:`landmark_couplings`)."""
    landmark_couplings: list[tuple[list[int], list[list[float]], list[float]]] = field(default_factory=list)
    """Groups of :attr:`landmark_priors` entered tied to the pose (``ekf.tie_blind_entries``): ``(ids, G (n, 3),
    X)``, their errors ``G (X_true − X)`` plus the prior's; the filter held ``cov + G P_XX Gᵀ`` with cross-covariance
    ``P_XX Gᵀ`` to the pose ``X`` they were entered from."""
    edge_measurements: list[tuple[str, str, float, float, list[list[float]]]] = field(default_factory=list)
    """Free edges found in this frame that updated the pose (``ekf.edge_updates``): ``(plane id, edge, u_l, u_r,
    covariance of (u_l, u_r) [px²])``; the map's accuracy is added to it."""
    wall_measurements: list[tuple] = field(default_factory=list)
    """Walls fitted in this frame that updated the pose (``ekf.wall_updates``, one joint update after the edges'):
    ``(plane id, innovation ν of (a, b), H = ∂(a, b)/∂X, ∂(a, b)/∂β or None, noise covariance, σ_β², pose of the
    update)``: ``ν ≈ H (X − X_update) + J_β β`` (``β`` the wall's shared disparity error, the filter's auxiliary
    state ``"wall:<id>"``, entered with variance σ_β² when the wall is first used)."""
    inflated: list[tuple] = field(default_factory=list)
    """Landmark directions whose variance was raised before this frame's update (``ekf.inflation_p``,
    :func:`~stablemarks.estimation.consistency.inflate_inconsistent`): ``(ids, t, α [m²], group)``."""
    candidates: list[dict] = field(default_factory=list)
    """Every feature the frame modelled, with its selection decision and, when rejected, the reason
    (:func:`model_log`): so that a rejection, e.g. the edge of an unmapped object in front of a wall ("off the
    wall", "beside something nearer"), can be read in the log as in ``landmarks.csv``."""
    boundaries: list[dict] = field(default_factory=list)
    """Every free edge found in the images, used or not, with why not (:func:`model_log`): a boundary that
    disagrees with the map's free edge is not used to model landmarks."""

    def to_dict(self) -> dict:
        """JSON-ready: arrays as lists."""
        def plain(v):
            return None if v is None else np.asarray(v).tolist()

        return {
            "index": self.index, "stamp": self.stamp, "pan": self.pan, "pan_command": self.pan_command,
            "pose": plain(self.pose), "cov_pose": plain(self.cov_pose), "dead_reckoning": plain(self.dead_reckoning),
            "true_pose": plain(self.true_pose), "observed": self.observed, "nis": self.nis,
            "associated": self.associated, "new": self.new, "dropped": self.dropped, "inflation": self.inflation,
            "n_landmarks": self.n_landmarks,
            "n_pairs": self.n_pairs, "n_candidates": self.n_candidates, "n_selected": self.n_selected,
            "warnings": self.warnings, "health": self.health, "timings": self.timings,
            "odometry": plain(self.odometry), "cov_odometry": plain(self.cov_odometry),
            "measurements": [list(m) for m in self.measurements],
            "landmark_priors": [{"ids": ids, "values": vals, "cov": np.asarray(cov).tolist()}
                                for ids, vals, cov in self.landmark_priors],
            "landmark_couplings": [{"ids": ids, "G": G, "pose": X} for ids, G, X in self.landmark_couplings],
            "wall_measurements": [{"plane": p, "nu": nu, "H": H, "J_bias": J, "R": R, "var_bias": v, "pose": X}
                                  for p, nu, H, J, R, v, X in self.wall_measurements],
            "inflated": [{"ids": list(ids), "t": float(t), "alpha": float(a), "group": bool(g)}
                         for ids, t, a, g in self.inflated],
            "candidates": self.candidates, "boundaries": self.boundaries,
        }


@dataclass(frozen=True, eq=False)
class Estimate:
    """The result of one :meth:`Localizer.step`.

    Attributes
    ----------
    stamp : the frame's time [s].
    pose : (3,) ``(x [m], y [m], theta [rad])`` of the robot in the map after the frame.
    cov : (3, 3) its covariance over ``(x, y, theta)`` [m², m², rad²].
    pan_command : the head pan [rad] the method asks for next (the pan policy's choice from this estimate).
    health : warnings about the filter's state, one sentence per condition that holds, starting with its name
        (``edges_not_found``, ``inconsistent``, ``odometry_disagrees``, ``blind``: :mod:`stablemarks.health`);
        empty when all is well.
    record : everything the frame did (:class:`FrameRecord`), for logs.
    front : the stereo front end's output (None for ``dead_reckoning``).
    model : the frame's landmark model on the reference planes (None where the method has none).
    entered : the landmarks entered in this frame and the candidates they came from.
    """

    stamp: float
    pose: np.ndarray
    cov: np.ndarray
    pan_command: float
    health: list[str]
    record: FrameRecord
    front: FrontEnd | None = None
    model: FrameLandmarks | None = None
    entered: Entered = field(default_factory=Entered)


@dataclass(frozen=True)
class _Turn:
    """The rotation shared by the walls fitted in one frame (:func:`~stablemarks.landmarks.common_turn`)."""

    angle: float = 0.0
    """Its estimate [rad] (0 without walls)."""
    m2: float = 0.0
    """Its Mahalanobis² against none (1 dof), with the pose's uncertainty."""
    walls: int = 0
    spread: float = 0.0
    """Mahalanobis² of the walls' slopes about it (``walls − 1`` dof)."""
    var_own: float = np.inf
    """Its variance from the fits alone [rad²]."""
    var_heading: float = 0.0
    """The prior heading's variance when it was measured [rad²]."""

    @property
    def together(self) -> bool:
        """Two or more walls turned together from the map: the shared turn beyond ``SLOPE_GATE_CHI2`` (χ²₁ 99.9 %)
        while the walls agree on it (their spread inside its χ² 99.9 % bound). A single turned wall, or walls turned
        different ways, may be other surfaces in their bands; a wrong pan turns every wall the same way."""
        return self.walls >= 2 and self.m2 > SLOPE_GATE_CHI2 and \
            self.spread <= float(chdtri(self.walls - 1, 0.001))

    def turned_back(self, ref: _Turn) -> bool:
        """Whether the walls turned back from ``ref`` (a turn seen earlier while the pose followed the odometry)
        beyond the fits' noise and the heading's drift since (Mahalanobis² of the difference beyond
        ``SLOPE_GATE_CHI2``): only then is a turn now inside the heading's (grown) uncertainty evidence that the pan
        is right again."""
        var = max(self.var_heading - ref.var_heading, 0.0) + self.var_own + ref.var_own
        return self.walls > 0 and (self.angle - ref.angle) ** 2 / var > SLOPE_GATE_CHI2


def _walls_turn(model: FrameLandmarks | None, camera: StereoCamera, world_map: Map) -> _Turn:
    """The rotation shared by the walls fitted in this frame, from the prior the frame was modelled with."""
    if model is None or not model.planes:
        return _Turn()
    d, m2, spread, var_own = common_turn(camera, [m.fit for m in model.planes], model.cov_X, world_map.accuracy_cov)
    return _Turn(d, m2, len(model.planes), spread, var_own, float(model.cov_X[2, 2]))


def _edges_missing(model: FrameLandmarks | None, config: Config, width: int) -> bool:
    """Whether most free edges expected in this frame were not found where the map puts them: of the edges
    searched (found, rejected or not found) and those on planes predicted in view but not found at all, fewer
    than half were found and accepted. One edge missed now and then (hidden, too far, a ragged border) is not
    evidence of a wrong pan; most of them are. A plane not found at all counts its free edges whose search
    windows lie where a disparity can be valid (:func:`~stablemarks.pipeline.disparity_limits`): a poster at
    the image's left border, inside the disparity range, cannot be found whatever the pan."""
    if model is None:
        return False
    limits = disparity_limits(config.sad, width)
    sigma = config.landmarks.search_sigma

    def searchable(e) -> bool:
        if not (e.free and np.all(np.isfinite(e.u))):
            return False
        return all(lim[0] < e.window(img, sigma)[0] and e.window(img, sigma)[1] < lim[1]
                   for img, lim in enumerate(limits))

    # Walls turned from the map are a wrong pan only when two or more are and none fits where the map puts it (a
    # wrong pan turns them all); one turned wall, alone or beside a good one, may be another surface caught in
    # its band (a wall behind a screen while the heading is uncertain).
    turned = sum(m.gated == "turned" for m in model.planes)
    pan_like = turned >= 2 and all(m.gated for m in model.planes)
    # an end found to be hidden behind something nearer (unmapped clutter in front of the wall) is where the map
    # puts it as far as the pan is concerned: neither found nor missed
    expected = sum(len(m.searched) - len(m.hidden) for m in model.planes if m.gated != "turned" or pan_like)
    expected += sum(sum(1 for e in pred.edges.values() if searchable(e))
                    for pred, fit in zip(model.predictions, model.fits, strict=True) if not fit)
    found = sum(len(m.boundaries) for m in model.planes)
    return expected > 0 and 2 * found < expected


def landmark_map_document(ekf: JointEKF, method: str = "stablemarks") -> dict:
    """The landmarks of ``ekf`` as a plain document (``landmarks.yaml``, loadable as ``prior_landmarks``):
    ``frame``, ``units``, ``method``, ``landmarks`` (wall landmarks as the distance ``s`` along their wall from
    the free edge ``edge`` with ``var_s``, plus the 2-D ``position`` and rank-1 ``cov2d``) and
    ``cov_landmarks``, their joint covariance in state order."""
    doc = {"frame": "map", "units": "metres; s is the distance along the wall from its free edge `edge`; var_s in m²",
           "method": method, **ekf.to_dict(joint=True)}
    doc.pop("pose", None)
    doc.pop("cov_pose", None)
    return doc


def _wall_terms(measurements) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray, np.ndarray]:
    """The stacked wall measurements (:attr:`FrameRecord.wall_measurements`): ``(nu (2m,), H (2m, 3), keys of the
    walls' auxiliary states, H_aux (2m, len(keys)), R (2m, 2m))``."""
    nu = np.array([v for m in measurements for v in m[1]], dtype=float)
    H = np.array([row for m in measurements for row in m[2]], dtype=float).reshape(-1, 3)
    R = scipy.linalg.block_diag(*[np.asarray(m[4], dtype=float) for m in measurements])
    keys = sorted({f"wall:{m[0]}" for m in measurements if m[3] is not None})
    H_aux = np.zeros((len(nu), len(keys)))
    for r, m in enumerate(measurements):
        if m[3] is not None:
            H_aux[2 * r:2 * r + 2, keys.index(f"wall:{m[0]}")] = m[3]
    return nu, H, keys, H_aux, R


def apply_wall_measurements(ekf: JointEKF, measurements) -> None:
    """Update ``ekf`` with a frame's wall measurements (:attr:`FrameRecord.wall_measurements`), entering each
    wall's shared disparity error as an auxiliary state (variance σ_β², :meth:`JointEKF.add_aux`) when it has
    none: what :meth:`Localizer.step` does with ``ekf.wall_updates``, so that a run's records replay it."""
    if not measurements:
        return
    nu, H, keys, H_aux, R = _wall_terms(measurements)
    var = {f"wall:{m[0]}": float(m[5]) for m in measurements if m[3] is not None}
    aux = [ekf.aux_index(k) if ekf.aux_index(k) is not None else ekf.add_aux(k, var[k]) for k in keys]
    ekf.update_pose_aux(nu, H, aux, H_aux, R)


class Localizer:
    """On-line landmark selection and EKF localization, one frame at a time.

    Parameters
    ----------
    world_map : the map of walls (reference planes).
    camera : the rectified stereo head on its mount, pan 0 (its ``sigma_img`` is replaced by the
        configuration's ``noise.sigma_img``).
    start_pose : (3,) the robot's start ``(x [m], y [m], theta [rad])`` in the map frame; default the origin.
    start_cov : (3, 3) its covariance; default σ = 5 cm, 5 cm, 1° (:data:`DEFAULT_START_COV`).
    config : every setting (:class:`stablemarks.Config`).
    method : ``stablemarks`` (default), ``plane_no_selection``, ``all_segments`` or ``dead_reckoning``
        (:mod:`stablemarks.methods`), or a :class:`~stablemarks.methods.Method` object.
    prior_landmarks : a landmark map saved by an earlier run (the document of ``landmarks.yaml``).
    """

    dense_disparity = False
    """True: the front end computes the whole disparity images (to look at them); by default only what the
    method reads (:func:`~stablemarks.pipeline.plane_regions`), with the same results."""

    def __init__(self, world_map: Map, camera: StereoCamera, *, start_pose=None, start_cov=None,
                 config: Config | None = None, method: str | Method = "stablemarks", prior_landmarks=None):
        self.config = config if config is not None else Config()
        # The widened search asks whether the walls moved as a whole (a slip, a kidnap): a wall fitted far from
        # the map is then the evidence, not a second surface in the band, so it is not gated there.
        self._probe_config = self.config.with_overrides({"landmarks": {"fit_gate_chi2": 1e9}})
        # a line is neither entered nor associated when its wall is seen more obliquely than this
        self._max_incidence = math.radians(self.config.landmarks.max_incidence_deg)
        self.world_map = world_map
        self.camera = self.config.camera(camera)
        self.method = method if isinstance(method, Method) else method_named(method)
        start = np.zeros(3) if start_pose is None else (
            start_pose.as_array() if isinstance(start_pose, SE2) else np.asarray(start_pose, dtype=float))
        if start.shape != (3,) or not np.all(np.isfinite(start)):
            raise InputError(expected("a finite pose (x, y, theta)", start_pose, where="start_pose"))
        self.start_cov = DEFAULT_START_COV.copy() if start_cov is None else np.asarray(start_cov, dtype=float)
        self.ekf = JointEKF(self.camera, start, self.start_cov, self.config.ekf)
        if prior_landmarks is not None:
            self.ekf.load_prior_landmarks(prior_landmarks, world_map)
        self._dead_reckoning = SE2.from_array(start)
        self._dr_cov = self.start_cov.copy()
        """Covariance of the dead reckoning (the start covariance carried through the odometry alone)."""
        self._heading_track: collections.deque = collections.deque(maxlen=self.config.health.drift_frames + 1)
        """Per frame: (estimate's heading − dead reckoning's [rad, unwrapped], the estimate's heading σ [rad], the
        odometry's heading variance summed since the start [rad²]): the ``heading_drift`` test."""
        self._odo_heading_var = 0.0
        self._missed: dict[int, int] = {}
        self._recoveries: collections.deque = collections.deque()
        """Frames of the last ``health.recoveries_frames`` in which the pose was recovered (``odometry_disagrees``)."""
        self._missed_after_recovery = 0
        """Frames in a row, since the last recovery, whose free edges were not found where the map puts them."""
        self._found = list(FOUND_PRIOR)
        """Landmarks found and missed among those predicted in view, over the frames where a pattern of at least
        ``health.min_pattern`` was used, plus :data:`FOUND_PRIOR`: the run's rate of finding landmarks in view."""
        self._lost_frames = 0
        """Frames in a row with no landmark found and the walls fitted away from the pose (:meth:`_relocalize`)."""
        self._unconfirmed: set[int] = set()
        self._observed_once = False  # a frame has updated from landmarks: the pose is no longer the start's alone
        """Landmarks entered in a frame that observed none of the filter's landmarks (the pose then rested on the
        odometry alone), until they are observed again: the frame's lines do not relocalize the pose onto them
        (:meth:`_relocation_from_lines`)."""
        self._turn_ref: _Turn | None = None
        """The last turn of the walls together while ``edges_not_found`` may hold (see :meth:`step`)."""
        self.health = HealthMonitor(self.config.health)
        self.retired: dict[int, LandmarkEstimate] = {}
        """Landmarks dropped from the filter, as they were when dropped (id → estimate)."""
        self._odometry: SE2 | None = None
        self._pan: float | None = None
        self._stamp: float | None = None
        self._dt: float | None = None
        self._index = 0
        self._groups: dict[int, int] = {}
        """Landmark id → the id of the group it was entered with (one boundary's features of one frame), for
        :func:`~stablemarks.estimation.consistency.inflate_inconsistent`."""
        self._n_groups = 0

    # ----------------------------------------------------------------- state
    @property
    def pose(self) -> np.ndarray:
        """(3,) the current estimate ``(x [m], y [m], theta [rad])`` in the map."""
        return self.ekf.pose

    @property
    def cov(self) -> np.ndarray:
        """(3, 3) its covariance."""
        return self.ekf.cov_pose

    @property
    def frames(self) -> int:
        """How many frames have been stepped."""
        return self._index

    def landmarks(self) -> list[LandmarkEstimate]:
        """The landmark map: every landmark of the filter, in state order (positions in the map frame)."""
        return [self.ekf.landmark(i) for i in self.ekf.landmark_ids]

    def landmarks_document(self) -> dict:
        """The landmark map as ``landmarks.yaml`` holds it (:func:`landmark_map_document`)."""
        return landmark_map_document(self.ekf, self.method.name)

    def save_landmarks(self, path: str | Path) -> Path:
        """Write :meth:`landmarks_document` as YAML to ``path`` (atomically: a temporary file, then renamed)."""
        import os

        import yaml

        path = Path(path)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(yaml.safe_dump(self.landmarks_document(), sort_keys=False))
        os.replace(tmp, path)
        return path

    # ----------------------------------------------------------------- steps
    def _widen_to_fit(self, pattern: list[tuple[int, int]], front: FrontEnd, pan: float,
                      ekf: JointEKF | None = None) -> tuple[float, bool]:
        """Widen the position covariance by factors of 4 until ``pattern`` (landmark id, pair index) fits as a
        typical sample (its joint NIS at most its mean, ``2 · len(pattern)``; merely inside the 99 % gate would
        leave the pose overconfident after the update), up to ``health.max_inflation``; returns the factor used.
        Only the position: a wheel slip or a kidnap moves the robot, and a heading that the images would turn far
        beyond its odometry is more likely a wrong head pan, which must not be absorbed into the pose. Returns the
        factor and whether the pattern fits; ``ekf``: widen that filter instead of the localizer's (a trial)."""
        ekf = self.ekf if ekf is None else ekf
        pairs = front.kept_pairs
        measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
        factor = 1.0
        while factor * 4.0 <= self.config.health.max_inflation:
            ekf.inflate_pose(4.0, position_only=True)
            factor *= 4.0
            if ekf.joint_nis(pattern, measured, pan) <= 2 * len(pattern):
                return factor, True
        return factor, False

    def _walls_offsets(self, front: FrontEnd, cam_k: StereoCamera):
        """The walls fitted in this frame as a measurement of the position across them, when together they
        disagree with the pose beyond their 99.9 % χ² bound: ``(nu, H, R)``, else None.

        Each wall fitted with its slope in agreement with the map (a wrong pan turns the walls; a kidnap or a
        slip only shifts them) measures the position across it: its fitted offset ``a`` is ``−J δ`` for a pose
        error ``δ`` (:func:`~stablemarks.landmarks.seen_wall_jacobian`, first row), with the fit's and the map's
        variance."""
        ekf = self.ekf
        model = self.method.model(front, cam_k, self.world_map, ekf.pose, ekf.cov_pose, self._probe_config)
        if model is None:
            return None
        cov_map = self.world_map.accuracy_cov
        fits = [f for f in model.fits if f and fit_disagreements(cam_k, f, ekf.cov_pose, cov_map)[1] <= SLOPE_GATE_CHI2]
        if not fits:
            return None
        H = np.array([-seen_wall_jacobian(cam_k, f)[0] for f in fits])
        nu = np.array([float(f.a) for f in fits])
        R = np.diag([float(f.cov_R[0, 0]) + float(cov_map[0, 0]) for f in fits])
        S = H @ ekf.cov_pose @ H.T + R
        if float(nu @ np.linalg.solve(S, nu)) <= float(chdtri(len(nu), 0.001)):
            return None  # the walls are where the pose puts them: not a kidnap
        return nu, H, R

    def _local_pose(self, assoc, front: FrontEnd, pan: float) -> np.ndarray | None:
        """The pose the frame's own associations ``assoc`` put the robot at: the filter's updated with all of them
        (on a copy), or None without any."""
        if not assoc:
            return None
        pairs = front.kept_pairs
        probe = self.ekf.copy()
        try:
            probe.update([(i, (pairs.u_left[j], pairs.u_right[j])) for i, j in assoc], pan,
                         iterations=self.config.ekf.iterations)
        except GeometryError:
            return None
        return probe.pose

    def _relocalize(self, walls, front: FrontEnd, cam_k: StereoCamera, pan: float, found: list | None = None):
        """Relocalize when no landmark was found where the pose puts them in ``health.relocalize_frames`` frames
        in a row while the walls fitted in the frame disagreed with it (:meth:`_walls_offsets`).

        Two ways, the first that works wins; either makes a copy of the filter, models the frame again from its
        pose and keeps the copy only if a pattern of at least ``health.min_pattern`` landmarks is then associated
        and jointly compatible. Returns ``(filter, factor, model, associations, way)`` (``"lines"`` or
        ``"walls"``) or None.

        1. From the landmarks on the frame's lines (:func:`~stablemarks.estimation.relocalize.pose_from_lines`):
           the pose within ``health.relocalize_radius`` of the prediction (and its heading within 3 σ + 1°: a
           wrong pan turns the view, and must not be taken for a turn of the robot) that puts the most landmarks
           on a line, if at least ``min_pattern + 1`` and two more than any other place. The copy's pose is
           re-initialised there, uncorrelated with the landmarks (the odometry that correlated them was wrong),
           with σ three times what the tolerance of one line allows at the landmarks' depth.
        2. From the walls: the copy's position covariance is widened by factors of 4 (up to
           ``health.max_inflation``) until the walls' offsets fit as a typical sample, and updated with them
           (:meth:`JointEKF.update_pose`). Two parallel walls fix the position across them and the heading
           together, so this alone can turn the heading (the room: 13° off after a 0.5 m slip).
        """
        ways = [("lines", lambda: self._relocation_from_lines(front, cam_k, pan, found))]
        if walls is not None:
            ways.append(("walls", lambda: self._relocation_from_walls(walls)))
        for how, way in ways:
            probe, factor = way()
            if probe is None:
                continue
            model = self.method.model(front, cam_k, self.world_map, probe.pose, probe.cov_pose, self._probe_config)
            report: dict = {}
            assoc = self.method.associate(probe, front, model, pan, cam_k, report, self._max_incidence)
            pattern = max(report.get("compatible") or [[]], key=len)
            if len(pattern) >= self.config.health.min_pattern:
                return probe, factor, model, assoc, how
        return None

    def _relocation_from_walls(self, walls) -> tuple[JointEKF | None, float]:
        """A copy of the filter updated with the walls' offsets ``(nu, H, R)``, its position covariance first
        widened until they fit (:meth:`_relocalize`, way 2), and the factor."""
        nu, H, R = walls

        def m2(P):
            return float(nu @ np.linalg.solve(H @ P @ H.T + R, nu))

        probe = self.ekf.copy()
        factor = 1.0
        while factor * 4.0 <= self.config.health.max_inflation and m2(probe.cov_pose) > len(nu):
            probe.inflate_pose(4.0, position_only=True)
            factor *= 4.0
        probe.update_pose(nu, H, R)
        return probe, factor

    def _relocation_from_lines(self, front: FrontEnd, cam_k: StereoCamera, pan: float, found: list | None = None
                               ) -> tuple[JointEKF | None, float]:
        """A copy of the filter re-initialised at the pose that puts the most landmarks on the frame's lines
        (:meth:`_relocalize`, way 1), and the factor by which its position variance exceeds the prior's; or
        ``(None, 1)``. With ``found`` (the associations the frame made where the pose puts the landmarks), the pose
        must put two more than that on a line, and lie beyond the prior's 99.9 % bound (otherwise the frame is no
        evidence of a slip or a kidnap), and put at least twice as many on a line as the pose those associations
        update the filter to (:meth:`_local_pose`, computed only when the rest holds) does, scored the same way
        (:func:`~stablemarks.estimation.relocalize.lines_score`): a scene of many evenly spaced lines puts
        landmarks on lines at other places too (the hall with ``noise.sigma_img`` 0.16, trial 1, frame 28: 5 of 11
        landmarks associated within the narrower gates, a place 0.12 m off with 10 on a line, relocalized there
        with the pose 7 σ off), and the count at the prediction itself is no fair comparison: its error of a
        few pixels puts none within the tight tolerance."""
        ekf, h = self.ekf, self.config.health
        # Landmarks entered blind are no ground to relocalize on: office, trial 12 of 20, frame 81, after two frames
        # without an observation and the heading 0.13 rad off, four landmarks were entered from the white board's
        # end found 22 px off (at a coat stand's pole in front of it), and at frame 82 the frame's lines put the
        # pose 0.17 m off onto them, held with σ 6 mm (pose NEES 514, landmark NEES 487). After a slip or a
        # kidnap the landmarks entered while the pose was being observed still witness it.
        ids = [i for i in ekf.landmark_ids if i not in self._unconfirmed]
        if len(ids) <= h.min_pattern:
            return None, 1.0
        P = np.array([ekf.landmark_position(i) for i in ids])
        pairs = front.kept_pairs
        tight = 3.0 * self.camera.sigma_img
        heading = 3.0 * math.sqrt(ekf.cov_pose[2, 2]) + math.radians(1.0)
        place = pose_from_lines(cam_k, P, ids, pairs.u_left, pairs.u_right, ekf.pose, radius=h.relocalize_radius,
                                heading=heading, tol_px=h.relocalize_tol_px, tight_px=tight,
                                sigma_img=self.camera.sigma_img)
        if place is None or len(place.inliers) < max(h.min_pattern + 1, place.runner_up + 2):
            return None, 1.0
        if found is not None:
            d = place.pose - ekf.pose
            d[2] = float(wrap_angle(d[2]))
            if len(place.inliers) < len(found) + 2 or float(d @ np.linalg.solve(ekf.cov_pose, d)) <= POSE_GATE_CHI2:
                return None, 1.0
            local = self._local_pose(found, front, pan)
            if local is not None and len(place.inliers) < 2 * lines_score(cam_k, local, P, pairs.u_left,
                                                                          pairs.u_right, tight):
                return None, 1.0
        inliers = P[[ids.index(i) for i in place.inliers]]
        depth = cam_k.to_camera(place.pose, inliers)[1]
        s_th = 3.0 * tight / cam_k.f
        s_xy = s_th * float(np.median(depth))
        # the isotropic σ, and the resection's own: what the inliers leave open (a shift with its turn, seen from
        # one frontal wall) stays uncertain
        covs = np.array([ekf.landmark_cov2d(i) for i in place.inliers])
        cov = np.diag([s_xy**2, s_xy**2, s_th**2]) + resection_cov(cam_k, place.pose, inliers, covs, tight,
                                                                   radius=h.relocalize_radius, heading=heading)
        probe = ekf.copy()
        probe.reset_pose(place.pose, cov)
        return probe, max(1.0, float(np.trace(cov[:2, :2]) / np.trace(ekf.cov_pose[:2, :2])))

    def _walls_missed(self, model: FrameLandmarks | None, assoc, pan: float, record: FrameRecord) -> frozenset[str]:
        """Ids of the walls modelled in this frame (a boundary found) that hold landmarks predicted in view of which
        none was associated: nothing new is entered on them in this frame. The frame contradicts the filter there
        (its landmarks are not where the pose puts them), and a boundary is checked only against that same pose:
        entered, its features would duplicate the landmarks not found, at another place (office, a turn with the
        heading 25 mrad off: seven landmarks entered beside the whiteboard's own, NEES 275 the next frame;
        storeroom, after a blind stretch: a free edge 0.58 m from the map's, let through by the position's σ along
        the wall, six landmarks entered from it and the pose re-initialised 0.7 m off). The walls reopen when their
        landmarks are found again, or once the ones missed ``ekf.max_missed`` frames in a row are dropped."""
        if model is None or not self.ekf.n_landmarks:
            return frozenset()
        modelled = {m.fit.plane.id: m.fit.plane.label for m in model.planes if m.boundaries}
        seen = {int(i) for i, _ in assoc}
        held: dict[str, list[int]] = {}
        for i in self.ekf.visible(pan, self._max_incidence):
            plane = self.ekf.landmark_plane(i)
            if plane is not None and plane.id in modelled:
                held.setdefault(plane.id, []).append(int(i))
        closed = frozenset(p for p, ids in held.items() if not seen.intersection(ids))
        for p in sorted(closed):
            record.warnings.append(f"plane {modelled[p]!r}: none of its {len(held[p])} landmarks in view was found: "
                                   "no new landmarks are entered on it in this frame")
        return closed

    def _missed_landmarks(self, model: FrameLandmarks | None, assoc, pan: float, dropped: list[int]) -> list[int]:
        """Wall landmarks predicted in view on a wall modelled in this frame (a boundary found) but not
        associated: counted frame by frame; those missed ``ekf.max_missed`` times in a row are returned."""
        if model is None or not self.ekf.n_landmarks:
            return []
        modelled = {m.fit.plane.id for m in model.planes if m.boundaries}
        seen = {i for i, _ in assoc}
        view = self.ekf.visible(pan, self._max_incidence)
        # one merged with a wall's end was not looked for (ekf.merge_px): not finding it says nothing against it
        merged = merged_with_edges(self.ekf, view, pan, model.predictions, self.config.ekf.merge_px) \
            if self.config.ekf.merge_px > 0 else set()
        out = []
        for i in view:
            if i in dropped or i in merged:
                continue
            if i in seen:
                self._missed.pop(i, None)
                continue
            plane = self.ekf.landmark_plane(i)
            if plane is None or plane.id not in modelled:
                continue
            self._missed[i] = self._missed.get(i, 0) + 1
            if self._missed[i] >= self.config.ekf.max_missed:
                out.append(i)
        return out

    def _heading_drift(self) -> tuple[float, float] | None:
        """``(turn [deg], z)`` when, over the last ``health.drift_frames`` frames, the estimate's heading has turned
        from the dead reckoning's by more than ``health.drift_sigma`` σ, with σ² the odometry's heading variance
        over those frames plus ``(σ_θ now + σ_θ then)²`` (the filter's heading errors at both ends, taken as fully
        correlated: the bound the difference of two correlated errors can reach); else None."""
        track = self._heading_track
        d = float(self.ekf.pose[2] - self._dead_reckoning.theta)
        if track:
            d = track[-1][0] + float(np.angle(np.exp(1j * (d - track[-1][0]))))
        track.append((d, float(np.sqrt(self.ekf.cov_pose[2, 2])), self._odo_heading_var))
        if len(track) < track.maxlen:
            return None
        (d0, s0, q0), (d1, s1, q1) = track[0], track[-1]
        z = (d1 - d0) / math.sqrt(q1 - q0 + (s0 + s1) ** 2)
        return (math.degrees(d1 - d0), z) if abs(z) > self.config.health.drift_sigma else None

    def _recheck_boundaries(self, model: FrameLandmarks, pan: float, record: FrameRecord
                            ) -> tuple[FrameLandmarks, dict]:
        """``model`` with the candidates of every snapped boundary that the frame's update makes incompatible with
        the map's free edge rejected (not entered, :data:`REASON_BOUNDARY_RECHECK`), and those boundaries,
        ``{(plane id, edge): NIS}``, for the log.

        The model was made from the prior; after a blind stretch its gate on a boundary
        (``landmarks.boundary_gate_sigma``) is wide, and a boundary snapped onto a line a few pixels inside the
        edge passes it (the office: a whiteboard's end snapped 7 px in, at 3 m; the four landmarks modelled from
        it held the pose 3 cm off with σ 0.8 cm for 20 frames). The frame's update narrows the pose: the
        boundary's columns must then fit the map's edge projected from it (NIS inside the association gate).
        """
        snapped = [b for pm in model.planes for b in pm.boundaries if b.snapped and b.cov_uv is not None]
        nis = self._edges_nis(snapped, pan)
        bad = {(b.plane_id, b.edge): float(v) for b, v in zip(snapped, nis, strict=True) if v > self.config.ekf.gate}
        if not bad:
            return model, {}
        for (plane_id, edge), nis in bad.items():
            record.warnings.append(
                f"plane {self.world_map[plane_id].label!r}: the boundary found at {edge} does not fit the map's free "
                f"edge at the updated pose (NIS {nis:.0f}): nothing is entered from it")
        return replace(model, candidates=[
            replace(c, selected=False, reason=REASON_BOUNDARY_RECHECK) if c.selected and (c.plane_id, c.edge) in bad
            else c for c in model.candidates]), bad

    def _update_edges(self, model: FrameLandmarks, entered: Entered, measurements, pan: float) -> list:
        """Update the pose with the free edges found again in this frame (``ekf.edge_updates``).

        A snapped boundary (moved onto its outermost member segment pair, Sec 3.2) is the image of the map's
        free edge, a point the map gives: its columns say where the robot is along that wall. Left out: the
        boundaries new landmarks were modelled from in this frame (their positions along the wall are measured
        from it: used twice, the pose and those landmarks would seem independent), boundaries whose line updated
        the filter as a landmark in this frame (the same pixels), the region's own border when no segment marks
        the edge (block matching moves it inward by about half a window: a bias, not noise), and an edge whose
        NIS lies outside the association gate. The map's accuracy is added to the noise.
        """
        used = {(c.plane_id, c.edge) for c in entered.candidates if c is not None}
        lines = np.array([ul for _, ul, _ in measurements])
        found = [b for pm in model.planes if not pm.gated for b in pm.boundaries
                 if b.snapped and b.cov_uv is not None and (b.plane_id, b.edge) not in used
                 and not (len(lines) and np.min(np.abs(lines - b.u[0])) < 1.0)]
        keep = [b for b, v in zip(found, self._edges_nis(found, pan), strict=True) if v <= self.config.ekf.gate]
        if not keep:
            return []
        pts, z, R, cov_map = self._edge_observations(keep)
        self.ekf.update_known_points(pts, z, R, pan, cov_points=cov_map)
        return [(b.plane_id, b.edge, float(b.u[0]), float(b.u[1]), np.asarray(b.cov_uv).tolist()) for b in keep]

    def _update_walls(self, model: FrameLandmarks, entered: Entered, cam_k: StereoCamera) -> list:
        """Update the pose with the walls fitted in this frame (``ekf.wall_updates``).

        A wall's fitted line ``(a, b)`` in its own frame is ``J (X_fit − X) + J_β β_w + w`` for the true pose
        ``X`` (:func:`~stablemarks.landmarks.seen_wall_jacobian` at the belief ``X_fit`` the fit was placed with),
        ``β_w`` the disparity error the wall's pixels share (:attr:`PlaneFit.J_bias`) and ``w`` the rest of the
        fit's error with the map's accuracy. ``β_w`` stays with a wall from frame to frame (measured: the fitted
        offset's error at the true pose is correlated 0.2–0.7 over 20 frames), so it is a state of the filter,
        one per wall (:meth:`JointEKF.add_aux`, prior σ ``planes.disparity_bias_px``), not noise counted anew in
        every frame: seeing a wall again from the same place adds nothing the first view did not give. Only walls
        used in the frame (not gated), jointly within the 99 % χ² bound, informative (``ekf.wall_info_ratio``: the
        pose's variance across the wall at least that many times the fit's), and not the walls new landmarks were
        modelled on in this frame (their positions come from the same fit: used twice, the pose and those
        landmarks would seem independent). Returns the measurements used (:attr:`FrameRecord.wall_measurements`)."""
        used = {c.plane_id for c in entered.candidates if c is not None}
        fits = [pm.fit for pm in model.planes if not pm.gated and pm.fit and pm.fit.plane.id not in used]
        if not fits:
            return []
        cov_map = self.world_map.accuracy_cov
        var_beta = float(self.config.planes.disparity_bias_px) ** 2
        X = self.ekf.pose
        ratio = float(self.config.ekf.wall_info_ratio)
        P_XX = self.ekf.cov_pose
        measurements = []
        for f in fits:
            J = seen_wall_jacobian(cam_k, f)
            if ratio > 0 and float(J[0] @ P_XX @ J[0]) < ratio * float(np.asarray(f.cov_R)[0, 0]):
                continue  # the pose already knows its distance from this wall as well as the fit says it
            dX = np.asarray(f.X, dtype=float) - X
            dX[2] = wrap_angle(dX[2])
            R = np.asarray(f.cov_R, dtype=float) + cov_map
            shared = var_beta > 0 and f.J_bias is not None
            if shared:
                R = R - var_beta * np.outer(f.J_bias, f.J_bias)  # the shared part is the state's
            measurements.append((f.plane.id, (np.array([f.a, f.b]) - J @ dX).tolist(), (-J).tolist(),
                                 np.asarray(f.J_bias, dtype=float).tolist() if shared else None, R.tolist(), var_beta,
                                 X.tolist()))
        if not measurements:
            return []
        nu, H, keys, H_aux, R = _wall_terms(measurements)
        idx = [0, 1, 2] + [self.ekf.aux_index(k) for k in keys]
        known = [i for i in idx if i is not None]
        Hf = np.hstack([H, H_aux])
        P = np.zeros((len(idx), len(idx)))
        at = [n for n, i in enumerate(idx) if i is not None]
        P[np.ix_(at, at)] = self.ekf.cov_block(known)
        for n, i in enumerate(idx):
            if i is None:
                P[n, n] = var_beta  # a wall seen for the first time: its prior
        S = Hf @ P @ Hf.T + R
        if float(nu @ np.linalg.solve(S, nu)) > float(chdtri(len(nu), 0.01)):
            return []
        apply_wall_measurements(self.ekf, measurements)
        return measurements

    def _edge_observations(self, boundaries) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Snapped ``boundaries`` as observations of the map's free edges: the edges' map positions (m, 2), the
        boundaries' columns (m, 2) and covariances (m, 2, 2), the edges' map covariances (m, 2, 2)."""
        return (np.array([self.world_map[b.plane_id].edge(b.edge) for b in boundaries]).reshape(-1, 2),
                np.array([b.u for b in boundaries], dtype=float).reshape(-1, 2),
                np.array([b.cov_uv for b in boundaries], dtype=float).reshape(-1, 2, 2),
                np.array([self.world_map.edge_cov(b.plane_id, b.edge) for b in boundaries]).reshape(-1, 2, 2))

    def _edges_nis(self, boundaries, pan: float) -> np.ndarray:
        """(m,) NIS of each snapped boundary against the map's free edge at the current pose."""
        pts, z, R, cov_map = self._edge_observations(boundaries)
        return self.ekf.known_point_nis(pts, z, R, pan, cov_points=cov_map)

    def _increment(self, odometry) -> tuple[SE2 | None, np.ndarray | None]:
        if odometry is None:
            return None, None
        pose = SE2.from_array(np.asarray(odometry, dtype=float))
        if self._odometry is None:
            return pose, None
        return pose, self._odometry.between(pose).as_array()

    def command_pan(self, odometry=None) -> float:
        """The pan [rad] the pan policy (``config.pan``) chooses for a frame taken at the wheel-odometry pose
        ``odometry`` (3,): from the current estimate moved by the odometry since the last frame (or from the
        current estimate when ``odometry`` is None)."""
        from .estimation import motion

        X = self.ekf.pose
        _, U = self._increment(odometry)
        if U is not None:
            X = motion(X, U)
        return choose_pan(self.config.pan, self.world_map, self.camera, X, self._pan, ekf=self.ekf, dt=self._dt,
                          max_incidence=self._max_incidence)

    def step(self, stamp: float, left: np.ndarray, right: np.ndarray, *, odometry=None, pan: float = 0.0
             ) -> Estimate:
        """Process one rectified stereo pair.

        Parameters
        ----------
        stamp : time [s].
        left, right : (H, W) ``uint8`` rectified grayscale images, left camera the reference.
        odometry : (3,) wheel-odometry pose ``(x [m], y [m], theta [rad])`` at ``stamp``; the increment since
            the previous frame predicts the pose (Eq 19) with the noise model ``config.odometry``. None: no
            odometry (the pose is predicted not to move).
        pan : the head's pan when the pair was taken [rad].
        """
        t0 = time.perf_counter()
        k = self._index
        pan = float(pan)
        odo_pose, U = self._increment(odometry)
        cov_U = None
        if U is not None:
            cov_U = self.config.odometry.covariance(SE2.from_array(U))
            self.ekf.predict(U, cov_U)
            _, F, J = motion(self._dead_reckoning.as_array(), U, jacobians=True)
            self._dr_cov = F @ self._dr_cov @ F.T + J @ cov_U @ J.T
            self._odo_heading_var += float(cov_U[2, 2])
            self._dead_reckoning = self._dead_reckoning @ SE2.from_array(U)
        if odo_pose is not None:
            self._odometry = odo_pose
        t1 = time.perf_counter()
        timings = {"predict": t1 - t0}
        record = FrameRecord(index=k, stamp=float(stamp), pan=pan, pan_command=pan, pose=self.ekf.pose,
                             cov_pose=self.ekf.cov_pose, dead_reckoning=self._dead_reckoning.as_array(),
                             odometry=U, cov_odometry=cov_U)
        front = model = None
        rechecked: dict = {}
        entered = Entered()
        method = self.method
        nis_high = disagree = edges_missing = turned = reinitialised = recovering = pan_suspect = False
        edges_found = True
        if method.uses_vision:
            check_pair(np.asarray(left), np.asarray(right))
            cam_k = self.camera.with_pan(pan)
            regions = None  # dense; else SAD only where the method reads it, with the same results (pipeline.py)
            if not self.dense_disparity:
                regions = plane_regions(cam_k, self.ekf.pose, self.ekf.cov_pose, self.world_map, self.config,
                                        np.shape(left)) if method.models_planes else Regions.none()
            front = run_front_end(left, right, self.config, regions)
            timings.update(front.timings)
            t2 = time.perf_counter()
            model = method.model(front, cam_k, self.world_map, self.ekf.pose, self.ekf.cov_pose, self.config)
            if model is not None:
                record.warnings, record.n_candidates = list(model.warnings), len(model.candidates)
                record.n_selected = len(model.selected)
            record.n_pairs = len(front.kept_pairs)
            edges_missing = _edges_missing(model, self.config, self.camera.width)
            # A wrong pan turns every wall in view the same way (a slip or a kidnap shifts them): walls turned
            # together are not where the pan says. Nothing is associated, updated or entered from this frame, and
            # it counts as one whose edges were not found.
            turn = _walls_turn(model, cam_k, self.world_map)
            turned = turn.together
            if turned:
                self._turn_ref = turn
                record.warnings.append(
                    f"the {turn.walls} walls in view are turned {np.degrees(turn.angle):+.1f}° together from the "
                    f"map's (Mahalanobis² {turn.m2:.0f} with the pose's uncertainty): the head's pan is probably "
                    "wrong; they are not used")
            edges_missing = edges_missing or turned
            # what clears edges_not_found: the walls found where the map puts them, not turned together, and,
            # after a turn raised it, turned back from it (the heading's uncertainty, grown meanwhile, would
            # otherwise soon take in the pan's error)
            edges_found = not edges_missing and turn.m2 <= SLOPE_GATE_CHI2
            if edges_found and self._turn_ref is not None and self.health.edges_latched:
                edges_found = turn.turned_back(self._turn_ref)
            pan_suspect = self.health.suspect_edges(edges_missing, edges_found) or turned or \
                self.health.drift is not None
            report: dict = {}
            assoc = [] if pan_suspect else method.associate(self.ekf, front, model, pan, cam_k, report,
                                                            self._max_incidence)
            if model is not None and (edges_missing or not assoc) and self.ekf.visible(pan):
                # the walls are not where the prediction puts them: look again with wider gates (a slip or a
                # kidnap moves them beyond the bands of a confident pose). Also while the pan is suspect: walls
                # that a shift of the position alone explains are a kidnap, not a wrong pan (below).
                wide = method.model(front, cam_k, self.world_map, self.ekf.pose,
                                    self.ekf.cov_pose * self.config.health.search_inflation, self._probe_config)
                wide_report: dict = {}
                method.associate(self.ekf, front, wide, pan, cam_k, wide_report, self._max_incidence)
                if wide_report.get("incompatible") and not wide_report.get("compatible"):
                    model, report = wide, wide_report
            if report.get("incompatible"):
                # A pattern of landmarks none of which was observed again since the frame that entered it is no
                # witness of a slip: the pose they disagree with is one odometry step from the one they were
                # modelled from, and a bad entry (a wrong pan, a misplaced boundary) is the likelier cause (the hall,
                # every pan 0.2 rad off: four landmarks entered at frame 15 widened the pose ×4096 at frame 16 and
                # pulled it 1.4 m along their wall). Such landmarks are simply not associated in this frame.
                report = {**report, "incompatible": [m for m in report["incompatible"]
                                                     if any(self.ekf.landmark(i).n_observed for i, _ in m)]}
            disagree = bool(report.get("incompatible")) and not report.get("compatible") and \
                max(len(m) for m in report["incompatible"]) >= self.config.health.min_pattern
            relocated = walls = None
            if not disagree and not turned and not assoc and model is not None and self.ekf.visible(pan):
                # no landmark found and no pattern either: a kidnap that moved the walls beyond even the widened
                # bands? The walls themselves, fitted where they are, say where the robot is (_relocalize), once
                # they have disagreed with the pose in health.relocalize_frames frames in a row.
                walls = self._walls_offsets(front, cam_k)
            self._lost_frames = self._lost_frames + 1 if walls is not None else 0
            if walls is not None and self._lost_frames >= self.config.health.relocalize_frames and \
                    self.health.drift is None:  # after heading_drift the estimate is dead reckoning's (module health)
                relocated = self._relocalize(walls, front, cam_k, pan)
            if relocated is None and not turned and not pan_suspect and model is not None:
                # Landmarks found, but few of those in view: after a slip across the view a few lines can fit a few
                # landmarks at the wrong pose (the corridor, 0.5 m sideways: three, jointly compatible, held the
                # heading 3° off). Where the frame's lines put many more of them elsewhere, the robot is there.
                if 2 * len(assoc) < self.ekf.n_landmarks:  # else not fewer than half of those in view either
                    n_view = len(self.ekf.visible(pan, self._max_incidence))
                    if n_view > self.config.health.min_pattern and 2 * len(assoc) < n_view:
                        relocated = self._relocalize(None, front, cam_k, pan, found=assoc)
            if relocated is not None:
                self.ekf, record.inflation, model, assoc, how = relocated
                reinitialised = how == "lines"
                if reinitialised:
                    record.warnings.append(
                        f"relocalized: the pose re-initialised at ({self.ekf.pose[0]:.3f} m, {self.ekf.pose[1]:.3f} m, "
                        f"{np.degrees(self.ekf.pose[2]):.1f}°) from the landmarks on the frame's lines, "
                        f"{np.hypot(*(self.ekf.pose[:2] - record.pose[:2])):.2f} m from the prediction")
                disagree = True
                pan_suspect = edges_missing = False
                edges_found = True
            if disagree and pan_suspect:
                # a wrong pan turns the walls; only a pattern that a position shift makes fit is a kidnap
                probe = self.ekf.copy()
                _, fits = self._widen_to_fit(max(report["incompatible"], key=len), front, pan, probe)
                disagree = fits and not turned
                if disagree:
                    pan_suspect = edges_missing = False
                    edges_found = True
            if relocated is None and disagree and \
                    self.health.runs["odometry_disagrees"] + 1 >= self.config.health.disagree_frames:
                record.inflation, _ = self._widen_to_fit(max(report["incompatible"], key=len), front, pan)
                assoc = method.associate(self.ekf, front, model, pan, cam_k, max_incidence=self._max_incidence)
            recovering = record.inflation != 1.0 or reinitialised  # the pose moved beyond the prediction's gates
            assoc, dropped = method.recheck(self.ekf, model, assoc, self.config.ekf.recheck_sigma, cam_k,
                                            self.config.landmarks.off_wall_sigma)
            dropped += self._missed_landmarks(model, assoc, pan, dropped)
            for i in dropped:
                self.retired[i] = self.ekf.landmark(i)
                self.ekf.remove_landmark(i)
                self._missed.pop(i, None)
            record.dropped = dropped
            n_view = len(self.ekf.visible(pan, self._max_incidence)) if assoc else 0
            block = self.config.sad.block_size
            one_line = lone_gate_px(self.ekf, assoc, pan, front.kept_pairs.u_left, block) \
                if 0 < len(assoc) < self.config.health.min_pattern and not recovering else 0.0
            if len(assoc) > 1 and one_line > 2 * block:
                # Two landmarks whose lines lie within one SAD window of each other (aisle: two edges 4 cm apart, 3 m
                # away, after 22 blind frames with the heading 12° off) are one line to the pose, with the same
                # ambiguity as a lone one below; their update held the position 0.27 m off with σ 3 cm.
                ids = ", ".join(str(i) for i, _ in assoc)
                record.warnings.append(
                    f"landmarks {ids} were the only ones associated, their lines within one {block} px SAD window of "
                    f"each other, in a gate of ±{one_line:.0f} px: not used until another line confirms them")
                assoc = []
            if len(assoc) == 1 and not recovering:
                # One line alone cannot be checked against anything: with a 2-D measurement and a 3-D pose, joint
                # compatibility accepts whatever lies in its gate. While the pose is well known the gate is a few
                # pixels wide; when it spans more than two SAD windows either side (after a turn, a blind stretch),
                # a neighbour of a line that was not found is as likely, and would collapse the covariance around a
                # wrong pose (loop: a 5° heading error held with σ 0.2° for four frames). Wait for a second one.
                # Nor when several landmarks were predicted in view and none of the others was found: the prediction
                # is then likely off (loop: a turn's odometry 4.8° off, 2.9 σ; the one line found near a landmark's
                # predicted column was its neighbour, NIS 1.65, and held the heading 4.8° off with σ 0.06°).
                half = one_line
                if half > 2 * block:
                    record.warnings.append(
                        f"landmark {assoc[0][0]} was the only one associated, in a gate of ±{half:.0f} px (more than "
                        f"two {self.config.sad.block_size} px SAD windows): not used until another one confirms it")
                    assoc = []
                elif n_view >= self.config.health.min_pattern:
                    record.warnings.append(
                        f"landmark {assoc[0][0]} was the only one of the {n_view} in view associated: not used until "
                        "another one confirms it")
                    assoc = []
            if 1 < len(assoc) < self.config.health.min_pattern and not recovering:
                # A small pattern among many landmarks in view: after an odometry error in a turn, two neighbouring
                # lines can fit two landmarks together (loop: 2 of 8 found, the heading held 4.8° off). Not used
                # when finding so few is unlikely at the rate this run finds the landmarks in its view.
                found, missed = self._found
                p = float(binom.cdf(len(assoc), n_view, found / (found + missed)))
                if p < self.config.health.few_found_p:
                    record.warnings.append(
                        f"only {len(assoc)} of the {n_view} landmarks in view were associated (probability {p:.1g} "
                        f"at this run's rate of finding them, {found / (found + missed):.0%}): not used")
                    assoc = []
            elif len(assoc) >= self.config.health.min_pattern and not recovering:
                self._found[0] += min(len(assoc), n_view)
                self._found[1] += max(0, n_view - len(assoc))
            record.associated = [int(i) for i, _ in assoc]
            chosen = self.ekf.select_for_update(assoc, pan)
            if chosen:
                pairs = front.kept_pairs
                measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
                observations = [(i, measured[j]) for i, j in chosen]
                if self.config.ekf.inflation_p > 0 and not recovering:
                    record.inflated = [(list(f.ids), f.t, f.alpha, f.group) for f in inflate_inconsistent(
                        self.ekf, observations, pan, self._groups, self.config.ekf.inflation_p)]
                res = self.ekf.update(observations, pan, frame=k, iterations=self.config.ekf.iterations)
                record.measurements = [(int(i), float(measured[j][0]), float(measured[j][1])) for i, j in chosen]
                record.observed = [int(i) for i in res.ids]
                record.nis = [float(v) for v in res.nis]
                nis_high = res.nis_total > float(chdtri(res.dof, 0.01))
            t3 = time.perf_counter()
            timings["associate_update"] = t3 - t2
            if not pan_suspect:
                if chosen and model is not None:
                    model, rechecked = self._recheck_boundaries(model, pan, record)
                closed = self._walls_missed(model, assoc, pan, record)
                # a frame that found none of the filter's landmarks may enter its new ones tied to the pose or widened
                # (enter_wall_landmarks): their boundary was told from other lines by the pose alone
                blind = None
                if not record.observed and self._observed_once:  # (at most one of the two: EKFConfig)
                    blind = "tied" if self.config.ekf.tie_blind_entries else \
                        "widened" if self.config.ekf.widen_blind_entries else None
                entered = method.enter(self.ekf, front, model, {int(j) for _, j in assoc}, cam_k, self.world_map, k,
                                       self.config, closed_planes=closed, blind=blind)
            record.new, record.landmark_priors = list(entered.ids), list(entered.priors)
            for ids_g, _, _ in entered.priors:
                self._n_groups += 1
                self._groups.update((int(i), self._n_groups) for i in ids_g)
            self._observed_once = self._observed_once or bool(record.observed)
            record.landmark_couplings = [(ids, np.asarray(G).tolist(), np.asarray(X).tolist())
                                         for ids, G, X in entered.couplings]
            if self._unconfirmed:  # confirmed once observed again (or gone)
                present = set(self.ekf.landmark_ids)
                self._unconfirmed = {i for i in self._unconfirmed
                                     if i in present and not self.ekf.landmark(i).n_observed}
            if entered.ids and not record.observed and self.ekf.n_landmarks > len(entered.ids):
                self._unconfirmed.update(int(i) for i in entered.ids)
            record.candidates, record.boundaries = model_log(model, rechecked)
            if not pan_suspect and not recovering and self.config.ekf.edge_updates and model is not None \
                    and len(record.observed) >= self.config.health.min_pattern and not self.health.active:
                record.edge_measurements = self._update_edges(model, entered, record.measurements, pan)
            informative = self.config.ekf.wall_info_ratio > 0  # walls while they tell the pose something, any frame
            if not pan_suspect and not recovering and self.config.ekf.wall_updates and model is not None \
                    and (informative or len(record.observed) >= self.config.health.min_pattern) \
                    and not self.health.active:
                record.wall_measurements = self._update_walls(model, entered, cam_k)
            timings["select"] = time.perf_counter() - t3
        drift = None
        if method.uses_vision and self.health.drift is None:
            if recovering:
                self._recoveries.append(k)
                self._missed_after_recovery = 0
            else:
                self._missed_after_recovery = self._missed_after_recovery + 1 \
                    if edges_missing or not edges_found else 0
            h = self.config.health
            while self._recoveries and self._recoveries[0] <= k - h.recoveries_frames:
                self._recoveries.popleft()
            # A recovered pose is not confirmed when the free edges are then missed where the map puts them from it,
            # in health.edges_frames frames in a row after it (not when missed before it: the edges a pose off in a
            # blind turn misses are what the recovery corrects, and one wall fitted turned from the map's in the next
            # frame is no evidence against it)
            drift = self._heading_drift() or \
                ((0.0, 0.0, "recoveries") if len(self._recoveries) >= h.max_recoveries else None) or \
                ((0.0, 0.0, "unconfirmed") if self._recoveries and not recovering
                 and self._missed_after_recovery >= h.edges_frames else None)
        if drift is not None:
            # the images' heading has run away from the odometry's: fall back on dead reckoning (module health)
            self.ekf.reset_pose(self._dead_reckoning.as_array(), self._dr_cov)
        self._pan = pan
        if self._stamp is not None and stamp > self._stamp:
            self._dt = float(stamp) - self._stamp
        self._stamp = float(stamp)
        self._index += 1
        record.pose, record.cov_pose = self.ekf.pose, self.ekf.cov_pose
        record.n_landmarks = self.ekf.n_landmarks
        record.pan_command = self.command_pan()
        record.health = self.health.update(edges_missing=edges_missing, nis_high=nis_high, disagree=disagree,
                                           observed=bool(record.observed), has_landmarks=self.ekf.n_landmarks > 0,
                                           inflation=record.inflation, edges_found=edges_found, drift=drift,
                                           reinitialised=reinitialised)
        if not self.health.edges_latched and not turned:
            self._turn_ref = None
        timings["total"] = time.perf_counter() - t0
        record.timings = timings
        return Estimate(record.stamp, record.pose, record.cov_pose, record.pan_command, list(record.health), record,
                        front, model, entered)
