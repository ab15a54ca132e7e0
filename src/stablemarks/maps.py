"""The 2D map of walls: reference planes with free edges, loading and saving, and visibility.

A wall is a vertical plane standing on a segment ``P_M1 → P_M2`` of the floor (paper Fig 4). An edge of a
wall is *free* when the camera can see it against the background (the partition's and the whiteboard's
edges in the paper); a landmark's position is measured along the wall from a free edge (Eq 15). Walls with
``reference: false`` are in the map only as occluders.

File format (YAML, metres)::

    frame: map                 # optional, informative
    planes:
      - id: partition          # unique, letters/digits/_/-
        name: partition        # optional, free text (default: the id)
        p1: [0.0, 4.0]         # P_M1 [m]
        p2: [1.2, 4.0]         # P_M2 [m]
        free_edges: [p1]       # which ends are free boundaries: [], [p1], [p2] or [p1, p2]
        z: [0.0, 1.8]          # optional bottom and top height [m] (default [0, 2.5])
        visible_from: both     # optional: both | left | right of the direction p1 → p2
        reference: true        # optional: false = occluder only
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import yaml
from numba import njit

from .errors import ConfigError, expected, short_repr
from .geometry import StereoCamera

_ID = re.compile(r"^[A-Za-z0-9_\-]+$")
SIDES = ("both", "left", "right")

COORDINATE_LIMIT = 1e6
"""Largest magnitude of a coordinate [m] (and of any number read by :func:`_number` unless told otherwise):
1000 km is far beyond any building, and squares and products of such numbers stay exact enough and finite."""

STAMP_LIMIT = 1e12
"""Largest magnitude of a time stamp [s] read from a file (about 31,700 years)."""


@dataclass(frozen=True)
class ReferencePlane:
    """One wall of the map: the segment ``p1 → p2`` on the floor [m] and its free edges."""

    id: str
    p1: tuple[float, float]
    p2: tuple[float, float]
    name: str = ""
    free_edges: tuple[str, ...] = ()
    z: tuple[float, float] = (0.0, 2.5)
    visible_from: str = "both"
    reference: bool = True

    @cached_property
    def P1(self) -> np.ndarray:
        return np.asarray(self.p1, dtype=float)

    @cached_property
    def P2(self) -> np.ndarray:
        return np.asarray(self.p2, dtype=float)

    @cached_property
    def length(self) -> float:
        """``d_M`` of Eq 15 [m]."""
        return float(np.linalg.norm(self.P2 - self.P1))

    @cached_property
    def direction(self) -> np.ndarray:
        """Unit vector from ``p1`` to ``p2``."""
        return (self.P2 - self.P1) / self.length

    @cached_property
    def normal(self) -> np.ndarray:
        """Unit normal to the left of ``p1 → p2``."""
        t = self.direction
        return np.array([-t[1], t[0]])

    @property
    def label(self) -> str:
        return self.name or self.id

    def edge(self, which: str) -> np.ndarray:
        """World position of edge ``"p1"`` or ``"p2"``."""
        return self.P1 if which == "p1" else self.P2

    def point_at(self, s, edge: str = "p1") -> np.ndarray:
        """World points ``(..., 2)`` at distances ``s`` [m] along the wall from ``edge`` to the other end (Eq 15)."""
        s = np.asarray(s, dtype=float)
        start, direction = (self.P1, self.direction) if edge == "p1" else (self.P2, -self.direction)
        return start + s[..., None] * direction

    def along(self, points, edge: str = "p1") -> np.ndarray:
        """Distance along the wall [m] of the projection of world points ``(..., 2)``, measured from ``edge``."""
        p = np.asarray(points, dtype=float)
        start, direction = (self.P1, self.direction) if edge == "p1" else (self.P2, -self.direction)
        return (p - start) @ direction

    def offset(self, points) -> np.ndarray:
        """Signed distance [m] of world points ``(..., 2)`` from the wall's line (positive on its left)."""
        return (np.asarray(points, dtype=float) - self.P1) @ self.normal

    def faces(self, viewpoint) -> bool:
        """Whether the wall's visible side faces a viewpoint ``(x, y)``."""
        side = float(self.offset(viewpoint))
        if self.visible_from == "left":
            return side > 0
        if self.visible_from == "right":
            return side < 0
        return side != 0

    def seen_within(self, viewpoint, point, max_incidence: float | None) -> bool:
        """Whether the sight line from ``viewpoint`` (2,) to ``point`` (2,) [m] meets the wall within
        ``max_incidence`` [rad] of its normal (None: always)."""
        if max_incidence is None:
            return True
        rel = np.asarray(point, dtype=float) - np.asarray(viewpoint, dtype=float)
        return abs(float(self.normal @ rel)) >= float(np.hypot(*rel)) * math.cos(max_incidence)

    def to_dict(self) -> dict:
        d = {
            "id": self.id,
            "name": self.name or self.id,
            "p1": [float(v) for v in self.p1],
            "p2": [float(v) for v in self.p2],
            "free_edges": list(self.free_edges),
            "z": [float(v) for v in self.z],
        }
        if self.visible_from != "both":
            d["visible_from"] = self.visible_from
        if not self.reference:
            d["reference"] = False
        return d


