"""Knowing when the localizer is lost: health conditions checked frame by frame.

:class:`HealthMonitor` watches the records of :meth:`stablemarks.Localizer.step` and reports, in
``Estimate.health`` and on every line of ``log.jsonl``, each condition that holds (one sentence each, the
condition's name first):

``edges_not_found``
    free edges of the map predicted in view for ``edges_frames`` frames in a row, none found: the head's pan
    (or the pose) is probably wrong. While it holds no new landmark is entered.
``inconsistent``
    the joint NIS of the frame's update above its 99 % χ² bound for ``nis_frames`` frames in a row.
``odometry_disagrees``
    a wall's pattern of landmarks was matched along the wall (which does not depend on the pose) but the whole
    pattern is incompatible with the predicted pose, in ``disagree_frames`` frames in a row: the odometry and
    the images disagree (a wheel slip, a kidnap). The localizer then widens the pose covariance just enough for
    the pattern to fit (:meth:`stablemarks.Localizer.step`) and updates from it.
``blind``
    no landmark observed for ``blind_frames`` frames in a row (while the filter holds landmarks).
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import ConfigError, expected

CONDITIONS = ("edges_not_found", "inconsistent", "odometry_disagrees", "blind")


@dataclass(frozen=True)
class HealthConfig:
    """Thresholds of the health conditions (module docstring): frames in a row before each one holds."""

    edges_frames: int = 5
    nis_frames: int = 3
    disagree_frames: int = 1
    blind_frames: int = 10
    max_inflation: float = 1e4
    """Largest factor the pose covariance is widened by to fit a disagreeing pattern."""

    def __post_init__(self) -> None:
        for name in ("edges_frames", "nis_frames", "disagree_frames", "blind_frames"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(expected("a positive integer", v, where=f"health.{name}"))
        if not (isinstance(self.max_inflation, int | float) and self.max_inflation >= 1):
            raise ConfigError(expected("a number >= 1", self.max_inflation, where="health.max_inflation"))


MESSAGES = {
    "edges_not_found": "edges_not_found: free edges of the map predicted in view were not found for {n} frames: "
                       "the head's pan may be wrong (a bag's pan comes from `pan_topic`, a sequence folder's from the "
                       "pan column of frames.csv); no new landmarks are entered meanwhile",
    "inconsistent": "inconsistent: the joint NIS of the update was above its 99 % bound for {n} frames: the filter "
                    "is inconsistent or diverging",
    "odometry_disagrees": "odometry_disagrees: the landmarks on a wall all pull the same way, incompatible with the "
                          "odometry (a wheel slip or a kidnap?): the pose covariance was widened ×{factor:.3g}",
    "blind": "blind: no landmark observed for {n} frames",
}


class HealthMonitor:
    """Counts each condition's frames in a row and says which hold (:meth:`update`)."""

    def __init__(self, config: HealthConfig = HealthConfig()):
        self.config = config
        self.runs = dict.fromkeys(CONDITIONS, 0)

    def update(self, *, edges_missing: bool, nis_high: bool, disagree: bool, observed: bool, has_landmarks: bool,
               inflation: float = 1.0) -> list[str]:
        """Advance the counters by one frame; returns the sentences of the conditions that hold now."""
        c = self.config
        now = {"edges_not_found": edges_missing, "inconsistent": nis_high, "odometry_disagrees": disagree,
               "blind": has_landmarks and not observed}
        for k, v in now.items():
            self.runs[k] = self.runs[k] + 1 if v else 0
        need = {"edges_not_found": c.edges_frames, "inconsistent": c.nis_frames,
                "odometry_disagrees": c.disagree_frames, "blind": c.blind_frames}
        return [MESSAGES[k].format(n=self.runs[k], factor=inflation) for k in CONDITIONS if self.runs[k] >= need[k]]

    def holds(self, name: str) -> bool:
        """Whether condition ``name`` held at the last update."""
        need = {"edges_not_found": self.config.edges_frames, "inconsistent": self.config.nis_frames,
                "odometry_disagrees": self.config.disagree_frames, "blind": self.config.blind_frames}[name]
        return self.runs[name] >= need
