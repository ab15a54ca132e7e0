"""More map inputs: ROS ``map_server`` occupancy maps (with wall extraction) and GeoJSON wall lists.

ROS map_server map (YAML, the image path relative to the YAML file)::

    image: lab.pgm              # PGM or PNG (any format OpenCV reads)
    resolution: 0.05            # [m / cell]
    origin: [-3.2, 1.5, 0.0]    # pose (x [m], y [m], yaw [rad]) of the lower-left corner of the image
    negate: 0                   # 1: white is occupied, black is free
    occupied_thresh: 0.65
    free_thresh: 0.196
    mode: trinary               # optional: trinary (default) | scale | raw

The image is read as ROS 2's ``nav2_map_server`` reads it. With the shade ``s = value / 255`` (the mean
of the colour channels; in trinary mode an alpha channel is averaged in too), the occupancy is
``p = 1 − s`` (``p = s`` when ``negate``); a cell is occupied (100) if ``p > occupied_thresh``, free (0)
if ``p < free_thresh``, otherwise unknown (−1). ``scale`` maps the values between the thresholds
linearly onto ``0…100`` (transparent pixels unknown); ``raw`` takes ``round(255 s)`` as the value
(outside ``0…100``: unknown). Grids keep the image's orientation: ``grid[v, u]``, row ``v = 0`` is the
TOP of the image, i.e. the largest ``y`` of the map when ``yaw = 0``.

Wall extraction (:func:`walls_from_occupancy`, pixel steps in :class:`WallExtraction`), in two stages.

*Which walls there are:* occupied cells → Guo–Hall skeleton → probabilistic Hough segments → collinear
pieces merged (longest first; a gap filled with occupied cells is no doorway) and refitted to the
skeleton → ends joined at corners and T-junctions → the other ends extended to the end of the occupied
cells and called *free* when the cells just beyond them (along the wall, across its width) are free space.

*Where the camera sees them,* to a fraction of a cell: a stereo camera sees a wall's **face**, half the
wall's thickness from its centre line (7.5 cm for a wall 3 cells of 5 cm thick), not its centre line.
Each wall's faces are measured on the original grid: in every grid column the wall crosses, the boundary
between its last occupied cell and the free (or unknown) cells beyond, on both sides; the wall's direction
is the one most of these boundaries agree on (holes, specks and ragged cells left out), then two parallel
lines are fitted to them by total least squares (the staircase of a slanted face averages out). A loose
end lies where the occupied cells between the faces end (the outer boundary of the last occupied cell
along the wall, to a fraction of a cell on a slanted wall); a joined end where the face meets the other
wall's face (on the inside of a corner the other wall's near face, on the outside its far face).

*One plane per visible side.* A side of a wall is *visible* when the cells beyond its face are free
space (not unknown, not the grid's border) along at least 30 % of it. Each visible side becomes its own
plane, on its face, with ``visible_from`` the side of ``p1 → p2`` the free space is on (``left`` or
``right``): a room's outer wall with unknown space behind it gives one plane (its inner face), a
free-standing partition gives two (one per face, each with the partition's free edges), and a face
that a T-junction's stem meets is cut in two at the stem's faces. A wall seen from no free space is kept
on its centre line as an occluder (``reference: false``, ``visible_from: both``). Every plane gets the
height ``WallExtraction.height`` (``--height`` of ``stablemarks map-walls``).

How close: on generated maps with walls 1–3 cells thick at any angle, ragged and with flipped cells
(``tests/test_map_walls_accuracy.py``), free edges lie within 2 cm of where they were drawn along the
wall wherever the cells fix them that well (on a slanted wall one cell thick, whose cells lie about a
cell apart along it, within what the cells allow: up to ~3 cm), faces within a few millimetres, and
walls of 1.5 m or more within 0.5° of their direction (a short slanted wall's cells fix its direction
only to about half a cell over its length).

GeoJSON (a ``FeatureCollection`` in local map metres ``(x, y)``, not WGS 84 longitude/latitude)::

    {"type": "FeatureCollection", "frame": "map", "features": [
      {"type": "Feature",
       "geometry": {"type": "LineString", "coordinates": [[0.0, 4.0], [1.2, 4.0]]},
       "properties": {"id": "partition", "free_edges": ["p1"], "z": [0.0, 1.8]}}]}

Properties as in the native map format (``id``, ``name``, ``free_edges``, ``z``, ``visible_from``,
``reference``; others are ignored); ``id`` defaults to the feature's ``id`` member, else ``feature<i>``.
A LineString of ``n`` points gives ``n − 1`` walls, a MultiLineString one or more per part; when a
feature gives several walls their ids get a suffix ``_1``, ``_2``, …, and ``free_edges`` refers to the
first (``p1``) and last (``p2``) point of each line. Other geometry types are rejected.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numba import njit

from ..errors import ConfigError, expected, short_repr
from ..maps import MAX_YAML_DEPTH, Map, ReferencePlane, _number, parse_map, parse_plane, read_yaml
from .images import imdecode_quietly

OCCUPIED = 100
FREE = 0
UNKNOWN = -1
MODES = ("trinary", "scale", "raw")


# ------------------------------------------------------------ occupancy maps
@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """An occupancy grid as ROS map_server publishes it, kept in the image's orientation.

    Attributes
    ----------
    grid : (H, W) int8, ``grid[v, u]`` with row 0 the top of the image: 100 occupied, 0 free,
        −1 unknown (``scale``/``raw`` modes: values in between too).
    resolution : cell size [m].
    origin : (3,) pose ``(x [m], y [m], yaw [rad])`` of the lower-left corner of the grid in the map.
    source : the YAML file it came from.
    """

    grid: np.ndarray
    resolution: float
    origin: np.ndarray
    source: str = ""

    @property
    def shape(self) -> tuple[int, int]:
        return self.grid.shape

    def cell_to_map(self, uv) -> np.ndarray:
        """Map coordinates (..., 2) [m] of pixel positions ``(u, v)`` (..., 2) (cell centres at integers)."""
        return cell_to_map(uv, self.grid.shape[0], self.resolution, self.origin)


def cell_to_map(uv, height: int, resolution: float, origin) -> np.ndarray:
    """Map coordinates (..., 2) [m] of pixel positions ``(u, v)`` (..., 2) of a grid ``height`` rows high.

    The cell ``(u, v)`` covers ``[u·r, (u+1)·r] × [(H−1−v)·r, (H−v)·r]`` in the grid's frame (y up, row 0
    at the top), which sits at ``origin = (x, y, yaw)`` in the map: ``p = (x, y) + R(yaw) · p_grid``.
    """
    uv = np.asarray(uv, dtype=float)
    x0, y0, yaw = (float(v) for v in origin)
    local = np.stack([(uv[..., 0] + 0.5) * resolution, (height - 0.5 - uv[..., 1]) * resolution], axis=-1)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([x0, y0]) + local @ np.array([[c, s], [-s, c]])


def _threshold(data: dict, key: str, where: str) -> float:
    value = _number(data[key], f"{where}: {key}")
    if not 0.0 <= value <= 1.0:
        raise ConfigError(expected("a probability in [0, 1]", data[key], where=f"{where}: {key}"))
    return value


def load_occupancy_map(yaml_path: str | Path) -> OccupancyMap:
    """Read a ROS map_server map (YAML + image) exactly as map_server does (see the module docstring).

    Raises :class:`ConfigError` naming the file and the field for a missing or malformed key, a missing
    or unreadable image (with the path it looked for), or thresholds not in ``0 ≤ free < occupied ≤ 1``.
    """
    path = Path(yaml_path)
    data = read_yaml(path, "map_server map file")
    if not isinstance(data, dict):
        raise ConfigError(expected("a mapping with image, resolution, origin, ...", type(data).__name__,
                                   where=str(path)))
    return _parse_occupancy(data, path)


def _parse_occupancy(data: dict, path: Path) -> OccupancyMap:
    where = str(path)
    for key in ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh"):
        if key not in data:
            raise ConfigError(f"{where}: missing field {key!r} (a ROS map_server map needs image, resolution, "
                              "origin, negate, occupied_thresh and free_thresh)")
    image = data["image"]
    if not isinstance(image, str) or not image.strip():
        raise ConfigError(expected("an image file name", image, where=f"{where}: image"))
    resolution = _number(data["resolution"], f"{where}: resolution")
    if not resolution > 0:
        raise ConfigError(expected("a positive cell size [m]", data["resolution"], where=f"{where}: resolution"))
    origin = data["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise ConfigError(expected("[x, y, yaw] in metres and radians", origin, where=f"{where}: origin"))
    origin = np.array([_number(v, f"{where}: origin[{i}]") for i, v in enumerate(origin)])
    negate = data["negate"]
    if negate not in (0, 1) or isinstance(negate, float):
        raise ConfigError(expected("0 or 1", negate, where=f"{where}: negate"))
    occupied_thresh = _threshold(data, "occupied_thresh", where)
    free_thresh = _threshold(data, "free_thresh", where)
    if not free_thresh < occupied_thresh:
        raise ConfigError(f"{where}: expected free_thresh < occupied_thresh, got free_thresh = {free_thresh:g} "
                          f"and occupied_thresh = {occupied_thresh:g}")
    mode = data.get("mode", "trinary")
    if mode not in MODES:
        raise ConfigError(expected(f"one of {', '.join(MODES)}", mode, where=f"{where}: mode"))

    image_path = Path(image).expanduser()
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    if not image_path.is_file():
        raise ConfigError(f"{where}: image: no such file {image_path}")
    try:
        buf = np.frombuffer(image_path.read_bytes(), np.uint8)
    except OSError as exc:
        raise ConfigError(f"{where}: image: cannot read {image_path} ({exc.strerror or exc.__class__.__name__})") \
            from None
    pixels, reason = imdecode_quietly(buf) if buf.size else (None, "empty file")  # libpng/OpenCV kept off stderr
    if pixels is None:
        why = f": {reason}" if reason else ""
        raise ConfigError(f"{where}: image: cannot read {image_path} (truncated, damaged or not an image format "
                          f"OpenCV reads{why})")
    grid = occupancy_from_image(pixels, bool(negate), occupied_thresh, free_thresh, mode)
    return OccupancyMap(grid, resolution, origin, where)


def occupancy_from_image(pixels: np.ndarray, negate: bool, occupied_thresh: float, free_thresh: float,
                         mode: str = "trinary") -> np.ndarray:
    """Occupancy values (H, W) int8 of a map image (H, W[, C]) as read by OpenCV (BGR[A], 8 or 16 bit).

    The rules of ``nav2_map_server`` (module docstring): 100 occupied, 0 free, −1 unknown.
    """
    img = np.asarray(pixels)
    full = float(np.iinfo(img.dtype).max) if np.issubdtype(img.dtype, np.integer) else 1.0
    img = img.astype(float)
    if img.ndim == 2:
        img = img[..., None]
    has_alpha = img.shape[2] in (2, 4)
    colour = img[..., : img.shape[2] - 1] if has_alpha else img
    alpha = img[..., -1] / full if has_alpha else np.ones(img.shape[:2])
    # mean of R, G, B (gray: all three equal) [+ opacity in trinary mode], then scaled to [0, 1]
    total = colour.sum(axis=2) * (3.0 / colour.shape[2])
    n = 3
    if mode == "trinary" and has_alpha:
        total, n = total + img[..., -1], 4
    shade = total / (n * full)
    if mode == "raw":
        value = np.rint(shade * 255.0)
        return np.where((value >= FREE) & (value <= OCCUPIED), value, UNKNOWN).astype(np.int8)
    occ = shade if negate else 1.0 - shade
    if mode == "scale":
        grid = np.rint((occ - free_thresh) / (occupied_thresh - free_thresh) * 100.0)
    else:
        grid = np.full(shade.shape, float(UNKNOWN))
    grid = np.where(occ < free_thresh, FREE, grid)
    grid = np.where(occ > occupied_thresh, OCCUPIED, grid)
    if mode == "scale":
        grid = np.where(alpha < 1.0, UNKNOWN, grid)
    return grid.astype(np.int8)


# ------------------------------------------------------------ wall extraction
@dataclass(frozen=True)
class WallExtraction:
    """Parameters of :func:`walls_from_occupancy`.

    Attributes
    ----------
    min_length : shortest wall kept [m].
    max_gap : collinear pieces closer than this along their line are one wall [m]; wider gaps
        (doorways) separate walls.
    angle_tol : largest angle between pieces merged into one wall [rad]; a piece too short to know its
        direction that well (``atan(2 offset_tol / length)`` is larger) is merged when it lies in the band.
    offset_tol : largest distance of a piece's end points from the line of the wall it joins [cells].
    join_tol : an end this close to another wall's line (beyond that wall's half thickness) is joined
        to it at their intersection: a corner or a T-junction, never a free edge [cells].
    probe : how far beyond an end the cells must be free for a free edge [cells].
    min_corner_angle : smallest angle between two walls joined at a corner [rad].
    height : ``(low, high)`` bottom and top of every wall [m] (the map's ``z``; finite, ``low < high``).
    """

    min_length: float = 0.3
    max_gap: float = 0.1
    angle_tol: float = float(np.deg2rad(5.0))
    offset_tol: float = 1.5
    join_tol: float = 3.0
    probe: float = 2.0
    min_corner_angle: float = float(np.deg2rad(20.0))
    height: tuple[float, float] = (0.0, 2.5)

    def __post_init__(self) -> None:
        where = "WallExtraction"
        z = self.height
        if (not isinstance(z, tuple | list) or len(z) != 2
                or not all(isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) for v in z)
                or not z[0] < z[1]):
            raise ConfigError(expected("(low, high) finite heights [m] with low < high", z, where=f"{where}.height"))
        object.__setattr__(self, "height", (float(z[0]), float(z[1])))
        for name, unit in (("min_length", "m"), ("offset_tol", "cells"), ("join_tol", "cells"),
                           ("probe", "cells")):
            if not getattr(self, name) > 0:
                raise ConfigError(expected(f"a positive number [{unit}]", getattr(self, name), where=f"{where}.{name}"))
        if not self.max_gap >= 0:
            raise ConfigError(expected("a non-negative number [m]", self.max_gap, where=f"{where}.max_gap"))
        for name in ("angle_tol", "min_corner_angle"):
            if not 0 < getattr(self, name) < np.pi / 2:
                raise ConfigError(expected("an angle in (0, pi/2) [rad]", getattr(self, name), where=f"{where}.{name}"))


@njit(cache=True)
def _guo_hall(img: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Guo–Hall thinning of a 0/1 uint8 image (H, W) whose border rows and columns are 0.

    (Zhang–Suen thinning, used before, deletes diagonal walls two to three cells thick entirely.)"""
    out = img.copy()
    H, W = out.shape
    marks = np.zeros_like(out)
    changed = True
    while changed:
        changed = False
        for step in range(2):
            n = 0
            for y in range(1, H - 1):
                for x in range(1, W - 1):
                    if out[y, x] == 0:
                        continue
                    p2, p3, p4 = out[y - 1, x] > 0, out[y - 1, x + 1] > 0, out[y, x + 1] > 0  # N, NE, E
                    p5, p6, p7 = out[y + 1, x + 1] > 0, out[y + 1, x] > 0, out[y + 1, x - 1] > 0  # SE, S, SW
                    p8, p9 = out[y, x - 1] > 0, out[y - 1, x - 1] > 0  # W, NW
                    c = (int(not p2 and (p3 or p4)) + int(not p4 and (p5 or p6))
                         + int(not p6 and (p7 or p8)) + int(not p8 and (p9 or p2)))
                    n1 = int(p9 or p2) + int(p3 or p4) + int(p5 or p6) + int(p7 or p8)
                    n2 = int(p2 or p3) + int(p4 or p5) + int(p6 or p7) + int(p8 or p9)
                    nn = min(n1, n2)
                    if step == 0:
                        m = (p6 or p7 or not p9) and p8
                    else:
                        m = (p2 or p3 or not p5) and p4
                    if c == 1 and 2 <= nn <= 3 and not m:
                        marks[y, x] = 1
                        n += 1
            if n > 0:
                changed = True
                for y in range(1, H - 1):
                    for x in range(1, W - 1):
                        if marks[y, x]:
                            out[y, x] = 0
                            marks[y, x] = 0
    return out


def skeleton(mask: np.ndarray) -> np.ndarray:
    """One-cell-wide skeleton (H, W) bool of a boolean mask (H, W) (Guo–Hall thinning)."""
    padded = np.pad(np.asarray(mask, dtype=np.uint8), 1)
    return _guo_hall(padded)[1:-1, 1:-1].astype(bool)


@dataclass
class _Line:
    """A wall in pixel coordinates during extraction: the line ``c + s·t`` over ``s ∈ [s0, s1]``."""

    c: np.ndarray
    t: np.ndarray
    s0: float
    s1: float
    samples: np.ndarray  # (N, 2) points supporting the fit
    joined: list
    partner: list = field(default_factory=lambda: [-1, -1])  # the wall each joined end was joined to

    @property
    def n(self) -> np.ndarray:
        return np.array([-self.t[1], self.t[0]])

    def end(self, k: int) -> np.ndarray:
        return self.c + (self.s0 if k == 0 else self.s1) * self.t

    def outward(self, k: int) -> np.ndarray:
        return -self.t if k == 0 else self.t

    @property
    def length(self) -> float:
        return self.s1 - self.s0


def _fit(samples: np.ndarray, ends: np.ndarray) -> _Line:
    """Total least-squares line through ``samples`` (N, 2); extent = projections of ``ends`` (M, 2)."""
    c = samples.mean(axis=0)
    t = np.linalg.svd(samples - c, full_matrices=False)[2][0]
    s = (ends - c) @ t
    return _Line(c, t, float(s.min()), float(s.max()), samples, [False, False])


def _samples(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    n = max(2, int(np.ceil(np.linalg.norm(b - a))) + 1)
    return a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)


def _arrays(lines: list[_Line]) -> tuple[np.ndarray, ...]:
    """Centres (n, 2), directions (n, 2), normals (n, 2), extents (n,), (n,) of the lines."""
    C = np.array([line.c for line in lines]).reshape(-1, 2)
    T = np.array([line.t for line in lines]).reshape(-1, 2)
    N = np.column_stack([-T[:, 1], T[:, 0]])
    return C, T, N, np.array([line.s0 for line in lines]), np.array([line.s1 for line in lines])


def _mergeable(a: _Line, others: list[_Line], p: WallExtraction, max_gap_px: float,
               mask: np.ndarray | None = None) -> np.ndarray:
    """Which of ``others`` can be merged into ``a`` (docstring of :func:`_merge`)."""
    C, T, N, S0, S1 = _arrays(others)
    E = np.stack([C + S0[:, None] * T, C + S1[:, None] * T], axis=1)  # (m, 2 ends, 2)
    L = S1 - S0
    a_long = a.length >= L
    lc = np.where(a_long[:, None], a.c[None], C)
    lt = np.where(a_long[:, None], a.t[None], T)
    ln = np.where(a_long[:, None], a.n[None], N)
    ls0, ls1 = np.where(a_long, a.s0, S0), np.where(a_long, a.s1, S1)
    ends = np.where(a_long[:, None, None], E, np.array([a.end(0), a.end(1)])[None])  # the shorter's ends
    d = ends - lc[:, None, :]
    off = np.abs(np.einsum("mkd,md->mk", d, ln)).max(axis=1)
    s = np.einsum("mkd,md->mk", d, lt)
    gap = np.maximum(s.min(axis=1) - ls1, ls0 - s.max(axis=1))
    # a short piece's direction is known only to about atan(2 offset_tol / length)
    short = np.minimum(a.length, L)
    cos_tol = np.cos(np.maximum(p.angle_tol, np.arctan2(2.0 * p.offset_tol, short)))
    ok = (np.abs(T @ a.t) >= cos_tol) & (off <= p.offset_tol)
    bridged = np.zeros(len(others), bool)
    if mask is not None:  # a wider gap filled with occupied cells is no doorway: the wall goes on
        for m in np.flatnonzero(ok & (gap > max_gap_px)):
            q = others[m]
            pa, pb = min(((a.end(i), q.end(j)) for i in (0, 1) for j in (0, 1)),
                         key=lambda e: float(np.linalg.norm(e[0] - e[1])))
            bridged[m] = bool(_cell(mask, _samples(pa, pb), False).all())
    return ok & ((gap <= max_gap_px) | bridged)


def _merge(lines: list[_Line], p: WallExtraction, max_gap_px: float, mask: np.ndarray | None = None) -> list[_Line]:
    """Merge collinear pieces until no pair is mergeable; each merged wall refitted to all its samples.

    Two pieces are mergeable when their directions differ by less than ``angle_tol`` (or than the
    shorter piece can resolve, ``atan(2 offset_tol / length)``), the shorter's end points lie within
    ``offset_tol`` of the longer's line, and the gap between them along that line is at most
    ``max_gap_px`` or filled with occupied cells of ``mask`` (a thick slanted wall's skeleton may break
    where a doorway could not be). Longest first, each wall takes every piece mergeable with it and is refitted, until
    it takes no more: a short piece at a corner, mergeable with both walls, goes to one of them and
    never chains the two walls into one.
    """
    lines = sorted(lines, key=lambda line: -line.length)
    i = 0
    while i < len(lines) - 1:
        rest = lines[i + 1:]
        ok = _mergeable(lines[i], rest, p, max_gap_px, mask)
        if not ok.any():
            i += 1
            continue
        group = [lines[i]] + [q for q, m in zip(rest, ok, strict=True) if m]
        ends = np.array([q.end(k) for q in group for k in (0, 1)])
        lines[i] = _fit(np.vstack([q.samples for q in group]), ends)
        lines[i + 1:] = [q for q, m in zip(rest, ok, strict=True) if not m]
    return lines


def _skeleton_near(skel: np.ndarray, line: _Line, s: np.ndarray, tol: float) -> np.ndarray:
    """Skeleton cells (M, 2) within ``tol`` of the line at the positions ``s`` along it [px]."""
    k = int(np.ceil(tol))
    pts = line.c + s[:, None, None] * line.t + np.arange(-k, k + 1)[None, :, None] * line.n
    cells = np.floor(pts.reshape(-1, 2) + 0.5)
    cells = cells[_cell(skel, cells, False)]
    W = skel.shape[1]
    cells = np.column_stack(np.divmod(np.unique(cells[:, 1] * W + cells[:, 0]), W))[:, ::-1]  # each once
    return cells[np.abs((cells - line.c) @ line.n) <= tol]


def _refit_to_skeleton(line: _Line, skel: np.ndarray, tol: float, max_gap: int = 2) -> _Line:
    """Refit a merged wall to the skeleton cells within ``tol`` of it; grow each end over the skeleton
    cells that continue it with gaps of at most ``max_gap`` [px] (Hough leaves some out); refit."""
    near = _skeleton_near(skel, line, np.arange(line.s0, line.s1 + 0.5), tol)
    if len(near) < 3:
        return line
    line = _fit(near, np.array([line.end(0), line.end(1)]))
    offsets = np.arange(-np.floor(tol), np.floor(tol) + 1)
    for k, sign in ((0, -1.0), (1, 1.0)):
        last, base, chunk = 0, 0, 32
        while base - last <= max_gap:
            d = np.arange(base + 1, base + chunk + 1)
            pts = line.end(k) + sign * d[:, None, None] * line.t + offsets[None, :, None] * line.n
            hits = d[_cell(skel, pts.reshape(-1, 2), False).reshape(len(d), -1).any(axis=1)]
            for h in hits:
                if h - last > max_gap:
                    break
                last = int(h)
            base += chunk
            if len(hits) == 0 or hits[-1] != last:
                break
        if k:
            line.s1 += last
        else:
            line.s0 -= last
    near = _skeleton_near(skel, line, np.arange(line.s0, line.s1 + 0.5), tol)
    return _fit(near, np.array([line.end(0), line.end(1)]))


def _cell(mask_or_grid: np.ndarray, pts: np.ndarray, outside) -> np.ndarray:
    """Values of the grid at the cells nearest pixel positions ``pts`` (N, 2); ``outside`` off the grid."""
    H, W = mask_or_grid.shape
    u = np.floor(pts[:, 0] + 0.5).astype(int)
    v = np.floor(pts[:, 1] + 0.5).astype(int)
    inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
    out = np.full(len(pts), outside, dtype=mask_or_grid.dtype)
    out[inside] = mask_or_grid[v[inside], u[inside]]
    return out


def _join(lines: list[_Line], half: np.ndarray, p: WallExtraction) -> None:
    """Move ends near another wall's line to the intersection of the lines (corners, T-junctions); each
    joined end remembers the wall it was joined to (``partner``)."""
    if len(lines) < 2:
        return
    C, T, N, S0, S1 = _arrays(lines)
    moves = []
    for i, a in enumerate(lines):
        cross = np.abs(T[:, 0] * a.t[1] - T[:, 1] * a.t[0])
        ok = cross >= np.sin(p.min_corner_angle)
        ok[i] = False
        if not ok.any():
            continue
        with np.errstate(divide="ignore", invalid="ignore"):  # parallel lines: left out by `ok`
            s = -np.einsum("jd,jd->j", a.c - C, N) / (N @ a.t)  # intersection c_a + s t_a on each line j
            X = a.c + s[:, None] * a.t
            sb = np.einsum("jd,jd->j", X - C, T)
        reach = p.join_tol + half + half[i]
        ok &= (sb >= S0 - reach) & (sb <= S1 + reach)
        for k in (0, 1):
            dist = np.linalg.norm(X - a.end(k), axis=1)
            near = ok & (dist <= reach)
            if near.any():
                j = int(np.flatnonzero(near)[np.argmin(dist[near])])
                moves.append((i, k, float(s[j]), j))
    for i, k, s, j in moves:
        if k == 0:
            lines[i].s0 = s
        else:
            lines[i].s1 = s
        lines[i].joined[k] = True
        lines[i].partner[k] = j


def _free_end(line: _Line, k: int, half: float, occupied: np.ndarray, grid: np.ndarray,
              p: WallExtraction) -> bool:
    """Extend a loose end to the end of the occupied cells; whether the cells beyond are free space."""
    step = 0.25
    out = line.outward(k)
    s = np.arange(0.0, 2 * half + p.join_tol + step / 2, step)  # skeletons stop short of the end by ~half
    occ = _cell(occupied, line.end(k) + s[:, None] * out, False)
    if occ.all():
        return False
    first = int(np.argmin(occ))  # first sample off the occupied cells
    reach = s[first - 1] + step / 2 if first > 0 else 0.0
    if k == 0:
        line.s0 -= reach
    else:
        line.s1 += reach
    beyond = np.arange(1.0, max(1.0, p.probe) + step / 2, 2 * step)
    across = np.array([-1.0, 0.0, 1.0]) * max(0.0, half - 0.5)  # the cells across the wall's width
    pts = (line.end(k) + beyond[:, None, None] * out + across[None, :, None] * line.n).reshape(-1, 2)
    values = _cell(grid, pts, UNKNOWN)
    return bool(np.all((values >= 0) & (values < OCCUPIED)))


# ------------------------------------------------------------ sub-cell faces and ends


@dataclass
class _Faces:
    """A wall measured to sub-cell accuracy, in pixel coordinates: the centre point ``c`` and direction ``t``
    (normal ``n``), the faces' offsets from ``c`` along ``n`` (``f[+1] > 0`` on the ``+n`` side, ``f[-1] < 0``),
    which sides border free space (``visible``) and the ends' positions along ``t`` from ``c`` (``ends``: the
    end of the occupied cells, for ends not joined to another wall)."""

    c: np.ndarray
    t: np.ndarray
    f: dict
    visible: dict
    ends: list

    @property
    def n(self) -> np.ndarray:
        return np.array([-self.t[1], self.t[0]])

    def face_point(self, side: int, s: float) -> np.ndarray:
        return self.c + s * self.t + self.f[side] * self.n


def _face_samples(line: _Line, half: float, occupied: np.ndarray, grid: np.ndarray, margins, p: WallExtraction
                  ) -> dict:
    """Where the occupied cells end on either side of the wall, column by column of the grid.

    For the side ``+1`` (toward ``line.n``) or ``−1``, the grid axis nearest that normal is walked from the
    wall's line outward in every grid column the wall crosses between ``margins`` [cells] from its ends;
    the face lies on the boundary between the last occupied cell and the first of at least two
    non-occupied ones (a shorter run is a hole). On a slanted face these boundaries form a staircase
    within half a cell (along the axis) of the face's line, centred on it.

    Returns per side ``(points (M, 2), free (M,))``: the face points in pixel coordinates (NaN where the
    walk finds no face within the wall's width: a hole through it, or another wall attached there) and
    whether the cells just beyond are free space (no unknown cell within ``probe``)."""
    lo, hi = line.s0 + margins[0], line.s1 - margins[1]
    if hi - lo < 2.0:  # a short wall: its middle part
        mid = 0.5 * (line.s0 + line.s1)
        lo, hi = mid - 0.25 * line.length, mid + 0.25 * line.length
    out = {}
    for side in (1, -1):
        normal = side * line.n
        a = int(np.argmax(np.abs(normal)))  # walk along grid axis a (0: u, 1: v) ...
        b = 1 - a  # ... in the columns of axis b
        step = 1 if normal[a] > 0 else -1
        ends = np.sort([(line.c + lo * line.t)[b], (line.c + hi * line.t)[b]])
        cols = np.arange(np.ceil(ends[0]), np.floor(ends[1]) + 1)
        if len(cols) == 0:
            out[side] = (np.zeros((0, 2)), np.zeros(0, bool))
            continue
        start = line.c[a] + (cols - line.c[b]) / line.t[b] * line.t[a]  # the line's crossing of each column
        reach = int(np.ceil((half + 2.5) / abs(normal[a]))) + 2
        k = np.arange(-1, reach + 1)
        cells_a = np.rint(start)[:, None] + step * k[None, :]  # (M, K) along axis a
        uv = np.empty(cells_a.shape + (2,))
        uv[..., a], uv[..., b] = cells_a, cols[:, None]
        occ = _cell(occupied, uv.reshape(-1, 2), False).reshape(cells_a.shape)
        clear = ~occ[:, 1:-1] & ~occ[:, 2:]  # cells i and i + 1 not occupied (i from 0)
        before = np.cumsum(occ, axis=1)[:, :-2] > 0  # some occupied cell up to i - 1
        exits = clear & before & occ[:, :-2]  # ... and i - 1 occupied
        i = np.argmax(exits, axis=1)
        ok = exits[np.arange(len(cols)), i]
        edge_a = cells_a[np.arange(len(cols)), i + 1] - 0.5 * step  # boundary before cell i
        pts = np.empty((len(cols), 2))
        pts[:, a], pts[:, b] = edge_a, cols
        dist = (pts - line.c) @ normal
        ok &= dist <= half + 2.0  # further out: another wall attached
        pts[~ok] = np.nan
        beyond = edge_a[:, None] + step * (0.5 + np.arange(int(np.ceil(p.probe))))[None, :]
        q = np.empty(beyond.shape + (2,))
        q[..., a], q[..., b] = beyond, cols[:, None]
        values = _cell(grid, q.reshape(-1, 2), UNKNOWN).reshape(beyond.shape)
        out[side] = (pts, ok & (values >= 0).all(axis=1))
    return out


def _parallel_fit(P: np.ndarray, side_of: np.ndarray, t0: np.ndarray) -> tuple[np.ndarray, dict]:
    """Total least squares of parallel lines, one per side: the direction ``t`` (``t · t0 ≥ 0``) and each
    side's offset ``n · p`` (``n`` = ``t`` turned left)."""
    groups = [g for g in (1, -1) if (side_of == g).sum() >= 2]
    t = t0
    if groups and sum((side_of == g).sum() for g in groups) >= 3:
        centred = np.vstack([P[side_of == g] - P[side_of == g].mean(axis=0) for g in groups])
        t = np.linalg.svd(centred, full_matrices=False)[2][0]
        t = t if t @ t0 >= 0 else -t
    n = np.array([-t[1], t[0]])
    return t, {g: float(np.mean(P[side_of == g] @ n)) for g in (1, -1) if (side_of == g).any()}


def _consensus_direction(P: np.ndarray, side_of: np.ndarray, t0: np.ndarray, spread: float = 6.0,
                         step: float = 0.05) -> np.ndarray:
    """The direction within ``spread`` degrees of ``t0`` along which most transitions line up: per side,
    the squared distance from the side's median line, capped at 0.6 cells, summed and least (a few
    flipped cells cannot tilt it as they tilt a least-squares line)."""
    a = np.deg2rad(np.arange(-spread, spread + step / 2, step))
    base = np.arctan2(t0[1], t0[0])
    N = np.stack([-np.sin(base + a), np.cos(base + a)], axis=1)  # (A, 2)
    proj = N @ P.T  # (A, M)
    loss = np.zeros(len(a))
    for g in (1, -1):
        sel = side_of == g
        if sel.sum() < 2:
            continue
        res = proj[:, sel] - np.median(proj[:, sel], axis=1, keepdims=True)
        loss += np.minimum(res**2, 0.36).sum(axis=1)
    best = base + a[int(np.argmin(loss))]
    return np.array([np.cos(best), np.sin(best)])


def _fit_faces(line: _Line, half: float, scans: dict) -> tuple[np.ndarray, np.ndarray, dict]:
    """The wall's direction and its faces' offsets: from the direction most face points agree on
    (:func:`_consensus_direction`), two parallel lines fitted by total least squares to the face points
    of both sides within 0.75 cells of each side's median line: holes, specks and ragged cells drop out,
    the staircase of a slanted face (within half a cell of its line) stays and averages out. Returns the
    point ``c``, the direction ``t`` and the offsets ``{+1: f+, -1: f−}`` of the faces from ``c`` along
    ``n``."""
    pts, side_of = [], []
    for side, (face, _) in scans.items():
        ok = np.isfinite(face[:, 0])
        pts.append(face[ok])
        side_of.append(np.full(int(ok.sum()), side))
    P, side_of = np.vstack(pts), np.concatenate(side_of)
    c, t, f = line.c, line.t, {}
    if len(P):
        t = _consensus_direction(P, side_of, line.t)
        keep = np.ones(len(P), bool)
        for _ in range(2):  # transitions within 0.75 cells of each side's median line, then refitted
            n = np.array([-t[1], t[0]])
            proj = P @ n
            new = np.zeros(len(P), bool)
            for g in (1, -1):
                sel = side_of == g
                if sel.any():
                    centre = np.median(proj[sel & keep] if (sel & keep).any() else proj[sel])
                    new[sel] = np.abs(proj[sel] - centre) <= 0.75
            if not new.any():
                break
            keep = new
            t, _ = _parallel_fit(P[keep], side_of[keep], t)
        t, d = _parallel_fit(P[keep], side_of[keep], t)
        n = np.array([-t[1], t[0]])
        f = {g: dg - float(c @ n) for g, dg in d.items()}
    for side in (1, -1):  # a side without transitions: the distance transform's width
        if side not in f:
            f[side] = f[-side] + side * 2.0 * half if -side in f else side * half
    if f[1] <= f[-1]:
        f = {1: half, -1: -half}
    return c, t, f


def _end_of_cells(occupied: np.ndarray, c, t, f: dict, s_coarse: float, outward: float) -> float:
    """Sub-cell position along ``t`` (from ``c``) where the wall's occupied cells end going ``outward`` (±1).

    The cells whose centres lie between the wall's faces (``f``; free cells within 0.05 cells of a face
    are left out: they may lie just outside the wall) near the coarse end are split into those before
    the end and those beyond it, with the fewest misplaced cells (an occupied one beyond, a free one before: holes and
    specks); the end lies halfway between the last cell before and the first beyond, on the outer
    boundary of the last occupied cell along the wall (to a fraction of a cell on a slanted wall)."""
    n = np.array([-t[1], t[0]])
    centre, half = 0.5 * (f[1] + f[-1]), 0.5 * (f[1] - f[-1])
    H, W = occupied.shape
    span = 5.0 + half
    corners = np.array([c + (s_coarse + a) * t + b * n for a in (-span, span)
                        for b in (centre - half - 1.0, centre + half + 1.0)])
    u0, v0 = np.floor(corners.min(axis=0)).astype(int) - 1
    u1, v1 = np.ceil(corners.max(axis=0)).astype(int) + 1
    vv, uu = np.mgrid[max(v0, 0):min(v1, H - 1) + 1, max(u0, 0):min(u1, W - 1) + 1]
    vv, uu = vv.ravel(), uu.ravel()
    cells = np.column_stack([uu, vv]).astype(float)
    along = outward * ((cells - c) @ t - s_coarse)
    across = np.abs((cells - c) @ n - centre)
    occ_all = occupied[vv, uu]
    # an occupied cell is inside the wall wherever it is; a free one only tells where the wall is not when
    # it is clearly inside the wall's width (a free cell on the line of a face may lie just outside it)
    sel = (across <= np.where(occ_all, half + 0.25, half - 0.05)) & (along >= -span + 1.0) & (along <= span)
    if not sel.any():
        return s_coarse
    u, occ = along[sel], occ_all[sel]
    order = np.argsort(u, kind="stable")
    u, occ = u[order], occ[order]
    # a split after the k-th cell: free cells up to k and occupied cells after k are misplaced
    loss = np.concatenate([[0], np.cumsum(~occ)]) + np.concatenate([np.cumsum(occ[::-1])[::-1], [0]])
    valid = np.concatenate([[False], u[1:] > u[:-1] + 1e-6, [True]])  # between distinct positions only
    best = np.flatnonzero(valid & (loss == loss[valid].min()))
    k = int(best[np.argmin(np.abs(u[best - 1]))])  # the best split nearest the coarse end
    last = u[k - 1]
    step = 1.0 / max(abs(t[0]), abs(t[1]))  # the next cell along the wall, beyond the grid's border
    nxt = u[k] if k < len(u) else last + step
    return s_coarse + outward * 0.5 * (last + min(nxt, last + step))


def _measure(line: _Line, half: float, lines: list[_Line], halves: np.ndarray, occupied: np.ndarray,
             grid: np.ndarray, p: WallExtraction) -> _Faces:
    """A wall's faces, direction and loose ends to sub-cell accuracy (module docstring)."""
    margins = []
    for k in (0, 1):  # leave out the cap of a loose end and, at a junction, the other wall's ragged face
        j = line.partner[k]
        if j < 0:
            margins.append(0.5)
            continue
        sin = max(abs(float(lines[j].n @ line.t)), 0.3)
        margins.append(halves[j] / sin + 1.0)
    scans = _face_samples(line, half, occupied, grid, margins, p)
    c, t, f = _fit_faces(line, half, scans)
    visible = {side: bool(free.sum() >= max(2, 0.3 * len(free))) for side, (_, free) in scans.items()}
    ends = []
    for k in (0, 1):
        s_coarse = float((line.end(k) - c) @ t)
        ends.append(None if line.joined[k] else _end_of_cells(occupied, c, t, f, s_coarse, -1.0 if k == 0 else 1.0))
    return _Faces(c, t, f, visible, ends)


def _cross_at(a: _Faces, side: int, b: _Faces, b_side: int) -> float | None:
    """Position along ``a`` (from ``a.c``) where ``a``'s face ``side`` meets ``b``'s face ``b_side``."""
    nb = b.n
    den = float(nb @ a.t)
    if abs(den) < 1e-6:
        return None
    return float((nb @ b.c + b.f[b_side] - nb @ a.c - a.f[side] * (nb @ a.n)) / den)


def _junction_face(i: int, k: int, side: int, lines: list[_Line], geo: list[_Faces]) -> float:
    """Where face ``side`` of wall ``i`` ends at its end ``k``, joined to wall ``j = lines[i].partner[k]``:
    on ``j``'s face toward wall ``i``'s body when the face is on the inside of the corner or ``j`` runs on
    through the junction (a T), else on ``j``'s far face (the outside of an L corner). Positions along
    ``geo[i].t`` from ``geo[i].c``; the junction of the centre lines when the faces do not meet near it."""
    g, line, j = geo[i], lines[i], lines[i].partner[k]
    other = geo[j]
    end = float((line.end(k) - g.c) @ g.t)
    into_i = g.t if k == 0 else -g.t  # from the junction into this wall's body
    sj = float((g.c + end * g.t - other.c) @ other.t)
    m = int(np.argmin([abs(sj - float((lines[j].end(q) - other.c) @ other.t)) for q in (0, 1)]))
    toward = 1 if other.n @ into_i > 0 else -1  # j's face toward this wall's body
    b_side = toward
    if lines[j].joined[m] and lines[j].partner[m] == i:  # an L corner: both walls end here
        into_j = other.t if m == 0 else -other.t
        if side * g.n @ into_j < 0:  # the outside of the corner
            b_side = -toward
    x = _cross_at(g, side, other, b_side)
    width = (other.f[1] - other.f[-1]) + (g.f[1] - g.f[-1])
    return end if x is None or abs(x - end) > 2.0 * width + 3.0 else x


def _face_pieces(i: int, lines: list[_Line], geo: list[_Faces], free: list, min_px: float) -> list:
    """The visible faces of wall ``i`` as pieces ``(side, s_a, s_b, free_a, free_b)`` along ``geo[i].t``
    (from ``geo[i].c``) of at least ``min_px``.

    A face ends at a loose end where the occupied cells end (free or not), at a joined end where it meets
    the other wall's face (:func:`_junction_face`); a face that the stem of a T-junction meets (a wall at
    least ``min_px`` long whose end is joined to this one, on this face's side) is cut between the stem's
    faces."""
    g, line = geo[i], lines[i]
    pieces = []
    for side in (1, -1):
        if not g.visible[side]:
            continue
        lim = [g.ends[k] if line.partner[k] < 0 else _junction_face(i, k, side, lines, geo) for k in (0, 1)]
        a, b = lim
        if b - a < min_px:
            continue
        cuts = []
        for j, stem in enumerate(lines):
            for m in (0, 1):
                if j == i or stem.partner[m] != i or j in line.partner or stem.length < min_px:
                    continue  # not a stem of this wall (a corner is handled at the ends)
                into_j = geo[j].t if m == 0 else -geo[j].t
                if side * g.n @ into_j <= 0:
                    continue  # on the other face
                xs = [_cross_at(g, side, geo[j], q) for q in (1, -1)]
                if None not in xs:
                    cuts.append((max(min(xs), a), min(max(xs), b)))
        edges = [(a, True)]
        for lo, hi in sorted(c for c in cuts if c[1] > c[0]):
            if lo <= edges[-1][0]:  # overlapping cuts
                edges[-1] = (max(edges[-1][0], hi), False)
                continue
            edges += [(lo, False), (hi, False)]
        edges.append((b, True))
        for (sa, ea), (sb, eb) in zip(edges[::2], edges[1::2], strict=True):
            if sb - sa >= min_px:
                pieces.append((side, sa, sb, ea and free[i][0], eb and free[i][1]))
    return pieces


def walls_from_occupancy(grid, resolution: float, origin, params: WallExtraction = WallExtraction(),
                         *, source: str = "") -> Map:
    """Walls of an occupancy grid as a :class:`Map` of the faces a camera sees, in map metres.

    Parameters
    ----------
    grid : (H, W) occupancy values in the image's orientation (row 0 at the top): 100 (or more) is
        occupied, negative is unknown, the rest is free space.
    resolution : cell size [m].
    origin : (3,) pose ``(x [m], y [m], yaw [rad])`` of the grid's lower-left corner in the map.
    params : the extraction's tolerances and the walls' height.

    Returns a map of planes ``wall01, wall02, …`` (longest first), one per face that borders free space
    (module docstring), end points rounded to 1 mm, ``p1`` the end with the smaller ``x`` (then ``y``),
    ``visible_from`` the side of ``p1 → p2`` the free space is on, ``free_edges`` the ends that stand
    free, ``z`` = ``params.height``. A wall seen from no free space is kept as an occluder
    (``reference: false``) on its centre line.
    """
    grid = np.asarray(grid)
    if grid.ndim != 2 or grid.size == 0:
        raise ConfigError(expected("a 2D occupancy grid (H, W)", grid.shape, where=source or "grid"))
    grid = grid.astype(np.int16)
    occupied = grid >= OCCUPIED
    mask = cv2.morphologyEx(occupied.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)) > 0
    skel = skeleton(mask)
    half_map = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5) - 0.5
    min_px = params.min_length / resolution
    # short pieces on purpose: merging joins them, and long-piece settings make the Hough transform skip cells
    found = cv2.HoughLinesP(skel.astype(np.uint8) * 255, 1.0, np.pi / 360, threshold=5, minLineLength=4.0,
                            maxLineGap=2.0)
    pieces = [] if found is None else [
        _fit(_samples(s[:2], s[2:]), s.reshape(2, 2)) for s in found.reshape(-1, 4).astype(float)
    ]
    max_gap_px = params.max_gap / resolution
    lines = [_refit_to_skeleton(line, skel, params.offset_tol) for line in _merge(pieces, params, max_gap_px, mask)]
    while len(merged := _merge(lines, params, max_gap_px, mask)) < len(lines):  # refits can grow walls into each other
        lines = [_refit_to_skeleton(line, skel, params.offset_tol) for line in merged]
    half = np.array([float(np.median(_cell(half_map, _samples(line.end(0), line.end(1)), 0.0))) for line in lines])
    keep = [i for i, line in enumerate(lines) if line.length + 2 * half[i] + 2 >= min_px]
    lines, half = [lines[i] for i in keep], half[keep]
    _join(lines, half, params)
    free = [[not line.joined[k] and _free_end(line, k, half[i], mask, grid, params) for k in (0, 1)]
            for i, line in enumerate(lines)]
    geo = [_measure(line, half[i], lines, half, occupied, grid, params) for i, line in enumerate(lines)]

    H = grid.shape[0]
    found_planes = []  # (length [m], P (2, 2) [m], free (2,), visible_from, reference)
    for i, line in enumerate(lines):
        g = geo[i]
        pieces = _face_pieces(i, lines, geo, free, min_px)
        if not pieces and not any(g.visible.values()):  # seen from nowhere: an occluder on its centre line
            ends = [g.ends[k] if g.ends[k] is not None else float((line.end(k) - g.c) @ g.t) for k in (0, 1)]
            if ends[1] - ends[0] < min_px:
                continue
            mid = 0.5 * (g.f[1] + g.f[-1])
            ends_px = np.array([g.c + e * g.t + mid * g.n for e in ends])
            P = cell_to_map(ends_px, H, resolution, origin)
            found_planes.append((P, (False, False), "both", False, ends_px.mean(axis=0)))
            continue
        for side, sa, sb, fa, fb in pieces:
            ends_px = np.array([g.face_point(side, sa), g.face_point(side, sb)])
            P = cell_to_map(ends_px, H, resolution, origin)
            toward = cell_to_map(0.5 * (ends_px[0] + ends_px[1]) + side * g.n, H, resolution, origin)
            d = P[1] - P[0]
            left = d[0] * (toward[1] - P[0, 1]) - d[1] * (toward[0] - P[0, 0]) > 0
            found_planes.append((P, (fa, fb), "left" if left else "right", True, ends_px.mean(axis=0)))
    walls = []
    for P, is_free, side, reference, mid_px in found_planes:
        P = np.round(P, 3)
        d = P[1] - P[0]
        if d[0] < -1e-9 or (abs(d[0]) <= 1e-9 and d[1] < 0):
            P, is_free = P[::-1], is_free[::-1]
            side = {"left": "right", "right": "left", "both": "both"}[side]
        walls.append((float(np.linalg.norm(P[1] - P[0])), P,
                      tuple(e for e, f in zip(("p1", "p2"), is_free, strict=True) if f), side, reference,
                      (round(float(mid_px[1]), 1), round(float(mid_px[0]), 1))))
    # longest first; equal lengths (the faces of one wall) in the grid's row and column order, so that the
    # ids do not depend on the map's origin
    walls.sort(key=lambda w: (-round(w[0], 2), w[5]))
    planes = tuple(
        ReferencePlane(f"wall{i + 1:02d}", (float(P[0, 0]), float(P[0, 1])), (float(P[1, 0]), float(P[1, 1])),
                       name=f"wall{i + 1:02d}", free_edges=edges, z=params.height, visible_from=side,
                       reference=reference)
        for i, (_, P, edges, side, reference, _) in enumerate(walls)
    )
    # what the extraction achieves (tests/test_map_walls_accuracy.py): faces to a fraction of a cell, 0.5°
    return Map(planes, "map", source, (max(0.02, 0.4 * float(resolution)), math.radians(0.5)))


