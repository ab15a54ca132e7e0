"""A simulated run as a frame source (:class:`~stablemarks.frames.FrameSource`), rendered frame by frame.

The robot's head follows the localizer's pan commands (the source is steerable): before rendering frame
``k`` it asks ``pan_for(odometry_k)`` — the pan the method wants at the odometry pose of that frame. Without
a command the run's own pans are used (the scenario's policy applied to dead reckoning, as
``stablemarks simulate`` records them).

With ``rendering = False`` (:func:`~stablemarks.online.run_online` sets it for a method that reads no images,
``dead_reckoning``) nothing is rendered: the frames have no images (``left``, ``right`` None) and their truth
is the geometric part only (:meth:`~stablemarks.sim.render.Renderer.truth`). Each frame's images draw from
their own random stream (:meth:`~stablemarks.sim.run.Run.frame_rng`), so skipping them changes no other draw.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator

import numpy as np

from ..frames import Frame
from .render import Renderer, renderer_for
from .run import Run


class SimulatedSource:
    """The frames of a simulated :class:`~stablemarks.sim.run.Run`, rendered on demand.

    ``stamp_step`` [s] between frames. ``initial_pose`` is the true start; ``config_defaults`` carries the
    scenario's odometry noise and pan policy for the localizer's configuration.
    """

    def __init__(self, run: Run, renderer: Renderer | None = None, stamp_step: float = 0.5, frames: int | None = None):
        self.run = run
        self.scenario = run.scenario
        self.name = run.scenario.name
        self.camera = run.scenario.camera
        self.world_map = run.scenario.map
        self.initial_pose = run.poses[0].as_array()
        self.renderer = renderer or renderer_for(run.scenario)
        self.stamp_step = stamp_step
        self.notes: list[str] = []
        self.pan_recorded = True  # every frame's pan is the simulated head's
        self.rendering = True
        self._n = len(run) if frames is None else min(int(frames), len(run))
        self._pan_for: Callable[[np.ndarray], float] | None = None
        plan = self.scenario.robot.pan
        lo, hi = self.scenario.pan_limits
        self.config_defaults = {
            "odometry": dataclasses.asdict(self.scenario.robot.odometry),
            "pan": {"policy": "fixed" if plan.policy == "fixed" else "free_edges", "angle": float(plan.angle),
                    "limits": [float(lo), float(hi)]},
        }

    def __len__(self) -> int:
        return self._n

    def steer(self, pan_for: Callable[[np.ndarray], float] | None) -> None:
        """Take each frame's pan from ``pan_for(odometry pose)`` (None: the run's recorded pans)."""
        self._pan_for = pan_for

    def frame(self, k: int, pan: float | None = None) -> Frame:
        """Frame ``k`` rendered with ``pan`` (default: the run's pan of that frame)."""
        odometry = self.run.dead_reckoning[k].as_array()
        pan = float(self.run.pans[k] if pan is None else pan)
        X = self.run.poses[k].as_array()
        left, right, truth = self._shot(k, X, pan)
        return Frame(k, k * self.stamp_step, left, right, odometry, pan, true_pose=X, truth=truth)

    def _shot(self, k: int, X, pan: float) -> tuple:
        """``(left, right, truth)`` of frame ``k`` taken from true pose ``X`` with ``pan``; without ``rendering``
        ``(None, None, geometric truth)``, nothing rendered and no random draw."""
        if not self.rendering:
            return None, None, self.renderer.truth(X, pan)
        sim = self.renderer.render(X, pan, self.run.frame_rng(k))
        return sim.left, sim.right, sim.truth

    def __iter__(self) -> Iterator[Frame]:
        for k in range(len(self)):
            pan = None
            if self._pan_for is not None:
                pan = self._pan_for(self.run.dead_reckoning[k].as_array())
            yield self.frame(k, pan)

    def close(self) -> None:
        """Nothing to release."""


def steered_by_method(run: Run, n_frames: int | None = None, *, config=None,
                      progress: Callable[[int, int], None] | None = None) -> Run:
    """``run`` with the pans its head takes when the method points it: the first ``n_frames`` frames (all by
    default) rendered and run through a :class:`~stablemarks.Localizer` that commands each frame's pan
    (:meth:`~stablemarks.Localizer.command_pan`, the configuration's ``pan`` section; ``config`` default: the
    defaults with the scenario's odometry noise and pan policy), as a robot whose localizer steers its head.
    The run's own pans (the scenario's rule applied to dead reckoning, :func:`~stablemarks.sim.run.simulate_run`)
    follow the robot's drifting belief; after a few metres they point the head where the walls are not, and a
    sequence recorded with them goes blind where the method would not (office: no landmark seen for 18 frames
    from frame 62). The frames after ``n_frames`` keep the run's pans. ``progress(k, n)`` after each frame."""
    from ..online import run_online

    n = len(run) if n_frames is None else int(n_frames)
    source = SimulatedSource(run, frames=n)
    pans: list[float] = []
    run_online(source, config=config, keep="nothing", progress=progress,
               observers=[lambda frame, _est, _loc: pans.append(float(frame.pan))])
    return dataclasses.replace(run, pans=tuple(pans) + tuple(run.pans[n:]))
