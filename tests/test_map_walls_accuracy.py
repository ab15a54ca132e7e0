"""How close ``stablemarks map-walls`` puts the walls to where they were drawn, on generated map_server maps.

Each map is generated here with its truth: walls are rectangles (a centre line, a thickness of 1–3 cells of
0.05 m) drawn into the grid by the rule "a cell is occupied when its centre lies inside a wall", in a room of
free space with unknown space outside. The layouts have a room with a doorway, a free-standing partition,
a free-standing L (a corner and two free ends) and a wall meeting the room wall in a T, either drawn on the
grid as by hand (axis-aligned, faces and ends on cell boundaries) or at angles with sub-cell positions, and
noise: ragged faces (cells along a face flipped either way) and a few flipped cells elsewhere. Flipped
cells are kept one and a half cells away from the free edges: a cell flipped there moves the edge in the
map itself.

The truth the extraction is measured against is where a stereo camera sees the walls: each face that
borders free space, cut where another wall meets it, with the wall's free ends on it. Measured: the free
edges along the wall (the goal: within 2 cm), the walls' directions (within 0.5°) and how far each face
lies from the extracted plane.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
import pytest
import yaml

from stablemarks.cli import main
from stablemarks.io.mapfiles import WallExtraction, load_any_map, walls_from_occupancy
from stablemarks.maps import load_map

RES = 0.05
RAGGED = 0.05  # chance of each cell along a face to be flipped (either way)
EPS = 1e-4


@dataclass
class TrueWall:
    """A drawn wall: the rectangle around the centre line ``p1 → p2`` (extended by ``ext`` at each end,
    for square corners) ``thick`` wide; ``free``: the ends that stand free."""

    p1: np.ndarray
    p2: np.ndarray
    thick: float
    free: tuple = ()
    ext: tuple = (0.0, 0.0)

    @property
    def t(self) -> np.ndarray:
        d = self.p2 - self.p1
        return d / np.linalg.norm(d)

    @property
    def n(self) -> np.ndarray:
        return np.array([-self.t[1], self.t[0]])

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.p2 - self.p1))

    def inside(self, pts: np.ndarray, grow: float = 0.0) -> np.ndarray:
        s = (pts - self.p1) @ self.t
        r = (pts - self.p1) @ self.n
        return ((s >= -self.ext[0] - grow) & (s <= self.length + self.ext[1] + grow)
                & (np.abs(r) <= self.thick / 2 + grow))


@dataclass
class Layout:
    walls: list
    room: np.ndarray  # (4, 2) corners of the free room (centre lines of the room walls)
    doors: list = field(default_factory=list)  # (4, 2) polygons made free after drawing the walls
    hand_drawn: bool = False


@dataclass
class Face:
    """Where the camera sees a wall: the face line from ``a`` to ``b`` [m], the unit normal ``n`` toward the
    free space it is seen from, and which of its ends are the wall's free ends."""

    a: np.ndarray
    b: np.ndarray
    n: np.ndarray
    free: tuple  # of "a", "b"
    wall: int

    @property
    def t(self) -> np.ndarray:
        return (self.b - self.a) / np.linalg.norm(self.b - self.a)