# ------------------------------------------------------------ GeoJSON
_PROPERTIES = ("name", "free_edges", "z", "visible_from", "reference")


def _lines_of(geometry: object, where: str) -> list[list]:
    if not isinstance(geometry, dict) or geometry.get("type") not in ("LineString", "MultiLineString"):
        got = geometry.get("type") if isinstance(geometry, dict) else geometry
        raise ConfigError(expected("a LineString or MultiLineString geometry", got, where=f"{where}.geometry"))
    coords = geometry.get("coordinates")
    parts = [coords] if geometry["type"] == "LineString" else coords
    if not isinstance(parts, list) or not parts:
        raise ConfigError(expected("a list of lines", coords, where=f"{where}.geometry.coordinates"))
    out = []
    for i, part in enumerate(parts):
        at = f"{where}.geometry.coordinates" + ("" if geometry["type"] == "LineString" else f"[{i}]")
        if not isinstance(part, list) or len(part) < 2:
            raise ConfigError(expected("a line of at least 2 positions [x, y]", part, where=at))
        line = []
        for j, pos in enumerate(part):
            if not isinstance(pos, list) or len(pos) not in (2, 3):
                raise ConfigError(expected("a position [x, y] in metres", pos, where=f"{at}[{j}]"))
            line.append([_number(pos[0], f"{at}[{j}][0]"), _number(pos[1], f"{at}[{j}][1]")])
        out.append(line)
    return out


