"""What a frame source gives the localizer: one :class:`Frame` at a time (the :class:`FrameSource` protocol).

A source is anything that yields stereo frames in order: a recorded sequence folder, a ROS bag, a KITTI or
EuRoC folder (:func:`stablemarks.io.open_sequence`), the simulator (:class:`stablemarks.sim.SimulatedSource`),
or a robot's driver in a user's own loop. The core never imports a source: it only reads these fields.

Frames (REP-103): the map frame is 2-D ``x, y`` [m] with ``theta`` [rad] counter-clockwise; the robot base
has ``x`` forward and ``y`` left; the pan [rad] is the stereo head's angle about the vertical relative to
the robot's heading (positive to the left).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from .geometry import StereoCamera
from .maps import Map


@dataclass(frozen=True, eq=False)
class Frame:
    """One rectified stereo frame with what the robot knew when it was taken.

    Attributes
    ----------
    index : position in the source, from 0.
    stamp : time [s].
    left, right : (H, W) ``uint8`` rectified grayscale images, left camera the reference; None from a simulator
        running a method that reads no images (:class:`stablemarks.sim.SimulatedSource`, ``rendering``).
    odometry : (3,) the wheel-odometry pose ``(x [m], y [m], theta [rad])`` in the odometry frame at
        ``stamp`` (only differences between frames are used).
    pan : the head's pan [rad] when the frame was taken.
    true_pose : (3,) the true pose in the map when known (simulation, ground truth), else None.
    truth : the simulator's ground truth of the frame's image edges (:class:`stablemarks.sim.FrameTruth`),
        for evaluation only; None for recordings.
    """

    index: int
    stamp: float
    left: np.ndarray
    right: np.ndarray
    odometry: np.ndarray
    pan: float = 0.0
    true_pose: np.ndarray | None = None
    truth: Any = None


@runtime_checkable
class FrameSource(Protocol):
    """A sequence of :class:`Frame` with the camera and the map they need (module docstring).

    Attributes
    ----------
    name : the recording's name (default output folder ``results/<name>``).
    camera : the rectified stereo head on its mount (pan 0).
    world_map : the map of walls.
    initial_pose : (3,) the robot's start in the map when the source knows it, else None.
    config_defaults : settings the source describes, as a configuration document ``{section: {key: value}}``
        (a simulated robot's odometry noise and pan policy); :meth:`stablemarks.Config.with_source_defaults`
        lets them fill what the user's configuration leaves at its default. Empty for most recordings.
    notes : sentences for the user about what was left out of the input.

    A source may also say whether each frame's pan was recorded (``pan_recorded``, True when absent): False
    when every frame is given the mount's pan because the recording has none (a ``frames.csv`` without its
    ``pan`` column, a bag without a pan topic or a moving joint on ``/tf``). ``stablemarks run`` warns then,
    unless the configuration says the head does not pan (``pan.policy: fixed``).
    """

    name: str
    camera: StereoCamera
    world_map: Map
    initial_pose: np.ndarray | None
    config_defaults: dict
    notes: list[str]

    def __len__(self) -> int: ...

    def __iter__(self) -> Iterator[Frame]: ...

    def close(self) -> None:
        """Release open files."""


@runtime_checkable
class SteerableSource(FrameSource, Protocol):
    """A source whose head follows the localizer's pan commands (a simulator, or a live robot).

    Before producing each frame the source asks ``pan_for(odometry)`` — with the wheel-odometry pose (3,) at
    which that frame is taken — for the pan to take it with; :meth:`stablemarks.Localizer.command_pan` is such
    a function.
    """

    def steer(self, pan_for: Callable[[np.ndarray], float] | None) -> None: ...
