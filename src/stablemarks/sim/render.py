"""The 2.5D stereo renderer: a rectified stereo pair of a scenario seen from a robot pose.

Rays leave each camera's optical centre through ``supersample`` sub-columns of every pixel and through its
centre; :meth:`World.zbuffer` picks, per row, the nearest surface whose height range contains the row's
height at that depth. A pixel whose sub-columns all see the surface its centre sees is shaded once, at the
centre; a pixel on an occlusion edge is shaded per sub-column and averaged, so vertical occlusion edges are
placed to ``1 / (2·supersample)`` px. Painted features are integrated analytically over each sample's
footprint on the wall (and over each row's height), so their edges are exact to floating point.

Shading (gray levels): ``albedo · (ambient + intensity · max(0, n·l)) + 255 · gloss · max(0, n·h)^shininess``
with ``l`` the direction to the point light and ``h`` the Blinn-Phong half vector towards the camera — so a
glossy whiteboard carries a highlight that moves with the viewpoint and differs between the two cameras.
The camera's optics and sensor (:class:`~stablemarks.sim.scenario.Optics`, the same for both images) then
turn this ideal irradiance into the recorded pair (:func:`expose`), in the order light takes:

1. lens blur (a Gaussian point spread function of ``blur_sigma`` px) and horizontal motion blur (a box of a
   per-frame length drawn uniformly in ``[0, motion_blur]`` px), one separable filter;
2. vignetting: a cos⁴-like radial falloff ``(1 + (r/r₀)²)⁻²`` about the principal point, ``r₀`` chosen so
   that the farthest corner keeps ``1 - vignetting`` of its light;
3. the per-frame exposure ``e = exp(N(0, exposure_sigma²))``: the signal ``S = e·V·blur(I)``;
4. sensor noise of variance ``image_noise² + shot_noise²·S/255`` (read noise plus Gaussian-approximated
   photon shot noise), then the per-frame analog gain ``g = exp(N(0, gain_sigma²))`` amplifies signal and
   noise alike;
5. rounding and clipping to ``uint8``.

The frame's random stream draws, in this order: the exposure, the left and then the right image's standard
normal noise fields, the gain, the motion-blur length. With all optics zero this is exactly the ideal
camera (exposure gain and constant Gaussian noise of ``image_noise``), image for image.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError, expected
from ..geometry import SE2, StereoCamera
from .scenario import MAX_IMAGE_SIDE, Feature, Scenario
from .truth import FrameTruth, frame_truth
from .world import BACKGROUND, CEILING, FLOOR, World

SUPERSAMPLE = 4
"""Rays per image column."""


@dataclass(frozen=True)
class SimFrame:
    """A rendered stereo pair and its ground truth.

    ``left``, ``right``: (H, W) uint8 rectified images; ``truth``: pose, pan and image edges.
    """

    left: np.ndarray
    right: np.ndarray
    truth: FrameTruth


class Renderer:
    """Renders one scenario; builds the world's textures once."""

    def __init__(self, scenario: Scenario, supersample: int = SUPERSAMPLE):
        if isinstance(supersample, bool) or not isinstance(supersample, int) or supersample < 1:
            raise InputError(expected("a positive integer number of rays per column", supersample,
                                      where="supersample"))
        cam = scenario.camera
        if not (1 <= cam.width <= MAX_IMAGE_SIDE and 1 <= cam.height <= MAX_IMAGE_SIDE):
            raise InputError(expected(f"an image of at most {MAX_IMAGE_SIDE}×{MAX_IMAGE_SIDE} px",
                                      f"{cam.width}×{cam.height} px", where="camera"))
        if supersample > 64:
            raise InputError(expected("at most 64 rays per column", supersample, where="supersample"))
        self.scenario = scenario
        self.world = World.from_scenario(scenario)
        self.supersample = int(supersample)

    def render(self, X, pan: float, rng: np.random.Generator) -> SimFrame:
        """The stereo pair from robot pose ``X`` (3,) with the head panned by ``pan`` [rad], and its truth.

        ``rng`` draws the frame's exposure, sensor noise, gain and motion blur (:func:`expose`), so a seed fixes
        the images.
        """
        sc = self.scenario
        X = np.asarray(X, dtype=float)
        camera = sc.camera.with_pan(pan)
        left, right = self.render_clean(X, pan)
        (img_l, img_r), drawn = expose((left, right), sc, rng)
        truth = frame_truth(self.world, camera, SE2.from_array(X), left_clean=left, exposure=drawn.exposure,
                            gain=drawn.gain, motion_blur=drawn.motion_blur)
        return SimFrame(img_l, img_r, truth)

    def truth(self, X, pan: float) -> FrameTruth:
        """The truth of the frame from ``X`` with ``pan`` without rendering it: what geometry gives (edge
        positions, columns, rows, visibility) — :meth:`render`'s truth but for what the images decide, the
        polarity of boundary edges (0) and the optics draws (exposure and gain 1, no motion blur)."""
        return frame_truth(self.world, self.scenario.camera.with_pan(pan), SE2.from_array(np.asarray(X, dtype=float)))

    def render_clean(self, X, pan: float) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free ``(left, right)`` float32 images (H, W) [gray levels, not clipped] at unit exposure."""
        camera = self.scenario.camera.with_pan(pan)
        X = np.asarray(X, dtype=float)
        centres = camera.optical_centres(X)
        left, right = (self._render_view(camera, X, o) for o in centres)
        return left, right

    # ----------------------------------------------------------- internals
    def _dirs(self, camera: StereoCamera, X, u: np.ndarray) -> np.ndarray:
        """Ray directions (N, 2) with unit forward component through image columns ``u`` [px]."""
        psi = camera.camera_pose(X).theta
        forward = np.array([np.cos(psi), np.sin(psi)])
        right = np.array([np.sin(psi), -np.cos(psi)])
        return forward + ((u - camera.cu) / camera.f)[:, None] * right

    def _render_view(self, camera: StereoCamera, X, origin: np.ndarray) -> np.ndarray:
        """One camera's noise-free image (H, W) float32 from optical centre ``origin`` (2,).

        The z-buffer runs on ``supersample`` sub-columns per pixel and on the pixel centres. A pixel whose
        sub-columns all see the centre's surface is shaded once, at its centre, with painted features
        integrated over the whole pixel; the others (occlusion edges) are shaded per sub-column and averaged.
        """
        world, ss = self.world, self.supersample
        H, W = camera.height, camera.width
        h, f, cv = camera.mount_height, camera.f, camera.cv
        rows = np.arange(H, dtype=float)
        sub_u = (np.arange(W * ss) + 0.5) / ss - 0.5
        sub_dirs = self._dirs(camera, X, sub_u)
        depth_s, pid_s = world.zbuffer(world.cast(origin, sub_dirs), rows, h, f, cv)
        dirs = self._dirs(camera, X, np.arange(W, dtype=float))
        depth_c, pid_c = world.zbuffer(world.cast(origin, dirs), rows, h, f, cv)
        pure = (pid_s.reshape(H, W, ss) == pid_c[:, :, None]).all(axis=2).ravel()
        image = np.empty(H * W, dtype=np.float32)
        idx = np.flatnonzero(pure)
        image[idx] = self._shade_samples(origin, dirs, self._dirs(camera, X, np.arange(W + 1) - 0.5),
                                         idx // W, idx % W, depth_c.ravel()[idx], pid_c.ravel()[idx], h, f, cv)
        idx = np.flatnonzero(~pure)
        if len(idx):
            sub = ((idx * ss)[:, None] + np.arange(ss)).ravel()  # flat indices into the (H, W·ss) buffers
            values = self._shade_samples(origin, sub_dirs, self._dirs(camera, X, np.arange(W * ss + 1) / ss - 0.5),
                                         sub // (W * ss), sub % (W * ss), depth_s.ravel()[sub], pid_s.ravel()[sub],
                                         h, f, cv)
            image[idx] = values.reshape(-1, ss).mean(axis=1)
        return image.reshape(H, W)

    def _shade_samples(self, origin, dirs, edge_dirs, rows, cols, depth, pid, h, f, cv) -> np.ndarray:
        """Gray levels (N,) of samples seen along rays ``dirs[cols]`` at image ``rows`` and ``depth`` [m].

        ``edge_dirs`` (len(dirs) + 1, 2) are the rays at the samples' left and right footprint boundaries.
        """
        out = np.empty(len(rows), dtype=np.float32)
        keys = pid.astype(np.int32) - CEILING  # >= 0
        order = np.argsort(keys, kind="stable")
        bounds = np.concatenate([[0], np.cumsum(np.bincount(keys))])
        for key in np.flatnonzero(np.diff(bounds)):
            idx = order[bounds[key]:bounds[key + 1]]
            p = int(key) + CEILING
            if p == BACKGROUND:
                out[idx] = self.scenario.room.background
                continue
            col = cols[idx]
            t = depth[idx].astype(np.float32)
            px = np.float32(origin[0]) + t * dirs[col, 0].astype(np.float32)
            py = np.float32(origin[1]) + t * dirs[col, 1].astype(np.float32)
            pz = np.float32(h) - (rows[idx].astype(np.float32) - np.float32(cv)) * t / np.float32(f)
            out[idx] = self._shade(p, origin, edge_dirs, col, t / np.float32(f), px, py, pz, h)
        return out

    def _shade(self, p: int, origin, edge_dirs, cols, dz, px, py, pz, h) -> np.ndarray:
        """Gray levels of samples of primitive ``p`` at world points ``(px, py, pz)`` [m].

        ``dz`` [m]: the height one image row spans at each sample's depth.
        """
        world, light = self.world, self.scenario.lighting
        n = len(px)
        gloss = 0.0
        if p == FLOOR or p == CEILING:
            grid = world.floor if p == FLOOR else world.ceiling
            albedo = grid.sample(px, py)
            normal = np.array([0.0, 0.0, 1.0 if p == FLOOR else -1.0], dtype=np.float32)
            nx, ny, nz = (np.full(n, c, dtype=np.float32) for c in normal)
        elif p < world.n_faces:
            obj = world.objects[world.face_owner[p]]
            a, e = world.face_a[p], world.face_e[p]
            s = (px - np.float32(a[0])) * np.float32(e[0]) + (py - np.float32(a[1])) * np.float32(e[1])
            z0 = world.face_z[p, 0]
            albedo = obj.texture.sample(s + np.float32(world.face_offset[p]), pz - np.float32(z0))
            if obj.features:
                albedo = albedo + self._features(obj.features, origin, edge_dirs, p, cols, pz, dz)
            side = np.sign(_cross2(e, np.asarray(origin) - a)) or 1.0
            nx = np.full(n, -e[1] * side, dtype=np.float32)
            ny = np.full(n, e[0] * side, dtype=np.float32)
            nz = np.zeros(n, dtype=np.float32)
            gloss = obj.gloss
        elif p < world.n_faces + world.n_cyl:
            c = p - world.n_faces
            obj = world.objects[world.cyl_owner[c]]
            cx, cy = world.cyl_c[c]
            r = np.float32(world.cyl_r[c])
            nx, ny = (px - np.float32(cx)) / r, (py - np.float32(cy)) / r
            nz = np.zeros(n, dtype=np.float32)
            albedo = obj.texture.sample(r * np.arctan2(ny, nx), pz)
        else:
            height, owner, faces, c = world.caps[p - world.n_faces - world.n_cyl]
            obj = world.objects[owner]
            if c >= 0:
                centre = world.cyl_c[c] - world.cyl_r[c]
                la, lb = px - np.float32(centre[0]), py - np.float32(centre[1])
            else:
                a, e = world.face_a[faces[0]], world.face_e[faces[0]]
                dx, dy = px - np.float32(a[0]), py - np.float32(a[1])
                la = dx * np.float32(e[0]) + dy * np.float32(e[1])
                lb = -dx * np.float32(e[1]) + dy * np.float32(e[0])
            albedo = obj.top.sample(la, lb)
            nx, ny = np.zeros(n, dtype=np.float32), np.zeros(n, dtype=np.float32)
            nz = np.ones(n, dtype=np.float32)
        # Lighting: ambient + diffuse from the point light + Blinn-Phong highlight on glossy walls.
        lx = np.float32(light.light_position[0]) - px
        ly = np.float32(light.light_position[1]) - py
        lz = np.float32(light.light_position[2]) - pz
        inv = 1.0 / np.sqrt(lx * lx + ly * ly + lz * lz)
        lx, ly, lz = lx * inv, ly * inv, lz * inv
        n_dot_l = nx * lx + ny * ly + nz * lz
        value = albedo * (np.float32(light.ambient) + np.float32(light.light_intensity) * np.maximum(n_dot_l, 0))
        if gloss > 0:
            vx, vy, vz = np.float32(origin[0]) - px, np.float32(origin[1]) - py, np.float32(h) - pz
            inv = 1.0 / np.sqrt(vx * vx + vy * vy + vz * vz)
            hx, hy, hz = lx + vx * inv, ly + vy * inv, lz + vz * inv
            inv = 1.0 / np.sqrt(hx * hx + hy * hy + hz * hz)
            n_dot_h = np.maximum((nx * hx + ny * hy + nz * hz) * inv, 0)
            spec = np.where(n_dot_l > 0, n_dot_h ** np.float32(light.shininess), 0)
            value = value + np.float32(255.0 * gloss) * spec
        return value

    def _features(self, features: tuple[Feature, ...], origin, edge_dirs, face: int, cols, pz,
                  dz) -> np.ndarray:
        """Albedo change [gray] of the painted features of a wall at its pixels.

        Horizontally each feature's profile is averaged exactly over the footprint ``[s(u-), s(u+)]`` of a
        sample (pixel or sub-column) on the wall; vertically over the height ``[z - dz/2, z + dz/2]`` a row covers.
        """
        world = self.world
        a, e = world.face_a[face], world.face_e[face]
        q = a - np.asarray(origin)
        with np.errstate(divide="ignore", invalid="ignore"):
            s_edge = _cross2(q, edge_dirs) / _cross2(edge_dirs, e)  # (R+1,) along the wall's line
        lo = np.minimum(s_edge[:-1], s_edge[1:])
        hi = np.maximum(s_edge[:-1], s_edge[1:])
        out = np.zeros(len(cols), dtype=np.float32)
        for feat in features:
            profile = _footprint_mean(feat, lo, hi)  # (R,)
            hit = profile[cols] != 0
            if not hit.any():
                continue
            z, d = pz[hit], dz[hit]
            cover = np.clip(np.minimum(feat.z[1], z + d / 2) - np.maximum(feat.z[0], z - d / 2), 0, None) / d
            out[hit] += np.float32(feat.contrast) * profile[cols][hit].astype(np.float32) * cover
        return out


def _cross2(u, v):
    u, v = np.asarray(u), np.asarray(v)
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _antiderivative(feat: Feature, x: np.ndarray) -> np.ndarray:
    """``∫_{-∞}^{x} g`` of the feature's unit profile ``g`` along ``s`` (x measured from ``feat.s``).

    edge: ``g = ½(1 + cos(π x / fade))`` on ``[0, fade]`` (a step that fades back smoothly), 0 elsewhere;
    bar: ``g = 1`` on ``[0, width]``.
    """
    if feat.kind == "bar":
        return np.clip(x, 0.0, feat.width)
    w = feat.fade
    xc = np.clip(x, 0.0, w)
    return 0.5 * (xc + w / np.pi * np.sin(np.pi * xc / w))


def _footprint_mean(feat: Feature, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Mean of the feature's unit profile over the intervals ``[lo, hi]`` of ``s`` [m] (NaN-safe: 0)."""
    a, b = lo - feat.s, hi - feat.s
    width = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (_antiderivative(feat, b) - _antiderivative(feat, a)) / width
    return np.where(np.isfinite(mean) & (width > 0), mean, 0.0)


