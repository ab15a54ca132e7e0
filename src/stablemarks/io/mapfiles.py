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

Wall extraction (:func:`walls_from_occupancy`, pixel steps in :class:`WallExtraction`): occupied cells →
Zhang–Suen skeleton → probabilistic Hough segments → collinear pieces merged and refitted to the
skeleton → ends joined at corners and T-junctions → the other ends extended to the end of the occupied
cells and called *free* when the cells just beyond them (along the wall, across its width) are free
space → walls in map metres.

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
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import ConfigError, expected
from ..maps import Map, ReferencePlane, _number, parse_map, parse_plane, read_yaml

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
    pixels = cv2.imread(str(image_path), cv2.IMREAD_UNCHANGED)
    if pixels is None:
        raise ConfigError(f"{where}: image: cannot read {image_path} (not an image format OpenCV reads)")
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
    """

    min_length: float = 0.3
    max_gap: float = 0.1
    angle_tol: float = float(np.deg2rad(5.0))
    offset_tol: float = 1.5
    join_tol: float = 3.0
    probe: float = 2.0
    min_corner_angle: float = float(np.deg2rad(20.0))

    def __post_init__(self) -> None:
        where = "WallExtraction"
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
def _zhang_suen(img: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Zhang–Suen thinning of a 0/1 uint8 image (H, W) whose border rows and columns are 0."""
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
                    p = (out[y - 1, x], out[y - 1, x + 1], out[y, x + 1], out[y + 1, x + 1],
                         out[y + 1, x], out[y + 1, x - 1], out[y, x - 1], out[y - 1, x - 1])
                    b = 0
                    a = 0
                    for k in range(8):
                        b += p[k]
                        if p[k] == 0 and p[(k + 1) % 8] == 1:
                            a += 1
                    if b < 2 or b > 6 or a != 1:
                        continue
                    # p[0] = N, p[2] = E, p[4] = S, p[6] = W
                    if step == 0 and (p[0] * p[2] * p[4] != 0 or p[2] * p[4] * p[6] != 0):
                        continue
                    if step == 1 and (p[0] * p[2] * p[6] != 0 or p[0] * p[4] * p[6] != 0):
                        continue
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
    """One-cell-wide skeleton (H, W) bool of a boolean mask (H, W) (Zhang–Suen thinning)."""
    padded = np.pad(np.asarray(mask, dtype=np.uint8), 1)
    return _zhang_suen(padded)[1:-1, 1:-1].astype(bool)


@dataclass
class _Line:
    """A wall in pixel coordinates during extraction: the line ``c + s·t`` over ``s ∈ [s0, s1]``."""

    c: np.ndarray
    t: np.ndarray
    s0: float
    s1: float
    samples: np.ndarray  # (N, 2) points supporting the fit
    joined: list

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