def _in_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Points inside a convex polygon (counter-clockwise corners)."""
    ok = np.ones(len(pts), bool)
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        ok &= (b[0] - a[0]) * (pts[:, 1] - a[1]) - (b[1] - a[1]) * (pts[:, 0] - a[0]) >= 0
    return ok


def _rot(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


MIN_AXIS_ANGLE = np.deg2rad(8.0)
"""Slanted walls are at least this far from the grid's axes: the cells of a wall within a few degrees of
an axis jog once or twice along it, and fix its direction only to about a cell over its length."""


def _off_axis(w: TrueWall) -> bool:
    a = np.arctan2(w.t[1], w.t[0]) % (np.pi / 2)
    return MIN_AXIS_ANGLE <= a <= np.pi / 2 - MIN_AXIS_ANGLE


def make_layout(seed: int, hand_drawn: bool) -> Layout:
    """A layout of :func:`_make_layout`; slanted ones drawn again until every wall is off the axes."""
    rng = np.random.default_rng(seed)
    for _ in range(100):
        layout = _make_layout(rng, hand_drawn)
        if hand_drawn or all(_off_axis(w) for w in layout.walls):
            return layout
    raise AssertionError("no layout with every wall off the grid's axes")


def _make_layout(rng, hand_drawn: bool) -> Layout:
    """A room 9 × 6 m (walls 1–3 cells thick, a doorway in the bottom wall), a free-standing partition, a
    free-standing L and a wall from the top wall into the room (a T), placed by ``rng``. Hand-drawn:
    axis-aligned with every face and end on a cell boundary; otherwise rotated, at sub-cell positions."""
    k = rng.integers(1, 4, size=8)  # thickness of each wall [cells]
    Wr, Hr = 9.0, 6.0
    if hand_drawn:
        alpha, shift = 0.0, np.zeros(2)
    else:
        alpha, shift = np.deg2rad(rng.uniform(8.0, 37.0)), rng.uniform(0.0, RES, 2)

    def snap(v: float, cells: int) -> float:
        # a centre line whose faces are on cell boundaries: on a boundary (even) or a centre (odd)
        if not hand_drawn:
            return v
        return (np.round(v / RES - (cells % 2) / 2) + (cells % 2) / 2) * RES

    R = _rot(alpha)
    centre = np.array([Wr / 2, Hr / 2])

    def place(p) -> np.ndarray:
        return R @ (np.asarray(p, float) - centre) + centre + shift

    walls = []
    # room: bottom wall in two pieces (a doorway), right, top, left; square outer corners
    x_left, x_right = snap(0.0, k[3]), snap(Wr, k[1])
    y_bot, y_top = snap(0.0, k[0]), snap(Hr, k[2])
    door = (snap(3.3, 0) if hand_drawn else 3.3 + rng.uniform(0, 0.3), 0.0)
    door = (door[0], door[0] + (0.9 if hand_drawn else rng.uniform(0.8, 1.0)))
    hb, hr, ht, hl = (k[i] * RES / 2 for i in range(4))
    walls.append(TrueWall(place((x_left, y_bot)), place((door[0], y_bot)), k[0] * RES, ("p2",), (hl, 0.0)))
    walls.append(TrueWall(place((door[1], y_bot)), place((x_right, y_bot)), k[0] * RES, ("p1",), (0.0, hr)))
    walls.append(TrueWall(place((x_right, y_bot)), place((x_right, y_top)), k[1] * RES, (), (hb, ht)))
    walls.append(TrueWall(place((x_right, y_top)), place((x_left, y_top)), k[2] * RES, (), (hr, hl)))
    walls.append(TrueWall(place((x_left, y_top)), place((x_left, y_bot)), k[3] * RES, (), (ht, hb)))
    room = np.array([place(p) for p in [(x_left, y_bot), (x_right, y_bot), (x_right, y_top), (x_left, y_top)]])
    # the doorway: free through the bottom wall and a little beyond
    doors = [np.array([place(p) for p in [(door[0], y_bot - 0.3), (door[1], y_bot - 0.3), (door[1], y_bot + 0.2),
                                          (door[0], y_bot + 0.2)]])]
    # a free-standing partition
    if hand_drawn:
        a = np.array([snap(1.2, 0), snap(2.0, k[4])])
        walls.append(TrueWall(place(a), place(a + [snap(2.0, 0), 0.0]), k[4] * RES, ("p1", "p2")))
    else:
        ang = np.deg2rad(rng.uniform(10.0, 80.0))
        c = np.array([2.2, 3.0]) + rng.uniform(-0.2, 0.2, 2)
        half = rng.uniform(0.75, 1.0) * np.array([np.cos(ang), np.sin(ang)])
        walls.append(TrueWall(place(c - half), place(c + half), k[4] * RES, ("p1", "p2")))
    # a free-standing L: the corner Q, free ends P and S
    if hand_drawn:
        Q = np.array([snap(6.6, k[5]), snap(1.5, k[5])])
        P, S = np.array([Q[0], snap(3.3, 0)]), np.array([snap(8.4, 0), Q[1]])
    else:
        ang = np.deg2rad(rng.uniform(0.0, 360.0))
        Q = np.array([6.8, 2.4]) + rng.uniform(-0.15, 0.15, 2)
        P = Q + rng.uniform(1.5, 1.8) * np.array([np.cos(ang), np.sin(ang)])
        turn = np.deg2rad(rng.uniform(70.0, 110.0)) * rng.choice([-1, 1])
        S = Q + rng.uniform(1.5, 1.8) * np.array([np.cos(ang + turn), np.sin(ang + turn)])
    hl_ = k[5] * RES / 2
    walls.append(TrueWall(place(P), place(Q), k[5] * RES, ("p1",), (0.0, hl_)))
    walls.append(TrueWall(place(Q), place(S), k[5] * RES, ("p2",), (hl_, 0.0)))
    # a wall from the top wall into the room (a T at the top wall)
    if hand_drawn:
        x = snap(4.0, k[6])
        walls.append(TrueWall(place((x, y_top)), place((x, snap(y_top - 1.8, 0))), k[6] * RES, ("p2",)))
    else:
        x = 3.9 + rng.uniform(-0.2, 0.2)
        ang = np.deg2rad(-90 + rng.uniform(-25.0, 25.0))
        end = np.array([x, y_top]) + 1.8 * np.array([np.cos(ang), np.sin(ang)])
        walls.append(TrueWall(place((x, y_top)), place(end), k[6] * RES, ("p2",)))
    return Layout(walls, room, doors, hand_drawn)


def cell_centres(shape, origin) -> np.ndarray:
    H, W = shape
    v, u = np.mgrid[0:H, 0:W]
    return np.stack([origin[0] + (u + 0.5) * RES, origin[1] + (H - v - 0.5) * RES], axis=-1).reshape(-1, 2)


def rasterize(layout: Layout, seed: int, noise: bool = True, margin: float = 0.6):
    """The map_server image (H, W) uint8 (0 occupied, 254 free, 205 unknown) and its origin."""
    rng = np.random.default_rng(seed + 1000)
    pts = np.vstack([layout.room] + [np.array([w.p1, w.p2]) for w in layout.walls])
    lo = np.floor((pts.min(axis=0) - margin) / RES) * RES
    hi = pts.max(axis=0) + margin
    W, H = (np.ceil((hi - lo) / RES)).astype(int)
    origin = np.array([lo[0], lo[1]])
    P = cell_centres((H, W), origin)
    free = _in_polygon(P, layout.room)
    occ = np.zeros(len(P), bool)
    for w in layout.walls:
        occ |= w.inside(P)
    for d in layout.doors:
        inside = _in_polygon(P, d)
        occ &= ~inside
        free |= inside
    free &= ~occ
    occ, free = occ.reshape(H, W), free.reshape(H, W)
    if noise:
        near_end = np.zeros(len(P), bool)
        for w in layout.walls:
            for e in w.free:
                end = w.p1 if e == "p1" else w.p2
                near_end |= np.linalg.norm(P - end, axis=1) < w.thick / 2 + 1.5 * RES
        near_end = near_end.reshape(H, W)
        occ0, free0 = occ.copy(), free.copy()
        # ragged faces: cells on either side of a face flipped with probability RAGGED
        pad = np.pad(occ0, 1)
        nb_occ = pad[:-2, 1:-1] | pad[2:, 1:-1] | pad[1:-1, :-2] | pad[1:-1, 2:]
        padf = np.pad(free0, 1)
        nb_free = padf[:-2, 1:-1] | padf[2:, 1:-1] | padf[1:-1, :-2] | padf[1:-1, 2:]
        # a face cell goes only where the wall behind it stays (no holes through 1-cell walls)
        thick_behind = cv2.erode(occ0.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        behind = cv2.dilate(thick_behind.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        out = occ0 & nb_free & behind & ~near_end & (rng.random((H, W)) < RAGGED)
        grow = free0 & nb_occ & ~near_end & (rng.random((H, W)) < RAGGED)
        occ[out], free[out] = False, True
        occ[grow], free[grow] = True, False
        # a few flipped cells: holes in the walls and specks in the free space
        for mask, to_occ in ((occ0 & ~near_end, False), (free0 & ~near_end, True)):
            idx = np.flatnonzero(mask)
            pick = rng.choice(idx, size=min(6, len(idx)), replace=False)
            occ.flat[pick], free.flat[pick] = to_occ, not to_occ
    img = np.full((H, W), 205, np.uint8)
    img[free] = 254
    img[occ] = 0
    return img, origin


def true_faces(layout: Layout, min_length: float = 0.3) -> list[Face]:
    """Every face of every wall that borders free space, cut where other walls meet it (runs of at least
    ``min_length``), with the wall's free ends marked."""
    faces = []
    for i, w in enumerate(layout.walls):
        s = np.arange(-w.ext[0], w.length + w.ext[1] + 5e-4, 1e-3)
        for side in (1.0, -1.0):
            n = side * w.n
            line = w.p1 + s[:, None] * w.t + (w.thick / 2) * n
            probe = line + EPS * 10 * n
            seen = _in_polygon(probe, layout.room)
            for d in layout.doors:
                seen |= _in_polygon(probe, d)
            for other in layout.walls:
                seen &= ~other.inside(probe)
            edges = np.flatnonzero(np.diff(np.r_[0, seen.astype(int), 0]))
            for a, b in zip(edges[::2], edges[1::2] - 1, strict=True):
                if s[b] - s[a] < min_length:
                    continue
                free = tuple(name for name, j, e in (("a", a, "p1"), ("b", b, "p2"))
                             if e in w.free and abs(s[j] - (0.0 if e == "p1" else w.length)) < 2e-3)
                faces.append(Face(line[a], line[b], n, free, i))
    return faces


