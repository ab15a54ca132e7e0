"""Where the stereo head looks: the pan policies, a decision of the method (paper Sec 6 and beyond).

``fixed``
    hold ``pan.angle``.
``free_edges``
    the paper's rule (Sec 6): look at the midpoint of the free edges of the reference planes in sight
    (:func:`stablemarks.motion.look_at_free_edges`).
``information``
    among the pans the head can reach before the next frame (``pan.max_rate`` times the frame interval,
    within ``pan.limits``), the one whose view promises the most information (:func:`expected_information`):
    the predicted reduction of the pose covariance from the landmarks expected in view, plus
    ``pan.new_edge_value`` for every free edge in view whose wall holds no landmark yet (where new landmarks
    can be modelled). The criterion is in ``docs/viewing.md``.

Angles in radians, relative to the robot's heading (positive to the left); rates in rad/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import InputError, expected
from .geometry import StereoCamera
from .maps import Map, segments_block
from .motion import look_at_free_edges

PAN_POLICIES = ("fixed", "free_edges", "information")


@dataclass(frozen=True)
class PanConfig:
    """Where the stereo head looks (module docstring).

    Attributes
    ----------
    policy : one of :data:`PAN_POLICIES`.
    angle : the fixed pan, and the first pan while no free edge is in sight [rad].
    limits : ``[min, max]`` mechanical pan range [rad].
    max_rate : fastest pan [rad/s]; with the frame interval it bounds the pans ``information`` weighs.
    new_edge_value : ``information``: the value [nat] of a free edge in view whose wall has no landmark yet.
    candidates : ``information``: how many pans it weighs across the reachable range.
    """

    policy: str = "free_edges"
    angle: float = 0.0
    limits: tuple[float, float] = (-math.pi / 2, math.pi / 2)
    max_rate: float = math.radians(60.0)
    new_edge_value: float = 1.0
    candidates: int = 13

    def __post_init__(self) -> None:
        if self.policy not in PAN_POLICIES:
            raise InputError(expected(f"one of {', '.join(PAN_POLICIES)}", self.policy, where="pan.policy"))
        for name in ("angle", "max_rate", "new_edge_value"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InputError(expected("a finite number", v, where=f"pan.{name}"))
        if self.max_rate <= 0 or self.new_edge_value < 0:
            raise InputError(expected("a positive rate and a non-negative value", (self.max_rate, self.new_edge_value),
                                      where="pan.max_rate, pan.new_edge_value"))
        lim = self.limits
        ok = isinstance(lim, list | tuple) and len(lim) == 2 and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and -math.pi <= v <= math.pi
            for v in lim) and lim[0] < lim[1]
        if not ok:
            raise InputError(expected("[min, max] in radians within [-pi, pi], min < max", lim, where="pan.limits"))
        object.__setattr__(self, "limits", (float(lim[0]), float(lim[1])))
        c = self.candidates
        if isinstance(c, bool) or not isinstance(c, int) or not 2 <= c <= 181:
            raise InputError(expected("a whole number in [2, 181]", c, where="pan.candidates"))


def choose_pan(config: PanConfig, world_map: Map, camera: StereoCamera, X, previous: float | None = None, *,
               ekf=None, dt: float | None = None, max_incidence: float | None = None) -> float:
    """The pan [rad] ``config.policy`` chooses for a frame taken at the believed pose ``X`` (3,), given the
    ``previous`` pan (None before the first frame), the filter ``ekf`` (for ``information``; its pose is
    ignored, ``X`` is used) and the frame interval ``dt`` [s] (None: the head reaches any pan).
    ``max_incidence`` [rad]: free edges on walls seen more obliquely are not looked for (nothing is modelled
    or associated there; :func:`~stablemarks.motion.look_at_free_edges`)."""
    lo, hi = config.limits
    start = config.angle if previous is None else previous
    if config.policy == "fixed":
        return float(np.clip(config.angle, lo, hi))
    paper = look_at_free_edges(world_map, camera, X, limits=(lo, hi), default=start, max_incidence=max_incidence)
    if config.policy == "free_edges" or ekf is None:
        return paper
    reach = np.inf if dt is None or previous is None else config.max_rate * dt
    a, b = max(lo, start - reach), min(hi, start + reach)
    grid = np.linspace(a, b, config.candidates)
    pans = np.unique(np.concatenate([grid, [np.clip(paper, a, b), np.clip(start, a, b)]]))
    scores = [expected_information(ekf, world_map, camera, X, p, config.new_edge_value, max_incidence)
              for p in pans]
    best = float(pans[int(np.argmax(scores))])
    # ties (nothing to gain anywhere): the paper's choice
    return best if max(scores) > scores[int(np.argmin(np.abs(pans - np.clip(paper, a, b))))] + 1e-9 else \
        float(np.clip(paper, a, b))


def expected_information(ekf, world_map: Map, camera: StereoCamera, X, pan: float, new_edge_value: float,
                         max_incidence: float | None = None) -> float:
    """What a frame taken at pose ``X`` with the head at ``pan`` promises [nat]: the sum of the
    ``ekf.config.max_updates_per_frame`` largest expected information gains about the pose
    (:meth:`JointEKF.information_gain`, each ``½ log det P_XX / det P_XX|z``) of the landmarks predicted inside
    both images (with ``ekf.update_selection: joint``, the information those the filter would choose give
    together, :meth:`JointEKF.joint_information`), plus ``new_edge_value`` for every free edge of a reference
    plane in view (in the image, on its wall's visible side, not hidden by another wall) whose wall holds no
    landmark. With ``max_incidence`` [rad],
    landmarks and free edges on walls seen more obliquely count for nothing (they are neither associated nor
    modelled: :meth:`JointEKF.visible`, ``landmarks.max_incidence_deg``)."""
    total = 0.0
    ids = ekf.landmark_ids
    if ids:
        with ekf.linearised_at(X):
            seen = [int(i) for i in ekf.visible(pan, max_incidence)]
            k = ekf.config.max_updates_per_frame
            if seen and ekf.config.update_selection == "joint":
                # what the k the filter would update with give together (ekf.update_selection)
                order = ekf.joint_selection(seen, pan, k) if len(seen) > k else list(range(len(seen)))
                if order is not None:
                    total += ekf.joint_information([seen[j] for j in order], pan)
                    seen = []
            if seen:
                gains = np.sort(ekf.information_gain(seen, pan))[::-1]
                total += float(np.sum(gains[:k]))
    if new_edge_value > 0:
        cam = camera.with_pan(pan)
        centre = cam.optical_centres(X)[0]
        with_landmarks = {ekf.landmark_plane(i).id for i in ids if ekf.landmark_plane(i) is not None}
        walls = world_map.segments()
        for k, plane in enumerate(world_map.planes):
            if not plane.reference or plane.id in with_landmarks or not plane.faces(centre):
                continue
            for e in plane.free_edges:
                p = plane.edge(e)
                if not plane.seen_within(centre, p, max_incidence):
                    continue
                uv = cam.project_columns(X, p)
                if not (np.all(np.isfinite(uv)) and np.all(cam.in_image(uv, 10.0))):
                    continue
                if segments_block(centre, p, walls, exclude=[k])[0]:
                    continue
                total += new_edge_value
    return total
