"""Knowing when the localizer is lost: health conditions checked frame by frame.

:class:`HealthMonitor` watches the records of :meth:`stablemarks.Localizer.step` and reports, in
``Estimate.health`` and on every line of ``log.jsonl``, each condition that holds (one sentence each, the
condition's name first):

``edges_not_found``
    a free edge searched in each of ``edges_frames`` frames in a row (predicted in the searchable image) was
    not found, or found where the map does not put it (an end found hidden behind something nearer that the map
    does not hold counts neither way: it is no evidence about the pan), or the walls in view were turned together
    from the map (their slopes share one turn far beyond the heading's uncertainty and agree on it,
    :func:`stablemarks.landmarks.common_turn`: a wrong pan turns every wall the same way, a slip or a kidnap
    shifts them): the head's pan (or the pose) is probably wrong. While it holds nothing is associated, updated
    or entered: the walls are not where the pan says, so the pose follows the odometry; a frame whose walls are
    turned together is not used even before it holds. It clears after ``edges_frames`` frames in a row find every
    searched edge where the map puts it with the walls not turned together, and, when a turn of the walls raised
    it, turned back from that turn beyond the heading's drift since (the heading's uncertainty grows while the
    pose follows the odometry and would otherwise soon take in the pan's error).
``inconsistent``
    the joint NIS of the frame's update above its 99 % χ² bound for ``nis_frames`` frames in a row.
``odometry_disagrees``
    a wall's pattern of landmarks was matched along the wall (which does not depend on the pose) but the whole
    pattern is incompatible with the predicted pose, in ``disagree_frames`` frames in a row: the odometry and
    the images disagree (a wheel slip, a kidnap). A pattern counts only if one of its landmarks was observed again
    since the frame that entered it: landmarks entered one odometry step ago that already disagree were more likely
    entered wrong (under a wrong pan) than witness a slip. The localizer then widens the pose covariance just enough for
    the pattern to fit (:meth:`stablemarks.Localizer.step`) and updates from it. When no landmark and no pattern
    is found at all (a kidnap that moved the walls beyond even the widened bands) in ``relocalize_frames`` frames
    in a row while the walls fitted in the frame disagree with the pose, or a frame finds fewer than half the
    landmarks in view, the pose is re-initialised where the frame's own lines put the most landmarks, within
    ``relocalize_radius`` (:func:`stablemarks.estimation.relocalize.pose_from_lines`; after a frame that found
    some, only where twice as many lie on a line as at the pose those found give), else the walls fitted in
    the frame, their slopes in agreement with the map, relocalize a copy of the filter across them; either is
    kept, and the condition holds, only if a pattern of ``min_pattern`` landmarks then associates and fits
    (``Localizer._relocalize``).
``blind``
    no landmark observed for ``blind_frames`` frames in a row (while the filter holds landmarks).
``heading_drift``
    over the last ``drift_frames`` frames the images turned the heading away from the odometry's by more than
    ``drift_sigma`` σ of what the odometry's heading noise over those frames and the filter's heading uncertainty
    at both ends allow. A head pan that changes without being recorded (a recording without its pan, a wrong
    pan topic) turns the walls slowly; the filter takes the turn into the heading frame by frame, each step
    within its gates, and ``edges_not_found`` never holds (the corridor with its pans left out: 0.2 rad taken in
    over 30 frames, ATE three times dead reckoning's). It also holds when the pose had to be recovered
    (``odometry_disagrees``) in ``max_recoveries`` of the last ``recoveries_frames`` frames (a slip or a kidnap is
    an event; the images and the odometry disagreeing again and again is a wrong model: the corridor without its
    pans, eight recoveries in 42 frames), and when, after such a recovery within ``recoveries_frames`` frames, the
    free edges are not found where the map puts them in ``edges_frames`` frames in a row after it (frames before it
    do not count: the edges missed in a blind turn are what a recovery corrects): a pose recovered from a true slip puts
    the walls back where the map has them, one recovered from lines seen under a wrong pan does not (the corridor
    without its pans, with ``noise.boundary_px`` 0.5: one recovery at frame 30, the edges missed from frame 41 on,
    and the recovered pose held 1.42 times dead reckoning's ATE). From then on the estimate is dead reckoning (the pose
    and its covariance from the start pose and the odometry alone: the images' history is not to be trusted) and
    nothing is associated, updated or entered; it holds for the rest of the run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ConfigError, expected

CONDITIONS = ("edges_not_found", "inconsistent", "odometry_disagrees", "blind", "heading_drift")


@dataclass(frozen=True)
class HealthConfig:
    """Thresholds of the health conditions (module docstring): frames in a row before each one holds."""

    edges_frames: int = 3
    nis_frames: int = 3
    disagree_frames: int = 1
    blind_frames: int = 10
    max_inflation: float = 1e4
    """Largest factor the pose covariance is widened by to fit a disagreeing pattern."""
    min_pattern: int = 3
    """A wall's pattern must match at least this many landmarks to count as evidence that the odometry is
    wrong (two lines can be matched one feature over, or be fitted by a translation where a wrong pan turned the
    view)."""
    search_inflation: float = 25.0
    """When the walls are not found where the prediction puts them, they are looked for again with the pose
    covariance widened by this factor (5 σ for 1 σ), before a slip or kidnap can be recognised."""
    relocalize_frames: int = 2
    """Frames in a row with no landmark found and the walls fitted away from the pose before the walls relocalize
    it (``odometry_disagrees``): one such frame also happens on clean runs (the office, a turn: a wall fit 2 cm
    off, and a pattern of three landmarks fitted the pose relocalized 7 cm away)."""
    relocalize_radius: float = 2.0
    """How far [m] from the predicted pose a relocalization from the landmarks on the frame's lines looks
    (``Localizer._relocalize``): the largest slip or kidnap it recovers from."""
    relocalize_tol_px: float = 10.0
    """A landmark is on one of the frame's lines, for a pose made from two lines, when both its columns are within
    this [px]: two triangulated lines 3 m away are each a few cm off in depth, which moves the other landmarks'
    predictions by several pixels (the pose is then refitted to all of them and checked with 3 σ_img)."""
    few_found_p: float = 0.01
    """A pattern of fewer than ``min_pattern`` landmarks is not used when finding so few of the landmarks predicted
    in view is less likely than this, given how often the run has found the landmarks in its view (binomial).
    After an odometry error in a turn every prediction moves by tens of pixels, and two neighbouring lines can
    fit two landmarks together (loop: 2 of 8 in view found, heading held 4.8° off with σ 0.1°, pose NEES 28000);
    on clean runs a landmark in view is found 84–94 % of the time (loop, office, hall), so 2 of 8 happens with
    probability 2·10⁻⁴ and 2 of 5 with 0.03."""
    drift_frames: int = 5
    """Frames over which the heading the images give is compared with the odometry's (``heading_drift``)."""
    drift_sigma: float = 4.0
    """How many σ the images may turn the heading from the odometry's over ``drift_frames`` frames before
    ``heading_drift`` holds. Measured on clean runs of every built-in scenario (first trials, and two more of
    corridor, office and hall): at most 2.5 σ over 5 frames; the corridor with its pans left out: 4 σ at frame
    24, 5 σ at 25."""

    max_recoveries: int = 3
    """``heading_drift`` holds when the pose had to be recovered (``odometry_disagrees``) in this many of the last
    ``recoveries_frames`` frames (none on clean runs of the built-in scenarios; one after a slip or a kidnap)."""
    recoveries_frames: int = 20

    def __post_init__(self) -> None:
        for name in ("edges_frames", "nis_frames", "disagree_frames", "blind_frames", "min_pattern", "drift_frames",
                     "relocalize_frames", "max_recoveries", "recoveries_frames"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(expected("a positive integer", v, where=f"health.{name}"))
        v = self.few_found_p
        if isinstance(v, bool) or not isinstance(v, int | float) or not 0 <= v < 1:
            raise ConfigError(expected("a probability in [0, 1)", v, where="health.few_found_p"))
        for name in ("relocalize_radius", "relocalize_tol_px"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v) and v > 0):
                raise ConfigError(expected("a positive number", v, where=f"health.{name}"))
        for name in ("max_inflation", "search_inflation", "drift_sigma"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not v >= 1:
                raise ConfigError(expected("a number >= 1", v, where=f"health.{name}"))


_PAN_OR_ODOMETRY = ("the head's pan may be wrong or changing unrecorded (a bag's pan comes from `pan_topic`, a "
                    "sequence folder's from the pan column of frames.csv), or the odometry's heading noise "
                    "(odometry.rot_per_m_deg, odometry.rot_per_rad) is set too small; the estimate is dead reckoning "
                    "from here on and nothing is updated from the images")

MESSAGES = {
    "edges_not_found": "edges_not_found: free edges of the map predicted in view were not found where the map puts "
                       "them for {n} frames: "
                       "the head's pan may be wrong (a bag's pan comes from `pan_topic`, a sequence folder's from the "
                       "pan column of frames.csv); no new landmarks are entered meanwhile",
    "inconsistent": "inconsistent: the joint NIS of the update was above its 99 % bound for {n} frames: the filter "
                    "is inconsistent or diverging",
    "odometry_disagrees": "odometry_disagrees: the landmarks on a wall all pull the same way, incompatible with the "
                          "odometry (a wheel slip or a kidnap?): the pose covariance was widened ×{factor:.3g}",
    "odometry_disagrees_reinitialised": "odometry_disagrees: the landmarks in view were found together far from "
                                        "where the odometry puts them (a wheel slip or a kidnap?): the pose was "
                                        "re-initialised from the landmarks on the frame's lines",
    "blind": "blind: no landmark observed for {n} frames",
    "heading_drift": "heading_drift: the images turned the heading {drift:+.1f}° from the odometry's over {w} frames "
                     "({z:.1f} σ): " + _PAN_OR_ODOMETRY,
    "heading_drift_recoveries": "heading_drift: the images and the odometry disagreed in {r} of the last {rw} frames "
                                "(each taken for a wheel slip or a kidnap): " + _PAN_OR_ODOMETRY,
    "heading_drift_unconfirmed": "heading_drift: the pose recovered in the last {rw} frames (taken for a wheel slip or "
                                 "a kidnap) was not confirmed: the free edges were then not found where the map puts "
                                 "them: " + _PAN_OR_ODOMETRY,
}


class HealthMonitor:
    """Counts each condition's frames in a row and says which hold (:meth:`update`)."""

    def __init__(self, config: HealthConfig = HealthConfig()):
        self.config = config
        self.runs = dict.fromkeys(CONDITIONS, 0)
        self.edges_latched = False
        self.drift: tuple[float, float] | None = None
        """``(turn [deg], z)`` when ``heading_drift`` first held (it then holds for the rest of the run)."""
        self._clean = 0

    def update(self, *, edges_missing: bool, nis_high: bool, disagree: bool, observed: bool, has_landmarks: bool,
               inflation: float = 1.0, edges_found: bool | None = None,
               drift: tuple[float, float] | None = None, reinitialised: bool = False) -> list[str]:
        """Advance the counters by one frame; returns the sentences of the conditions that hold now.

        ``edges_found``: whether the frame found its walls where the map puts them, which is what clears
        ``edges_not_found`` (default: not ``edges_missing``; a frame can be neither, e.g. one wall turned).
        ``drift``: ``(turn [deg], z)`` when the images turned the heading from the odometry's beyond
        ``drift_sigma`` in this frame (``heading_drift`` then holds from now on); a third item ``"recoveries"`` says
        it holds for too many recoveries instead, ``"unconfirmed"`` for a recovery the free edges did not confirm.
        ``reinitialised``: the pose was re-initialised from the landmarks in this frame rather than its covariance
        widened (the sentence of ``odometry_disagrees`` says so)."""
        c = self.config
        found = _found(edges_missing, edges_found)
        if drift is not None and self.drift is None:
            self.drift = drift
        now = {"edges_not_found": edges_missing, "inconsistent": nis_high, "odometry_disagrees": disagree,
               "blind": has_landmarks and not observed, "heading_drift": self.drift is not None}
        for k, v in now.items():
            self.runs[k] = self.runs[k] + 1 if v else 0
        # edges_not_found holds until as many frames in a row find every searched edge where the map puts it
        self._clean = self._clean + 1 if found else 0
        if self.runs["edges_not_found"] >= c.edges_frames:
            self.edges_latched = True
        elif self._clean >= c.edges_frames:
            self.edges_latched = False
        if self.edges_latched:
            self.runs["edges_not_found"] = max(self.runs["edges_not_found"], c.edges_frames)
        turn, z, kind = (*self.drift, "turn")[:3] if self.drift is not None else (0.0, 0.0, "turn")

        def message(k):
            if k == "odometry_disagrees" and reinitialised:
                return MESSAGES["odometry_disagrees_reinitialised"]
            if k == "heading_drift" and kind != "turn":
                return MESSAGES[f"heading_drift_{kind}"]
            return MESSAGES[k]
        return [message(k).format(n=self.runs[k], factor=inflation, drift=turn, z=z, w=c.drift_frames,
                                  r=c.max_recoveries, rw=c.recoveries_frames)
                for k in CONDITIONS if self.holds(k)]

    def suspect_edges(self, edges_missing: bool, edges_found: bool | None = None) -> bool:
        """Whether, with this frame's ``edges_missing`` (and ``edges_found``, :meth:`update`), ``edges_not_found``
        will hold after :meth:`update`."""
        c = self.config.edges_frames
        if self.edges_latched:
            found = _found(edges_missing, edges_found)
            return not found or self._clean + 1 < c
        return edges_missing and self.runs["edges_not_found"] + 1 >= c

    @property
    def active(self) -> bool:
        """Whether any condition held at the last update."""
        return any(self.holds(k) for k in CONDITIONS)

    def holds(self, name: str) -> bool:
        """Whether condition ``name`` held at the last update."""
        c = self.config
        need = {"edges_not_found": c.edges_frames, "inconsistent": c.nis_frames,
                "odometry_disagrees": c.disagree_frames, "blind": c.blind_frames, "heading_drift": 1}[name]
        return self.runs[name] >= need


def _found(edges_missing: bool, edges_found: bool | None) -> bool:
    """Whether a frame found its walls where the map puts them (what clears ``edges_not_found``): not
    ``edges_missing``, and ``edges_found`` when given (a frame can be neither, e.g. one wall turned)."""
    return not edges_missing if edges_found is None else edges_found and not edges_missing