# --------------------------------------------------------------- optics and sensor
@dataclass(frozen=True)
class FrameOptics:
    """The per-frame random draws of :func:`expose`: exposure and analog gain factors, motion-blur length [px]."""

    exposure: float = 1.0
    gain: float = 1.0
    motion_blur: float = 0.0


def expose(clean: tuple[np.ndarray, ...], scenario: Scenario,
           rng: np.random.Generator) -> tuple[tuple[np.ndarray, ...], FrameOptics]:
    """Record ideal images ``clean`` (H, W) float32 [gray levels] through the scenario's optics and sensor.

    All images (the stereo pair) share the frame's optics and draws; each gets its own noise field. Returns the
    ``uint8`` images and the frame's draws (order of the draws in the module docstring).
    """
    op, read = scenario.optics, scenario.image_noise
    exposure = float(np.exp(rng.normal(0.0, scenario.lighting.exposure_sigma)))
    normals = [rng.normal(0.0, 1.0, c.shape) for c in clean]
    gain = float(np.exp(rng.normal(0.0, op.gain_sigma))) if op.gain_sigma > 0 else 1.0
    length = float(op.motion_blur * rng.random()) if op.motion_blur > 0 else 0.0
    kernels = blur_kernels(op.blur_sigma, length)
    images = []
    for image, z in zip(clean, normals, strict=True):
        if kernels is not None:
            image = cv2.sepFilter2D(image, -1, kernels[0], kernels[1], borderType=cv2.BORDER_REFLECT)
        if op.vignetting > 0:
            signal = image * (vignetting_map(image.shape, scenario.camera.cu, scenario.camera.cv, op.vignetting)
                              * np.float32(exposure))
        else:
            signal = image * exposure
        if op.shot_noise > 0:
            variance = np.float32(read * read) + np.float32(op.shot_noise ** 2 / 255.0) * np.maximum(signal, 0)
            sigma = np.sqrt(variance) * np.float32(gain)
        else:
            sigma = read * gain
        recorded = (signal * gain if gain != 1.0 else signal) + z * sigma
        images.append(np.clip(np.rint(recorded), 0, 255).astype(np.uint8))
    return tuple(images), FrameOptics(exposure, gain, length)