def _merge(lines: list[_Line], p: WallExtraction, max_gap_px: float) -> list[_Line]:
    """Merge collinear pieces until no pair is mergeable; each merged wall refitted to all its samples.

    Two pieces are mergeable when their directions differ by less than ``angle_tol`` (or than the
    shorter piece can resolve, ``atan(2 offset_tol / length)``), the shorter's end points lie within
    ``offset_tol`` of the longer's line, and the gap between them along that line is at most
    ``max_gap_px``; mergeable pieces are grouped transitively (connected components).
    """
    while len(lines) > 1:
        C, T, N, S0, S1 = _arrays(lines)
        E = np.stack([C + S0[:, None] * T, C + S1[:, None] * T], axis=1)  # (n, 2 ends, 2)
        L = S1 - S0
        rows, cols = [], []
        for i in range(len(lines) - 1):
            j = np.arange(i + 1, len(lines))
            i_long = L[i] >= L[j]
            lc, lt, ln = (np.where(i_long[:, None], X[i], X[j]) for X in (C, T, N))
            ls0, ls1 = np.where(i_long, S0[i], S0[j]), np.where(i_long, S1[i], S1[j])
            ends = np.where(i_long[:, None, None], E[j], E[i][None])  # the shorter's ends (m, 2, 2)
            d = ends - lc[:, None, :]
            off = np.abs(np.einsum("mkd,md->mk", d, ln)).max(axis=1)
            s = np.einsum("mkd,md->mk", d, lt)
            gap = np.maximum(s.min(axis=1) - ls1, ls0 - s.max(axis=1))
            # a short piece's direction is known only to about atan(2 offset_tol / length)
            short = np.minimum(L[i], L[j])
            cos_tol = np.cos(np.maximum(p.angle_tol, np.arctan2(2.0 * p.offset_tol, short)))
            ok = (np.abs(T[j] @ T[i]) >= cos_tol) & (off <= p.offset_tol) & (gap <= max_gap_px)
            rows += [i] * int(ok.sum())
            cols += j[ok].tolist()
        if not rows:
            break
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(lines), len(lines)))
        n_groups, label = connected_components(graph, directed=False)
        merged = []
        for g in range(n_groups):
            members = np.flatnonzero(label == g)
            if len(members) == 1:
                merged.append(lines[members[0]])
            else:
                merged.append(_fit(np.vstack([lines[m].samples for m in members]), E[members].reshape(-1, 2)))
        lines = merged
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
    """Move ends near another wall's line to the intersection of the lines (corners, T-junctions)."""
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
                moves.append((i, k, float(s[np.flatnonzero(near)[np.argmin(dist[near])]])))
    for i, k, s in moves:
        if k == 0:
            lines[i].s0 = s
        else:
            lines[i].s1 = s
        lines[i].joined[k] = True


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


def walls_from_occupancy(grid, resolution: float, origin, params: WallExtraction = WallExtraction(),
                         *, source: str = "") -> Map:
    """Walls of an occupancy grid as a :class:`Map` in map metres.

    Parameters
    ----------
    grid : (H, W) occupancy values in the image's orientation (row 0 at the top): 100 (or more) is
        occupied, negative is unknown, the rest is free space.
    resolution : cell size [m].
    origin : (3,) pose ``(x [m], y [m], yaw [rad])`` of the grid's lower-left corner in the map.
    params : the extraction's tolerances.

    Returns a map of walls ``wall01, wall02, …`` (longest first), end points rounded to 1 mm, ``p1`` the
    end with the smaller ``x`` (then ``y``), ``free_edges`` the ends that stand free (module docstring),
    ``z`` the default height.
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
    lines = [_refit_to_skeleton(line, skel, params.offset_tol) for line in _merge(pieces, params, max_gap_px)]
    while len(merged := _merge(lines, params, max_gap_px)) < len(lines):  # refits can grow walls into each other
        lines = [_refit_to_skeleton(line, skel, params.offset_tol) for line in merged]
    half = np.array([float(np.median(_cell(half_map, _samples(line.end(0), line.end(1)), 0.0))) for line in lines])
    keep = [i for i, line in enumerate(lines) if line.length + 2 * half[i] + 2 >= min_px]
    lines, half = [lines[i] for i in keep], half[keep]
    _join(lines, half, params)
    free = [[not line.joined[k] and _free_end(line, k, half[i], mask, grid, params) for k in (0, 1)]
            for i, line in enumerate(lines)]
    walls = []
    for line, is_free in zip(lines, free, strict=True):
        if line.length < min_px:
            continue
        P = np.round(cell_to_map(np.array([line.end(0), line.end(1)]), grid.shape[0], resolution, origin), 3)
        d = P[1] - P[0]
        if d[0] < -1e-9 or (abs(d[0]) <= 1e-9 and d[1] < 0):
            P, is_free = P[::-1], is_free[::-1]
        walls.append((float(np.linalg.norm(d)), P, tuple(e for e, f in zip(("p1", "p2"), is_free, strict=True) if f)))
    walls.sort(key=lambda w: -w[0])
    planes = tuple(
        ReferencePlane(f"wall{i + 1:02d}", (float(P[0, 0]), float(P[0, 1])), (float(P[1, 0]), float(P[1, 1])),
                       name=f"wall{i + 1:02d}", free_edges=edges)
        for i, (_, P, edges) in enumerate(walls)
    )
    return Map(planes, "map", source)


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
def _read_json(path: Path) -> object:
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such map file") from None
    except (IsADirectoryError, PermissionError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read map file: {exc.__class__.__name__}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None


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
