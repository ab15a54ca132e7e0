"""A simulated run written as a recorded-sequence folder (``stablemarks simulate``).

The simulator renders; :mod:`stablemarks.io.sequence` writes the folder. The folder then runs like any
recording (``stablemarks run``), with the run's ground truth beside it for evaluation.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError, expected
from ..io.sequence import FRAME_PERIOD, image_name, write_sequence
from .run import Run


def write_simulated_sequence(
    run: Run,
    out_dir: str | Path,
    *,
    n_frames: int | None = None,
    period: float = FRAME_PERIOD,
    force: bool = False,
    on_frame: Callable[[int], None] | None = None,
) -> Path:
    """Render the first ``n_frames`` frames of a simulated run (all by default) into a sequence folder.

    Frame ``k`` is stamped ``k · period`` [s]. ``odometry.csv`` holds the run's dead reckoning (its noisy
    odometry integrated from the true start), ``groundtruth.tum`` the true poses, ``groundtruth.json`` the
    run's header and each frame's truth (:meth:`Run.record`) with its stamp and image paths, and
    ``sequence.yaml`` the true start as ``initial_pose``. ``on_frame(k)`` is called after frame ``k`` is
    written (a progress bar). Atomic as :func:`write_sequence`.
    """
    if n_frames is None:
        n_frames = len(run)
    if isinstance(n_frames, bool) or not isinstance(n_frames, int | np.integer) or not 1 <= n_frames <= len(run):
        raise InputError(expected(f"a number of frames in [1, {len(run)}]", n_frames, where="frames"))
    if not (math.isfinite(period) and period > 0):
        raise InputError(expected("a positive frame period [s]", period, where="period"))
    n = int(n_frames)
    stamps = period * np.arange(n)
    records: list[dict] = []

    def images() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for k in range(n):
            frame = run.render(k)
            records.append({"stamp": float(stamps[k]), "left": image_name("left", k),
                            "right": image_name("right", k), **run.record(k, frame)})
            yield frame.left, frame.right
            if on_frame is not None:
                on_frame(k)

    scenario = run.scenario
    return write_sequence(
        out_dir,
        name=scenario.name,
        description=f"simulated run of scenario {scenario.name!r} ({scenario.source}), seed {run.seed}, "
                    f"{n} of {len(run)} frames",
        camera=scenario.camera,
        world_map=scenario.map,
        stamps=stamps,
        odometry=np.array([p.as_array() for p in run.dead_reckoning[:n]]),
        pans=np.array(run.pans[:n]),
        images=images(),
        groundtruth=np.array([p.as_array() for p in run.poses[:n]]),
        truth=lambda: {**run.header(), "n_frames": n, "frame_period": period, "frames": records},
        initial_pose=scenario.robot.start,
        force=force,
    )