@dataclass(frozen=True)
class Map:
    """The walls of a map, in the map frame (2-D ``x, y`` [m], z up; REP-103).

    ``planes`` are the walls (:class:`ReferencePlane`: a vertical plane standing on the floor segment
    ``p1 → p2`` [m], with its free edges, heights ``z`` [m], visible side and whether it is a reference plane
    or only an occluder). ``map[id]`` gives a wall by id; iterating gives the walls in order.
    ``accuracy`` ``(offset [m], angle [rad])``: how far (σ) a mapped wall may lie from the real one along its
    normal and turn from it — ``(0, 0)`` for an exact map (a scenario's), ``(0.02, 0.5°)`` for walls extracted
    from an occupancy grid; the map file's ``accuracy: {offset: m, angle_deg: deg}``.
    """

    planes: tuple[ReferencePlane, ...]
    frame: str = "map"
    source: str = field(default="", compare=False)
    accuracy: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        ids = [p.id for p in self.planes]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ConfigError(f"{self.source or 'map'}: planes: duplicate id {dup[0]!r}")

    @property
    def accuracy_cov(self) -> np.ndarray:
        """(2, 2) covariance of a mapped wall's offset [m] and slope from :attr:`accuracy`, as the fitted-wall tests
        take it (:func:`~stablemarks.landmarks.fit_disagreements`, :func:`~stablemarks.landmarks.common_turn`)."""
        offset, angle = self.accuracy
        return np.diag([offset, np.tan(angle)]) ** 2

    def edge_cov(self, plane_id: str, which: str) -> np.ndarray:
        """(2, 2) covariance [m²] of the map position of a wall's free edge ``which`` (``"p1"``/``"p2"``) from
        :attr:`accuracy`: along the wall's normal its offset σ plus its angle σ turning the wall about its middle
        (half its length away); along the wall the offset σ (an end is drawn as well as a wall is placed)."""
        offset, angle = self.accuracy
        plane = self[plane_id]
        n, d = plane.normal, plane.direction
        across = offset**2 + (math.tan(angle) * plane.length / 2.0) ** 2
        return across * np.outer(n, n) + offset**2 * np.outer(d, d)

    def __getitem__(self, plane_id: str) -> ReferencePlane:
        for p in self.planes:
            if p.id == plane_id:
                return p
        raise KeyError(plane_id)

    def __iter__(self):
        return iter(self.planes)

    def __len__(self) -> int:
        return len(self.planes)

    @property
    def reference_planes(self) -> tuple[ReferencePlane, ...]:
        return tuple(p for p in self.planes if p.reference)

    def segments(self) -> np.ndarray:
        """All walls as an array ``(K, 2, 2)`` of end points [m]."""
        if not self.planes:
            return np.zeros((0, 2, 2))
        return np.array([[p.P1, p.P2] for p in self.planes])

    def others(self, plane_id: str) -> tuple[np.ndarray, list[int], np.ndarray]:
        """The walls :meth:`segments` (K, 2, 2) (read-only: made once per map), the index of wall ``plane_id`` among
        them to leave out (``[]`` when not in the map) and the indices of the others (:func:`kept_walls`): what the
        landmark stage's ray casts past a wall ask of the map a dozen times a frame."""
        cache = self._others
        if plane_id not in cache:
            ids = [p.id for p in self.planes]
            exclude = [ids.index(plane_id)] if plane_id in ids else []
            kept = kept_walls(len(ids), exclude)
            kept.setflags(write=False)
            cache[plane_id] = (exclude, kept)
        exclude, kept = cache[plane_id]
        return self._segments, list(exclude), kept

    @cached_property
    def _segments(self) -> np.ndarray:
        """:meth:`segments`, made once (read-only)."""
        walls = self.segments()
        walls.setflags(write=False)
        return walls

    @cached_property
    def _others(self) -> dict[str, tuple[list[int], np.ndarray]]:
        """:meth:`others`' answers by wall id, made on first request."""
        return {}

    def to_dict(self) -> dict:
        d = {"frame": self.frame}
        if any(self.accuracy):
            d["accuracy"] = {"offset": float(self.accuracy[0]), "angle_deg": math.degrees(self.accuracy[1])}
        return {**d, "planes": [p.to_dict() for p in self.planes]}

    def save(self, path: str | Path) -> None:
        Path(path).write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))

    @classmethod
    def from_dict(cls, data: object, source: str = "map") -> Map:
        return parse_map(data, source)

    @classmethod
    def load(cls, path: str | Path) -> Map:
        return load_map(path)


