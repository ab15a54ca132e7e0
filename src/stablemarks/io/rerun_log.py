"""An on-line run as a rerun recording (``.rrd``), for the rerun viewer (``pip install
'stablemarks[rerun]'``, then ``rerun run.rrd``). matplotlib figures stay the default; this is optional.

What is logged (map frame, metres, ``z`` up, REP-103), on the timelines ``frame`` (index) and ``time``
(the frame stamp [s]):

``world/walls``                 the map's walls as rectangles from ``z_low`` to ``z_high``: reference planes
                                blue, other walls grey; ``world/walls/free_edges`` orange verticals
``world/landmarks``             every landmark the filter holds in that frame, at its estimate then: a
                                vertical line over its height and, on the floor, its 2σ uncertainty (an
                                ellipse; a segment along the wall for a wall landmark, Eq 17)
``world/trajectory/*``          the estimate (green), dead reckoning (grey) and the truth (white) so far
``world/robot``                 heading arrow and 2σ position ellipse of the estimate; ``world/robot/camera``
                                the stereo head's viewing direction
``camera/left``, ``camera/right``  the rectified images with their vertical segments (cyan) and the landmarks
                                updated in that frame (green) or newly selected (yellow) projected from the
                                estimate
``log``                         one line per frame: pairs, associations, updates, new landmarks

:class:`RerunRecorder` is an observer of :func:`stablemarks.online.run_online`: it logs each frame as the
loop steps through it (the images and segments the front end already has; nothing is computed again or
kept in memory), under a temporary name renamed when the recorder closes.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..config import Config
from ..errors import GeometryError, StablemarksError

INSTALL_HINT = "pip install 'stablemarks[rerun]'"

_BLUE, _GREY, _ORANGE = (70, 130, 230), (150, 150, 150), (255, 150, 40)
_GREEN, _YELLOW, _CYAN, _WHITE = (60, 200, 90), (250, 220, 40), (40, 220, 230), (240, 240, 240)


def require_rerun():
    """The ``rerun`` module, or a one-line :class:`StablemarksError` telling how to install it."""
    try:
        import rerun
    except ImportError:
        raise StablemarksError(f"`save_rrd` needs the rerun-sdk package: {INSTALL_HINT}") from None
    return rerun


def ellipse(mean, cov, n_sigma: float = 2.0, n: int = 48) -> np.ndarray:
    """Points ``(n + 1, 2)`` of the ``n_sigma`` ellipse of a 2-D Gaussian (a segment when ``cov`` has rank 1)."""
    w, V = np.linalg.eigh(0.5 * (np.asarray(cov, float) + np.asarray(cov, float).T))
    a = np.linspace(0.0, 2.0 * np.pi, n + 1)
    circle = np.stack([np.cos(a), np.sin(a)], axis=-1)
    return np.asarray(mean, float) + n_sigma * circle * np.sqrt(np.clip(w, 0.0, None)) @ V.T


def _floor(points2d, z: float = 0.0) -> np.ndarray:
    p = np.asarray(points2d, float)
    return np.column_stack([p, np.full(len(p), z)])


def _segment_strips(segments) -> list[np.ndarray]:
    """Each vertical image segment as a 2-point strip ``[(u, v_top), (u, v_bottom)]`` [px]."""
    mid = 0.5 * (segments.v_top + segments.v_bottom)
    strips = []
    for u, s, top, bottom, m in zip(segments.u, segments.slope, segments.v_top, segments.v_bottom, mid, strict=True):
        strips.append(np.array([[u + s * (top - m), top], [u + s * (bottom - m), bottom]]))
    return strips


def _log_map(rec, rr, world_map) -> None:
    strips, colors, labels, edges = [], [], [], []
    for plane in world_map.planes:
        z0, z1 = plane.z
        p1, p2 = plane.P1, plane.P2
        strips.append(np.array([[*p1, z0], [*p2, z0], [*p2, z1], [*p1, z1], [*p1, z0]]))
        colors.append(_BLUE if plane.reference else _GREY)
        labels.append(plane.label)
        edges += [np.array([[*plane.edge(e), z0], [*plane.edge(e), z1]]) for e in plane.free_edges]
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    if strips:
        rec.log("world/walls", rr.LineStrips3D(strips, colors=colors, labels=labels, radii=0.01), static=True)
    if edges:
        rec.log("world/walls/free_edges", rr.LineStrips3D(edges, colors=_ORANGE, radii=0.02), static=True)


def _log_landmarks(rec, rr, landmarks, height: float) -> None:
    if not landmarks:
        rec.log("world/landmarks", rr.Clear(recursive=True))
        return
    lines, rings, labels = [], [], []
    for lm in landmarks:
        z0 = lm.z_low if lm.z_low is not None else 0.0
        z1 = lm.z_high if lm.z_high is not None else height
        lines.append(np.array([[*lm.position, z0], [*lm.position, z1]]))
        rings.append(_floor(ellipse(lm.position, lm.cov2d)))
        labels.append(str(lm.id))
    rec.log("world/landmarks", rr.LineStrips3D(lines, colors=_YELLOW, labels=labels, radii=0.015))
    rec.log("world/landmarks/uncertainty", rr.LineStrips3D(rings, colors=_YELLOW, radii=0.005))


def _log_image(rec, rr, side: str, image, segments, marks) -> None:
    rec.log(f"camera/{side}", rr.Image(image))
    rec.log(f"camera/{side}/segments", rr.LineStrips2D(_segment_strips(segments), colors=_CYAN, radii=0.8))
    if marks:
        strips, colors, labels = zip(*marks, strict=True)
        rec.log(f"camera/{side}/landmarks", rr.LineStrips2D(list(strips), colors=list(colors), labels=list(labels),
                                                            radii=1.5))
    else:
        rec.log(f"camera/{side}/landmarks", rr.Clear(recursive=False))


def _marks(camera, X, landmarks, colour_of) -> tuple[list, list]:
    """Image strips of the landmarks in ``colour_of`` (id → colour), projected from pose ``X``: left, right."""
    left, right = [], []
    for lm in landmarks:
        if lm.id not in colour_of:
            continue
        z0 = lm.z_low if lm.z_low is not None else 0.0
        z1 = lm.z_high if lm.z_high is not None else 2.0 * camera.mount_height
        try:
            u_l, u_r, v_top, v_bottom = camera.project_line(X, [*lm.position, z0, z1])
        except GeometryError:  # behind the camera
            continue
        for u, out in ((u_l, left), (u_r, right)):
            out.append((np.array([[u, v_top], [u, v_bottom]]), colour_of[lm.id], str(lm.id)))
    return left, right


class RerunRecorder:
    """Log a run frame by frame to ``path`` (module docstring); use as a context manager around the loop and
    pass it as an observer: ``with RerunRecorder(path, source, config) as rec: run_online(..., observers=[rec])``.

    ``source`` gives the map, the camera and the name; ``config`` is unused but kept for symmetry with the
    loop's other outputs. Raises :class:`StablemarksError` when rerun-sdk is not installed.
    """

    def __init__(self, path: str | Path, source, config: Config = Config()):
        self.rr = require_rerun()
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.name}.tmp")
        self.world_map = source.world_map
        self.height = max((p.z[1] for p in self.world_map.planes), default=2.5)
        self.rec = self.rr.RecordingStream("stablemarks", recording_id=f"{source.name}")
        self._tracks: dict[str, list] = {"estimate": [], "dead_reckoning": [], "truth": []}

    def __enter__(self) -> RerunRecorder:
        self.rec.save(self._tmp)
        _log_map(self.rec, self.rr, self.world_map)
        return self

    def __call__(self, frame, est, localizer) -> None:
        rr, rec, r = self.rr, self.rec, est.record
        k = r.index
        rec.set_time("frame", sequence=k)
        rec.set_time("time", duration=float(r.stamp))
        landmarks = localizer.landmarks()
        _log_landmarks(rec, rr, landmarks, self.height)
        self._tracks["estimate"].append(r.pose[:2])
        self._tracks["dead_reckoning"].append(r.dead_reckoning[:2])
        if frame.true_pose is not None:
            self._tracks["truth"].append(np.asarray(frame.true_pose, float)[:2])
        for name, colour in (("estimate", _GREEN), ("dead_reckoning", _GREY), ("truth", _WHITE)):
            if self._tracks[name]:
                rec.log(f"world/trajectory/{name}", rr.LineStrips3D([_floor(self._tracks[name], 0.01)], colors=colour,
                                                                    radii=0.01))
        X = r.pose
        heading = np.array([np.cos(X[2]), np.sin(X[2]), 0.0])
        view = np.array([np.cos(X[2] + r.pan), np.sin(X[2] + r.pan), 0.0])
        rec.log("world/robot", rr.Arrows3D(vectors=[0.3 * heading], origins=[[X[0], X[1], 0.02]], colors=_GREEN))
        rec.log("world/robot/uncertainty", rr.LineStrips3D([_floor(ellipse(X[:2], r.cov_pose[:2, :2]), 0.02)],
                                                           colors=_GREEN, radii=0.005))
        camera = localizer.camera.with_pan(r.pan)
        centre = camera.camera_pose(X).translation
        rec.log("world/robot/camera", rr.Arrows3D(vectors=[0.5 * view], origins=[[*centre, camera.mount_height]],
                                                  colors=_CYAN))
        if est.front is not None:
            colour_of = {i: _GREEN for i in r.observed} | {i: _YELLOW for i in r.new}
            marks_left, marks_right = _marks(camera, X, landmarks, colour_of)
            _log_image(rec, rr, "left", frame.left, est.front.left_segments, marks_left)
            _log_image(rec, rr, "right", frame.right, est.front.right_segments, marks_right)
        rec.log("log", rr.TextLog(f"frame {k}: {r.n_pairs} segment pairs, {len(r.associated)} associated, "
                                  f"{len(r.observed)} updated, {len(r.new)} new, {r.n_landmarks} landmarks"))

    def __exit__(self, exc_type, *exc) -> None:
        try:
            self.rec.flush()
            self.rec.disconnect()
            if exc_type is None:
                os.replace(self._tmp, self.path)
        finally:
            self._tmp.unlink(missing_ok=True)
