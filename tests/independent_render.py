"""A stereo pair rendered by a renderer that is not the project's: pybullet's TinyRenderer, headless.

The front-end tests elsewhere render with :mod:`stablemarks.sim`, whose optics, textures and noise the method was
tuned on. Here the images come from pybullet (``p.DIRECT``, ``ER_TINY_RENDERER``) with grayscale photographs
from ``skimage.data`` as textures (gravel, brick, grass, and the ``camera``/``coffee`` photographs pasted on a
panel as posters), so what the method is tested on was made by code that knows nothing of it.

Camera convention (measured, not assumed; ``tests/test_independent_render.py`` checks it): TinyRenderer samples
image pixel ``i`` at window coordinate ``i`` (a pixel corner, not its centre ``i + 0.5``) and flips the rows, so a
projection matrix built from the field of view alone (``computeProjectionMatrixFOV``) puts a point 0.5 px to the
right of and 0.5 px above where the pinhole model ``u = cu + f X/Z``, ``v = cv + f Y/Z`` with
``cu = (W − 1)/2`` puts it. :func:`projection_matrix` adds the off-centre terms that undo this, for any
principal point. Each image is rendered at ``supersample`` times the resolution and box-filtered down (a real
sensor integrates over its pixel; TinyRenderer has no anti-aliasing), then Gaussian noise is added.

:class:`SceneRenderer` builds a scene once and renders it from many poses (a whole sequence:
``benchmarks/independent_sequence.py``), optionally with a grey ``background`` where nothing is; :func:`render_pair`
is it for one pose.

Frames are the project's (``stablemarks.geometry``): the map is ``x, y`` on the floor, ``z`` up; the left optical
centre is at the robot's position ``mount_height`` above the floor looking along its heading; the right one is
``baseline`` to its right.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

NEAR, FAR = 0.05, 60.0
"""Clipping planes of the rendering [m]."""


# ------------------------------------------------------------------ the scene
@dataclass(frozen=True)
class Surface:
    """A textured rectangle: corner ``origin`` (3,) [m], edge vectors ``along`` (3,) (the texture's columns) and
    ``up`` (3,) (its rows, bottom to top); ``texture`` an (h, w) uint8 image covering one tile of ``tile`` (m
    along, m up), repeated over the rectangle. The visible side is the one from which ``along`` × ``up`` points
    towards the viewer."""

    name: str
    origin: tuple[float, float, float]
    along: tuple[float, float, float]
    up: tuple[float, float, float]
    texture: np.ndarray = field(repr=False)
    tile: tuple[float, float] = (1.0, 1.0)


@dataclass(frozen=True)
class Pole:
    """A vertical cylinder standing on the floor at ``(x, y)`` [m], plain grey ``gray`` (0–1)."""

    name: str
    x: float
    y: float
    radius: float
    height: float
    gray: float = 0.2


@dataclass(frozen=True)
class Disc:
    """A flat disc of ``radius`` [m] centred on ``centre`` (3,) facing the direction ``heading`` [rad] looks from
    (its normal along −heading): a fronto-parallel disc projects to a circle centred on its centre's image."""

    name: str
    centre: tuple[float, float, float]
    radius: float
    heading: float
    gray: float = 0.0


@dataclass(frozen=True)
class Scene:
    """What is rendered; pixels where nothing is are white (TinyRenderer's empty pixels)."""

    surfaces: tuple[Surface, ...] = ()
    poles: tuple[Pole, ...] = ()
    discs: tuple[Disc, ...] = ()


# ------------------------------------------------------------------ textures from photographs
def gray_photo(name: str) -> np.ndarray:
    """``skimage.data.<name>()`` as (h, w) uint8 grayscale."""
    import skimage.data

    img = getattr(skimage.data, name)()
    if img.ndim == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img, dtype=np.uint8)


def fit_texture(img: np.ndarray, width: int, height: int) -> np.ndarray:
    """``img`` resampled to ``width`` × ``height`` texels (area averaging when shrinking)."""
    shrink = width < img.shape[1] or height < img.shape[0]
    return cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_CUBIC)