def end_interval(w: TrueWall, end: str, shape, origin) -> float:
    """How well the grid fixes the end ``end`` of wall ``w`` along the wall: half the gap, along the wall,
    between the last cell centre within the wall's width before the end and the first beyond it [m]
    (beyond it: a tenth of a cell inside the faces, as an extraction knows the faces to about that).

    No estimate can promise better: every end within that gap gives the same cells. It is half a cell
    or less on an axis-aligned wall (nothing when drawn on cell boundaries) and on a slanted wall two or
    three cells thick; on a slanted wall one cell thick, whose cell centres lie about a cell apart along
    it, up to about 0.7 of a cell (3.5 cm at 45°)."""
    P = cell_centres(shape, origin)
    e = 0.0 if end == "p1" else w.length
    s = (P - w.p1) @ w.t - e
    if end == "p1":
        s = -s
    r = np.abs((P - w.p1) @ w.n)
    near = np.abs(s) < 6 * RES
    inside = near & (r <= w.thick / 2)
    clearly = near & (r <= w.thick / 2 - 0.1 * RES)  # the faces are known to about a tenth of a cell
    return 0.5 * (s[clearly & (s > 0)].min() - s[inside & (s <= 0)].max())


def write_map_server(tmp_path, name: str, img: np.ndarray, origin) -> str:
    cv2.imwrite(str(tmp_path / f"{name}.pgm"), img)
    doc = {"image": f"{name}.pgm", "resolution": RES, "origin": [float(origin[0]), float(origin[1]), 0.0],
           "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


KEYS = ("edges", "limits", "angles", "offsets", "sides", "unmatched", "extra", "free_found")


def compare(planes, faces: list[Face], tol_offset: float = 0.12, tol_angle_deg: float = 4.0, limits=None) -> dict:
    """Match each true face to the extracted plane on it (nearest line within ``tol_offset`` and
    ``tol_angle_deg``, overlapping it along the wall) and measure the errors.

    ``limits(face, which)`` gives the grid's own limit on a free edge (:func:`end_interval`).

    Returns ``{"edges": [(along, across) [m] per true free edge], "limits": [m per true free edge],
    "angles": [deg per face],
    "offsets": [m, the face's distance from its plane's line, per face], "sides": [whether the plane's
    visible_from is the face's free side, per face], "unmatched": [faces], "extra": [planes matched by no
    face], "free_found": [(face, which end, found?)]}``.
    """
    out = {key: [] for key in KEYS}
    used = set()
    for f in faces:
        best, best_d = None, tol_offset
        for j, p in enumerate(planes):
            if abs(p.direction @ f.t) < np.cos(np.deg2rad(tol_angle_deg)):
                continue
            d = max(abs(float(p.offset(f.a))), abs(float(p.offset(f.b))))
            s = np.sort([p.along(f.a), p.along(f.b)])
            overlap = min(s[1], p.length) - max(s[0], 0.0)
            if overlap < 0.5 * min(s[1] - s[0], p.length):
                continue
            if d < best_d:
                best, best_d = j, d
        if best is None:
            out["unmatched"].append(f)
            continue
        used.add(best)
        p = planes[best]
        out["angles"].append(float(np.degrees(np.arccos(min(1.0, abs(p.direction @ f.t))))))
        mid = 0.5 * (f.a + f.b)
        out["offsets"].append(abs(float(p.offset(mid))))
        seen = {"left": p.normal, "right": -p.normal}.get(p.visible_from)
        out["sides"].append(seen is not None and float(seen @ f.n) > 0.99)
        for which in f.free:
            true = f.a if which == "a" else f.b
            ends = [(e, p.edge(e)) for e in ("p1", "p2")]
            e, found = min(ends, key=lambda item: np.linalg.norm(item[1] - true))
            along = float((found - true) @ f.t)
            across = float((found - true) @ f.n)
            out["edges"].append((along, across))
            out["limits"].append(limits(f, which) if limits else 0.0)
            out["free_found"].append((f, which, e in p.free_edges))
    out["extra"] = [p for j, p in enumerate(planes) if j not in used]
    return out


SEEDS = [(1, True), (2, True), (3, False), (4, False), (5, False), (6, False), (7, False)]


def measure(tmp_path, extract=load_any_map, seeds=SEEDS, noise: bool = True) -> dict:
    """Generate the maps, extract the walls with ``extract(yaml_path)``, compare; all errors pooled."""
    pooled = {key: [] for key in KEYS}
    for seed, hand in seeds:
        layout = make_layout(seed, hand)
        img, origin = rasterize(layout, seed, noise)
        walls = extract(write_map_server(tmp_path, f"gen{seed}", img, origin))

        def limits(face, which, layout=layout, shape=img.shape, origin=origin):
            return end_interval(layout.walls[face.wall], "p1" if which == "a" else "p2", shape, origin)

        res = compare(list(walls.planes), true_faces(layout), limits=limits)
        for key in pooled:
            pooled[key] += res[key]
    return pooled


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    return measure(tmp_path_factory.mktemp("maps"))


def test_every_visible_face_found_once_and_seen_from_its_free_side(measured):
    assert not measured["unmatched"], [(f.a, f.b) for f in measured["unmatched"]]
    assert not measured["extra"], [(p.id, p.p1, p.p2) for p in measured["extra"]]
    assert all(found for _, _, found in measured["free_found"])
    assert all(measured["sides"])


def test_free_edges_within_2cm_along_the_wall(measured):
    """Within 2 cm wherever the cells fix the edge that well; elsewhere (slanted walls one cell thick)
    within what the cells allow (:func:`end_interval`) and half a centimetre."""
    along = np.abs([a for a, _ in measured["edges"]])
    across = np.abs([c for _, c in measured["edges"]])
    limit = np.array(measured["limits"])
    assert len(along) >= 60
    fixed = limit <= 0.015
    assert fixed.sum() >= 30
    assert along[fixed].max() <= 0.02, sorted(along[fixed])[-5:]
    assert np.all(along <= np.maximum(0.02, limit + 0.005)), [(a, b) for a, b in zip(along, limit, strict=True)
                                                             if a > max(0.02, b + 0.005)]
    assert np.median(along) <= 0.01
    assert across.max() <= 0.015


def test_directions_within_half_a_degree(measured):
    assert max(measured["angles"]) <= 0.5
    assert np.median(measured["angles"]) <= 0.1


def test_planes_on_the_faces(measured):
    offsets = np.array(measured["offsets"])
    assert offsets.max() <= 0.01 and np.median(offsets) <= 0.003


def test_a_hand_drawn_map_to_the_millimetre(tmp_path):
    """Walls drawn on the cells (axis-aligned, faces and ends on cell boundaries), ragged and flipped
    cells: every face and free edge where it was drawn (end points are rounded to 1 mm)."""
    m = measure(tmp_path, seeds=[(1, True), (2, True)])
    assert not m["unmatched"] and not m["extra"] and all(m["sides"])
    assert np.abs(m["edges"]).max() <= 0.0011
    assert max(m["offsets"]) <= 0.0011 and max(m["angles"]) <= 0.02


def test_a_wall_one_cell_thick_is_two_planes_a_cell_apart(tmp_path):
    grid = np.zeros((40, 80), np.int8)
    grid[20, 10:70] = 100  # a free-standing wall one cell thick, 3 m long, cells of 5 cm
    planes = sorted(walls_from_occupancy(grid, RES, [0.0, 0.0, 0.0]).planes, key=lambda p: p.p1[1])
    assert len(planes) == 2
    lower, upper = planes
    # row 20 of 40 spans y = 0.95 .. 1.0 m (row 0 at the top); x from 0.5 to 3.5 m
    assert lower.p1 == (0.5, 0.95) and lower.p2 == (3.5, 0.95) and lower.visible_from == "right"
    assert upper.p1 == (0.5, 1.0) and upper.p2 == (3.5, 1.0) and upper.visible_from == "left"
    assert lower.free_edges == upper.free_edges == ("p1", "p2")
    assert lower.z == (0.0, 2.5)
    high = walls_from_occupancy(grid, RES, [0.0, 0.0, 0.0], WallExtraction(height=(0.1, 1.8)))
    assert {p.z for p in high} == {(0.1, 1.8)}


def test_a_room_wall_is_its_inner_face_only():
    grid = np.full((60, 60), -1, np.int8)
    grid[10:50, 10:50] = 0  # a free room ...
    grid[10:13, 10:50] = 100  # ... its top wall, 3 cells thick, unknown beyond
    grid[13:50, 10:13] = 100  # ... and its left wall
    walls = walls_from_occupancy(grid, RES, [0.0, 0.0, 0.0])
    assert len(walls) == 2 and all(p.reference for p in walls)
    top = next(p for p in walls if abs(p.p1[1] - p.p2[1]) < 1e-9)
    left = next(p for p in walls if abs(p.p1[0] - p.p2[0]) < 1e-9)
    # top wall: rows 10..12 of 60 → y from 2.35 to 2.5; its inner face at y = 2.35, from the left wall's
    # inner face (x = 0.65) to the end of the room's cells (x = 2.5); seen from below (the right of p1 → p2)
    assert top.p1 == (0.65, 2.35) and top.p2 == (2.5, 2.35) and top.visible_from == "right"
    assert left.p1[0] == left.p2[0] == 0.65 and max(left.p1[1], left.p2[1]) == 2.35


def test_map_walls_command_height_and_picture(tmp_path, capsys):
    layout = make_layout(3, False)
    img, origin = rasterize(layout, 3)
    path = write_map_server(tmp_path, "gen3", img, origin)
    out = tmp_path / "out" / "walls.yaml"
    assert main(["map-walls", path, "--out", str(out), "--height", "0.05,2.2"]) == 0
    printed = capsys.readouterr().out
    assert "seen from" in printed and "height 0.05–2.2 m" in printed
    walls = load_map(out)
    assert {p.z for p in walls} == {(0.05, 2.2)}
    assert {p.visible_from for p in walls} <= {"left", "right"}
    png = cv2.imread(str(out.with_suffix(".png")))
    assert png is not None and png.shape[0] > 1200 and png.shape[1] > 900


@pytest.mark.parametrize(("height", "message"), [
    ("2,1", "--height: expected LOW < HIGH [m], got '2,1'"),
    ("0,inf", "--height: expected finite heights [m], got '0,inf'"),
    ("1", "--height: expected LOW,HIGH"),
    ("a,2", "--height: expected LOW,HIGH"),
])
def test_map_walls_command_rejects_a_bad_height(tmp_path, capsys, height, message):
    layout = make_layout(1, True)
    img, origin = rasterize(layout, 1)
    path = write_map_server(tmp_path, "gen1", img, origin)
    out = tmp_path / "out" / "walls.yaml"
    assert main(["map-walls", path, "--out", str(out), f"--height={height}"]) == 1
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