def blur_kernels(sigma: float, length: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Separable ``(horizontal, vertical)`` kernels of a Gaussian PSF of ``sigma`` [px] and a horizontal box of
    ``length`` [px] (pixel-integrated); ``None`` when both are nothing."""
    box = _box_kernel(length)
    if sigma <= 0 and length <= 1e-6:
        return None
    gauss = _gauss_kernel(sigma)
    return np.convolve(gauss, box).astype(np.float32), gauss.astype(np.float32)


def _gauss_kernel(sigma: float) -> np.ndarray:
    if sigma <= 0:
        return np.ones(1)
    half = max(1, math.ceil(3.0 * sigma))
    return cv2.getGaussianKernel(2 * half + 1, sigma, cv2.CV_64F).ravel()


def _box_kernel(length: float) -> np.ndarray:
    """Discrete kernel of a centred horizontal box of ``length`` [px] acting on a pixel image.

    The image is read as the linear interpolation of its pixels (a triangle kernel), smeared by the box and
    sampled again: ``w_j = (T(j + L/2) - T(j - L/2)) / L`` with ``T`` the triangle's integral. ``[1]`` for
    ``L = 0``; the weights change continuously with ``L``.
    """
    if length <= 1e-6:
        return np.ones(1)
    half = math.ceil(length / 2 + 1) - 1
    j = np.arange(-half, half + 1, dtype=float)
    w = (_tri_integral(j + length / 2) - _tri_integral(j - length / 2)) / length
    return w / w.sum()


def _tri_integral(x: np.ndarray) -> np.ndarray:
    """``∫_{-∞}^{x} max(0, 1 - |t|) dt``."""
    x = np.clip(x, -1.0, 1.0)
    return np.where(x < 0, 0.5 * (x + 1) ** 2, 1.0 - 0.5 * (1 - x) ** 2)


@functools.lru_cache(maxsize=8)
def vignetting_map(shape: tuple[int, int], cu: float, cv: float, vignetting: float) -> np.ndarray:
    """Relative illumination (H, W) float32: ``(1 + (r/r₀)²)⁻²`` about ``(cu, cv)``, ``1 - vignetting`` in the
    farthest corner."""
    H, W = shape
    rc2 = max((u - cu) ** 2 + (v - cv) ** 2 for u in (0, W - 1) for v in (0, H - 1))
    if vignetting <= 0 or rc2 == 0:
        return np.ones(shape, dtype=np.float32)
    r0_2 = rc2 / ((1.0 - vignetting) ** -0.5 - 1.0)
    u = (np.arange(W) - cu) ** 2
    v = (np.arange(H) - cv) ** 2
    out = (1.0 / (1.0 + (v[:, None] + u[None, :]) / r0_2) ** 2).astype(np.float32)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=4)
def renderer_for(scenario: Scenario) -> Renderer:
    """A cached :class:`Renderer` per scenario (its textures are built once)."""
    return Renderer(scenario)


def render_stereo(scenario: Scenario, X, pan: float, rng: np.random.Generator) -> SimFrame:
    """Render the stereo pair of ``scenario`` from robot pose ``X = (x, y, theta)`` with pan ``pan`` [rad].

    ``rng`` draws the exposure gain and sensor noise; the world (textures) does not depend on it.
    """
    return renderer_for(scenario).render(X, pan, rng)
