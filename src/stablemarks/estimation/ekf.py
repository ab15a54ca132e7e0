"""The joint EKF over the robot pose and the landmarks (paper Sec 5, Eqs 19–20; DESIGN.md §4).

State ``S = (X, l_1 … l_n)`` in the map frame: the robot pose ``X = (x [m], y [m], theta [rad])`` followed by
the landmarks, each of one of two kinds:

- ``wall``: one number ``s`` [m], the distance along a known wall from its free edge ``edge`` (``"p1"`` or
  ``"p2"``); the landmark stands at ``P = plane.point_at(s, edge)`` (Eq 15 with ``s = d_p``). Its 2-D
  covariance for output is rank 1 along the wall, ``var_s · t tᵀ`` with ``t`` the unit direction from that
  edge (Eq 17, Table 1's ``σ_y = 0``), while the filter's covariance stays non-singular.
- ``point``: ``(x, y)`` [m], a vertical line on no known wall (the ``all_segments`` baseline).

Prediction (Eq 19) composes the pose with an odometry increment given in the robot frame, ``X' = X ⊕ U``,
and touches only the pose rows and columns of the covariance: O(n). The observation of a landmark (Eq 20,
the explicit form of ``G(S, L) = 0``) is the pair of image columns ``(u_l, u_r)`` [px] of its vertical line
seen from the pose, with the stereo head panned by the frame's ``pan`` [rad], and noise ``R = σ_img² I``.
An update stacks the frame's observations and uses the Joseph form restricted to the columns they touch,
``P − K PHtᵀ − PHt Kᵀ + K S Kᵀ`` with ``PHt = P[:, idx] H_subᵀ``: O(N²·m) for N state dimensions and m
observations, never O(N³).

Threads: the update's products are thin in one dimension (2m ≈ 12); on such shapes a multi-threaded BLAS
was measured several times slower than one thread (DESIGN §4; 60 ms against 12 ms for 1000 landmarks
on the 2-core development machine under load). :meth:`JointEKF.update` therefore pins BLAS to one thread
around its O(N²) part when the state has at least ``BLAS_PIN_MIN_DIM`` dimensions, through one
process-wide ``threadpoolctl.ThreadpoolController`` (entering its limit costs ~0.1 ms; a fresh
``threadpool_limits`` call costs ~5 ms, more than a small update). The limit is process-wide while it
lasts. Callers running many filter steps may as well wrap their whole loop::

    from threadpoolctl import threadpool_limits
    with threadpool_limits(limits=1, user_api="blas"):
        ...  # predict / associate / update
"""

from __future__ import annotations

import contextlib
import copy as _copy
import functools
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from numba import njit
from scipy.optimize import linear_sum_assignment
from scipy.special import chdtri
from threadpoolctl import ThreadpoolController

from ..errors import ConfigError, GeometryError, InputError, expected
from ..geometry import SE2, StereoCamera, wrap_angle
from ..maps import Map, ReferencePlane

KINDS = ("wall", "point")
EDGES = ("p1", "p2")
BLAS_PIN_MIN_DIM = 256
"""State size from which :meth:`JointEKF.update` pins BLAS to one thread (module docstring)."""


@functools.cache
def _blas_controller() -> ThreadpoolController:
    return ThreadpoolController()


def _one_blas_thread(n_dims: int):
    """A context pinning BLAS to one thread for a state of ``n_dims`` dimensions (no-op below the threshold)."""
    if n_dims < BLAS_PIN_MIN_DIM:
        return contextlib.nullcontext()
    return _blas_controller().limit(limits=1, user_api="blas")


# ------------------------------------------------------------------ motion
def motion(X, U, *, jacobians: bool = False):
    """Compose the pose with an odometry increment: ``X' = X ⊕ U`` (paper Eq 19).

    Parameters
    ----------
    X : (3,) pose ``(x [m], y [m], theta [rad])`` of the robot in the map frame.
    U : (3,) increment ``(dx [m], dy [m], dtheta [rad])`` in the robot frame at ``X``.
    jacobians : also return ``J_X`` (3, 3) = ∂X'/∂X and ``J_U`` (3, 3) = ∂X'/∂U.

    Returns
    -------
    X' : (3,) new pose, heading wrapped to ``[-pi, pi)``.
    """
    X = np.asarray(X, dtype=float)
    U = np.asarray(U, dtype=float)
    c, s = np.cos(X[2]), np.sin(X[2])
    X_new = np.array([X[0] + c * U[0] - s * U[1], X[1] + s * U[0] + c * U[1], wrap_angle(X[2] + U[2])])
    if not jacobians:
        return X_new
    J_X = np.array([[1.0, 0.0, -s * U[0] - c * U[1]], [0.0, 1.0, c * U[0] - s * U[1]], [0.0, 0.0, 1.0]])
    J_U = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return X_new, J_X, J_U


# ----------------------------------------------------------- configuration
@dataclass(frozen=True)
class EKFConfig:
    """Parameters of :class:`JointEKF`.

    Attributes
    ----------
    gate_probability : probability mass of the χ² gate (2 dof) on an association's Mahalanobis distance.
    max_updates_per_frame : ``k``, how many associated landmarks update the state per frame (the paper's
        "several, less uncertain landmarks", Sec 5), chosen by :meth:`JointEKF.select_for_update`.
    update_selection : how those ``k`` are chosen: ``"individual"`` (the ``k`` with the largest information gain
        about the pose each on its own) or ``"joint"`` (greedily, each the one that adds most to what those already
        chosen give: six landmarks that each pin the heading best are not the six that pin the pose best).
    margin_px : a landmark is a candidate for association only if both its predicted columns lie this
        far inside the image [px].
    max_missed : a wall landmark predicted in view on a wall modelled in the frame but not associated for this
        many frames in a row is dropped from the filter (marginalised out): it was wrong or is not stable.
    landmark_sigma_floor : no landmark is held more certain than this along its wall [m]: after an update, a
        landmark whose σ fell below it gets the difference added to its variance. The errors of a landmark do not
        all average out over the frames it is seen in: the part of its line's column error that stays with it
        (0.011 px RMS on lab, 0.038 on room, 0.045 on office, 0.071 on hall: its mean over the frames it updated
        the filter) and errors of its model (a boundary snapped onto a line beside the edge, the fitted wall's
        shared disparity error), so repeated observations cannot shrink its error without bound. A floor in
        pixels at the current view (0.05 px) was tried: the office's landmarks, 3–6 m away, came out 10 times
        too certain (landmark NEES 11.6, 8 trials); 1 mm left the hall's, 6–12 m away, 3 times too certain.
        0 turns it off.
    recheck_sigma : an associated wall landmark whose along-wall position disagrees with the frame's own model
        of the same line by more than this many σ (both variances) is dropped and entered again from the
        frame's model: an error made from afar is corrected, not locked in.
    iterations : most Gauss–Newton iterations of the localizer's landmark updates (the iterated EKF; 1: the
        ordinary EKF update); they stop as soon as a step moves no observed state component by 1 % of its
        posterior σ. While the pose is well known one extra iteration changes nothing that matters; after a blind
        stretch or a turn (a heading σ of several degrees) the single linearisation at the predicted pose leaves
        the pose off by more than the covariance it returns (storeroom: 58 mm off with σ 5 mm, NEES 1512, in
        the frame two landmarks were found again after 80 blind frames; iterated: 5 mm off, NEES 7).
    edge_updates : update the pose with the free edges found in the frame (:meth:`JointEKF.update_known_points`):
        a snapped boundary is the image of a point the map gives, so every frame that finds one again says
        where the robot is along that wall. The paper uses a boundary only once, when the landmarks are modelled
        from it; then the pose along a wall is known only as well as the first boundary was found. Only in frames
        that update from a pattern of ``health.min_pattern`` landmarks while no health condition holds. Off by
        default: with ``noise.boundary_px`` 0.25 the ATE fell 1.7–3 times on lab, room and corridor and by
        16–31 % on office and hall (``stablemarks eval``, 20 trials), but an office and a hall trial ended
        overconfident (run-mean pose NEES 87 and 20), and two fault recoveries fail with it (the room
        kidnapped by 0.5 m ends overconfident; the corridor whose pan is left out while the head turns is not
        recognised in time).
    wall_updates : update the pose with the walls fitted in the frame (:meth:`Localizer._update_walls`): a wall's
        fitted line says how far the camera is from it and how it is turned, to millimetres, where a landmark's
        line says it only through its disparity (σ of centimetres at 3 m). The disparity error a wall's pixels
        share stays with the wall over many frames, so it is a state of the filter per wall (:meth:`add_aux`,
        prior σ ``planes.disparity_bias_px``, which must then be > 0), not noise counted in every frame. Off by
        default: with ``planes.disparity_bias_px`` 0.03 and ``planes.disparity_tilt_px`` 0.06 (5 trials, December
        2026) the ATE fell by a fifth to a third on every scene (lab 26.3 → 21.8 mm, corridor 16.0 → 13.6, room
        26.4 → 19.0, office 11.6 → 7.9, hall 18.9 → 13.3), but corridor and office spent 15–17 % of their frames
        above the pose NEES bounds (none before) and the office's landmarks became overconfident (landmark NEES
        0.38 → 1.93): the walls' remaining errors (their tilt, the clutter in front of them) are not all in the
        model yet. Hence ``wall_info_ratio``.
    wall_info_ratio : with ``wall_updates``, a wall updates the pose only while the pose's variance across the wall
        (the predicted variance of the fitted offset from ``P_XX``) is at least this many times the fit's own
        variance of that offset: while it tells the pose something the filter does not already hold. The walls
        then update in any frame (also one that found no landmark), not only in frames that updated from a
        pattern of landmarks, and stop once the pose knows what they say, before their errors left out of the
        model add up. 0: every fitted wall in frames with a pattern of landmarks (the first form). With 1
        (5 trials, December 2026, bias 0.03 px, tilt 0.06 px): ATE lab 26.3 → 23.7 mm, room 26.4 → 19.3, corridor
        16.0 → 13.9, office 11.6 → 8.2, hall 18.9 → 14.4, storeroom 85.6 → 57.1 (precision 0.96 → 1.00, recall
        0.46 → 0.58); frames above the pose NEES bounds none on lab, room and hall, 1 % on the corridor, 6 % on
        the office, but 52 % on the storeroom (pose NEES 2.13 → 8.09): where clutter stands in front of the walls
        their fits are biased beyond their covariance, and the walls hold the pose there.
    tie_blind_entries : landmarks entered in a frame that found none of the filter's landmarks (after the first
        frame that did) enter as SLAM enters what it measures (:func:`~stablemarks.methods.enter_wall_landmarks`):
        where the line's ray from the pose meets the mapped wall, with the cross-covariance to the pose that
        implies, not at their distance from a boundary the pose alone told apart from other lines. Off by
        default: on an office rendered by pybullet it kept two landmarks modelled from a white board's end found
        on a coat stand's pole from pulling the pose 0.2 m off (pose NEES 6.79 → 2.88), but on the storeroom (20
        trials) it made the filter overconfident (pose NEES 2.36 → 3.21, 19 % of frames above the bounds, none
        before): two such landmarks entered 27 frames apart, with heading σ of 3–4°, seen together cut σθ from
        3.8° to 0.5° with the heading 1.8° off, the linearisation error EKF-SLAM is known for at such heading
        uncertainty.
    landmark_sigma_floor_per_m : a floor that grows with the landmark's range from the camera at the update:
        ``landmark_sigma_floor + this × range`` [m per m]. A line's error that stays with it is a fixed angle, so
        its share of the landmark's error grows with range. 0: off.
    inflation_p : before each update, the directions of the landmark state that an entry error moves (the common
        shift of a group entered from one boundary, of a wall's landmarks, one landmark's own) are tested against
        the frame's innovations with the pose profiled out, each at this false-alarm probability, and those the
        data contradict get the variance they lack (:func:`~stablemarks.estimation.consistency.inflate_inconsistent`):
        the landmark model's σ can be what its errors usually are while a wrong boundary or a line on texture is
        widened when it shows. 0: off.
    merge_px : a landmark whose predicted line lies closer than this to the predicted image of a free edge of a
        wall in view (in either image, at the prior mean) is not associated in that frame [px]. The line detector
        (Sobel_x, ksize 3, non-maximum suppression along the row) merges two vertical edges 2–3 px apart into one
        line between them, and at 3 px with a 1 px blur it still places each 0.4 px off (from 4 px: < 0.1 px,
        from 5 px: < 0.01 px); a landmark that close to a wall's end is found on the merged line, and when the pose
        is uncertain enough for its gate to hold the edge as well, the edge passes for the landmark (storeroom: a
        door frame's bar 2 cm from the wall's end, 3 px at 4.5 m, associated after 21 blind frames with the line of
        the wall's end, held the pose 72 mm off with σ 17 mm). The relative position of a landmark and its wall's
        end in the image does not depend on the pose error, so the test is sharp even when the gate is wide. Two
        landmarks merged on one line are already left out as ambiguous
        (:func:`~stablemarks.estimation.associate_frame`). 0: off.
    widen_blind_entries : landmarks entered in a frame that found none of the filter's landmarks (after the first
        frame that did) enter at their distance from the boundary, as the map's, but with the pose's variance
        along the wall added (``G P_XX Gᵀ``, no cross-covariance): the boundary was told from the lines beside it
        by the pose alone and may be any of them.
    """

    gate_probability: float = 0.99
    max_updates_per_frame: int = 6
    update_selection: str = "individual"
    margin_px: float = 0.0
    max_missed: int = 5
    recheck_sigma: float = 3.0
    landmark_sigma_floor: float = 0.005
    edge_updates: bool = False
    wall_updates: bool = False
    wall_info_ratio: float = 1.0
    tie_blind_entries: bool = False
    iterations: int = 5
    landmark_sigma_floor_per_m: float = 0.0
    inflation_p: float = 0.0
    widen_blind_entries: bool = False
    merge_px: float = 0.0

    def __post_init__(self) -> None:
        for name in ("edge_updates", "wall_updates", "tie_blind_entries", "widen_blind_entries"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(expected("true or false", getattr(self, name), where=f"ekf.{name}"))
        if self.tie_blind_entries and self.widen_blind_entries:
            raise ConfigError("ekf.tie_blind_entries and ekf.widen_blind_entries: expected at most one of them true "
                              "(two ways to enter the same landmarks)")
        if isinstance(self.inflation_p, bool) or not isinstance(self.inflation_p, int | float) or \
                not 0.0 <= self.inflation_p < 1.0:
            raise ConfigError(expected("a probability in [0, 1) (0: off)", self.inflation_p, where="ekf.inflation_p"))
        if not 0.0 < self.gate_probability < 1.0:
            raise ConfigError(expected("a probability in (0, 1)", self.gate_probability,
                                       where="ekf.gate_probability"))
        if self.update_selection not in ("individual", "joint"):
            raise ConfigError(expected("'individual' or 'joint'", self.update_selection, where="ekf.update_selection"))
        k = self.max_updates_per_frame
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
            raise ConfigError(expected("a positive integer", k, where="ekf.max_updates_per_frame"))
        for name in ("max_missed", "iterations"):
            m = getattr(self, name)
            if isinstance(m, bool) or not isinstance(m, int | np.integer) or m < 1:
                raise ConfigError(expected("a positive integer", m, where=f"ekf.{name}"))
        v = self.landmark_sigma_floor_per_m
        if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v >= 0):
            raise ConfigError(expected("a non-negative number of metres per metre of range", v,
                                       where="ekf.landmark_sigma_floor_per_m"))
        if not (np.isfinite(self.landmark_sigma_floor) and self.landmark_sigma_floor >= 0):
            raise ConfigError(expected("a non-negative number of metres", self.landmark_sigma_floor,
                                       where="ekf.landmark_sigma_floor"))
        if not (np.isfinite(self.recheck_sigma) and self.recheck_sigma > 0):
            raise ConfigError(expected("a positive number", self.recheck_sigma, where="ekf.recheck_sigma"))
        r = self.wall_info_ratio
        if isinstance(r, bool) or not (np.isfinite(r) and r >= 0):
            raise ConfigError(expected("a non-negative number", self.wall_info_ratio, where="ekf.wall_info_ratio"))
        v = self.merge_px
        if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v >= 0):
            raise ConfigError(expected("a non-negative number of pixels (0: off)", v, where="ekf.merge_px"))
        if not (np.isfinite(self.margin_px) and self.margin_px >= 0):
            raise ConfigError(expected("a non-negative number of pixels", self.margin_px, where="ekf.margin_px"))

    @property
    def gate(self) -> float:
        """χ² threshold on the squared Mahalanobis distance of a 2-D innovation."""
        return float(chdtri(2, 1.0 - self.gate_probability))  # χ²⁻¹(p; 2)


