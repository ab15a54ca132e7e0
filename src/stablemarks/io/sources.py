"""Opening recorded runs as frame sources for the on-line loop (:func:`stablemarks.online.run_online`).

A source gives the camera, the map, the start pose, and per frame the stamp, the odometry increment with
its covariance, the head's pan and the rectified stereo pair.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import SequenceError


def open_source(path: str | Path, *, noise=None, start_pose=None):
    """Open a recorded sequence folder (our format, see :mod:`stablemarks.io.sequence`)."""
    from ..online import SequenceSource
    from .sequence import SEQUENCE_FILE, load_sequence

    p = Path(path)
    if not p.exists():
        raise SequenceError(f"{p}: no such folder")
    if p.is_dir() and (p / SEQUENCE_FILE).exists():
        return SequenceSource(load_sequence(p), noise=noise, start_pose=start_pose)
    raise SequenceError(f"{p}: not a recorded sequence: expected a folder with {SEQUENCE_FILE} (see README)")
