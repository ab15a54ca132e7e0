"""Ground truth of a rendered frame: every vertical image edge the world makes, where it is, whether it shows.

The edges are: one per ``edge`` feature, two per ``bar`` feature (``<id>-a`` at ``s``, ``<id>-b`` at
``s + width``), and one per free edge of a wall in the map (``<wall>-p1`` / ``<wall>-p2``, ``kind:
boundary``, spanning the wall's height). For each, in both cameras: its true columns ``u_l``, ``u_r`` and
rows ``v_top``, ``v_bottom`` (:meth:`StereoCamera.project_line`, Eq 3), whether it is *in view* (in front of
the camera, its column inside the image and some of its rows too), and which fraction of its rows is seen
unoccluded (each row's sight line checked against every other surface of the world with the renderer's own
ray caster); it is *visible* when that fraction is at least :data:`VISIBLE_FRACTION`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..geometry import MIN_DEPTH, SE2, StereoCamera
from .world import World

VISIBLE_FRACTION = 0.5
"""An edge counts as visible in an image when at least this fraction of its rows is seen."""


@dataclass(frozen=True)
class EdgeTruth:
    """One vertical image edge of the world in one frame.

    Positions: ``s`` along the wall from ``p1`` [m], world ``(x, y)`` [m], heights ``z`` (low, high) [m];
    image: ``u_l``, ``u_r``, ``v_top``, ``v_bottom`` [px] (NaN behind the camera). ``polarity``: sign of the
    brightness step in the left image going right (+1 / -1; 0 if unknown, e.g. a boundary out of view).
    """

    id: str
    kind: str  # "feature" | "boundary"
    wall: str
    feature: str
    s: float
    x: float
    y: float
    z: tuple[float, float]
    polarity: int
    u_l: float
    u_r: float
    v_top: float
    v_bottom: float
    in_view_l: bool
    in_view_r: bool
    visible_fraction_l: float
    visible_fraction_r: float

    @property
    def boundary(self) -> bool:
        return self.kind == "boundary"

    @property
    def visible_l(self) -> bool:
        return self.in_view_l and self.visible_fraction_l >= VISIBLE_FRACTION

    @property
    def visible_r(self) -> bool:
        return self.in_view_r and self.visible_fraction_r >= VISIBLE_FRACTION

    @property
    def line(self) -> np.ndarray:
        """The landmark ``L = (x, y, z_low, z_high)`` of Eq 1."""
        return np.array([self.x, self.y, self.z[0], self.z[1]])

    def to_dict(self) -> dict:
        d = asdict(self)
        d["z"] = list(self.z)
        d["boundary"] = self.boundary
        d["visible_l"] = self.visible_l
        d["visible_r"] = self.visible_r
        for key in ("u_l", "u_r", "v_top", "v_bottom"):
            d[key] = None if math.isnan(d[key]) else d[key]
        return d


@dataclass(frozen=True)
class FrameTruth:
    """True pose ``X`` (world), head pan [rad], the frame's image edges, and its optics draws.

    ``exposure`` and ``gain``: the frame's exposure and analog gain factors; ``motion_blur``: the length [px] of
    its horizontal motion blur (see :func:`stablemarks.sim.render.expose`).
    """

    pose: SE2
    pan: float
    exposure: float
    edges: tuple[EdgeTruth, ...]
    gain: float = 1.0
    motion_blur: float = 0.0

    def edge(self, edge_id: str) -> EdgeTruth:
        for e in self.edges:
            if e.id == edge_id:
                return e
        raise KeyError(edge_id)

    def to_dict(self) -> dict:
        return {
            "pose": self.pose.as_array().tolist(),
            "pan": self.pan,
            "exposure": self.exposure,
            "gain": self.gain,
            "motion_blur": self.motion_blur,
            "edges": [e.to_dict() for e in self.edges],
        }


def _edge_list(world: World) -> list[tuple[str, str, str, str, float, tuple[float, float], float]]:
    """``(id, kind, wall, feature, s, z, step)`` for every edge of the world (step: albedo change along +s)."""
    sc = world.scenario
    out = []
    for feat in sc.features:
        for eid, s, step in feat.edges():
            out.append((eid, "feature", feat.wall, feat.id, s, feat.z, step))
    for w in sc.walls:
        if w.in_map:
            for e in w.free_edges:
                out.append((f"{w.id}-{e}", "boundary", w.id, "", 0.0 if e == "p1" else w.plane.length, w.z, 0.0))
    return out


def frame_truth(world: World, camera: StereoCamera, X: SE2, *, left_clean: np.ndarray | None = None,
                exposure: float = 1.0, gain: float = 1.0, motion_blur: float = 0.0) -> FrameTruth:
    """The ground truth of the frame taken from pose ``X`` with ``camera`` (its ``pan`` set).

    ``left_clean`` (H, W), the noise-free left image, gives the polarity of boundary edges (the background
    decides it); without it their polarity is 0.
    """
    Xa = X.as_array()
    H = camera.height
    h, f, cv = camera.mount_height, camera.f, camera.cv
    owners = {obj.id: k for k, obj in enumerate(world.objects) if obj.kind == "wall"}
    origins = camera.optical_centres(Xa)
    edges = []
    for eid, kind, wall_id, feat_id, s, z, step in _edge_list(world):
        plane = world.scenario.wall(wall_id).plane
        p = plane.point_at(s)
        Xc, Zc = camera.to_camera(Xa, p)
        Xc, Zc = float(Xc), float(Zc)
        front = Zc > MIN_DEPTH
        if front:
            u_l = camera.cu + f * Xc / Zc
            u_r = u_l - f * camera.baseline / Zc
            v_top = camera.cv + f * (h - z[1]) / Zc
            v_bot = camera.cv + f * (h - z[0]) / Zc
        else:
            u_l = u_r = v_top = v_bot = math.nan
        rows = np.arange(math.ceil(v_top), math.floor(v_bot) + 1, dtype=float) if front else np.zeros(0)
        rows_in = rows[(rows >= 0) & (rows <= H - 1)]
        views, fractions = [], []
        for u, o in zip((u_l, u_r), origins, strict=True):
            in_view = bool(front and camera.in_image(u) and len(rows_in) > 0)
            frac = 0.0
            if in_view:
                cast = world.cast(o, ((p - o) / Zc)[None, :])
                depth, _ = world.zbuffer(cast, rows_in, h, f, cv, exclude_owner=owners[wall_id], room=False)
                frac = float(np.count_nonzero(depth[:, 0] >= Zc * (1 - 1e-9))) / max(1, len(rows))
            views.append(in_view)
            fractions.append(frac)
        if kind == "feature":
            du = camera.project_columns(Xa, plane.point_at(s + 1e-3))[0] - u_l if front else 0.0
            polarity = int(np.sign(step) * np.sign(du)) if np.isfinite(du) else 0
        else:
            polarity = _measured_polarity(left_clean, u_l, rows_in) if views[0] else 0
        edges.append(EdgeTruth(
            eid, kind, wall_id, feat_id, float(s), float(p[0]), float(p[1]), (float(z[0]), float(z[1])),
            polarity, float(u_l), float(u_r), float(v_top), float(v_bot), views[0], views[1],
            fractions[0], fractions[1],
        ))
    return FrameTruth(X, float(camera.pan), float(exposure), tuple(edges), float(gain), float(motion_blur))


def _measured_polarity(image: np.ndarray | None, u: float, rows: np.ndarray, step: float = 2.0,
                       min_step: float = 2.0) -> int:
    """Sign of the mean brightness change from column ``u - step`` to ``u + step`` over ``rows``.

    0 when there is no image or the change is under ``min_step`` gray levels.
    """
    if image is None or len(rows) == 0:
        return 0
    block = image[rows.astype(int)]
    W = block.shape[1]

    def column(c: float) -> np.ndarray:
        c = min(max(c, 0.0), W - 1.0)
        i0 = min(int(c), W - 2)
        w = c - i0
        return block[:, i0] * (1 - w) + block[:, i0 + 1] * w

    diff = float(np.mean(column(u + step) - column(u - step)))
    return 0 if abs(diff) < min_step else int(np.sign(diff))