# --------------------------------------------------------------- landmarks
@dataclass(frozen=True)
class NewLandmark:
    """A landmark to enter the filter: its kind, initial state value and the data kept beside it.

    ``value`` is ``(s,)`` [m] for a ``wall`` landmark (distance along ``plane`` from ``edge``) and ``(x, y)``
    [m] in the map frame for a ``point`` landmark. ``z_low, z_high`` [m] are the line's ends (Eq 1) and
    ``polarity`` the sign of its brightness step in the left image (+1 dark to bright going right, -1 the
    other way, 0 unknown), kept for matching and output only. Build with :meth:`wall` or :meth:`point`.
    """

    kind: str
    value: tuple[float, ...]
    plane: ReferencePlane | None = None
    edge: str = "p1"
    z_low: float | None = None
    z_high: float | None = None
    polarity: int = 0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InputError(expected(f"one of {KINDS}", self.kind, where="landmark.kind"))
        n = 1 if self.kind == "wall" else 2
        if len(self.value) != n or not all(np.isfinite(self.value)):
            raise InputError(expected(f"{n} finite number(s)", self.value, where=f"{self.kind} landmark.value"))
        if self.kind == "wall":
            if not isinstance(self.plane, ReferencePlane):
                raise InputError(expected("a ReferencePlane", self.plane, where="wall landmark.plane"))
            if self.edge not in EDGES:
                raise InputError(expected(f"one of {EDGES}", self.edge, where="wall landmark.edge"))

    @classmethod
    def wall(cls, plane: ReferencePlane, s: float, edge: str = "p1", z_low: float | None = None,
             z_high: float | None = None, polarity: int = 0) -> NewLandmark:
        return cls("wall", (float(s),), plane, edge, z_low, z_high, int(polarity))

    @classmethod
    def point(cls, xy, z_low: float | None = None, z_high: float | None = None, polarity: int = 0) -> NewLandmark:
        xy = np.asarray(xy, dtype=float).reshape(-1)
        return cls("point", tuple(float(v) for v in xy), None, "p1", z_low, z_high, int(polarity))

    @property
    def dim(self) -> int:
        """Number of state dimensions (1 for ``wall``, 2 for ``point``)."""
        return 1 if self.kind == "wall" else 2


@functools.lru_cache(maxsize=256)
def _chi2_gate(dof: int, tail: float) -> float:
    """``chdtri(dof, tail)``, the χ² gate of ``dof`` degrees of freedom, remembered: :meth:`JointEKF.associate_joint`
    asks for the same few gates once per trial pair, every frame (a scipy ufunc call each, ~5 µs)."""
    return chdtri(dof, tail)


@dataclass
class _Track:
    """The filter's bookkeeping of one landmark (its value and covariance live in the state).

    ``start`` (2,) and ``J_p_l`` (2, 2) give its map position ``P = start + J_p_l @ (l_1, l_2)``: for a wall
    landmark ``start`` is the edge, the first column the unit direction from it and the second column zero
    (the state index of ``l_2`` repeats ``l_1``); for a point ``start = 0`` and ``J_p_l = I``.
    """

    id: int
    kind: str
    plane: ReferencePlane | None
    edge: str
    z_low: float | None
    z_high: float | None
    first_frame: int | None
    last_frame: int | None
    n_observed: int = 0
    polarity: int = 0
    start: np.ndarray = field(init=False, repr=False)
    J_p_l: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind == "point":
            self.start, self.J_p_l = np.zeros(2), np.eye(2)
        else:
            t = self.plane.direction if self.edge == "p1" else -self.plane.direction
            self.start, self.J_p_l = self.plane.edge(self.edge), np.array([[t[0], 0.0], [t[1], 0.0]])

    @property
    def dim(self) -> int:
        return 1 if self.kind == "wall" else 2


@dataclass(frozen=True, eq=False)
class LandmarkEstimate:
    """A snapshot of one landmark of the filter.

    ``value`` is ``(s,)`` or ``(x, y)`` and ``cov`` its (1, 1) or (2, 2) covariance over the state
    dimensions; ``position`` (2,) [m] and ``cov2d`` (2, 2) [m²] are in the map frame (rank 1 along the wall
    for a ``wall`` landmark, Eq 17).
    """

    id: int
    kind: str
    plane_id: str | None
    edge: str | None
    value: np.ndarray
    cov: np.ndarray
    position: np.ndarray
    cov2d: np.ndarray
    z_low: float | None
    z_high: float | None
    n_observed: int
    first_frame: int | None
    last_frame: int | None
    polarity: int = 0

    def to_dict(self) -> dict:
        """Plain JSON/YAML-able fields (see :meth:`JointEKF.landmarks_to_dict`)."""
        d: dict = {"id": self.id, "kind": self.kind}
        if self.kind == "wall":
            d.update(plane=self.plane_id, edge=self.edge, s=float(self.value[0]), var_s=float(self.cov[0, 0]))
        else:
            d.update(x=float(self.value[0]), y=float(self.value[1]), cov=self.cov.tolist())
        def plain(v, kind):
            return None if v is None else kind(v)

        d.update(position=self.position.tolist(), cov2d=self.cov2d.tolist(), z_low=plain(self.z_low, float),
                 z_high=plain(self.z_high, float), n_observed=int(self.n_observed),
                 first_frame=plain(self.first_frame, int), last_frame=plain(self.last_frame, int),
                 polarity=int(self.polarity))
        return d


# ------------------------------------------------------------------ results
@dataclass(frozen=True, eq=False)
class ObservationPrediction:
    """Predicted observations of landmarks ``ids`` (m,) for one pan angle (Eqs 3, 4 and 20).

    Attributes
    ----------
    ids : (m,) landmark ids.
    uv : (m, 2) predicted ``(u_l, u_r)`` [px]; NaN for lines not in front of the camera.
    J_I_X : (m, 2, 3) Jacobian w.r.t. the pose ``(x, y, theta)``.
    J_I_l : (m, 2, 2) Jacobian w.r.t. the landmark's state: ``(x, y)`` for points; ``(s, ·)`` for wall
        landmarks, whose second column is zero.
    S : (m, 2, 2) innovation covariance ``H P Hᵀ + R`` [px²].
    in_view : (m,) both columns inside the image (with the configured margin) and the line in front.
    """

    ids: np.ndarray
    uv: np.ndarray
    J_I_X: np.ndarray
    J_I_l: np.ndarray
    S: np.ndarray
    in_view: np.ndarray


@dataclass(frozen=True, eq=False)
class UpdateResult:
    """What one update used and saw, for evaluation.

    ``ids`` (m,), ``innovations`` (m, 2) = measured − predicted ``(u_l, u_r)`` [px], ``nis`` (m,) the
    normalised innovation squared of each observation alone (2 dof), ``nis_total`` that of the stacked
    innovation (``dof = 2m``).
    """

    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    innovations: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    nis: np.ndarray = field(default_factory=lambda: np.zeros(0))
    nis_total: float = 0.0

    @property
    def dof(self) -> int:
        return 2 * len(self.ids)