def parse_geojson(data: object, source: str = "geojson") -> Map:
    """Validate a GeoJSON FeatureCollection of wall lines (module docstring) and return its :class:`Map`."""
    if not isinstance(data, dict) or data.get("type") != "FeatureCollection":
        got = data.get("type") if isinstance(data, dict) else type(data).__name__
        raise ConfigError(expected("a GeoJSON FeatureCollection", got, where=f"{source}: type"))
    features = data.get("features")
    if not isinstance(features, list):
        raise ConfigError(expected("a list of features", features, where=f"{source}: features"))
    frame = data.get("frame", "map")
    if not isinstance(frame, str):
        raise ConfigError(expected("a frame name", frame, where=f"{source}: frame"))
    planes = []
    for i, feature in enumerate(features):
        where = f"{source}: features[{i}]"
        if not isinstance(feature, dict) or feature.get("type") != "Feature":
            raise ConfigError(expected("a GeoJSON Feature", feature, where=where))
        props = feature.get("properties") or {}
        if not isinstance(props, dict):
            raise ConfigError(expected("a mapping of properties", props, where=f"{where}.properties"))
        lines = _lines_of(feature.get("geometry"), where)
        base = {k: props[k] for k in _PROPERTIES if k in props}
        base["id"] = props.get("id", feature.get("id", f"feature{i}"))
        free = base.pop("free_edges", [])
        free = [free] if isinstance(free, str) else free
        if not isinstance(free, list) or any(e not in ("p1", "p2") for e in free):
            raise ConfigError(expected("a list drawn from ['p1', 'p2']", free, where=f"{where}.properties.free_edges"))
        segments = [(line, j) for line in lines for j in range(len(line) - 1)]
        for n, (line, j) in enumerate(segments):
            ends = {"p1": j == 0, "p2": j == len(line) - 2}  # the line's first and last point
            entry = dict(base, p1=line[j], p2=line[j + 1], free_edges=[e for e in free if ends[e]])
            if len(segments) > 1:
                entry["id"] = f"{base['id']}_{n + 1}"
                entry.setdefault("name", base["id"])
            planes.append(parse_plane(entry, where))
    return Map(tuple(planes), frame, source)


