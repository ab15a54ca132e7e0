"""The simulated world as ray-castable primitives, with procedural textures.

A scenario becomes three kinds of primitives (DESIGN §6, 2.5D):

- *faces*: vertical rectangles standing on a floor segment ``a → a + length·e`` from ``z_low`` to
  ``z_high`` (walls, the four sides of each box);
- *cylinders*: vertical circles (poles);
- *caps*: the horizontal tops of boxes and poles, seen from above when they are lower than the camera;

plus the floor (``z = 0``), an optional ceiling and the background. Walls are thin and look the same from
both sides (texture and painted features); ``visible_from`` matters to the map only. A ray in the floor plane from an
optical centre ``o`` with direction ``D`` whose forward component (along the camera's optical axis) is 1
reaches a point at parameter ``t`` equal to its depth ``Z_c``; image row ``v`` then sees the height
``z = h - (v - c_v) t / f``. Casting a fan of such rays against every primitive and keeping, for every row,
the nearest primitive whose height range contains the row's height is exact for this world
(:meth:`World.zbuffer`); the renderer and the ground truth's occlusion test both use it.

Textures are band-limited Gaussian noise fields (two octaves: blobs of ``scale`` and ``4·scale``), sampled on
a periodic grid of ``scale / 4`` and seeded by the object's id, so the world looks the same in every run.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter

from .scenario import Feature, Scenario, Texture

BACKGROUND, FLOOR, CEILING = -1, -2, -3
"""Primitive indices of the surroundings in :meth:`World.zbuffer`'s id buffer."""

_MAX_CELLS = (2048, 1024)
"""Largest texture grid (along, up); larger surfaces repeat the pattern."""