# ------------------------------------------------------------- linear algebra
def _add_sym_rank(P: np.ndarray, A: np.ndarray, K: np.ndarray, block: int = 256) -> None:
    """``P ← P + A Kᵀ + K Aᵀ`` in place for a symmetric (N, N) ``P`` and (N, r) ``A``, ``K``.

    A symmetric rank-2r update: each strip of rows ``P[i0:i1, i0:]`` on and above the diagonal gets one
    (b, 2r) × (2r, N − i0) product, and is then mirrored below the diagonal. Half the flops of
    ``P += A @ K.T + K @ A.T``, no (N, N) temporary, no column-wise walk over ``P`` (``M + M.T`` in NumPy
    costs several times the product), and ``P`` stays exactly symmetric.
    """
    n = len(P)
    left = np.concatenate([A, K], axis=1)
    right = np.concatenate([K, A], axis=1)
    for i0 in range(0, n, block):
        i1 = min(i0 + block, n)
        strip = P[i0:i1, i0:]
        strip += left[i0:i1] @ right[i0:].T
        _mirror_upper(strip[:, : i1 - i0])
        P[i1:, i0:i1] = strip[:, i1 - i0:].T


@njit(cache=True)
def _mirror_upper(D):  # pragma: no cover - numba
    """``D ← triu(D) + triu(D, 1)ᵀ`` in place for a square block ``D`` (a view into ``P``): the upper triangle
    plus 0.0 (as the sum adds it: −0.0 becomes +0.0), mirrored below the diagonal — the same bits as the NumPy
    expression without its four (b, b) temporaries (~8 µs for a small state, most of a small update's mirroring)."""
    n = D.shape[0]
    for i in range(n):
        for j in range(i, n):
            D[i, j] = D[i, j] + 0.0
        for j in range(i):
            D[i, j] = D[j, i]


NIS_DECISION_TOL = 1e-6
"""Relative margin around a χ² gate inside which :meth:`JointEKF.associate_joint` decides a trial with the
stacked solve of :meth:`JointEKF.joint_nis` instead of its running Cholesky factor (:func:`_sequential_trials`)."""


@njit(cache=True, inline="always")
def _s_block(P, H5, idx5, i, j, a, b):  # pragma: no cover - numba
    """Entry ``(a, b)`` of the (2, 2) block ``H_i P[idx5_i, idx5_j] H_jᵀ`` of the stacked innovation covariance
    of landmarks ``i`` and ``j`` (``H5`` (c, 2, 5) their Jacobians over the state indices ``idx5`` (c, 5))."""
    acc = 0.0
    for p in range(5):
        hp = H5[i, a, p]
        if hp == 0.0:
            continue
        row = idx5[i, p]
        inner = 0.0
        for q in range(5):
            inner += P[row, idx5[j, q]] * H5[j, b, q]
        acc += hp * inner
    return acc