def map_to_geojson(world_map: Map) -> dict:
    """The walls of a map as a GeoJSON FeatureCollection in map metres (one LineString per wall)."""
    features = []
    for plane in world_map.planes:
        d = plane.to_dict()
        features.append({
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": [d.pop("p1"), d.pop("p2")]},
            "properties": {**d, "reference": plane.reference},
        })
    return {"type": "FeatureCollection", "frame": world_map.frame, "features": features}


def save_geojson(world_map: Map, path: str | Path) -> None:
    """Write a map as GeoJSON (see :func:`map_to_geojson`)."""
    Path(path).write_text(json.dumps(map_to_geojson(world_map), indent=1))


# ------------------------------------------------------------ any map
class JSONLimitError(ValueError):
    """A JSON document breaks one of the strict reader's rules (:func:`load_json_text`)."""


def _unique_keys(pairs: list[tuple[str, object]]) -> dict:
    """``object_pairs_hook`` of :func:`load_json_text`: the object as a dict, unless a key comes twice."""
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise JSONLimitError(f"duplicate key {short_repr(key, 60)} in one object")
        out[key] = value
    return out


def _check_json_depth(doc: object) -> None:
    """Refuse a document nested deeper than :data:`~stablemarks.maps.MAX_YAML_DEPTH` (iterative)."""
    stack = [(doc, 1)]
    while stack:
        node, depth = stack.pop()
        children = node.values() if isinstance(node, dict) else node if isinstance(node, list) else None
        if children is None:
            continue
        if depth > MAX_YAML_DEPTH:
            raise JSONLimitError(f"nested deeper than {MAX_YAML_DEPTH} levels")
        stack.extend((c, depth + 1) for c in children if isinstance(c, dict | list))