# ---------------------------------------------------------------- parsing
def _number(v, where: str, limit: float = COORDINATE_LIMIT) -> float:
    """``v`` as a float: a finite YAML/JSON number (not a boolean) of magnitude at most ``limit``; else a
    one-line :class:`ConfigError` naming ``where``. Integers of any size are fine to pass (no overflow)."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ConfigError(expected("a finite number", v, where=where))
    try:
        value = float(v)
    except OverflowError:  # an integer beyond the float range
        value = math.inf
    if not math.isfinite(value):
        raise ConfigError(expected("a finite number", v, where=where))
    if abs(value) > limit:
        raise ConfigError(expected(f"a number within ±{limit:g}", v, where=where))
    return value


def _pair(v, where: str, what: str = "a list of 2 numbers [x, y] in metres") -> tuple[float, float]:
    if not isinstance(v, list | tuple) or len(v) != 2:
        raise ConfigError(expected(what, v, where=where))
    return (_number(v[0], f"{where}[0]"), _number(v[1], f"{where}[1]"))


def parse_plane(data: object, where: str) -> ReferencePlane:
    """Validate one plane entry of a map file (see the module docstring)."""
    if not isinstance(data, dict):
        raise ConfigError(expected("a mapping with id, p1, p2", data, where=where))
    known = {"id", "name", "p1", "p2", "free_edges", "z", "visible_from", "reference"}
    unknown = sorted(set(data) - known, key=str)  # keys of any type: `~:` is None, `1:` an int
    if unknown:
        raise ConfigError(f"{where}: unknown field {short_repr(unknown[0])} (known: {', '.join(sorted(known))})")
    for key in ("id", "p1", "p2"):
        if key not in data:
            raise ConfigError(f"{where}: missing field {key!r}")
    pid = data["id"]
    if isinstance(pid, int) and not isinstance(pid, bool):
        pid = str(pid)
    if not isinstance(pid, str) or not _ID.match(pid):
        raise ConfigError(expected("an id of letters, digits, '_' or '-'", pid, where=f"{where}.id"))
    name = data.get("name", pid)
    if not isinstance(name, str):
        raise ConfigError(expected("a string", name, where=f"{where}.name"))
    p1 = _pair(data["p1"], f"{where}.p1")
    p2 = _pair(data["p2"], f"{where}.p2")
    if np.hypot(p2[0] - p1[0], p2[1] - p1[1]) < 1e-6:
        raise ConfigError(f"{where}: p1 and p2 are the same point {list(p1)}; a wall needs a length")
    free = data.get("free_edges", [])
    if isinstance(free, str):
        free = [free]
    if not isinstance(free, list) or any(e not in ("p1", "p2") for e in free) or len(set(free)) != len(free):
        raise ConfigError(expected("a list drawn from ['p1', 'p2']", free, where=f"{where}.free_edges"))
    z = _pair(data.get("z", [0.0, 2.5]), f"{where}.z", "a list [z_low, z_high] in metres")
    if not z[1] > z[0]:
        raise ConfigError(expected("z_high > z_low", list(z), where=f"{where}.z"))
    side = data.get("visible_from", "both")
    if side not in SIDES:
        raise ConfigError(expected(f"one of {', '.join(SIDES)}", side, where=f"{where}.visible_from"))
    ref = data.get("reference", True)
    if not isinstance(ref, bool):
        raise ConfigError(expected("true or false", ref, where=f"{where}.reference"))
    return ReferencePlane(pid, p1, p2, name, tuple(sorted(free)), z, side, ref)


def parse_map(data: object, source: str = "map") -> Map:
    """Validate a map document (already parsed from YAML)."""
    if not isinstance(data, dict):
        raise ConfigError(expected("a mapping with a 'planes' list", type(data).__name__, where=source))
    if "planes" not in data:
        raise ConfigError(f"{source}: missing field 'planes' (a list of walls)")
    planes = data["planes"]
    if not isinstance(planes, list):
        raise ConfigError(expected("a list of walls", planes, where=f"{source}: planes"))
    if not planes:
        raise ConfigError(f"{source}: planes: expected at least one wall, got an empty list")
    frame = data.get("frame", "map")
    if not isinstance(frame, str):
        raise ConfigError(expected("a frame name", frame, where=f"{source}: frame"))
    parsed = tuple(parse_plane(p, f"{source}: planes[{i}]") for i, p in enumerate(planes))
    return Map(parsed, frame, source, _accuracy(data.get("accuracy"), f"{source}: accuracy"))


def _accuracy(value, where: str) -> tuple[float, float]:
    if value is None:
        return (0.0, 0.0)
    if not isinstance(value, dict) or set(value) - {"offset", "angle_deg"}:
        raise ConfigError(expected("a mapping {offset: m, angle_deg: deg}", value, where=where))
    offset = _number(value.get("offset", 0.0), f"{where}.offset", 10.0)
    angle = _number(value.get("angle_deg", 0.0), f"{where}.angle_deg", 45.0)
    if offset < 0 or angle < 0:
        raise ConfigError(expected("σ >= 0", value, where=where))
    return (offset, math.radians(angle))


# ------------------------------------------------------------------- YAML
MAX_YAML_DEPTH = 100
"""Deepest nesting of lists and mappings a YAML document may have."""

MAX_YAML_EXPANSION = 100_000
"""How many more nodes a YAML document may have with its aliases expanded than written out (an "alias
bomb", a few lines that expand to billions of nodes, is refused)."""

MAX_YAML_DIGITS = 25
"""Longest integer a YAML document may hold, in digits (int64 needs 19); longer ones are refused before
they are converted."""

INT64_MAX = 2**63 - 1

_YAML_BASE = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class YAMLLimitError(yaml.MarkedYAMLError):
    """A YAML document breaks one of the strict loader's rules (duplicate key, huge integer, alias bomb)."""


class StrictYAMLLoader(_YAML_BASE):  # type: ignore[misc, valid-type]
    """``yaml.safe_load``'s loader, stricter: a key repeated in one mapping, an integer beyond int64, a
    timestamp that is no date, nesting deeper than :data:`MAX_YAML_DEPTH` and alias expansion beyond
    :data:`MAX_YAML_EXPANSION` are errors (:class:`YAMLLimitError`, with the line) instead of a silent
    last-one-wins, an overflow deep inside a validator or a loader that never returns."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.setdefault(key, key_node)
                except TypeError:  # unhashable: the base class says so
                    continue
                if first is not key_node:
                    raise YAMLLimitError("while constructing a mapping", node.start_mark,
                                         f"duplicate key {short_repr(key, 60)} (first at line "
                                         f"{first.start_mark.line + 1})", key_node.start_mark)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node):
        digits = sum(ch.isdigit() for ch in str(node.value))
        if digits > MAX_YAML_DIGITS:
            raise YAMLLimitError(None, None, f"integer of {digits} digits is out of range (at most "
                                 f"{INT64_MAX} in magnitude)", node.start_mark)
        value = super().construct_yaml_int(node)
        if abs(value) > INT64_MAX:
            raise YAMLLimitError(None, None, f"integer {short_repr(value, 40)} is out of range (at most "
                                 f"{INT64_MAX} in magnitude)", node.start_mark)
        return value

    def construct_yaml_timestamp(self, node):
        try:
            return super().construct_yaml_timestamp(node)
        except (ValueError, OverflowError) as exc:
            raise YAMLLimitError(None, None, f"{short_repr(node.value, 40)} is not a valid date: {exc}",
                                 node.start_mark) from None


StrictYAMLLoader.add_constructor("tag:yaml.org,2002:int", StrictYAMLLoader.construct_yaml_int)
StrictYAMLLoader.add_constructor("tag:yaml.org,2002:timestamp", StrictYAMLLoader.construct_yaml_timestamp)


def _check_node_graph(root) -> None:
    """Refuse a composed document that nests deeper than :data:`MAX_YAML_DEPTH`, refers to itself through an
    alias, or whose aliases expand it by more than :data:`MAX_YAML_EXPANSION` nodes (iterative: no recursion;
    scalars, most of a document, are counted without a visit of their own)."""
    scalar = yaml.ScalarNode
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    on_path: set[int] = set()
    distinct = 0

    def children(n):
        if isinstance(n, yaml.SequenceNode):
            return n.value
        return [c for pair in n.value for c in pair]  # a mapping

    if isinstance(root, scalar):
        return
    stack = [(root, False)]
    while stack:
        n, done = stack.pop()
        key = id(n)
        if done:
            on_path.discard(key)
            total, deepest = 1, 0
            for c in children(n):
                if isinstance(c, scalar):
                    total += 1
                    deepest = max(deepest, 1)
                else:
                    total += size[id(c)]
                    deepest = max(deepest, depth[id(c)])
            size[key], depth[key] = total, deepest + 1
            if deepest + 1 > MAX_YAML_DEPTH:
                raise YAMLLimitError(None, None, f"nested deeper than {MAX_YAML_DEPTH} levels", n.start_mark)
            continue
        if key in size:
            continue
        on_path.add(key)
        stack.append((n, True))
        for c in children(n):
            if isinstance(c, scalar):
                distinct += 1  # shared scalars (aliases of a scalar) are counted again: harmless
                continue
            if id(c) in on_path:
                raise YAMLLimitError(None, None, "an alias refers to a node that contains it (a recursive "
                                     "structure)", c.start_mark)
            if id(c) not in size:
                stack.append((c, False))
    written = distinct + len(size)
    if size[id(root)] > written + MAX_YAML_EXPANSION:
        raise YAMLLimitError(None, None, f"its aliases expand it to {short_repr(size[id(root)], 30)} nodes from "
                             f"{written} written (at most {MAX_YAML_EXPANSION} more are allowed)", root.start_mark)


def load_yaml_text(text: str) -> object:
    """Parse one YAML document with :class:`StrictYAMLLoader`; raises :class:`yaml.YAMLError` (with a mark
    where there is one) for anything malformed or beyond the loader's limits."""
    loader = StrictYAMLLoader(text)
    try:
        try:
            node = loader.get_single_node()
        except RecursionError:
            raise YAMLLimitError(None, None, "nested too deeply", None) from None
        if node is None:
            return None
        _check_node_graph(node)
        try:
            return loader.construct_document(node)
        except RecursionError:
            raise YAMLLimitError(None, None, "nested too deeply", node.start_mark) from None
    finally:
        loader.dispose()


def yaml_error_text(exc: yaml.YAMLError) -> str:
    """``at line L, column C: problem`` (or just the problem) of a YAML error, for one-line messages."""
    mark = getattr(exc, "problem_mark", None)
    at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
    problem = getattr(exc, "problem", None) or "invalid YAML"
    return f"{at}: {problem}"


def parse_yaml(text: str, source: str) -> object:
    """Parse YAML ``text`` strictly (:func:`load_yaml_text`); errors become one :class:`ConfigError` line
    ``SOURCE: invalid YAML at line L, column C: problem``."""
    try:
        return load_yaml_text(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: invalid YAML{yaml_error_text(exc)}") from None


def read_yaml(path: str | Path, what: str = "file") -> object:
    """Read a YAML file strictly (:func:`parse_yaml`: duplicate keys, integers beyond int64, alias bombs and
    deep nesting are errors); a missing file or a syntax error becomes a one-line :class:`ConfigError`."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such {what}") from None
    except (IsADirectoryError, NotADirectoryError, PermissionError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read {what}: {exc.__class__.__name__}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read {what}: {exc.strerror or exc.__class__.__name__}") from None
    return parse_yaml(text, str(path))


def load_map(path: str | Path) -> Map:
    """Load and validate a map file (YAML, metres, map frame: ``planes`` with ``id``, ``p1``, ``p2``, optional
    ``free_edges``, ``z``, ``visible_from``, ``reference``; the module docstring has the format). A malformed
    file raises :class:`~stablemarks.errors.ConfigError` naming the file and the field."""
    return parse_map(read_yaml(path, "map file"), str(path))


# ------------------------------------------------------------- visibility
def _crossings(origins, rays, walls, exclude: Sequence[int] = ()):
    """Ray/wall intersections: ``lam`` (N, K) along ``rays`` (N, 2) from ``origins`` ((N, 2) or one (2,)) to
    each kept wall of ``walls`` (K, 2, 2), NaN where a ray misses the wall or runs parallel to it.

    One numba loop (:func:`_crossings_kernel`): the landmark stage asks this of a handful of rays a few dozen
    times a frame, where a dozen small NumPy temporaries per call cost ~50 µs; the same element-wise arithmetic
    (``s = b − a``, ``denom = r0 s1 − r1 s0``, ``lam = (qx s1 − qy s0) / denom``, ``mu = (qx r1 − qy r0) / denom``)."""
    o = np.asarray(origins, dtype=float).reshape(-1, 2)
    r = np.asarray(rays, dtype=float).reshape(-1, 2)
    walls = np.asarray(walls, dtype=float).reshape(-1, 2, 2)
    kept = kept_walls(len(walls), exclude)
    if len(o) != len(r) and len(o) != 1 and len(r) != 1:
        raise ValueError(f"_crossings: {len(o)} origins and {len(r)} rays do not broadcast")
    return _crossings_kernel(o, r, walls, kept)


def kept_walls(n_walls: int, exclude: Sequence[int] = ()) -> np.ndarray:
    """Indices (int) of the ``n_walls`` walls left after leaving out those in ``exclude`` (np.delete's index rules
    and errors)."""
    kept = np.arange(n_walls)
    return np.delete(kept, list(exclude)) if len(exclude) else kept


@njit(cache=True, error_model="numpy")
def nearest_crossing(o0, o1, r0, r1, walls, kept):  # pragma: no cover - numba
    """:func:`ray_distances` of one ray from ``(o0, o1)`` along the unit ``(r0, r1)`` to the walls ``walls[kept]``:
    the least crossing beyond 1e-9 m, ``inf`` when none."""
    dist = np.inf
    for j in range(kept.shape[0]):
        lam = _crossing(o0, o1, r0, r1, walls, kept[j])
        if lam > 1e-9 and lam < dist:
            dist = lam
    return dist


@njit(cache=True, error_model="numpy")
def sight_blocked(o0, o1, r0, r1, walls, kept):  # pragma: no cover - numba
    """:func:`segments_block` of one sight line from ``(o0, o1)`` to ``(o0 + r0, o1 + r1)`` past the walls
    ``walls[kept]``: whether one crosses it strictly between its ends (:func:`_blocked`'s bounds)."""
    for j in range(kept.shape[0]):
        lam = _crossing(o0, o1, r0, r1, walls, kept[j])
        if (lam > 1e-9) & (lam < 1 - 1e-6):
            return True
    return False


@njit(cache=True, error_model="numpy")
def _crossings_kernel(o, r, walls, kept):  # pragma: no cover - numba
    """:func:`_crossings` of origins ``o`` (N or 1, 2), rays ``r`` (N or 1, 2) and the walls ``walls[kept]``."""
    n = max(o.shape[0], r.shape[0])
    lam = np.empty((n, kept.shape[0]))
    for i in range(n):
        oi = 0 if o.shape[0] == 1 else i
        ri = 0 if r.shape[0] == 1 else i
        for j in range(kept.shape[0]):
            lam[i, j] = _crossing(o[oi, 0], o[oi, 1], r[ri, 0], r[ri, 1], walls, kept[j])
    return lam


@njit(cache=True, error_model="numpy", inline="always")
def _crossing(o0, o1, r0, r1, walls, w):  # pragma: no cover - numba
    """:func:`_crossings` of one ray ``o + lam r`` and one wall ``walls[w]`` (K, 2, 2): ``lam``, NaN where the ray
    misses the wall or runs parallel to it."""
    a0, a1 = walls[w, 0, 0], walls[w, 0, 1]
    s0, s1 = walls[w, 1, 0] - a0, walls[w, 1, 1] - a1
    denom = r0 * s1 - r1 * s0
    qx = a0 - o0
    qy = a1 - o1
    lj = (qx * s1 - qy * s0) / denom
    mu = (qx * r1 - qy * r0) / denom
    return lj if (abs(denom) > 1e-12) & (mu >= 0) & (mu <= 1) else np.nan


def segments_block(origins, targets, walls, exclude: Sequence[int] = ()) -> np.ndarray:
    """Whether the sight lines ``origins → targets`` (N, 2) cross any wall of ``walls`` (K, 2, 2).

    Walls whose index is in ``exclude`` are ignored (the wall a target lies on). Touching a wall only
    at the very end of the sight line does not block.
    """
    o = np.asarray(origins, dtype=float).reshape(-1, 2)
    t = np.asarray(targets, dtype=float).reshape(-1, 2)
    if len(t) == 0 or len(np.asarray(walls).reshape(-1, 4)) == len(exclude):
        return np.zeros(len(t), dtype=bool)
    return _blocked(_crossings(o, t - o, walls, exclude))


def _blocked(lam: np.ndarray) -> np.ndarray:
    """(N,) whether sight lines cross a wall strictly between their ends, from :func:`_crossings` (N, K)."""
    with np.errstate(invalid="ignore"):
        return ((lam > 1e-9) & (lam < 1 - 1e-6)).any(axis=1)


def ray_distances(origins, directions, walls, exclude: Sequence[int] = ()) -> np.ndarray:
    """Distance (N,) [m] from ``origins`` along unit ``directions`` (N, 2) to the first wall of ``walls``
    (K, 2, 2) they hit, ``inf`` where none (walls with an index in ``exclude`` are ignored)."""
    d = np.asarray(directions, dtype=float).reshape(-1, 2)
    if len(d) == 0 or len(np.asarray(walls).reshape(-1, 4)) == len(exclude):
        return np.full(len(d), np.inf)
    lam = _crossings(origins, d, walls, exclude)
    with np.errstate(invalid="ignore"):
        lam = np.where(lam > 1e-9, lam, np.inf)
    return lam.min(axis=1)


@dataclass(frozen=True)
class VisiblePart:
    """The part of a wall a camera sees: intervals of distance along the wall from ``p1`` [m]."""

    plane: ReferencePlane
    intervals: tuple[tuple[float, float], ...]
    free_edges_visible: tuple[str, ...]

    @property
    def visible_length(self) -> float:
        return float(sum(b - a for a, b in self.intervals))


def visible_parts(
    world_map: Map,
    camera: StereoCamera,
    X,
    *,
    max_range: float = 12.0,
    margin_px: float = 0.0,
    edge_tol: float = 0.02,
    planes: Iterable[ReferencePlane] | None = None,
) -> list[VisiblePart]:
    """Which walls, and which parts of each, the left camera sees from robot pose ``X``.

    A point of a wall is visible when it projects inside the left image (with ``margin_px`` to spare),
    lies within ``max_range`` [m] in front of the camera (depth above 5 cm), the wall faces the camera, and
    no other wall of the map blocks the sight line. Walls with nothing visible are left out. A free edge
    counts as visible when the visible part reaches within ``edge_tol`` [m] of it.

    The intervals are exact: along a wall ``s ↦ P(s)`` every condition changes only where the depth, the
    range or the image column reach their limits, or where the sight line passes an end of another wall or
    the point crosses another wall's line. Those break points are computed in closed form, for all walls at
    once, and each piece between two is tested at its middle; the wall's ends are tested too (an end
    touching another wall may be all that is seen of a wall: a zero-length interval).
    """
    centre, _ = camera.optical_centres(X)
    index = {p.id: i for i, p in enumerate(world_map.planes)}
    targets = [p for p in (planes if planes is not None else world_map.planes) if p.faces(centre)]
    if not targets:
        return []
    walls = world_map._segments  # (K, 2, 2), made once per map (read-only)
    own = np.array([index[p.id] for p in targets])
    P1 = walls[own, 0]  # (T, 2)
    length = np.array([p.length for p in targets])
    t = (walls[own, 1] - P1) / length[:, None]
    q = P1 - centre
    psi = camera.camera_pose(X).theta
    c, s = math.cos(psi), math.sin(psi)
    # linear limits g·(q + s t) = k: depth Z_c = 0.05 m and the image sides f X_c = (u − cu) Z_c
    sides = np.array([-0.5 + margin_px, camera.width - 0.5 - margin_px])[:, None] - camera.cu
    g = np.concatenate([[[c, s]], camera.f * np.array([[s, -c]]) - sides * np.array([[c, s]])])  # (3, 2)
    k = np.array([_MIN_DEPTH_VISIBLE, 0.0, 0.0])
    qt = (q * t).sum(-1)[:, None]
    tips = walls.reshape(-1, 2) - centre  # sight lines through the walls' ends
    e = walls[:, 1] - walls[:, 0]  # crossings with the walls' lines
    with np.errstate(divide="ignore", invalid="ignore"):
        b = np.concatenate([
            np.zeros_like(qt),
            (k - q @ g.T) / (t @ g.T),
            -qt + np.sqrt(qt**2 - (q * q).sum(-1)[:, None] + max_range**2) * np.array([-1.0, 1.0]),  # range
            _cross(q[:, None, :], tips[None]) / _cross(tips[None], t[:, None, :]),
            _cross(walls[None, :, 0] - P1[:, None], e[None]) / _cross(t[:, None, :], e[None]),
        ], axis=1)  # fmt: skip
    L = length[:, None]
    b = np.where((b > 0) & (b < L), b, L)
    b[:, 0] = 0.0
    b.sort(axis=1)
    # the wall's start on its own (an end touching another wall may be all that is seen of a wall), the
    # pieces between break points (some of zero length: skipped), the wall's end on its own
    lo = np.concatenate([np.zeros_like(L), b[:, :-1], L], axis=1)
    hi = np.concatenate([np.zeros_like(L), b[:, 1:], L], axis=1)
    test = hi > lo
    test[:, [0, -1]] = True
    row, col = np.nonzero(test)
    mid = 0.5 * (lo[row, col] + hi[row, col])
    pts = P1[row] + mid[:, None] * t[row]
    Xc, Zc = camera.to_camera(X, pts)
    uv = camera.project_columns(X, pts)
    ok = (Zc > _MIN_DEPTH_VISIBLE) & (np.hypot(Xc, Zc) <= max_range) & camera.in_image(uv[:, 0], margin_px)
    if ok.any():
        lam = _crossings(centre, pts[ok] - centre, walls)
        lam[np.arange(len(lam)), own[row[ok]]] = np.nan  # a wall does not hide itself
        ok[ok] = ~_blocked(lam)
    # the runs of seen pieces of each wall, over its tested pieces only (in order: np.nonzero's row-major order):
    # a wall's break points are a few among the map's many, so most of its pieces are empty and were walked for
    # nothing (hall: 31 walls, ~60 pieces each, 1 in 7 tested)
    found: list[list[list[float]]] = [[] for _ in targets]
    run, prev = False, -1
    for r, a, z, v in zip(row.tolist(), lo[row, col].tolist(), hi[row, col].tolist(), ok.tolist(), strict=True):
        if r != prev:
            run, prev = False, r
        if v and run:
            found[r][-1][1] = z
        elif v:
            found[r].append([a, z])
        run = v
    out: list[VisiblePart] = []
    for plane, intervals in zip(targets, found, strict=True):
        if not intervals:
            continue
        free = tuple(
            e for e in plane.free_edges
            if any(abs((0.0 if e == "p1" else plane.length) - v) <= edge_tol for iv in intervals for v in iv)
        )
        out.append(VisiblePart(plane, tuple((a, z) for a, z in intervals), free))
    return out


_MIN_DEPTH_VISIBLE = 0.05
"""Wall points nearer than this in front of the camera [m] are not visible."""


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z component of the cross product of 2-D vectors ``(..., 2)``."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