@njit(cache=True)
def _sequential_trials(P, H5, idx5, var_img, nu, order_r, order_c, gates, start, taken_r, taken_c, tol
                       ):  # pragma: no cover - numba
    """The trials of :meth:`JointEKF.associate_joint` from ``order_r[start:]``, ``order_c[start:]`` (landmark row,
    measurement column, cheapest first) on top of the pairs ``taken_r``, ``taken_c`` already chosen.

    The joint NIS of a trial (the chosen pairs and one more) is ``|w|² + |u|²``: ``w = L⁻¹ ν`` of the chosen pairs
    with ``L`` the Cholesky factor of their stacked innovation covariance, grown by the new pair's two rows (its
    block column ``B`` against the chosen ones, ``Y = L⁻¹ B``, the Schur complement ``S_nn − YᵀY`` factored in
    closed form, ``u`` the new rows of ``w``), so each trial costs O(m) blocks instead of a fresh (2m, 2m) solve.
    Blocks are read from ``P`` as needed (:func:`_s_block`), never the whole covariance of the landmarks in view.
    ``nu`` (c, k, 2): the innovation of every pair [px]; ``gates[n]``: the χ² gate of ``2n`` dof.

    Returns ``(stop, rows, cols)``: the chosen pairs and ``stop = -1`` when every trial was decided, else the
    index of the first trial left undecided — its NIS within ``tol`` (relative) of its gate, or a Schur
    complement not clearly positive definite (also while refactoring the chosen pairs) — for the caller to decide
    with the stacked solve before it resumes after it."""
    c, k = nu.shape[0], nu.shape[1]
    cap = 2 * min(c, k)
    L = np.zeros((cap, cap))
    w = np.zeros(cap)
    blk = np.empty(cap, np.int64)  # the landmark row of each factored dimension
    comp = np.empty(cap, np.int64)  # and which of its two observation rows it is
    out_r = np.empty(cap // 2, np.int64)
    out_c = np.empty(cap // 2, np.int64)
    used_r = np.zeros(c, np.bool_)
    used_c = np.zeros(k, np.bool_)
    Y = np.empty((cap, 2))
    n = 0
    ok = True
    pending = -1
    t = start
    # refactor the chosen pairs first (pending >= 0: a chosen pair), then try the ordered ones
    while True:
        if pending < len(taken_r) - 1:
            pending += 1
            r, col = taken_r[pending], taken_c[pending]
            is_taken = True
        else:
            while t < len(order_r) and (used_r[order_r[t]] or used_c[order_c[t]]):
                t += 1
            if t >= len(order_r):
                return -1, out_r[:n], out_c[:n]
            if not ok:
                return t, out_r[:n], out_c[:n]
            r, col = order_r[t], order_c[t]
            is_taken = False
        m2 = 2 * n
        for d in range(m2):  # Y = L⁻¹ B, B[d, b] = S[dim d, (r, b)]
            for b in range(2):
                v = _s_block(P, H5, idx5, blk[d], r, comp[d], b)
                for e in range(d):
                    v -= L[d, e] * Y[e, b]
                Y[d, b] = v / L[d, d]
        d00 = _s_block(P, H5, idx5, r, r, 0, 0) + var_img
        d10 = _s_block(P, H5, idx5, r, r, 1, 0)
        d11 = _s_block(P, H5, idx5, r, r, 1, 1) + var_img
        v0, v1 = nu[r, col, 0], nu[r, col, 1]
        for d in range(m2):
            d00 -= Y[d, 0] * Y[d, 0]
            d10 -= Y[d, 1] * Y[d, 0]
            d11 -= Y[d, 1] * Y[d, 1]
            v0 -= Y[d, 0] * w[d]
            v1 -= Y[d, 1] * w[d]
        good = d00 > 1e-12 * var_img
        l00 = np.sqrt(d00) if good else 1.0
        l10 = d10 / l00
        e11 = d11 - l10 * l10
        good = good and e11 > 1e-12 * var_img
        l11 = np.sqrt(e11) if good else 1.0
        u0 = v0 / l00
        u1 = (v1 - l10 * u0) / l11
        if is_taken:  # chosen already: kept; a factor that is not clearly positive definite decides nothing more
            accept = True
            ok = ok and good
        else:
            if not good:
                return t, out_r[:n], out_c[:n]
            nis = u0 * u0 + u1 * u1
            for d in range(m2):
                nis += w[d] * w[d]
            gate = gates[n + 1]
            if abs(nis - gate) <= tol * gate:
                return t, out_r[:n], out_c[:n]
            accept = nis <= gate
            t += 1
        if accept:
            for d in range(m2):
                L[m2, d] = Y[d, 0]
                L[m2 + 1, d] = Y[d, 1]
            L[m2, m2], L[m2 + 1, m2], L[m2 + 1, m2 + 1] = l00, l10, l11
            w[m2], w[m2 + 1] = u0, u1
            blk[m2], blk[m2 + 1] = r, r
            comp[m2], comp[m2 + 1] = 0, 1
            out_r[n], out_c[n] = r, col
            used_r[r] = True
            used_c[col] = True
            n += 1


@njit(cache=True)
def _greedy_joint(M, k):  # pragma: no cover - numba
    """:meth:`JointEKF.joint_selection`'s greedy picks on ``M`` (3 + 2m, 3 + 2m), the joint covariance of the pose
    and the m stacked observations (overwritten: conditioned on each pick in turn). Returns the picks (k,), or an
    empty array where a pose or observation covariance is not positive definite."""
    n = M.shape[0]
    m = (n - 3) // 2
    taken = np.zeros(m, np.bool_)
    out = np.empty(k, np.int64)
    for step in range(k):
        # the pose's inverse covariance, by Cholesky
        a00, a10, a11 = M[0, 0], M[1, 0], M[1, 1]
        a20, a21, a22 = M[2, 0], M[2, 1], M[2, 2]
        if not a00 > 0.0:
            return out[:0]
        l00 = np.sqrt(a00)
        l10, l20 = a10 / l00, a20 / l00
        e11 = a11 - l10 * l10
        if not e11 > 0.0:
            return out[:0]
        l11 = np.sqrt(e11)
        l21 = (a21 - l20 * l10) / l11
        e22 = a22 - l20 * l20 - l21 * l21
        if not e22 > 0.0:
            return out[:0]
        l22 = np.sqrt(e22)
        best, best_gain = -1, -np.inf
        for j in range(m):
            if taken[j]:
                continue
            r0, r1 = 3 + 2 * j, 4 + 2 * j
            s00, s01, s11 = M[r0, r0], M[r0, r1], M[r1, r1]
            g00, g01, g11 = s00, s01, s11
            for a in range(2):
                ra = r0 + a
                w0 = M[0, ra] / l00
                w1 = (M[1, ra] - l10 * w0) / l11
                w2 = (M[2, ra] - l20 * w0 - l21 * w1) / l22
                if a == 0:
                    v0, v1, v2 = w0, w1, w2
                    g00 -= w0 * w0 + w1 * w1 + w2 * w2
                else:
                    g01 -= v0 * w0 + v1 * w1 + v2 * w2
                    g11 -= w0 * w0 + w1 * w1 + w2 * w2
            d_s = s00 * s11 - s01 * s01
            d_x = g00 * g11 - g01 * g01
            if not (d_s > 0.0 and d_x > 0.0):
                return out[:0]
            gain = 0.5 * (np.log(d_s) - np.log(d_x))
            if gain > best_gain:  # the first of equal gains: the caller's order
                best, best_gain = j, gain
        out[step] = best
        taken[best] = True
        # condition M on the pick: M -= M[:, b] S_b^-1 M[b, :]
        r0, r1 = 3 + 2 * best, 4 + 2 * best
        s00, s01, s11 = M[r0, r0], M[r0, r1], M[r1, r1]
        det = s00 * s11 - s01 * s01
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        c0 = M[:, r0].copy()
        c1 = M[:, r1].copy()
        for p in range(n):
            u0 = i00 * c0[p] + i01 * c1[p]
            u1 = i01 * c0[p] + i11 * c1[p]
            for q in range(p, n):
                v = M[p, q] - (u0 * c0[q] + u1 * c1[q])
                M[p, q] = v
                M[q, p] = v
    return out


GAIN_RANK_TOL = 1e-6
"""Relative gap [nat] between information gains below which :meth:`JointEKF.select_for_update` ranks its pairs by
:meth:`JointEKF.information_gain` itself instead of the closed form (:func:`_closed_form_gains`)."""


@njit(cache=True)
def _closed_form_gains(S, C, P_XX):  # pragma: no cover - numba
    """(m,) :meth:`JointEKF.information_gain` in closed form: ``½ log(det S_j / det (S_j − W_j W_jᵀ))`` with
    ``W_j = C_j L⁻ᵀ``, ``L`` the Cholesky factor of ``P_XX`` (3×3) and 2×2 determinants, all on scalars — a few
    µs instead of NumPy's pseudo-inverse (an eigendecomposition and a dozen array operations, 25–150 µs a frame).
    All NaN where ``P_XX`` is not clearly positive definite (its smallest eigenvalue under 1e-9 of its largest, by
    the bound ``λ_min ≥ det / (tr / 2)²``: there the pseudo-inverse differs from the inverse) or a determinant is
    not positive."""
    m = S.shape[0]
    out = np.full(m, np.nan)
    a00, a10, a11 = P_XX[0, 0], P_XX[1, 0], P_XX[1, 1]
    a20, a21, a22 = P_XX[2, 0], P_XX[2, 1], P_XX[2, 2]
    tr = a00 + a11 + a22
    if not (a00 > 0.0 and tr > 0.0):
        return out
    l00 = np.sqrt(a00)
    l10, l20 = a10 / l00, a20 / l00
    e11 = a11 - l10 * l10
    if not e11 > 0.0:
        return out
    l11 = np.sqrt(e11)
    l21 = (a21 - l20 * l10) / l11
    e22 = a22 - l20 * l20 - l21 * l21
    if not (e22 > 0.0 and a00 * e11 * e22 >= 1e-9 * tr * (0.5 * tr) ** 2):
        return out
    l22 = np.sqrt(e22)
    for j in range(m):
        w = np.empty((2, 3))
        for a in range(2):  # row a of W = C L⁻ᵀ: L w_a = c_a
            w0 = C[j, a, 0] / l00
            w1 = (C[j, a, 1] - l10 * w0) / l11
            w[a, 0], w[a, 1], w[a, 2] = w0, w1, (C[j, a, 2] - l20 * w0 - l21 * w1) / l22
        s00, s01, s10, s11 = S[j, 0, 0], S[j, 0, 1], S[j, 1, 0], S[j, 1, 1]
        g00 = s00 - (w[0, 0] * w[0, 0] + w[0, 1] * w[0, 1] + w[0, 2] * w[0, 2])
        g01 = s01 - (w[0, 0] * w[1, 0] + w[0, 1] * w[1, 1] + w[0, 2] * w[1, 2])
        g10 = s10 - (w[1, 0] * w[0, 0] + w[1, 1] * w[0, 1] + w[1, 2] * w[0, 2])
        g11 = s11 - (w[1, 0] * w[1, 0] + w[1, 1] * w[1, 1] + w[1, 2] * w[1, 2])
        det_s = s00 * s11 - s01 * s10
        det_g = g00 * g11 - g01 * g10
        if det_s > 0.0 and det_g > 0.0:
            out[j] = 0.5 * (np.log(det_s) - np.log(det_g))
    return out


# ---------------------------------------------------------------- validation
def _matrix(a, shape: tuple[int, int], where: str) -> np.ndarray:
    m = np.asarray(a, dtype=float)
    if m.shape != shape or not np.isfinite(m).all():
        got = f"shape {m.shape}" if m.shape != shape else "non-finite entries"
        raise InputError(f"{where}: expected a finite {shape[0]}×{shape[1]} matrix, got {got}")
    return m


def _covariance(a, n: int, where: str) -> np.ndarray:
    """A symmetric PSD (n, n) matrix, symmetrised exactly."""
    m = _matrix(a, (n, n), where)
    scale = max(1.0, float(np.abs(m).max(initial=0.0)))
    if not np.allclose(m, m.T, rtol=0.0, atol=1e-9 * scale):
        raise InputError(f"{where}: expected a symmetric matrix, got one with asymmetry "
                         f"{np.abs(m - m.T).max():.3g}")
    m = 0.5 * (m + m.T)
    if n and np.linalg.eigvalsh(m).min() < -1e-9 * scale:
        raise InputError(f"{where}: expected a positive semi-definite matrix, got smallest eigenvalue "
                         f"{np.linalg.eigvalsh(m).min():.3g}")
    return m


# --------------------------------------------------------------------- filter
def _wrap(a) -> float:
    """:func:`wrap_angle` of one angle on Python floats: the same IEEE operations (``%`` floors as NumPy's
    remainder does, with the divisor's sign), without the array call (a dozen a frame in :meth:`JointEKF.update`)."""
    return (float(a) + math.pi) % (2.0 * math.pi) - math.pi


def _backtrack(cost, x_from: np.ndarray, x_to: np.ndarray, c_from: float, halvings: int = 5
               ) -> tuple[np.ndarray, float, tuple] | None:
    """The point on the step ``x_from → x_to`` (heading wrapped) whose ``cost`` does not exceed ``c_from``,
    trying the whole step and then halves of it, with its cost and projection (``cost(x)`` returns both); None if
    none does. Differences within 1e-9 of the cost (its round-off near the minimum) count as no increase, so that
    the result does not depend on them."""
    step = x_to - x_from
    step[2] = _wrap(step[2])
    slack = 1e-9 * max(1.0, abs(c_from))
    t = 1.0
    for _ in range(halvings + 1):
        x = x_from + t * step
        x[2] = _wrap(x[2])
        c, projection = cost(x)
        if c <= c_from + slack:
            return x, c, projection
        t *= 0.5
    return None


class JointEKF:
    """EKF over the robot pose and the landmarks (paper Sec 5; module docstring for the model).

    Parameters
    ----------
    camera : the stereo head (its ``pan`` is replaced per frame by the ``pan`` argument of the methods); its
        ``sigma_img`` [px] is the observation noise, ``R = sigma_img² I`` per observation (Sec 2.3.1).
    pose : (3,) or :class:`SE2`, initial ``(x, y, theta)`` in the map frame.
    cov_pose : (3, 3) over ``(x [m], y [m], theta [rad])``.
    config : :class:`EKFConfig`.

    The filter is mutable: :meth:`predict`, :meth:`add_landmarks`, :meth:`update` and
    :meth:`remove_landmark` change it; accessors return copies.
    """

    def __init__(self, camera: StereoCamera, pose, cov_pose, config: EKFConfig | None = None) -> None:
        self._camera_base = camera
        self.config = config if config is not None else EKFConfig()
        x0 = pose.as_array() if isinstance(pose, SE2) else np.asarray(pose, dtype=float)
        if x0.shape != (3,) or not np.isfinite(x0).all():
            raise InputError(expected("a finite pose (x, y, theta)", pose, where="ekf.pose"))
        self._x = x0.copy()
        self._x[2] = wrap_angle(self._x[2])
        self._P = _covariance(cov_pose, 3, "ekf.cov_pose").copy()
        self._var_img = float(camera.sigma_img) ** 2
        self._R1 = self._var_img * np.eye(2)
        self._panned = (camera.pan, camera)
        self._tracks: dict[int, _Track] = {}
        self._next_id = 0
        self._aux: dict[str, int] = {}  # auxiliary states (a wall's shared disparity error), between pose and landmarks
        self._projected = None  # (camera, state bytes, projection of every landmark): see _project
        self._reindex()

    # --------------------------------------------------------- bookkeeping
    def _reindex(self) -> None:
        """Rebuild the per-landmark arrays (state order = insertion order)."""
        n = len(self._tracks)
        self._ids = np.fromiter(self._tracks, dtype=int, count=n)
        self._row = {int(i): r for r, i in enumerate(self._ids)}
        tracks = list(self._tracks.values())
        dims = np.array([t.dim for t in tracks], dtype=int)
        first = self._l0 + np.concatenate([[0], np.cumsum(dims)[:-1]]).astype(int) if n else np.zeros(0, dtype=int)
        self._idx2 = np.stack([first, first + dims - 1], axis=1)  # state indices of (l_1, l_2); walls repeat l_1
        self._start = np.array([t.start for t in tracks]).reshape(n, 2)
        self._J_p_l = np.array([t.J_p_l for t in tracks]).reshape(n, 2, 2)
        self._projected = None  # made with the former landmarks

    @property
    def _l0(self) -> int:
        """The state index of the first landmark: after the pose and the auxiliary states."""
        return 3 + len(self._aux)

    def _rows(self, ids, where: str) -> np.ndarray:
        ids = [int(i) for i in ids]
        missing = [i for i in ids if i not in self._row]
        if missing:
            raise InputError(expected("ids of landmarks in the filter", missing[0], where=where))
        if len(set(ids)) != len(ids):
            raise InputError(f"{where}: expected each landmark at most once, got ids {ids}")
        return np.array([self._row[i] for i in ids], dtype=int)

    def _slice_of_row(self, r: int) -> slice:
        return slice(int(self._idx2[r, 0]), int(self._idx2[r, 1]) + 1)

    def _camera(self, pan: float) -> StereoCamera:
        """The camera panned by ``pan`` (the last one is cached: a frame asks several times)."""
        if self._panned[0] != pan:
            self._panned = (pan, self._camera_base.with_pan(pan))
        return self._panned[1]

    @property
    def camera(self) -> StereoCamera:
        """The stereo head the filter was made with."""
        return self._camera_base

    # ------------------------------------------------------------ accessors
    @property
    def pose(self) -> np.ndarray:
        """(3,) ``(x, y, theta)`` in the map frame."""
        return self._x[:3].copy()

    @property
    def cov_pose(self) -> np.ndarray:
        """(3, 3) covariance over ``(x, y, theta)``."""
        return self._P[:3, :3].copy()

    @property
    def state(self) -> np.ndarray:
        """(N,) the full state ``(X, l_1 … l_n)``."""
        return self._x.copy()

    @property
    def cov(self) -> np.ndarray:
        """(N, N) the full covariance (a copy: O(N²))."""
        return self._P.copy()

    @property
    def landmark_ids(self) -> list[int]:
        """Ids in state order."""
        return [int(i) for i in self._ids]

    @property
    def n_landmarks(self) -> int:
        return len(self._tracks)

    def landmark_plane(self, landmark_id: int) -> ReferencePlane | None:
        """The wall a ``wall`` landmark lies on (None for a point landmark)."""
        self._rows([landmark_id], "landmark_plane")
        return self._tracks[int(landmark_id)].plane

    def state_slice(self, landmark_id: int) -> slice:
        """Where a landmark's ``(s,)`` or ``(x, y)`` sits in :attr:`state`."""
        return self._slice_of_row(int(self._rows([landmark_id], "state_slice")[0]))

    def landmark_position(self, landmark_id: int) -> np.ndarray:
        """(2,) map-frame ``(x, y)`` [m] of a landmark."""
        return self._position_of_row(int(self._rows([landmark_id], "landmark_position")[0]))

    def _position_of_row(self, r: int) -> np.ndarray:
        """:meth:`landmark_position` of state row ``r``."""
        return self._start[r] + self._J_p_l[r] @ self._x[self._idx2[r]]

    def landmark_cov2d(self, landmark_id: int) -> np.ndarray:
        """(2, 2) map-frame covariance [m²]; rank 1 along the wall for a wall landmark (Eq 17)."""
        r = int(self._rows([landmark_id], "landmark_cov2d")[0])
        J, i = self._J_p_l[r], self._idx2[r]
        return J @ self._P[np.ix_(i, i)] @ J.T

    def landmark(self, landmark_id: int) -> LandmarkEstimate:
        """A snapshot of one landmark."""
        r = int(self._rows([landmark_id], "landmark")[0])
        t = self._tracks[int(landmark_id)]
        sl = self._slice_of_row(r)
        return LandmarkEstimate(
            id=t.id, kind=t.kind, plane_id=t.plane.id if t.plane is not None else None,
            edge=t.edge if t.kind == "wall" else None, value=self._x[sl].copy(), cov=self._P[sl, sl].copy(),
            position=self.landmark_position(t.id), cov2d=self.landmark_cov2d(t.id), z_low=t.z_low,
            z_high=t.z_high, n_observed=t.n_observed, first_frame=t.first_frame, last_frame=t.last_frame,
            polarity=t.polarity)

    def copy(self) -> JointEKF:
        """An independent copy of the filter."""
        return _copy.deepcopy(self)

    # -------------------------------------------------------------- predict
    def predict(self, U, cov_U) -> None:
        """Odometry prediction (paper Eq 19): ``X ← X ⊕ U``, landmarks unchanged.

        ``U`` (3,) is the increment in the robot frame, ``cov_U`` (3, 3) its covariance over
        ``(dx [m], dy [m], dtheta [rad])``. Only the pose blocks change: ``P_XX ← F P_XX Fᵀ + J_U cov_U J_Uᵀ``,
        ``P_XL ← F P_XL``: O(n).
        """
        U = np.asarray(U, dtype=float)
        if U.shape != (3,) or not np.isfinite(U).all():
            raise InputError(expected("a finite odometry increment (dx, dy, dtheta)", U, where="predict.U"))
        cov_U = _matrix(cov_U, (3, 3), "predict.cov_U")  # symmetric PSD by contract; not checked per step
        X_new, F, J_U = motion(self._x[:3], U, jacobians=True)
        P = self._P
        P_XX = F @ P[:3, :3] @ F.T + J_U @ cov_U @ J_U.T
        self._x[:3] = X_new
        P[:3, :3] = 0.5 * (P_XX + P_XX.T)
        if len(P) > 3:
            P[:3, 3:] = F @ P[:3, 3:]
            P[3:, :3] = P[:3, 3:].T

    @contextlib.contextmanager
    def linearised_at(self, pose):
        """A context in which the filter's pose mean is ``pose`` (3,) (covariance unchanged), to predict
        observations and information from another pose (the next frame's, for the pan choice); restored after."""
        saved = self._x[:3].copy()
        self._x[:3] = np.asarray(pose, dtype=float)
        try:
            yield self
        finally:
            self._x[:3] = saved

    def inflate_pose(self, factor: float, *, position_only: bool = False) -> None:
        """Widen the pose covariance: ``P_XX ← factor · P_XX`` (``factor ≥ 1``; with ``position_only`` the
        ``(x, y)`` block alone), cross-covariances kept. The change adds a PSD block (``(factor − 1)`` times a
        diagonal block of ``P``), so ``P`` stays PSD (recovery from a slip or kidnap)."""
        if not (np.isfinite(factor) and factor >= 1.0):
            raise InputError(expected("a factor >= 1", factor, where="inflate_pose.factor"))
        k = 2 if position_only else 3
        self._P[:k, :k] *= factor

    def add_landmark_variance(self, landmark_ids: Sequence[int], variance: float) -> None:
        """Add ``variance`` [m²] along the common shift of the wall landmarks ``landmark_ids``: ``P ← P + α v vᵀ``
        with ``v`` 1 on each of their ``s`` (an error they share, or one landmark's own, larger than their
        covariance held; :func:`~stablemarks.estimation.consistency.inflate_inconsistent`). ``α ≥ 0``: ``P`` stays
        PSD."""
        if not (np.isfinite(variance) and variance >= 0):
            raise InputError(expected("a non-negative variance", variance, where="add_landmark_variance"))
        idx = np.array([self._idx2[r, 0] for r in self._rows(list(landmark_ids), "add_landmark_variance")])
        self._P[np.ix_(idx, idx)] += variance

    def reset_pose(self, pose, cov_pose) -> None:
        """Replace the pose estimate by one made without the landmarks (dead reckoning, when the images can no
        longer be trusted): mean ``pose`` (3,), covariance ``cov_pose`` (3, 3), no correlation with the landmarks.
        ``P`` stays PSD (block diagonal of two PSD blocks)."""
        x = np.asarray(pose, dtype=float)
        if x.shape != (3,) or not np.isfinite(x).all():
            raise InputError(expected("a finite pose (x, y, theta)", pose, where="reset_pose.pose"))
        self._x[:3] = x
        self._x[2] = wrap_angle(self._x[2])
        self._P[:3, :3] = _covariance(cov_pose, 3, "reset_pose.cov_pose")
        self._P[:3, 3:] = 0.0
        self._P[3:, :3] = 0.0

    def update_pose(self, nu, H, R) -> float:
        """One EKF update with a linear(ised) measurement of the pose alone: innovation ``nu`` (k,), Jacobian
        ``H`` (k, 3) over ``(x, y, theta)``, noise ``R`` (k, k) (the walls fitted in a frame, when relocalizing
        after a kidnap). Joseph form over the whole state, as :meth:`update`; returns the innovation's
        Mahalanobis²."""
        nu = np.asarray(nu, dtype=float).reshape(-1)
        k = len(nu)
        H = _matrix(H, (k, 3), "update_pose.H")
        R = _matrix(R, (k, k), "update_pose.R")
        PHt, S, sol = self._gain(np.arange(3), H, nu, R)
        K = sol[:, :-1].T
        self._x += K @ nu
        self._x[2] = wrap_angle(self._x[2])
        _add_sym_rank(self._P, 0.5 * (K @ S) - PHt, K)
        return float(nu @ sol[:, -1])

    def cov_block(self, indices: Sequence[int]) -> np.ndarray:
        """The covariance over the state ``indices`` (a copy), without copying the whole of ``P``."""
        idx = np.asarray(indices, dtype=int)
        return self._P[np.ix_(idx, idx)].copy()

    def aux_index(self, key: str) -> int | None:
        """The state index of the auxiliary state ``key`` (:meth:`add_aux`), None if it has none."""
        return self._aux.get(key)

    def add_aux(self, key: str, variance: float) -> int:
        """Add a scalar auxiliary state ``key`` with mean 0 and ``variance``, uncorrelated with the rest, and return
        its state index: an error shared by a wall's measurements over many frames (its disparity error, ``ekf.
        wall_updates``), estimated with the pose instead of counted anew in every frame. It sits between the pose
        and the landmarks, is constant under :meth:`predict`, and is not a landmark (no id, not observed as one)."""
        if key in self._aux:
            raise InputError(f"add_aux: the auxiliary state {key!r} exists")
        if not (np.isfinite(variance) and variance > 0):
            raise InputError(expected("a positive variance", variance, where="add_aux.variance"))
        i = self._l0
        self._x = np.insert(self._x, i, 0.0)
        P = np.insert(np.insert(self._P, i, 0.0, axis=0), i, 0.0, axis=1)
        P[i, i] = float(variance)
        self._P = P
        self._aux[key] = i
        self._reindex()
        return i

    def update_pose_aux(self, nu, H, aux: Sequence[int], H_aux, R) -> float:
        """:meth:`update_pose` for a measurement that also depends on auxiliary states: ``H`` (k, 3) over the pose,
        ``H_aux`` (k, len(aux)) over the states at indices ``aux`` (:meth:`add_aux`). Joseph form; returns the
        innovation's Mahalanobis²."""
        nu = np.asarray(nu, dtype=float).reshape(-1)
        k = len(nu)
        aux = [int(a) for a in aux]
        if any(not 3 <= a < self._l0 for a in aux):
            raise InputError(expected("indices of auxiliary states", aux, where="update_pose_aux.aux"))
        H = np.hstack([_matrix(H, (k, 3), "update_pose_aux.H"), _matrix(H_aux, (k, len(aux)), "update_pose_aux.H_aux")])
        R = _matrix(R, (k, k), "update_pose_aux.R")
        PHt, S, sol = self._gain(np.array([0, 1, 2, *aux]), H, nu, R)
        K = sol[:, :-1].T
        self._x += K @ nu
        self._x[2] = wrap_angle(self._x[2])
        _add_sym_rank(self._P, 0.5 * (K @ S) - PHt, K)
        return float(nu @ sol[:, -1])

    def _gain(self, idx: np.ndarray, H: np.ndarray, nu: np.ndarray, R: np.ndarray | None = None):
        """The Kalman gain's pieces for a measurement with Jacobian ``H`` over the state indices ``idx``:
        ``PHt = P[:, idx] Hᵀ``, ``S = H P[idx, idx] Hᵀ + R`` (symmetrised; ``R`` None: ``σ_img² I``, the line
        observations of :meth:`update`) and ``S⁻¹ [PHtᵀ | ν]`` by one solve (the gain is its transposed left part)."""
        PHt = self._P[:, idx] @ H.T
        S = H @ PHt[idx]
        S = 0.5 * (S + S.T)
        if R is None:
            S.flat[:: len(S) + 1] += self._var_img  # the diagonal
        else:
            S = S + R
        return PHt, S, np.linalg.solve(S, np.column_stack([PHt.T, nu]))

    # ------------------------------------------------------------------ add
    def add_landmarks(self, new: Sequence[NewLandmark], cov_new, *, cov_pose_new=None,
                      frame: int | None = None, ids: Sequence[int] | None = None) -> list[int]:
        """Append landmarks to the state with a joint initial covariance (DESIGN §4).

        Parameters
        ----------
        new : the landmarks, in the order their dimensions appear in ``cov_new``.
        cov_new : (D, D) joint covariance over their state dimensions (``D = Σ dim``). Landmarks modelled
            from the same boundary in one frame share its variance as cross-covariance; entering them as
            independent makes the filter overconfident.
        cov_pose_new : (3, D) cross-covariance with the pose (default zero: a landmark measured from a
            wall's known edge is nearly independent of the pose error). The new landmarks are taken as
            independent of the old ones given the pose, so their cross-covariance with the old landmarks is
            ``P_LX P_XX⁺ cov_pose_new`` (zero by default); any other choice could make ``P`` indefinite.
        frame : frame index recorded as the landmarks' first frame.
        ids : their ids (default: fresh ones); must not be in use.

        Returns the ids of the new landmarks.
        """
        new = list(new)
        if not new:
            return []
        for i, lm in enumerate(new):
            if not isinstance(lm, NewLandmark):
                raise InputError(expected("a NewLandmark", type(lm).__name__, where=f"add_landmarks.new[{i}]"))
        D = sum(lm.dim for lm in new)
        C = _covariance(cov_new, D, "add_landmarks.cov_new")
        cross = None
        if cov_pose_new is not None:
            cross = _matrix(cov_pose_new, (3, D), "add_landmarks.cov_pose_new")
            _covariance(np.block([[self._P[:3, :3], cross], [cross.T, C]]), 3 + D,
                        "add_landmarks: joint covariance of pose and new landmarks")
        if ids is None:
            ids = list(range(self._next_id, self._next_id + len(new)))
        ids = [int(i) for i in ids]
        if len(ids) != len(new) or len(set(ids)) != len(ids) or any(i in self._tracks for i in ids):
            raise InputError(expected(f"{len(new)} distinct unused landmark ids", ids, where="add_landmarks.ids"))
        N = len(self._x)
        P = np.zeros((N + D, N + D))
        P[:N, :N] = self._P
        P[N:, N:] = C
        if cross is not None:
            P[:N, N:] = self._P[:, :3] @ (np.linalg.pinv(self._P[:3, :3], hermitian=True) @ cross)
            P[:3, N:] = cross
            P[N:, :N] = P[:N, N:].T
        self._P = P
        self._x = np.concatenate([self._x, np.concatenate([np.asarray(lm.value, float) for lm in new])])
        for i, lm in zip(ids, new, strict=True):
            self._tracks[i] = _Track(i, lm.kind, lm.plane, lm.edge, lm.z_low, lm.z_high, frame, frame,
                                     polarity=lm.polarity)
        self._next_id = max(self._next_id, max(ids) + 1)
        self._reindex()
        return ids

    def remove_landmark(self, landmark_id: int) -> None:
        """Drop a landmark (marginalise it out: delete its rows and columns)."""
        r = int(self._rows([landmark_id], "remove_landmark")[0])
        keep = np.ones(len(self._x), dtype=bool)
        keep[self._slice_of_row(r)] = False
        self._x = self._x[keep]
        self._P = self._P[np.ix_(keep, keep)]
        del self._tracks[int(landmark_id)]
        self._reindex()

    # ------------------------------------------------------------ observation
    def _project(self, rows: np.ndarray, x: np.ndarray, camera: StereoCamera):
        """``uv`` (m, 2), ``J_I_X`` (m, 2, 3), ``J_I_l`` (m, 2, 2) of landmarks ``rows`` at state ``x``.

        At the filter's own state every landmark is projected once and kept (:attr:`_projected`): association,
        :meth:`select_for_update` and the update's first linearisation all project there, ~20 µs a call in a
        frame. A later call at the same state bytes, camera object and landmarks (:meth:`_reindex` drops it) takes
        its rows from it: the same numbers, as each landmark's projection is computed on its own."""
        cache = self._projected
        if cache is not None and cache[0] is camera and cache[1] == x.tobytes():
            uv, J_I_X, J_I_l = cache[2]
            return uv[rows], J_I_X[rows], J_I_l[rows]
        if x is not self._x:
            return self._project_rows(rows, x, camera)
        every = self._project_rows(np.arange(len(self._ids)), x, camera)
        self._projected = (camera, x.tobytes(), every)
        return every[0][rows], every[1][rows], every[2][rows]

    def _project_rows(self, rows: np.ndarray, x: np.ndarray, camera: StereoCamera):
        """:meth:`_project` computed."""
        J_p_l = self._J_p_l[rows]
        p = self._start[rows] + np.einsum("mij,mj->mi", J_p_l, x[self._idx2[rows]])
        uv, J_I_X, J_I_p = camera.project_columns(x[:3], p, jacobians=True)
        return uv, J_I_X, J_I_p @ J_p_l

    def _idx5(self, rows: np.ndarray) -> np.ndarray:
        """(m, 5) state indices ``(x, y, theta, l_1, l_2)`` of each landmark's observation."""
        idx = np.empty((len(rows), 5), dtype=self._idx2.dtype)
        idx[:, :3] = (0, 1, 2)
        idx[:, 3:] = self._idx2[rows]
        return idx

    def predict_observation(self, ids: Iterable[int] | None = None, pan: float = 0.0) -> ObservationPrediction:
        """Predicted columns, Jacobians and innovation covariances of landmarks ``ids`` (default all).

        Paper Eqs 3–4 and 20: ``(u_l, u_r) = J(X, P(l))`` with the head panned by ``pan`` [rad];
        ``S_j = H_j P H_jᵀ + R``, ``H_j = [J_I_X, 0 … J_I_l … 0]``.
        """
        rows = np.arange(len(self._ids)) if ids is None else self._rows(list(ids), "predict_observation")
        uv, J_I_X, J_I_l = self._project(rows, self._x, self._camera(pan))
        idx = self._idx5(rows)
        H = np.concatenate([J_I_X, J_I_l], axis=2)  # (m, 2, 5)
        P_sub = self._P[idx[:, :, None], idx[:, None, :]]
        S = H @ P_sub @ np.swapaxes(H, 1, 2) + self._R1
        S = 0.5 * (S + np.swapaxes(S, 1, 2))
        m = self.config.margin_px
        in_view = np.isfinite(uv).all(axis=1) & self._camera_base.in_image(uv, m).all(axis=1)
        return ObservationPrediction(self._ids[rows].copy(), uv, J_I_X, J_I_l, S, in_view)

    def visible(self, pan: float = 0.0, max_incidence: float | None = None) -> list[int]:
        """Ids of the landmarks predicted inside both images (the default association candidates).

        ``max_incidence`` [rad]: also leave out the wall landmarks whose viewing ray from the left optical
        centre meets their wall farther than this from its normal. At a grazing angle the lines of one wall
        crowd together in the image and change with the viewpoint, so a line there is easily taken for its
        neighbour (office, partition seen at 69° and 87°: associated 5–8 px off its true line, the only such
        errors among 535 observations).
        """
        pred = self.predict_observation(None, pan)
        keep = pred.in_view.copy()
        if max_incidence is not None and len(keep):
            rows = np.flatnonzero(keep)
            walls = [self._tracks[int(i)].plane for i in self._ids[rows]]
            rows = np.array([r for r, w in zip(rows, walls, strict=True) if w is not None], dtype=int)
            if len(rows):
                normals = np.array([w.normal for w in walls if w is not None])
                view = self._start[rows] + np.einsum("mij,mj->mi", self._J_p_l[rows], self._x[self._idx2[rows]])
                view -= self._camera(pan).optical_centres(self._x[:3])[0]
                cos = np.abs(np.einsum("mi,mi->m", view, normals)) / np.maximum(np.linalg.norm(view, axis=1), 1e-12)
                keep[rows] = cos >= np.cos(max_incidence)
        return [int(i) for i in pred.ids[keep]]

    def observation_model(self, ids: Sequence[int], pan: float = 0.0
                          ) -> tuple[Callable[[np.ndarray], np.ndarray], np.ndarray]:
        """The stacked observation function of landmarks ``ids`` and its dense Jacobian (Eq 20).

        Returns ``h`` mapping a full state (N,) to the stacked columns (2m,) = ``(u_l, u_r)`` per landmark,
        and ``H`` (2m, N) = ∂h/∂S at the current state. For checks and dense reference filters; the
        update itself never builds the dense ``H``.
        """
        rows = self._rows(ids, "observation_model")
        cam = self._camera(pan)

        def h(x: np.ndarray) -> np.ndarray:
            return self._project(rows, np.asarray(x, dtype=float), cam)[0].reshape(-1)

        _, J_I_X, J_I_l = self._project(rows, self._x, cam)
        H = np.zeros((2 * len(rows), len(self._x)))
        for j, r in enumerate(rows):
            H[2 * j:2 * j + 2, :3] = J_I_X[j]
            # np.add.at: a wall landmark's two indices coincide and its second column is zero.
            np.add.at(H[2 * j:2 * j + 2], (slice(None), self._idx2[r]), J_I_l[j])
        return h, H

    # ------------------------------------------------------------- association
    def association_costs(self, measured, pan, candidates, extra_cost):
        """Landmarks in view ``ids`` (c,), measurements ``z`` (k, 2), squared Mahalanobis distances ``d2``
        (c, k) and ``cost`` = ``d2`` + ``extra_cost`` (its rows in the order of ``candidates``)."""
        return self._association_costs(measured, pan, candidates, extra_cost)[0]

    def _association_costs(self, measured, pan, candidates, extra_cost):
        """``(ids, z, d2, cost)`` of :meth:`association_costs` and the projection of the landmarks in view
        ``(uv, J_I_X, J_I_l)`` it was made from (row by row as :meth:`_project` gives them), for
        :meth:`associate_joint`'s trials (a second projection of the same landmarks costs ~15–30 µs)."""
        z = np.asarray(measured, dtype=float).reshape(-1, 2) if np.size(measured) else np.zeros((0, 2))
        if not np.isfinite(z).all():
            raise InputError(expected("finite measured columns", measured, where="associate.measured"))
        pred = self.predict_observation(candidates, pan)
        ids, uv, S = pred.ids[pred.in_view], pred.uv[pred.in_view], pred.S[pred.in_view]
        projection = (uv, pred.J_I_X[pred.in_view], pred.J_I_l[pred.in_view])
        if len(ids) == 0 or len(z) == 0:
            empty = np.zeros((len(ids), len(z)))
            return (ids, z, empty + np.inf, empty + np.inf), projection
        nu = z[None, :, :] - uv[:, None, :]  # (c, k, 2)
        d2 = np.einsum("cki,cij,ckj->ck", nu, np.linalg.inv(S), nu)
        cost = d2
        if extra_cost is not None:
            extra = np.asarray(extra_cost, dtype=float)
            # +inf forbids a pair; anything else must be finite
            extra = _matrix(np.where(extra == np.inf, 0.0, extra), (len(pred.ids), len(z)), "associate.extra_cost")
            extra = np.where(np.asarray(extra_cost, dtype=float) == np.inf, np.inf, extra)
            cost = d2 + extra[pred.in_view]
        return (ids, z, d2, cost), projection

    def associate(self, measured, pan: float = 0.0, candidates: Sequence[int] | None = None,
                  extra_cost=None) -> list[tuple[int, int]]:
        """Assign measured column pairs to landmarks one-to-one.

        Parameters
        ----------
        measured : (k, 2) measured ``(u_l, u_r)`` [px] of this frame's segment pairs.
        pan : the frame's pan angle [rad].
        candidates : landmark ids to consider (default all); only those predicted inside both images stay.
        extra_cost : optional (c, k) cost added to the squared Mahalanobis distance to break ties (e.g. from
            heights or row extents), rows in the order of ``candidates`` (or of :attr:`landmark_ids`).

        Each pair must pass the χ² gate (``config.gate_probability``, 2 dof) on its squared Mahalanobis
        distance ``νᵀ S⁻¹ ν``; :func:`scipy.optimize.linear_sum_assignment` then finds the one-to-one matching
        of least total cost in which leaving a landmark unassigned costs the gate value (global nearest
        neighbour with a non-assignment option): a landmark out of sight does not take a neighbour's
        measurement and push the others along. Pairs outside the gate are never assigned.

        Returns ``[(landmark id, measurement index), …]`` sorted by measurement index.
        """
        ids, z, d2, cost = self.association_costs(measured, pan, candidates, extra_cost)
        feasible = (d2 <= self.config.gate) & np.isfinite(cost)
        if not feasible.any():
            return []
        c = len(ids)
        big = (np.abs(cost[feasible]).max() + 1.0 + self.config.gate) * (c + 1)
        dummy = np.full((c, c), big)
        np.fill_diagonal(dummy, self.config.gate)
        rows, cols = linear_sum_assignment(np.concatenate([np.where(feasible, cost, big), dummy], axis=1))
        pairs = [(int(ids[r]), int(col)) for r, col in zip(rows, cols, strict=True)
                 if col < len(z) and feasible[r, col]]
        return sorted(pairs, key=lambda p: p[1])

    def joint_nis(self, pairs: Sequence[tuple[int, int]], measured, pan: float = 0.0) -> float:
        """Joint NIS ``νᵀ S⁻¹ ν`` of a set of (landmark id, measurement index) pairs, with the full joint
        innovation covariance (the pose error is shared by all of them); ``2·len(pairs)`` dof."""
        if not pairs:
            return 0.0
        z = np.asarray(measured, dtype=float).reshape(-1, 2)[[j for _, j in pairs]]
        rows = self._rows([i for i, _ in pairs], "joint_nis")
        return self._joint_nis(rows, z, *self._project(rows, self._x, self._camera(pan)))

    def _joint_nis(self, rows: np.ndarray, z: np.ndarray, uv: np.ndarray, J_I_X: np.ndarray, J_I_l: np.ndarray
                   ) -> float:
        """:meth:`joint_nis` of landmarks ``rows`` (m,) measured at ``z`` (m, 2), their projections (``uv``,
        ``J_I_X``, ``J_I_l`` of :meth:`_project`, row by row) given."""
        m = len(rows)
        idx = np.concatenate([np.arange(3), self._idx2[rows].ravel()])
        ar = np.arange(m)
        H_l = np.zeros((m, 2, m, 2))
        H_l[ar, :, ar, :] = J_I_l
        H = np.concatenate([J_I_X.reshape(2 * m, 3), H_l.reshape(2 * m, 2 * m)], axis=1)
        S = H @ self._P[np.ix_(idx, idx)] @ H.T
        S[np.diag_indices(2 * m)] += self._var_img
        nu = (z - uv).reshape(-1)
        return float(nu @ np.linalg.solve(S, nu))

    def joint_compatible(self, pairs: Sequence[tuple[int, int]], measured, pan: float = 0.0) -> bool:
        """Whether the pairs' joint NIS lies inside the χ² gate of ``2·len(pairs)`` dof."""
        return self.joint_nis(pairs, measured, pan) <= chdtri(2 * len(pairs), 1.0 - self.config.gate_probability)

    def associate_joint(self, measured, pan: float = 0.0, candidates: Sequence[int] | None = None,
                        extra_cost=None, *, costs=None) -> list[tuple[int, int]]:
        """One-to-one association whose pairs are *jointly* compatible.

        All landmarks in view share the pose error, so a set of pairs that each pass the gate can still be
        impossible together (a landmark out of sight taking its neighbour's segment and pushing the others
        along by one). Pairs that pass the individual χ² gate are taken in order of increasing Mahalanobis
        distance (plus ``extra_cost``), each kept only if its landmark and measurement are still free and
        the joint NIS of the set stays inside the χ² gate of ``2n`` dof (sequential compatible nearest
        neighbour, a greedy form of joint compatibility). An infinite ``extra_cost`` forbids a pair.
        ``costs``: :meth:`association_costs` of the same arguments, when the caller has them already.
        """
        projection = None
        if costs is None:
            costs, projection = self._association_costs(measured, pan, candidates, extra_cost)
        ids, z, d2, cost = costs
        r_gated, c_gated = np.nonzero((d2 <= self.config.gate) & np.isfinite(cost))
        if len(r_gated) == 0:
            return []
        order = np.argsort(cost[r_gated, c_gated], kind="stable")  # the order of Python's stable sort on the costs
        order_r, order_c = r_gated[order], c_gated[order]
        # every trial's joint NIS from the landmarks in view projected once, by a running Cholesky factor
        rows = self._rows(ids, "associate_joint")
        if projection is None:
            projection = self._project(rows, self._x, self._camera(pan))
        uv, J_I_X, J_I_l = projection
        H5 = np.ascontiguousarray(np.concatenate([J_I_X, J_I_l], axis=2))
        idx5 = np.ascontiguousarray(self._idx5(rows))
        nu = z[None, :, :] - uv[:, None, :]  # (c, k, 2), as (z − uv) of each trial
        p = self.config.gate_probability
        n_max = min(len(ids), len(z))
        gates = np.array([_chi2_gate(2 * n, 1.0 - p) if n else 0.0 for n in range(n_max + 1)])
        taken_r = np.zeros(0, dtype=np.int64)
        taken_c = np.zeros(0, dtype=np.int64)
        start = 0
        while True:
            stop, taken_r, taken_c = _sequential_trials(self._P, H5, idx5, self._var_img, nu, order_r, order_c,
                                                        gates, start, taken_r, taken_c, NIS_DECISION_TOL)
            if stop < 0:
                break
            # a trial too close to its gate (or badly conditioned) for the running factor: the stacked solve
            tr = np.append(taken_r, order_r[stop])
            tc = np.append(taken_c, order_c[stop])
            if self._joint_nis(rows[tr], z[tc], uv[tr], J_I_X[tr], J_I_l[tr]) <= gates[len(tr)]:
                taken_r, taken_c = tr, tc
            start = stop + 1
        return sorted(((int(ids[r]), int(c)) for r, c in zip(taken_r, taken_c, strict=True)), key=lambda q: q[1])

    def information_gain(self, ids: Sequence[int], pan: float = 0.0) -> np.ndarray:
        """(m,) expected information each landmark's observation alone gives about the pose [nat].

        The mutual information between the observation ``z_j`` and the pose ``X``,
        ``I = ½ log det S_j / det Cov(z_j | X)`` with ``Cov(z_j | X) = S_j − C_j P_XX⁺ C_jᵀ`` and
        ``C_j = Cov(z_j, X)`` (``⁺``: pseudo-inverse); by symmetry of mutual information it equals
        ``½ log det P_XX / det P_XX|z_j``, the log-det reduction of the pose covariance by updating with that
        landmark alone. An uncertain landmark gains less: its own error explains much of the innovation.
        """
        return self._information_gain(*self._information_terms(ids, pan))

    def _information_terms(self, ids: Sequence[int], pan: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What :meth:`information_gain` is made of: ``S`` (m, 2, 2) [px²], ``C = Cov(z_j, X)`` (m, 2, 3) and
        ``P_XX`` (3, 3)."""
        rows = self._rows(ids, "information_gain")
        pred = self.predict_observation(ids, pan)
        P_XX = self._P[:3, :3]
        P_lX = self._P[self._idx2[rows][:, :, None], np.arange(3)[None, None, :]]  # (m, 2, 3)
        return pred.S, pred.J_I_X @ P_XX + pred.J_I_l @ P_lX, P_XX

    @staticmethod
    def _information_gain(S: np.ndarray, C: np.ndarray, P_XX: np.ndarray) -> np.ndarray:
        """:meth:`information_gain` from its terms (:meth:`_information_terms`)."""
        S_given_X = S - C @ np.linalg.pinv(P_XX, hermitian=True) @ np.swapaxes(C, 1, 2)
        return 0.5 * (np.linalg.slogdet(S)[1] - np.linalg.slogdet(S_given_X)[1])

    def select_for_update(self, pairs: Sequence[tuple[int, int]], pan: float = 0.0,
                          k: int | None = None) -> list[tuple[int, int]]:
        """The ``k`` associated pairs (default ``config.max_updates_per_frame``) whose landmarks give the
        most information about the pose (:meth:`information_gain`), best first: the paper's "several, less
        uncertain landmarks" (Sec 5)."""
        pairs = list(pairs)
        k = self.config.max_updates_per_frame if k is None else int(k)
        if not pairs:
            return []
        if self.config.update_selection == "joint" and len(pairs) > k:
            order = self.joint_selection([p[0] for p in pairs], pan, k)
            if order is not None:
                return [pairs[i] for i in order]
        terms = self._information_terms([p[0] for p in pairs], pan)
        gain = _closed_form_gains(*terms)
        order = np.argsort(-gain, kind="stable")
        g = gain[order]
        # the closed form agrees with the pseudo-inverse and slogdet to ~1e-12 nat; where the ranking that decides
        # the k best could turn on less than GAIN_RANK_TOL (or the pose covariance is near singular: NaN), rank by
        # the gains as information_gain makes them
        gaps = g[:-1][: k] - g[1:][: k]
        if not (np.isfinite(g).all() and (gaps > GAIN_RANK_TOL * (1.0 + np.abs(g[1:][: k]))).all()):
            order = np.argsort(-self._information_gain(*terms), kind="stable")
        return [pairs[i] for i in order[:k]]

    def joint_information(self, ids: Sequence[int], pan: float = 0.0) -> float:
        """Expected information [nat] the observations of landmarks ``ids`` *together* give about the pose:
        ``½ log det P_XX / det P_XX|z_ids``, with every correlation between them (their landmarks' and the
        pose's) counted; for one landmark it is :meth:`information_gain`."""
        P_XX, C, S = self._observation_joint(list(ids), pan)
        post = P_XX - C @ np.linalg.solve(S, C.T)
        return 0.5 * float(np.linalg.slogdet(P_XX)[1] - np.linalg.slogdet(post)[1])

    def _observation_joint(self, ids: list[int], pan: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(P_XX (3, 3), C = Cov(X, z) (3, 2m), S = Cov(z) (2m, 2m))`` of the stacked predicted observations of
        ``ids`` (``(u_l, u_r)`` each), with their cross-covariances: ``S = H P Hᵀ + R``, ``C = P_X· Hᵀ``."""
        rows = self._rows(ids, "select_for_update")
        _, J_I_X, J_I_l = self._project(rows, self._x, self._camera(pan))
        idx = self._idx5(rows)  # (m, 5): the pose's three and the landmark's two state indices
        H = np.concatenate([J_I_X, J_I_l], axis=2)  # (m, 2, 5)
        m = len(rows)
        blocks = self._P[idx[:, None, :, None], idx[None, :, None, :]]  # (m, m, 5, 5)
        S = np.einsum("iab,ijbc,jdc->iajd", H, blocks, H).reshape(2 * m, 2 * m) + self._var_img * np.eye(2 * m)
        C = np.einsum("xjb,jab->xja", self._P[:3][:, idx], H).reshape(3, 2 * m)
        return self._P[:3, :3].copy(), C, 0.5 * (S + S.T)

    def joint_selection(self, ids: list[int], pan: float, k: int) -> list[int] | None:
        """Indices into ``ids`` of ``k`` landmarks chosen greedily by joint information about the pose
        (``ekf.update_selection: joint``): each step takes the landmark whose observation, given those already
        taken, reduces ``log det P_XX`` most (the conditional gain has :meth:`information_gain`'s closed form on the
        covariance of the pose and the remaining observations conditioned on the chosen ones; a rank-2 Schur
        update per step). The first is :meth:`information_gain`'s best. None where the pose covariance or a
        conditioned observation covariance is not positive definite (the caller ranks individually)."""
        P_XX, C, S = self._observation_joint(ids, pan)
        picks = _greedy_joint(np.block([[P_XX, C], [C.T, S]]), min(k, len(ids)))
        return [int(j) for j in picks] if len(picks) else None

    # ----------------------------------------------------------------- update
    def _map_cost(self, rows: np.ndarray, idx: np.ndarray, z: np.ndarray, x0: np.ndarray, camera: StereoCamera):
        """The cost an iterated update lowers, as a function of the state: the prior's Mahalanobis distance
        over the observed part of the state plus the columns' squared residuals over σ_img²; None where that
        part of the covariance is singular (a Cholesky factorisation fails). ``cost(x)`` returns the cost and
        :meth:`_project`'s result at ``x``, which the next linearisation there takes instead of projecting again."""
        idx_u = np.array(sorted(set(idx.tolist())), dtype=idx.dtype)  # np.unique's, without its overhead
        P_u = self._P[idx_u[:, None], idx_u]
        try:
            np.linalg.cholesky(P_u)
        except np.linalg.LinAlgError:
            return None
        info = np.linalg.inv(P_u)  # a few states: the inverse once, a product per evaluation
        var = self._var_img

        def cost(x: np.ndarray) -> tuple[float, tuple]:
            projection = self._project(rows, x, camera)
            uv = projection[0]
            if not np.isfinite(uv).all():
                return np.inf, projection
            d = x[idx_u] - x0[idx_u]
            d[2] = _wrap(d[2])
            r = (z - uv).reshape(-1)
            return float(d @ info @ d + r @ r / var), projection

        return cost

    def update(self, observations: Sequence[tuple[int, Sequence[float]]], pan: float = 0.0, *,
               frame: int | None = None, iterations: int = 1) -> UpdateResult:
        """One stacked EKF update with the observed columns of landmarks (paper Eq 20).

        Parameters
        ----------
        observations : ``[(landmark id, (u_l, u_r)), …]`` [px], each landmark at most once.
        pan : the frame's pan angle [rad].
        frame : frame index recorded as the landmarks' last observation.
        iterations : most Gauss–Newton iterations of the iterated EKF (1: the ordinary EKF update), each step
            taken only as far as it does not raise the update's MAP cost (:meth:`_map_cost`, :func:`_backtrack`);
            they stop when a step moves no observed state component by 1 % of its posterior σ. The localizer uses
            ``ekf.iterations`` (:class:`EKFConfig`): after a blind stretch, a turn or a slip the predicted pose is
            far from the one the images imply, and one linearisation there returns a covariance smaller than the
            error.

        With ``idx`` the pose's and the observed landmarks' state indices and ``H_sub`` (2m, |idx|)::

            PHt = P[:, idx] H_subᵀ                      (N, 2m)
            S   = H_sub PHt[idx] + R                     (2m, 2m)
            K   = PHt S⁻¹                                (a solve, not an inverse)
            x  += K ν                                    (ν = z − h(x); heading wrapped)
            P  ← P − K PHtᵀ − PHt Kᵀ + K S Kᵀ            (Joseph form, exactly)

        The last line is evaluated as ``P + A Kᵀ + K Aᵀ`` with ``A = ½ K S − PHt`` by one symmetric rank-2m
        update over the upper triangle, mirrored (:func:`_add_sym_rank`): ``P`` stays exactly symmetric and no
        (N, N) temporary is made. An empty list changes nothing.
        """
        obs = list(observations)
        if not obs:
            return UpdateResult()
        rows = self._rows([o[0] for o in obs], "update.observations")
        z = np.asarray([o[1] for o in obs], dtype=float)
        m = len(rows)
        if z.shape != (m, 2) or not np.isfinite(z).all():
            raise InputError(expected("finite (u_l, u_r) per observation", [o[1] for o in obs],
                                      where="update.observations"))
        idx = np.concatenate([np.arange(3), self._idx2[rows].ravel()])
        ar = np.arange(m)
        camera = self._camera(pan)
        x0 = self._x.copy()
        x_i = x0
        n_it = max(1, int(iterations))
        cost = self._map_cost(rows, idx, z, x0, camera) if n_it > 1 else None
        c_i, projection = np.inf, None  # the cost at x_i and the projection there, when the cost computed it
        for it in range(n_it):
            uv, J_I_X, J_I_l = projection if projection is not None else self._project(rows, x_i, camera)
            if not np.isfinite(uv).all():
                bad = int(self._ids[rows[~np.isfinite(uv).all(axis=1)][0]])
                raise GeometryError(f"landmark {bad} is behind the camera; it cannot update the filter")
            H_l = np.zeros((m, 2, m, 2))
            H_l[ar, :, ar, :] = J_I_l  # block diagonal; a wall landmark's repeated index gets a zero column
            H = np.concatenate([J_I_X.reshape(2 * m, 3), H_l.reshape(2 * m, 2 * m)], axis=1)
            # iterated EKF: the innovation relinearised at x_i, ν_i = z − h(x_i) − H_i (x0 − x_i)
            dx = x0[idx] - x_i[idx]
            dx[2] = _wrap(dx[2])
            nu = (z - uv).reshape(-1) - H @ dx
            if it == 0:
                nu0 = nu
            with _one_blas_thread(len(self._x)):
                PHt, S, sol = self._gain(idx, H, nu)
                K = sol[:, :-1].T
                x_new = x0 + K @ nu
            if it > 0 and cost is not None:
                # a Gauss–Newton step of the MAP cost, taken only as far as it lowers that cost (halved up to
                # five times): undamped, it can overshoot where two or three lines fix the pose with a wide prior
                found = _backtrack(cost, x_i, x_new, c_i)
                if found is None:
                    break  # no descent: x_i stays, with the linearisation at it just made
                x_new, c_new, projection = found
            elif cost is not None:
                c_new, projection = cost(x_new)
            step = np.abs(x_new[idx] - x_i[idx])
            step[2] = abs(_wrap(x_new[2] - x_i[2]))
            x_i = x_new
            if cost is not None:
                c_i = c_new
                if not np.isfinite(c_i):
                    break  # a line behind the camera there: the ordinary update's result stays
            if it > 0:
                # converged when the step moves no observed state component by 1 % of its posterior σ (the
                # mean's share of the NEES then changes by 1e-4): clean frames stop after one relinearisation
                var_post = self._P[idx, idx] - np.einsum("ij,ij->i", K[idx], PHt[idx])
                if (step <= 0.01 * np.sqrt(np.maximum(var_post, 0.0))).all():
                    break
        self._x = x_i
        with _one_blas_thread(len(self._x)):
            _add_sym_rank(self._P, 0.5 * (K @ S) - PHt, K)
        nu = nu0
        sol = np.linalg.solve(S, nu[:, None]) if iterations > 1 else sol[:, -1:]
        self._x[2] = _wrap(self._x[2])
        nis_total = float(nu @ sol[:, -1])
        nu2 = nu.reshape(m, 2)
        S_blocks = S.reshape(m, 2, m, 2)[ar, :, ar, :]
        nis = np.einsum("mi,mi->m", nu2, np.linalg.solve(S_blocks, nu2[..., None])[..., 0])
        for r in rows:
            t = self._tracks[int(self._ids[r])]
            t.n_observed += 1
            t.last_frame = frame if frame is not None else t.last_frame
        floor = self.config.landmark_sigma_floor**2
        per_m = self.config.landmark_sigma_floor_per_m
        if floor > 0 or per_m > 0:
            centre = camera.optical_centres(self._x[:3])[0] if per_m > 0 else None
            for r in rows:
                i = int(self._idx2[r, 0])
                if self._tracks[int(self._ids[r])].kind != "wall":
                    continue
                f2 = floor
                if per_m > 0:  # the floor at this landmark's range from the camera
                    rng = float(np.hypot(*(self._position_of_row(r) - centre)))
                    f2 = (self.config.landmark_sigma_floor + per_m * rng) ** 2
                if self._P[i, i] < f2:
                    self._P[i, i] = f2  # adds floor − P_ii ≥ 0 on the diagonal: P stays PSD
        return UpdateResult(self._ids[rows].copy(), nu2, nis, nis_total)

    def _known_points(self, points, measured, cov_measured, pan: float, cov_points):
        """The observation model of :meth:`update_known_points`: ``(nu (m, 2), J_I_X (m, 2, 3), R (m, 2, 2))``,
        ``R`` the measurement covariances plus the points' own projected into the images."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        z = np.asarray(measured, dtype=float).reshape(-1, 2)
        m = len(p)
        R = np.asarray(cov_measured, dtype=float)
        if R.shape != (m, 2, 2) or not np.isfinite(R).all():
            raise InputError(expected(f"a finite ({m}, 2, 2) array of covariances", R.shape,
                                      where="update_known_points.cov_measured"))
        if z.shape != (m, 2) or not (np.isfinite(z).all() and np.isfinite(p).all()):
            raise InputError(expected("finite (u_l, u_r) and positions, one per point", z,
                                      where="update_known_points"))
        uv, J_I_X, J_I_p = self._camera(pan).project_columns(self._x[:3], p, jacobians=True)
        if cov_points is not None:
            C = np.asarray(cov_points, dtype=float).reshape(m, 2, 2)
            R = R + J_I_p @ C @ np.swapaxes(J_I_p, 1, 2)
        return z - uv, J_I_X, R

    def update_known_points(self, points, measured, cov_measured, pan: float = 0.0, *,
                            cov_points=None) -> UpdateResult:
        """Update the pose with the observed columns of points whose map positions are known (not in the state).

        ``points`` (m, 2) [m] in the map frame, ``measured`` (m, 2) their ``(u_l, u_r)`` [px], ``cov_measured``
        (m, 2, 2) the measurement covariances [px²], ``cov_points`` (m, 2, 2) the points' own uncertainty in the
        map [m²] (projected into the images and added). ``H = [∂(u_l, u_r)/∂X, 0 …]`` touches the pose's
        columns only; the update is the stacked one of :meth:`update` (:meth:`_gain`), in Joseph form. ``ids`` of
        the result are the points' indices.
        """
        if len(np.asarray(points, dtype=float).reshape(-1, 2)) == 0:
            return UpdateResult()
        nu2, J_I_X, R = self._known_points(points, measured, cov_measured, pan, cov_points)
        if not np.isfinite(nu2).all():
            raise GeometryError("a known point is behind the camera; it cannot update the filter")
        m = len(nu2)
        ar = np.arange(m)
        blocks = np.zeros((m, 2, m, 2))
        blocks[ar, :, ar, :] = R
        nu = nu2.reshape(-1)
        with _one_blas_thread(len(self._x)):
            PHt, S, sol = self._gain(np.arange(3), J_I_X.reshape(2 * m, 3), nu, blocks.reshape(2 * m, 2 * m))
            K = sol[:, :-1].T
            self._x = self._x + K @ nu
            _add_sym_rank(self._P, 0.5 * (K @ S) - PHt, K)
        self._x[2] = wrap_angle(self._x[2])
        S_blocks = S.reshape(m, 2, m, 2)[ar, :, ar, :]
        nis = np.einsum("mi,mi->m", nu2, np.linalg.solve(S_blocks, nu2[..., None])[..., 0])
        return UpdateResult(ar, nu2, nis, float(nu @ sol[:, -1]))

    def known_point_nis(self, points, measured, cov_measured, pan: float = 0.0, *, cov_points=None) -> np.ndarray:
        """(m,) the NIS (2 dof) each known point's observation would have alone (:meth:`update_known_points`);
        infinite for a point behind the camera."""
        if len(np.asarray(points, dtype=float).reshape(-1, 2)) == 0:
            return np.zeros(0)
        nu, J_I_X, R = self._known_points(points, measured, cov_measured, pan, cov_points)
        S = J_I_X @ self._P[:3, :3] @ np.swapaxes(J_I_X, 1, 2) + R
        out = np.full(len(nu), np.inf)
        ok = np.isfinite(nu).all(axis=1)
        out[ok] = np.einsum("mi,mi->m", nu[ok], np.linalg.solve(S[ok], nu[ok][..., None])[..., 0])
        return out

    # ---------------------------------------------------------- serialisation
    def landmarks_to_dict(self) -> list[dict]:
        """The landmarks as plain dicts (JSON/YAML-able), in state order.

        Wall: ``id, kind, plane, edge, s, var_s``; point: ``id, kind, x, y, cov``; both: ``position,
        cov2d, z_low, z_high, n_observed, first_frame, last_frame, polarity``.
        """
        return [self.landmark(i).to_dict() for i in self.landmark_ids]

    def to_dict(self, *, joint: bool = False) -> dict:
        """Pose, pose covariance and landmarks as plain dicts; with ``joint`` also ``cov_landmarks``,
        the (D, D) covariance over all landmark state dimensions in state order (cross-covariances kept)."""
        d = {"pose": self.pose.tolist(), "cov_pose": self.cov_pose.tolist(), "landmarks": self.landmarks_to_dict()}
        if joint:
            d["cov_landmarks"] = self._P[self._l0:, self._l0:].tolist()
        return d

    def load_prior_landmarks(self, data, world_map: Map, *, source: str = "landmarks") -> list[int]:
        """Add a landmark map saved by :meth:`to_dict` / :meth:`landmarks_to_dict` (ids kept).

        ``data`` is a list of landmark dicts or a mapping with ``landmarks`` and optionally
        ``cov_landmarks`` (their joint covariance); without it the landmarks enter independent with their
        own variances. Wall landmarks name their plane in ``world_map``. They enter uncorrelated with the
        pose. Returns their ids.
        """
        joint = None
        if isinstance(data, Mapping):
            if "landmarks" not in data:
                raise ConfigError(f"{source}: missing field 'landmarks'")
            joint = data.get("cov_landmarks")
            data = data["landmarks"]
        if not isinstance(data, list):
            raise ConfigError(expected("a list of landmarks", type(data).__name__, where=source))
        new, ids, blocks = [], [], []
        for i, d in enumerate(data):
            lm, var = _parse_landmark(d, world_map, f"{source}: landmarks[{i}]")
            new.append(lm)
            ids.append(int(d["id"]))
            blocks.append(var)
        D = sum(lm.dim for lm in new)
        if joint is not None:
            try:
                cov = _covariance(joint, D, f"{source}: cov_landmarks")
            except InputError as exc:
                raise ConfigError(str(exc)) from None
        else:
            cov = scipy.linalg.block_diag(*blocks) if blocks else np.zeros((0, 0))
        try:
            out = self.add_landmarks(new, cov, ids=ids)
        except InputError as exc:
            raise ConfigError(f"{source}: {exc}") from None
        for lm_id, d in zip(out, data, strict=True):
            t = self._tracks[lm_id]
            t.n_observed = int(d.get("n_observed", 0))
            t.first_frame, t.last_frame = d.get("first_frame"), d.get("last_frame")
        return out


def _number(d: Mapping, key: str, where: str, *, nonneg: bool = False) -> float:
    if key not in d:
        raise ConfigError(f"{where}: missing field {key!r}")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v) or (nonneg and v < 0):
        raise ConfigError(expected("a non-negative number" if nonneg else "a finite number", v, where=f"{where}.{key}"))
    return float(v)


def _parse_landmark(d: object, world_map: Map, where: str) -> tuple[NewLandmark, np.ndarray]:
    """One saved landmark → (NewLandmark, its own covariance)."""
    if not isinstance(d, Mapping):
        raise ConfigError(expected("a mapping with id and kind", d, where=where))
    lm_id = d.get("id")
    if isinstance(lm_id, bool) or not isinstance(lm_id, int | np.integer):
        raise ConfigError(expected("an integer id", lm_id, where=f"{where}.id"))
    kind = d.get("kind")
    heights = {}
    for key in ("z_low", "z_high"):
        if d.get(key) is not None:
            heights[key] = _number(d, key, where)
    polarity = d.get("polarity", 0)
    if polarity not in (-1, 0, 1) or isinstance(polarity, bool):
        raise ConfigError(expected("-1, 0 or 1", polarity, where=f"{where}.polarity"))
    heights["polarity"] = int(polarity)
    if kind == "wall":
        plane_id = d.get("plane")
        try:
            plane = world_map[plane_id]
        except KeyError:
            raise ConfigError(expected(f"a plane of the map ({', '.join(p.id for p in world_map)})", plane_id,
                                       where=f"{where}.plane")) from None
        edge = d.get("edge", "p1")
        if edge not in EDGES:
            raise ConfigError(expected(f"one of {EDGES}", edge, where=f"{where}.edge"))
        lm = NewLandmark.wall(plane, _number(d, "s", where), edge, **heights)
        return lm, np.array([[_number(d, "var_s", where, nonneg=True)]])
    if kind == "point":
        lm = NewLandmark.point((_number(d, "x", where), _number(d, "y", where)), **heights)
        try:
            cov = _covariance(d.get("cov"), 2, f"{where}.cov")
        except InputError as exc:
            raise ConfigError(str(exc)) from None
        return lm, cov
    raise ConfigError(expected(f"one of {KINDS}", kind, where=f"{where}.kind"))