def load_json_text(text: str) -> object:
    """Parse JSON strictly, as the YAML loader (:func:`stablemarks.maps.load_yaml_text`) reads YAML: a key
    repeated in one object and nesting deeper than :data:`~stablemarks.maps.MAX_YAML_DEPTH` are errors
    (:class:`JSONLimitError`) instead of a silent last-one-wins or a ``RecursionError``; syntax errors are
    :class:`json.JSONDecodeError`."""
    try:
        doc = json.loads(text, object_pairs_hook=_unique_keys)
    except RecursionError:
        raise JSONLimitError(f"nested too deeply (at most {MAX_YAML_DEPTH} levels)") from None
    _check_json_depth(doc)
    return doc


def _read_json(path: Path) -> object:
    """A JSON map file (:func:`load_json_text`); every failure is one :class:`ConfigError` line naming it."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such map file") from None
    except (IsADirectoryError, NotADirectoryError, PermissionError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read map file: {exc.__class__.__name__}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read map file: {exc.strerror or exc.__class__.__name__}") from None
    try:
        return load_json_text(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
    except JSONLimitError as exc:
        raise ConfigError(f"{path}: invalid JSON: {exc}") from None


def load_any_map(path: str | Path, params: WallExtraction = WallExtraction()) -> Map:
    """Load walls from any supported map file, recognised by its content.

    - native map YAML (a mapping with ``planes``; :mod:`stablemarks.maps`),
    - ROS map_server YAML (``image`` and ``resolution``): walls extracted with ``params``,
    - GeoJSON (``.geojson``/``.json``, or any file, with ``type: FeatureCollection``).
    """
    path = Path(path)
    data = _read_json(path) if path.suffix.lower() in (".geojson", ".json") else read_yaml(path, "map file")
    if isinstance(data, dict):
        if "planes" in data:
            return parse_map(data, str(path))
        if "image" in data and "resolution" in data:
            occ = _parse_occupancy(data, path)
            return walls_from_occupancy(occ.grid, occ.resolution, occ.origin, params, source=str(path))
        if data.get("type") == "FeatureCollection":
            return parse_geojson(data, str(path))
    got = f"a mapping with keys {sorted(map(str, data))}" if isinstance(data, dict) else type(data).__name__
    raise ConfigError(f"{path}: not a map file: expected a stablemarks map (with 'planes'), a ROS map_server "
                      f"map (with 'image' and 'resolution') or a GeoJSON FeatureCollection, got {got}")