def poster_board(size_m: tuple[float, float], texel_m: float, posters, base: str = "gravel",
                 base_tile_m: float = 1.2) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """A board's texture: the photograph ``base`` tiled every ``base_tile_m`` [m], lightened and flattened like a
    speckled board, with photographs pasted on it as posters ``(name, s0, s1, z0, z1)`` [m] (from the board's
    left end and bottom). Returns the texture (rows top to bottom) and the posters' ``(s0, s1)``."""
    W = int(round(size_m[0] / texel_m))
    H = int(round(size_m[1] / texel_m))
    n = int(round(base_tile_m / texel_m))
    tile = fit_texture(gray_photo(base), n, n).astype(float)
    tile = 150.0 + 0.5 * (tile - tile.mean())
    board = np.tile(tile, (H // n + 1, W // n + 1))[:H, :W]
    for name, s0, s1, z0, z1 in posters:
        c0, c1 = int(round(s0 / texel_m)), int(round(s1 / texel_m))
        r0, r1 = H - int(round(z1 / texel_m)), H - int(round(z0 / texel_m))
        board[r0:r1, c0:c1] = fit_texture(gray_photo(name), c1 - c0, r1 - r0)
    return np.clip(board, 0, 255).astype(np.uint8), [(s0, s1) for _, s0, s1, _, _ in posters]


# ------------------------------------------------------------------ cameras
def projection_matrix(width: int, height: int, f: float, cu: float, cv: float, near: float = NEAR, far: float = FAR
                      ) -> list[float]:
    """pybullet's (column-major) projection matrix of a pinhole camera of ``width`` × ``height`` px, focal length
    ``f`` [px] and principal point ``(cu, cv)`` [px] (pixel centres at integer coordinates, row 0 at the top).

    From the intrinsics: vertical field of view ``2 atan(height / 2 / f)`` and aspect ``width / height`` (square
    pixels), then the principal point as off-centre terms for TinyRenderer's sampling at window coordinate ``i``
    (module docstring): ``x_ndc = 2 (cu + f X/Z) / W − 1`` and ``y_ndc = 2 (H − 1 − cv − f Y/Z) / H − 1``."""
    import pybullet as p

    fov = math.degrees(2.0 * math.atan(height / 2.0 / f))
    P = list(p.computeProjectionMatrixFOV(fov, width / height, near, far))
    P[8] = 1.0 - 2.0 * cu / width
    P[9] = 1.0 - 2.0 * (height - 1.0 - cv) / height
    return P


def camera_centres(camera, X) -> tuple[np.ndarray, np.ndarray, float]:
    """World positions (3,) of the left and right optical centres at robot pose ``X`` and their heading [rad]."""
    cx, cy, psi = camera.camera_pose(X).as_array()
    right = np.array([math.sin(psi), -math.cos(psi), 0.0])  # camera x in the world
    left_c = np.array([cx, cy, camera.mount_height])
    return left_c, left_c + camera.baseline * right, float(psi)


def pinhole(camera, X, points) -> np.ndarray:
    """(..., 3) ``(u_left, u_right, v)`` of world points (..., 3) by the project's pinhole model [px]."""
    pts = np.asarray(points, dtype=float)
    uv = camera.project_columns(X, pts[..., :2])
    _, Zc = camera.to_camera(X, pts[..., :2])
    v = camera.cv + camera.f * (camera.mount_height - pts[..., 2]) / Zc
    return np.concatenate([uv, v[..., None]], axis=-1)


# ------------------------------------------------------------------ rendering
@dataclass(frozen=True)
class RenderedPair:
    """``left``, ``right`` (H, W) uint8; ``labels_left``/``labels_right`` (H, W) int: the index in
    ``names`` of the object covering the whole pixel (all its sub-samples), −1 for mixed or empty pixels."""

    left: np.ndarray
    right: np.ndarray
    labels_left: np.ndarray
    labels_right: np.ndarray
    names: tuple[str, ...]

    def label(self, name: str) -> int:
        return self.names.index(name)


def _surface_obj(path: Path, s: Surface) -> None:
    """An OBJ of ``s`` as a grid of quads, each one tile with texture coordinates 0–1 (the last ones cut)."""
    o, a, u = (np.asarray(v, dtype=float) for v in (s.origin, s.along, s.up))
    la, lu = float(np.linalg.norm(a)), float(np.linalg.norm(u))
    ea, eu = a / la, u / lu
    normal = np.cross(ea, eu)
    lines = []
    nv = 0
    for i in range(math.ceil(la / s.tile[0] - 1e-9)):
        for j in range(math.ceil(lu / s.tile[1] - 1e-9)):
            a0, a1 = i * s.tile[0], min(la, (i + 1) * s.tile[0])
            u0, u1 = j * s.tile[1], min(lu, (j + 1) * s.tile[1])
            ta, tu = (a1 - a0) / s.tile[0], (u1 - u0) / s.tile[1]
            for da, du, tx, ty in ((a0, u0, 0.0, 0.0), (a1, u0, ta, 0.0), (a1, u1, ta, tu), (a0, u1, 0.0, tu)):
                q = o + da * ea + du * eu
                lines.append(f"v {q[0]:.6f} {q[1]:.6f} {q[2]:.6f}")
                lines.append(f"vt {tx:.6f} {ty:.6f}")
            k = nv + 1
            lines.append(f"f {k}/{k}/1 {k + 1}/{k + 1}/1 {k + 2}/{k + 2}/1")
            lines.append(f"f {k}/{k}/1 {k + 2}/{k + 2}/1 {k + 3}/{k + 3}/1")
            nv += 4
    lines.insert(0, f"vn {normal[0]:.6f} {normal[1]:.6f} {normal[2]:.6f}")
    path.write_text("\n".join(lines) + "\n")


def _disc_obj(path: Path, radius: float, n: int = 128) -> None:
    """A disc in the local x–z plane, normal −y (CCW seen from −y)."""
    lines = ["vn 0 -1 0", "v 0 0 0"]
    lines += [f"v {radius * math.cos(2 * math.pi * k / n):.6f} 0 {radius * math.sin(2 * math.pi * k / n):.6f}"
              for k in range(n)]
    lines += [f"f 1//1 {2 + k}//1 {2 + (k + 1) % n}//1" for k in range(n)]
    path.write_text("\n".join(lines) + "\n")


def _build(p, cid: int, scene: Scene, tmp: Path) -> dict[int, int]:
    """Create the scene's bodies in client ``cid``; returns body id → index in the scene's names."""
    ids = {}
    k = 0
    for s in scene.surfaces:
        obj, png = tmp / f"{s.name}.obj", tmp / f"{s.name}.png"
        _surface_obj(obj, s)
        cv2.imwrite(str(png), cv2.cvtColor(np.asarray(s.texture, np.uint8), cv2.COLOR_GRAY2BGR))
        vs = p.createVisualShape(p.GEOM_MESH, fileName=str(obj), rgbaColor=[1, 1, 1, 1], physicsClientId=cid)
        body = p.createMultiBody(baseVisualShapeIndex=vs, physicsClientId=cid)
        tex = p.loadTexture(str(png), physicsClientId=cid)
        p.changeVisualShape(body, -1, textureUniqueId=tex, physicsClientId=cid)
        ids[body] = k
        k += 1
    for pole in scene.poles:
        g = pole.gray
        vs = p.createVisualShape(p.GEOM_CYLINDER, radius=pole.radius, length=pole.height, rgbaColor=[g, g, g, 1],
                                 physicsClientId=cid)
        body = p.createMultiBody(baseVisualShapeIndex=vs, basePosition=[pole.x, pole.y, pole.height / 2],
                                 physicsClientId=cid)
        ids[body] = k
        k += 1
    for disc in scene.discs:
        obj = tmp / f"disc_{disc.name}.obj"
        _disc_obj(obj, disc.radius)
        g = disc.gray
        vs = p.createVisualShape(p.GEOM_MESH, fileName=str(obj), rgbaColor=[g, g, g, 1], physicsClientId=cid)
        q = p.getQuaternionFromEuler([0.0, 0.0, disc.heading - math.pi / 2])
        body = p.createMultiBody(baseVisualShapeIndex=vs, basePosition=list(disc.centre), baseOrientation=q,
                                 physicsClientId=cid)
        ids[body] = k
        k += 1
    return ids


def names(scene: Scene) -> tuple[str, ...]:
    return tuple(o.name for o in (*scene.surfaces, *scene.poles, *scene.discs))


class SceneRenderer:
    """A :class:`Scene` built once in a headless pybullet client, rendered from many poses (a whole sequence):
    ``with SceneRenderer(scene) as r: pair = r.render(camera, X, rng=...)``. :func:`render_pair` is this for
    one pose."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.cid: int | None = None
        self.lut = np.full(1, -1, np.int64)

    def __enter__(self) -> SceneRenderer:
        import pybullet as p

        self.cid = p.connect(p.DIRECT)
        try:
            with tempfile.TemporaryDirectory(prefix="indep_render_") as tmp:
                ids = _build(p, self.cid, self.scene, Path(tmp))
        except BaseException:
            self.close()
            raise
        self.lut = np.full(max(ids, default=0) + 2, -1, np.int64)
        for body, k in ids.items():
            self.lut[body] = k
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.cid is not None:
            import pybullet as p

            p.disconnect(self.cid)
            self.cid = None

    def render(self, camera, X, *, supersample: int = 3, noise_sigma: float = 1.5, rng=None, seed: int = 0,
               ambient: float = 0.65, background: float | None = None,
               light_direction=(-1.0, -2.0, 3.0)) -> RenderedPair:
        """The stereo pair of ``camera`` at robot pose ``X`` (:func:`render_pair`); noise from ``rng`` (a
        ``numpy`` generator; default one of ``seed``), left image first. ``background``: the grey level
        [0–255] of sub-samples that see nothing (default: TinyRenderer's white)."""
        import pybullet as p

        if self.cid is None:
            raise RuntimeError("SceneRenderer.render outside its with block")
        cid, lut = self.cid, self.lut
        s = int(supersample)
        W, H = camera.width * s, camera.height * s
        P = projection_matrix(W, H, camera.f * s, camera.cu * s + (s - 1) / 2, camera.cv * s + (s - 1) / 2)
        rng = np.random.default_rng(seed) if rng is None else rng
        c_left, c_right, psi = camera_centres(camera, X)
        fwd = np.array([math.cos(psi), math.sin(psi), 0.0])
        images, labels = [], []
        for eye in (c_left, c_right):
            V = p.computeViewMatrix(eye.tolist(), (eye + fwd).tolist(), [0.0, 0.0, 1.0], physicsClientId=cid)
            _, _, rgb, _, seg = p.getCameraImage(
                W, H, V, P, renderer=p.ER_TINY_RENDERER, shadow=0, lightDirection=list(light_direction),
                lightAmbientCoeff=ambient, lightDiffuseCoeff=1.0 - ambient, lightSpecularCoeff=0.0,
                physicsClientId=cid)
            rgb = np.asarray(rgb, np.uint8).reshape(H, W, 4)[..., :3].astype(float)
            gray = rgb @ np.array([0.299, 0.587, 0.114])
            seg = np.asarray(seg, np.int64).reshape(H, W)
            if background is not None:
                gray = np.where(seg < 0, float(background), gray)
            gray = gray.reshape(camera.height, s, camera.width, s).mean(axis=(1, 3))
            gray = gray + noise_sigma * rng.standard_normal(gray.shape)
            images.append(np.clip(np.rint(gray), 0, 255).astype(np.uint8))
            lab = np.where(seg >= 0, lut[np.clip(seg, 0, len(lut) - 1)], -1)
            blocks = lab.reshape(camera.height, s, camera.width, s)
            same = (blocks == blocks[:, :1, :, :1]).all(axis=(1, 3))
            labels.append(np.where(same, blocks[:, 0, :, 0], -1))
        return RenderedPair(images[0], images[1], labels[0], labels[1], names(self.scene))


def render_pair(scene: Scene, camera, X, *, supersample: int = 3, noise_sigma: float = 1.5, seed: int = 0,
                ambient: float = 0.65) -> RenderedPair:
    """Render the stereo pair of ``camera`` (a :class:`~stablemarks.geometry.StereoCamera`, zero pan and mount
    offsets or not) at robot pose ``X`` (3,) with pybullet's TinyRenderer, headless.

    Each image is rendered at ``supersample`` × the resolution (focal length ``supersample·f``, principal point
    ``supersample·c + (supersample − 1)/2``: the same rays through the sub-pixel centres), averaged over
    ``supersample`` × ``supersample`` blocks, converted to gray (BT.601) and given Gaussian noise of
    ``noise_sigma`` grey levels (``numpy`` generator of ``seed``). Light: ``ambient`` plus diffuse from above
    behind the camera, no specular, no shadows."""
    with SceneRenderer(scene) as r:
        return r.render(camera, X, supersample=supersample, noise_sigma=noise_sigma, seed=seed, ambient=ambient)


# ------------------------------------------------------------------ the test scenes
BACK_Y = 7.0
"""The back wall: the plane ``y = BACK_Y`` [m], 16 m wide and 6 m high (it fills the view behind everything)."""
POSTERS = (("camera", 0.25, 0.85, 0.75, 1.35), ("coffee", 1.45, 2.15, 0.8, 1.3))
"""Photographs on the panel: ``(name, s0, s1, z0, z1)`` [m], ``s`` along the panel from its free edge, ``z`` above
the floor: their vertical sides are the panel's strongest vertical lines."""
TEXEL = 0.0025
"""The panel texture's texel [m]: about a pixel of the 3× supersampled image at 3.5 m."""


@dataclass(frozen=True)
class PanelSetup:
    """A free-standing panel from the floor to ``height`` [m] between ``free_end`` (its free edge, in view) and
    ``other_end`` (out of view), and optionally a pole at ``pole`` (x, y) [m]."""

    free_end: tuple[float, float]
    other_end: tuple[float, float]
    height: float = 1.8
    pole: tuple[float, float] | None = None
    pole_radius: float = 0.03

    @property
    def length(self) -> float:
        return float(np.hypot(*np.subtract(self.other_end, self.free_end)))


def panel_surface(setup: PanelSetup, viewpoint) -> Surface:
    """The panel's textured face towards ``viewpoint`` (x, y): a speckled board (gravel) with :data:`POSTERS`."""
    a, b = np.asarray(setup.free_end, float), np.asarray(setup.other_end, float)
    L = setup.length
    # start at the end that makes along × up face the viewpoint
    d = (b - a) / L
    facing = np.array([d[1], -d[0]]) @ (np.asarray(viewpoint, float)[:2] - a) > 0
    origin, along = (a, b - a) if facing else (b, a - b)
    from_free = facing  # texture columns run from the free edge
    posters = [(n, s0, s1, z0, z1) if from_free else (n, L - s1, L - s0, z0, z1) for n, s0, s1, z0, z1 in POSTERS]
    board, _ = poster_board((L, setup.height), TEXEL, posters)
    return Surface("panel", (origin[0], origin[1], 0.0), (along[0], along[1], 0.0), (0.0, 0.0, setup.height),
                   board, (L, setup.height))


def panel_scene(setup: PanelSetup, viewpoint) -> Scene:
    """Floor (grass), the back wall (brick), the panel (:func:`panel_surface`) and the pole if any: a grey
    cylinder from the floor to 2 m."""
    surfaces = (
        Surface("floor", (-8.0, -1.0, 0.0), (16.0, 0.0, 0.0), (0.0, 10.0, 0.0),
                fit_texture(gray_photo("grass"), 400, 400), (1.0, 1.0)),
        Surface("back", (-8.0, BACK_Y, 0.0), (16.0, 0.0, 0.0), (0.0, 0.0, 6.0),
                fit_texture(gray_photo("brick"), 400, 400), (1.6, 1.6)),
        panel_surface(setup, viewpoint),
    )
    poles = () if setup.pole is None else (Pole("pole", setup.pole[0], setup.pole[1], setup.pole_radius, 2.0, 0.2),)
    return Scene(surfaces, poles)