@dataclass(frozen=True)
class TextureGrid:
    """A periodic albedo field [gray levels] on a grid of ``res`` [m], sampled bilinearly.

    ``values`` (ny + 1, nx + 1) float32 holds one period plus a wrapped copy of its first row and column.
    """

    values: np.ndarray
    res: float

    @classmethod
    def build(cls, texture: Texture, extent: tuple[float, float], key: str) -> TextureGrid:
        """The albedo of ``texture`` over ``extent`` (along, up) [m]; ``key`` seeds the noise."""
        if texture.kind == "plain" or texture.contrast == 0:
            return cls(np.full((2, 2), texture.base, dtype=np.float32), 1.0)
        res = texture.scale / 4.0
        nx = int(min(max(8, math.ceil(extent[0] / res) + 1), _MAX_CELLS[0]))
        ny = int(min(max(8, math.ceil(extent[1] / res) + 1), _MAX_CELLS[1]))
        rng = np.random.default_rng(zlib.crc32(key.encode()))
        field_ = np.zeros((ny, nx))
        for sigma, weight in ((2.0, 1.0), (8.0, 0.3)):
            octave = gaussian_filter(rng.standard_normal((ny, nx)), sigma, mode="wrap")
            field_ += weight * octave / octave.std()
        values = texture.base + texture.contrast * field_ / field_.std()
        return cls(np.pad(values, ((0, 1), (0, 1)), mode="wrap").astype(np.float32), res)

    def sample(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Albedo at surface coordinates ``(a, b)`` [m] (any equal shapes), bilinear, periodic."""
        ny, nx = self.values.shape[0] - 1, self.values.shape[1] - 1
        if nx == 1:
            return np.full(np.shape(a), self.values[0, 0], dtype=np.float32)
        inv = np.float32(1.0 / self.res)
        x = np.mod(np.asarray(a, dtype=np.float32) * inv, np.float32(nx))
        y = np.mod(np.asarray(b, dtype=np.float32) * inv, np.float32(ny))
        x0 = np.minimum(x.astype(np.int32), nx - 1)
        y0 = np.minimum(y.astype(np.int32), ny - 1)
        fx, fy = x - x0, y - y0
        flat = self.values.ravel()
        i00 = y0 * (nx + 1) + x0
        v00, v01 = flat[i00], flat[i00 + 1]
        v10, v11 = flat[i00 + nx + 1], flat[i00 + nx + 2]
        top = v00 + fx * (v01 - v00)
        return top + fy * (v10 + fx * (v11 - v10) - top)


@dataclass(frozen=True)
class SurfaceObject:
    """One object of the world (wall, box or pole): its texture, gloss and painted features."""

    kind: str  # "wall" | "box" | "pole"
    id: str
    texture: TextureGrid
    gloss: float = 0.0
    features: tuple[Feature, ...] = ()
    top: TextureGrid | None = None  # the cap of a box or pole


@dataclass(frozen=True)
class Cast:
    """Rays from ``origin`` (2,) with directions ``dirs`` (R, 2) cast against every primitive.

    ``t_face``, ``s_face`` (R, K): depth parameter and texture coordinate along each face (``inf`` where
    missed); ``t_cyl`` (R, P): entry depth into each cylinder; ``t_cap`` (R, C, 2): entry and exit depth of
    each cap's solid (``inf`` where missed).
    """

    origin: np.ndarray
    dirs: np.ndarray
    t_face: np.ndarray
    s_face: np.ndarray
    t_cyl: np.ndarray
    t_cap: np.ndarray


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


@dataclass
class World:
    """Ray-castable primitives of a scenario (see the module docstring)."""

    scenario: Scenario
    objects: list[SurfaceObject] = field(default_factory=list)
    # faces (K): start point, unit direction, length, z range, owner object, texture offset along it
    face_a: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    face_e: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    face_len: np.ndarray = field(default_factory=lambda: np.zeros(0))
    face_z: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    face_owner: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    face_offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # cylinders (P): centre, radius, z range, owner object
    cyl_c: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    cyl_r: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cyl_z: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    cyl_owner: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    # caps (C): height, owner object, and the faces (box) or cylinder (pole) bounding the solid
    caps: list[tuple[float, int, tuple[int, ...], int]] = field(default_factory=list)
    floor: TextureGrid | None = None
    ceiling: TextureGrid | None = None

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> World:
        faces: list[tuple] = []
        world = cls(scenario)
        feats = {w.id: tuple(f for f in scenario.features if f.wall == w.id) for w in scenario.walls}
        for w in scenario.walls:
            plane = w.plane
            owner = len(world.objects)
            world.objects.append(SurfaceObject(
                "wall", w.id, TextureGrid.build(w.texture, (plane.length, w.z[1] - w.z[0]), f"wall:{w.id}"),
                w.gloss, feats[w.id]))
            faces.append((plane.P1, plane.direction, plane.length, w.z, owner, 0.0))
        cyl, caps = [], []
        for b in scenario.boxes:
            owner = len(world.objects)
            perimeter = 2.0 * (b.size[0] + b.size[1])
            world.objects.append(SurfaceObject(
                "box", b.id, TextureGrid.build(b.texture, (perimeter, b.height), f"box:{b.id}"),
                top=TextureGrid.build(b.texture, b.size, f"box-top:{b.id}")))
            corners = b.corners()
            offset = 0.0
            first = len(faces)
            for i in range(4):
                a, c = corners[i], corners[(i + 1) % 4]
                length = float(np.hypot(*(c - a)))
                faces.append((a, (c - a) / length, length, (0.0, b.height), owner, offset))
                offset += length
            caps.append((b.height, owner, tuple(range(first, first + 4)), -1))
        for p in scenario.poles:
            owner = len(world.objects)
            world.objects.append(SurfaceObject(
                "pole", p.id, TextureGrid.build(p.texture, (2 * math.pi * p.radius, p.height), f"pole:{p.id}"),
                top=TextureGrid.build(p.texture, (2 * p.radius, 2 * p.radius), f"pole-top:{p.id}")))
            caps.append((p.height, owner, (), len(cyl)))
            cyl.append((p.center, p.radius, (0.0, p.height), owner))
        if faces:
            world.face_a = np.array([f[0] for f in faces], dtype=float)
            world.face_e = np.array([f[1] for f in faces], dtype=float)
            world.face_len = np.array([f[2] for f in faces], dtype=float)
            world.face_z = np.array([f[3] for f in faces], dtype=float)
            world.face_owner = np.array([f[4] for f in faces], dtype=int)
            world.face_offset = np.array([f[5] for f in faces], dtype=float)
        if cyl:
            world.cyl_c = np.array([c[0] for c in cyl], dtype=float)
            world.cyl_r = np.array([c[1] for c in cyl], dtype=float)
            world.cyl_z = np.array([c[2] for c in cyl], dtype=float)
            world.cyl_owner = np.array([c[3] for c in cyl], dtype=int)
        world.caps = caps
        room = scenario.room
        world.floor = TextureGrid.build(room.floor, (6.0, 6.0), "floor")
        if room.ceiling_height is not None:
            world.ceiling = TextureGrid.build(room.ceiling, (6.0, 6.0), "ceiling")
        return world

    @property
    def n_faces(self) -> int:
        return len(self.face_len)

    @property
    def n_cyl(self) -> int:
        return len(self.cyl_r)

    def primitive_owner(self, pid: int) -> int:
        """Object index of primitive ``pid`` (faces, then cylinders, then caps); -1 for the surroundings."""
        if pid < 0:
            return -1
        if pid < self.n_faces:
            return int(self.face_owner[pid])
        if pid < self.n_faces + self.n_cyl:
            return int(self.cyl_owner[pid - self.n_faces])
        return self.caps[pid - self.n_faces - self.n_cyl][1]

    # ------------------------------------------------------------- casting
    def cast(self, origin, dirs) -> Cast:
        """Intersect rays ``origin + t·dirs`` (R rays, ``t > 0``) with every face, cylinder and cap solid."""
        o = np.asarray(origin, dtype=float).reshape(2)
        D = np.asarray(dirs, dtype=float).reshape(-1, 2)
        R = len(D)
        # faces: o + t D = a + s e  ->  t = (a-o)×e / D×e,  s = (a-o)×D / D×e
        q = self.face_a - o  # (K, 2)
        denom = _cross(D[:, None, :], self.face_e[None, :, :])  # (R, K)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = _cross(q, self.face_e)[None, :] / denom
            s = _cross(q[None, :, :], D[:, None, :]) / denom
        hit = (np.abs(denom) > 1e-12) & (t > 1e-9) & (s >= 0) & (s <= self.face_len)
        t_face = np.where(hit, t, np.inf)
        s_face = np.where(hit, s + self.face_offset, np.nan)
        # cylinders: |o + t D - c|² = r², entry root
        t_cyl = np.full((R, self.n_cyl), np.inf)
        t_cyl_out = np.full((R, self.n_cyl), np.inf)
        if self.n_cyl:
            w = o - self.cyl_c  # (P, 2)
            A = np.einsum("ri,ri->r", D, D)[:, None]
            B = 2.0 * (D @ w.T)  # (R, P)
            C = (np.einsum("pi,pi->p", w, w) - self.cyl_r**2)[None, :]
            disc = B**2 - 4 * A * C
            root = np.sqrt(np.where(disc > 0, disc, 0.0))
            t1 = (-B - root) / (2 * A)
            t2 = (-B + root) / (2 * A)
            ok = (disc > 0) & (t1 > 1e-9)
            t_cyl = np.where(ok, t1, np.inf)
            t_cyl_out = np.where(ok, t2, np.inf)
        t_cap = np.full((R, len(self.caps), 2), np.inf)
        for j, (_, _, faces, c) in enumerate(self.caps):
            if c >= 0:
                t_cap[:, j, 0], t_cap[:, j, 1] = t_cyl[:, c], t_cyl_out[:, c]
            else:
                tf = t_face[:, list(faces)]
                finite = np.isfinite(tf)
                two = finite.sum(axis=1) >= 2
                t_cap[two, j, 0] = np.min(tf[two], axis=1)
                t_cap[two, j, 1] = np.max(np.where(finite[two], tf[two], -np.inf), axis=1)
        return Cast(o, D, t_face, s_face, t_cyl, t_cap)

    def zbuffer(self, cast: Cast, rows: np.ndarray, h: float, f: float, cv: float, *,
                exclude_owner: int = -1, room: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Depth and primitive of the nearest surface seen by each image row of each ray.

        Parameters
        ----------
        cast : rays whose directions have unit forward component (``t`` = depth ``Z_c`` [m]).
        rows : (V,) increasing image rows ``v`` [px] (need not be contiguous).
        h, f, cv : camera height [m], focal length [px] and principal row [px].
        exclude_owner : an object index to leave out (the wall an edge under test lies on).
        room : include floor and ceiling.

        Returns
        -------
        depth : (V, R) depth ``Z_c`` [m] of the seen point (``inf``: background).
        pid : (V, R) int16 primitive index: faces ``0..K-1``, cylinders ``K..K+P-1``, caps after them;
        :data:`FLOOR`, :data:`CEILING` or :data:`BACKGROUND`.
        """
        v = np.asarray(rows, dtype=float)
        R = cast.dirs.shape[0]
        depth = np.full((len(v), R), np.inf)
        pid = np.full((len(v), R), BACKGROUND, dtype=np.int16)
        if room:
            below = v > cv
            with np.errstate(divide="ignore"):
                d_floor = np.where(below, f * h / (v - cv), np.inf)
            depth[below] = d_floor[below, None]
            pid[below] = FLOOR
            hc = self.scenario.room.ceiling_height
            if hc is not None and hc > h:
                above = v < cv
                depth[above] = (f * (hc - h) / (cv - v[above]))[:, None]
                pid[above] = CEILING

        def paint(k: int, t: np.ndarray, v_lo: np.ndarray, v_hi: np.ndarray, depth_rows=None) -> None:
            finite = np.flatnonzero(np.isfinite(t))
            if len(finite) == 0:
                return
            c0, c1 = finite[0], finite[-1] + 1
            lo, hi = v_lo[c0:c1], v_hi[c0:c1]
            r0 = int(np.searchsorted(v, np.nanmin(lo), side="left"))
            r1 = int(np.searchsorted(v, np.nanmax(hi), side="right"))
            if r1 <= r0:
                return
            vv = v[r0:r1, None]
            sub = depth[r0:r1, c0:c1]
            d = np.broadcast_to(t[c0:c1] if depth_rows is None else depth_rows[r0:r1, None], sub.shape)
            m = (vv >= lo) & (vv <= hi) & (d < sub)
            np.copyto(sub, d, where=m)
            np.copyto(pid[r0:r1, c0:c1], np.int16(k), where=m)

        with np.errstate(divide="ignore", invalid="ignore"):
            for k in range(self.n_faces):
                if self.face_owner[k] == exclude_owner:
                    continue
                t = cast.t_face[:, k]
                z0, z1 = self.face_z[k]
                paint(k, t, cv + f * (h - z1) / t, cv + f * (h - z0) / t)
            for p in range(self.n_cyl):
                if self.cyl_owner[p] == exclude_owner:
                    continue
                t = cast.t_cyl[:, p]
                z0, z1 = self.cyl_z[p]
                paint(self.n_faces + p, t, cv + f * (h - z1) / t, cv + f * (h - z0) / t)
            for j, (height, owner, _, _) in enumerate(self.caps):
                if owner == exclude_owner or height >= h:
                    continue  # a top at or above the eyes is not seen
                t_in, t_out = cast.t_cap[:, j, 0], cast.t_cap[:, j, 1]
                d_rows = np.where(v > cv, f * (h - height) / (v - cv), np.inf)
                paint(self.n_faces + self.n_cyl + j, t_in,
                      cv + f * (h - height) / t_out, cv + f * (h - height) / t_in, d_rows)
        return depth, pid
