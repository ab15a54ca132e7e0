"""The on-line loop over a whole frame source: it only loops (paper Sec 5).

:func:`run_online` feeds every :class:`~stablemarks.frames.Frame` of a
:class:`~stablemarks.frames.FrameSource` to a :class:`~stablemarks.localizer.Localizer`, steers a source
whose head follows commands (the simulator), calls the observers after each step and collects the
records. What a frame does is the localizer's business; what is done with the frames' records (logs,
figures, the evaluation's ground-truth bookkeeping) is the observers' and the caller's.

How much of each frame the loop keeps is the caller's choice (``keep``): the whole :class:`FrameRecord`
(the evaluation and the smoother read the measurements and priors), only the :class:`PoseRecord` the
end-of-run outputs need (a long run whose log is streamed to disk by an observer,
:class:`stablemarks.io.results.LogWriter`), or nothing (a soak that only measures).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Literal, Protocol

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


@dataclass(frozen=True, slots=True)
class PoseRecord:
    """The slim part of a :class:`FrameRecord` that a run's end-of-run outputs read (trajectories, Figure 10,
    the motion summary, ``trajectory.kitti``): kept per frame by ``run_online(..., keep="poses")``.

    It has no measurements, priors, NIS or landmark lists: code that needs them fails on the attribute
    instead of reading an empty list.
    """

    index: int
    stamp: float
    pan: float
    pose: np.ndarray
    cov_pose: np.ndarray
    dead_reckoning: np.ndarray
    true_pose: np.ndarray | None
    n_landmarks: int

    @classmethod
    def of(cls, r: FrameRecord) -> PoseRecord:
        return cls(r.index, r.stamp, r.pan, r.pose, r.cov_pose, r.dead_reckoning, r.true_pose, r.n_landmarks)


Keep = Literal["records", "poses", "nothing"]
"""What :func:`run_online` keeps per frame: the whole :class:`FrameRecord`, its :class:`PoseRecord`, or none."""


@dataclass
class OnlineResult:
    """A whole run: per-frame records, the final filter and the first view's landmark model.

    ``records`` holds a :class:`FrameRecord` per frame, or a :class:`PoseRecord` per frame, or nothing,
    as ``run_online``'s ``keep`` asked; ``n_frames`` is the number of frames run either way.

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
    frames_run: int | None = None
    """Frames run when the records were not kept (``keep="nothing"``); None: one per record."""

    @property
    def n_frames(self) -> int:
        """The number of frames run."""
        return len(self.records) if self.frames_run is None else self.frames_run

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
    keep: Keep = "records",
) -> OnlineResult:
    """Step ``localizer`` through every frame of ``source`` and collect the records.

    Without a ``localizer`` one is made from the source's map and camera with the keyword arguments
    (``start_pose`` default: the source's ``initial_pose``, else the origin; ``config``: the source's
    defaults — :attr:`~stablemarks.frames.FrameSource.config_defaults` — fill what it leaves at the default).
    A steerable source (:class:`~stablemarks.frames.SteerableSource`) takes each frame's pan from
    :meth:`Localizer.command_pan`. A simulated source renders no images for a method that reads none
    (``uses_vision`` False: its ``rendering`` is set off). ``progress(k, n)`` is called after each frame.

    ``keep``: ``"records"`` (default) keeps every frame's :class:`FrameRecord`; ``"poses"`` only its
    :class:`PoseRecord` (the observers still see the whole record: stream the log with
    :class:`stablemarks.io.results.LogWriter`); ``"nothing"`` keeps no per-frame data (``result.n_frames``
    still counts the frames).
    """
    if keep not in ("records", "poses", "nothing"):
        raise ValueError(f"keep: expected 'records', 'poses' or 'nothing', got {keep!r}")
    if localizer is None:
        config = (config or Config()).with_source_defaults(getattr(source, "config_defaults", None) or {})
        start = source.initial_pose if start_pose is None else start_pose
        localizer = Localizer(source.world_map, source.camera, start_pose=start, start_cov=start_cov,
                              config=config, method=method, prior_landmarks=prior_landmarks)
    if isinstance(source, SteerableSource):
        source.steer(localizer.command_pan)
    if hasattr(source, "rendering"):  # a simulator renders only for a method that reads the images
        source.rendering = localizer.method.uses_vision
    records: list[FrameRecord] | list[PoseRecord] = []
    first_view = None
    n = len(source)
    done = 0
    for frame in source:
        est = localizer.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        if first_view is None and est.model is not None:
            first_view = est.model
        if frame.true_pose is not None:
            est = replace(est, record=replace(est.record, true_pose=np.asarray(frame.true_pose, dtype=float)))
        if keep == "records":
            records.append(est.record)
        elif keep == "poses":
            records.append(PoseRecord.of(est.record))
        done += 1
        for observe in observers:
            observe(frame, est, localizer)
        if progress is not None:
            progress(done, n)
    return OnlineResult(source.name, localizer.method.name, records, localizer.ekf, localizer.world_map, first_view,
                        cov0=localizer.start_cov, retired=dict(localizer.retired),
                        frames_run=done if keep == "nothing" else None)
