"""The on-line loop over a whole frame source: it only loops (paper Sec 5).

:func:`run_online` feeds every :class:`~stablemarks.frames.Frame` of a
:class:`~stablemarks.frames.FrameSource` to a :class:`~stablemarks.localizer.Localizer`, steers a source
whose head follows commands (the simulator), calls the observers after each step and collects the
records. What a frame does is the localizer's business; what is done with the frames' records (logs,
figures, the evaluation's ground-truth bookkeeping) is the observers' and the caller's.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from .config import Config
from .estimation import JointEKF
from .frames import Frame, FrameSource, SteerableSource
from .localizer import Estimate, FrameRecord, Localizer
from .maps import Map
from .pipeline import FrameLandmarks


class Observer(Protocol):
    """Called after every step with the frame, its estimate and the localizer (read-only by contract)."""

    def __call__(self, frame: Frame, estimate: Estimate, localizer: Localizer) -> None: ...


@dataclass
class OnlineResult:
    """A whole run: per-frame records, the final filter and the first view's landmark model.

    ``truth_of`` (landmark id → true feature id), ``rejected_truth`` (true feature id → the reason the
    selection rejected it) and ``visible_truth`` (per frame, the true features in view) are filled by the
    evaluation's ground-truth observer (:class:`stablemarks.evaluation.TruthObserver`); empty otherwise.
    """

    name: str
    method: str
    records: list[FrameRecord]
    ekf: JointEKF
    world_map: Map
    first_view: FrameLandmarks | None = None
    truth_of: dict[int, str] = field(default_factory=dict)
    rejected_truth: dict[str, str] = field(default_factory=dict)
    cov0: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    visible_truth: list[list[str]] = field(default_factory=list)
    retired: dict = field(default_factory=dict)
    """Landmarks dropped from the filter during the run, as they were when dropped (id → estimate)."""

    def landmark(self, landmark_id: int):
        """A landmark of the run: in the final filter, or as it was when dropped."""
        if landmark_id in self.retired and landmark_id not in self.ekf.landmark_ids:
            return self.retired[landmark_id]
        return self.ekf.landmark(landmark_id)

    @property
    def stamps(self) -> np.ndarray:
        """(K,) frame times [s]."""
        return np.array([r.stamp for r in self.records])

    @property
    def poses(self) -> np.ndarray:
        """(K, 3) the estimate per frame, map frame."""
        return np.array([r.pose for r in self.records])

    @property
    def covs(self) -> np.ndarray:
        """(K, 3, 3) its covariance."""
        return np.array([r.cov_pose for r in self.records])

    @property
    def dead_reckoning(self) -> np.ndarray:
        """(K, 3) odometry alone from the start pose."""
        return np.array([r.dead_reckoning for r in self.records])

    @property
    def true_poses(self) -> np.ndarray | None:
        """(K, 3) the true poses, or None unless every frame has one."""
        if any(r.true_pose is None for r in self.records):
            return None
        return np.array([r.true_pose for r in self.records])


def run_online(
    source: FrameSource,
    localizer: Localizer | None = None,
    *,
    observers: Sequence[Observer] = (),
    progress: Callable[[int, int], None] | None = None,
    start_pose=None,
    start_cov=None,
    config: Config | None = None,
    method: str = "stablemarks",
    prior_landmarks=None,
) -> OnlineResult:
    """Step ``localizer`` through every frame of ``source`` and collect the records.

    Without a ``localizer`` one is made from the source's map and camera with the keyword arguments
    (``start_pose`` default: the source's ``initial_pose``, else the origin; ``config``: the source's
    defaults — :attr:`~stablemarks.frames.FrameSource.config_defaults` — fill what it leaves at the default).
    A steerable source (:class:`~stablemarks.frames.SteerableSource`) takes each frame's pan from
    :meth:`Localizer.command_pan`. ``progress(k, n)`` is called after each frame.
    """
    if localizer is None:
        config = (config or Config()).with_source_defaults(getattr(source, "config_defaults", None) or {})
        start = source.initial_pose if start_pose is None else start_pose
        localizer = Localizer(source.world_map, source.camera, start_pose=start, start_cov=start_cov,
                              config=config, method=method, prior_landmarks=prior_landmarks)
    if isinstance(source, SteerableSource):
        source.steer(localizer.command_pan)
    records: list[FrameRecord] = []
    first_view = None
    n = len(source)
    for frame in source:
        est = localizer.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        if first_view is None and est.model is not None:
            first_view = est.model
        record = est.record
        if frame.true_pose is not None:
            record = replace(record, true_pose=np.asarray(frame.true_pose, dtype=float))
        records.append(record)
        for observe in observers:
            observe(frame, est, localizer)
        if progress is not None:
            progress(len(records), n)
    return OnlineResult(source.name, localizer.method.name, records, localizer.ekf, localizer.world_map, first_view,
                        cov0=localizer.start_cov, retired=dict(localizer.retired))
