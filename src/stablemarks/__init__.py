"""stablemarks: on-line selection of stable visual landmarks under uncertainty.

A library (geometry, maps, stereo front end, plane fitting, landmark modeling and selection, joint
EKF) and the ``stablemarks`` command built on it. The library never imports the CLI or plotting.

The streaming API::

    import stablemarks as sm
    seq = sm.open_sequence("DIR")                 # a sequence folder, a ROS bag, a KITTI or EuRoC folder
    loc = sm.Localizer(seq.world_map, seq.camera, start_pose=seq.initial_pose, config=sm.Config())
    for frame in seq:
        est = loc.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        est.pose, est.cov, est.pan_command, est.health

Names are imported on first use, so ``import stablemarks.geometry`` stays light.
"""

from __future__ import annotations

import importlib

from .errors import StablemarksError

__version__ = "0.1.0"

_LAZY = {
    "Config": "config",
    "Localizer": "localizer",
    "Estimate": "localizer",
    "FrameRecord": "localizer",
    "Frame": "frames",
    "FrameSource": "frames",
    "run_online": "online",
    "OnlineResult": "online",
    "open_sequence": "io.sources",
    "load_map": "maps",
    "StereoCamera": "geometry",
    "SE2": "geometry",
    "Map": "maps",
    "SimulatedSource": "sim.source",
}

__all__ = ["StablemarksError", "__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
