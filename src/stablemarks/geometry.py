"""Planar poses and the rectified stereo camera on a mobile robot, with analytic Jacobians.

Frames (DESIGN.md §3, REP-103): the world/map frame is ``x, y`` on the floor with ``z`` up; the robot
base has ``x`` forward, ``y`` left; the camera optical frame has ``z`` forward, ``x`` right, ``y`` down.
The stereo head is mounted at ``(mount_x, mount_y)`` in the robot frame, ``mount_height`` above the
floor, and pans by ``pan`` about the vertical axis through the *left* camera's optical centre, so the
camera heading in the world is ``theta + pan``. The left camera is the reference; the right one sits at
``+baseline`` along camera ``x``. Disparity ``d = u_l - u_r = f b / Z_c > 0``.

Robot state ``X = (x [m], y [m], theta [rad])``; a vertical line landmark ``L = (x, y, z_low, z_high)``
(paper Eq 1). Every function here is vectorised over leading axes of the point arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from .errors import GeometryError, InputError, expected

SIGMA_IMG = 0.5
"""Pixel quantization error of a line's column, paper Sec 2.3.1 [px]."""

MIN_DEPTH = 1e-3
"""Points closer than this in front of the camera [m] are treated as not projectable."""


def wrap_angle(a):
    """Wrap angles to ``[-pi, pi)``; works on scalars and arrays."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def rot2(theta: float) -> np.ndarray:
    """2×2 rotation matrix of angle ``theta`` [rad]."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


@njit(cache=True, error_model="numpy")
def _project_kernel(p, cx, cy, c, s, cu, f, b, r0, r1, jacobians):  # pragma: no cover - numba
    """:meth:`StereoCamera.project_columns` of points ``p`` (n, 2): ``uv`` (n, 2) and, with ``jacobians``,
    ``J_I_X`` (n, 2, 3) and ``J_I_p`` (n, 2, 2) (else empty). The array code's element-wise operations point by
    point in the same order (squares as products, as NumPy's; no fused multiply-adds without fastmath), so the
    same IEEE doubles, without its ~40 array temporaries."""
    n = p.shape[0]
    uv = np.empty((n, 2))
    m = n if jacobians else 0
    J_X = np.empty((m, 2, 3))
    J_p = np.empty((m, 2, 2))
    fb = f * b
    for i in range(n):
        dx = p[i, 0] - cx
        dy = p[i, 1] - cy
        Xc = s * dx - c * dy
        Zc = c * dx + s * dy
        Zs = Zc if Zc > MIN_DEPTH else np.nan
        ul = cu + f * Xc / Zs
        uv[i, 0] = ul
        uv[i, 1] = ul - fb / Zs
        if jacobians:
            dul_dXc = f / Zs
            dul_dZc = -f * Xc / (Zs * Zs)
            dur_dZc = dul_dZc + fb / (Zs * Zs)
            p00 = dul_dXc * s + dul_dZc * c
            p01 = dul_dXc * -c + dul_dZc * s
            p10 = dul_dXc * s + dur_dZc * c
            p11 = dul_dXc * -c + dur_dZc * s
            dXc_dth = c * dx + s * dy - (s * r0 - c * r1)
            dZc_dth = -s * dx + c * dy - (c * r0 + s * r1)
            J_p[i, 0, 0] = p00
            J_p[i, 0, 1] = p01
            J_p[i, 1, 0] = p10
            J_p[i, 1, 1] = p11
            J_X[i, 0, 0] = -p00
            J_X[i, 0, 1] = -p01
            J_X[i, 0, 2] = dul_dXc * dXc_dth + dul_dZc * dZc_dth
            J_X[i, 1, 0] = -p10
            J_X[i, 1, 1] = -p11
            J_X[i, 1, 2] = dul_dXc * dXc_dth + dur_dZc * dZc_dth
    return uv, J_X, J_p


@njit(cache=True, error_model="numpy")
def _triangulate_kernel(u_l, u_r, cx, cy, c, s, cu, f, b):  # pragma: no cover - numba
    """:meth:`StereoCamera.triangulate`'s element-wise part for columns (n,) in the world: points ``p`` (n, 2), the
    Jacobian ``J`` (n, 2, 2) of ``p`` w.r.t. ``(u_l, u_r)`` and the camera coordinates ``Xc``, ``Zc`` (n,). The array
    code's operations point by point in the same order (squares as products, as NumPy's), so the same doubles."""
    n = u_l.shape[0]
    p = np.empty((n, 2))
    J = np.empty((n, 2, 2))
    Xc_out = np.empty(n)
    Zc_out = np.empty(n)
    fb = f * b
    for i in range(n):
        d = u_l[i] - u_r[i]
        d = d if d > 0 else np.nan
        Zc = fb / d
        Xc = (u_l[i] - cu) * Zc / f
        dZ_dur = fb / (d * d)
        dZ_dul = -dZ_dur
        dX_dul = Zc / f + (u_l[i] - cu) * dZ_dul / f
        dX_dur = (u_l[i] - cu) * dZ_dur / f
        J[i, 0, 0] = s * dX_dul + c * dZ_dul
        J[i, 0, 1] = s * dX_dur + c * dZ_dur
        J[i, 1, 0] = -c * dX_dul + s * dZ_dul
        J[i, 1, 1] = -c * dX_dur + s * dZ_dur
        p[i, 0] = cx + c * Zc + s * Xc
        p[i, 1] = cy + s * Zc - c * Xc
        Xc_out[i] = Xc
        Zc_out[i] = Zc
    return p, J, Xc_out, Zc_out


@dataclass(frozen=True)
class SE2:
    """A planar rigid transform ``T_a_b``: pose of frame b in frame a (``x, y`` in m, ``theta`` in rad).

    ``T_a_c = T_a_b @ T_b_c``; ``p_a = T_a_b.transform(p_b)``.
    """

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    @classmethod
    def from_array(cls, a) -> SE2:
        a = np.asarray(a, dtype=float).reshape(3)
        return cls(float(a[0]), float(a[1]), float(wrap_angle(a[2])))

    def as_array(self) -> np.ndarray:
        """``(3,)`` array ``(x, y, theta)``."""
        return np.array([self.x, self.y, self.theta])

    @property
    def translation(self) -> np.ndarray:
        return np.array([self.x, self.y])

    @property
    def rotation(self) -> np.ndarray:
        return rot2(self.theta)

    def matrix(self) -> np.ndarray:
        """3×3 homogeneous matrix."""
        m = np.eye(3)
        m[:2, :2] = self.rotation
        m[:2, 2] = self.translation
        return m

    def __matmul__(self, other: SE2) -> SE2:
        t = self.translation + self.rotation @ other.translation
        return SE2(float(t[0]), float(t[1]), float(wrap_angle(self.theta + other.theta)))

    def inverse(self) -> SE2:
        t = -self.rotation.T @ self.translation
        return SE2(float(t[0]), float(t[1]), float(wrap_angle(-self.theta)))

    def transform(self, points) -> np.ndarray:
        """Map points ``(..., 2)`` given in frame b into frame a."""
        p = np.asarray(points, dtype=float)
        return p @ self.rotation.T + self.translation

    def between(self, other: SE2) -> SE2:
        """The relative motion ``self⁻¹ @ other`` (odometry increment from self to other)."""
        return self.inverse() @ other


@dataclass(frozen=True)
class StereoCamera:
    """A rectified stereo head on a mobile robot.

    Attributes
    ----------
    width, height : image size [px].
    f : focal length [px] (square pixels after rectification).
    cu, cv : principal point [px].
    baseline : distance between the optical centres [m]; the right camera at ``+baseline`` along camera x.
    mount_x, mount_y : position of the left optical centre (pan axis) in the robot frame [m].
    mount_height : height of the optical centres above the floor [m].
    pan : pan angle of the head relative to the robot's heading [rad], positive to the left.
    sigma_img : column uncertainty of a line in one image [px] (paper Sec 2.3.1).
    """

    width: int = 640
    height: int = 480
    f: float = 500.0
    cu: float = 319.5
    cv: float = 239.5
    baseline: float = 0.12
    mount_x: float = 0.0
    mount_y: float = 0.0
    mount_height: float = 1.0
    pan: float = 0.0
    sigma_img: float = SIGMA_IMG

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if not (isinstance(v, int | np.integer) and v > 0):
                raise InputError(expected("a positive integer number of pixels", v, where=f"camera.{name}"))
        for name in ("f", "baseline", "sigma_img"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(expected("a positive number", v, where=f"camera.{name}"))
        for name in ("cu", "cv", "mount_x", "mount_y", "mount_height", "pan"):
            if not np.isfinite(getattr(self, name)):
                raise InputError(expected("a finite number", getattr(self, name), where=f"camera.{name}"))

    # ------------------------------------------------------------------ frames
    def with_pan(self, pan: float) -> StereoCamera:
        return replace(self, pan=float(pan))

    def _frame(self, X) -> tuple[float, float, float, float, float]:
        """Left optical centre ``(c_x, c_y)`` [m] in the world, camera heading ``psi = theta + pan`` wrapped to
        ``[-pi, pi)`` [rad] and its ``(cos psi, sin psi)``, as Python floats (per-call cost matters: every
        projection and triangulation starts here; ``tolist`` of the float64 array: the same numbers as ``float`` of
        each element, in a fifth of the time)."""
        x, y, th = np.asarray(X, dtype=float).tolist()
        c_th, s_th = math.cos(th), math.sin(th)
        psi = (th + self.pan + math.pi) % (2.0 * math.pi) - math.pi
        cx = x + (c_th * self.mount_x - s_th * self.mount_y)
        cy = y + (s_th * self.mount_x + c_th * self.mount_y)
        return cx, cy, psi, math.cos(psi), math.sin(psi)

    def _centre_rate(self, X) -> tuple[float, float]:
        """``d c_cam / d theta`` (2,): how the left optical centre moves as the robot turns [m/rad]."""
        th = float(X[2])
        c_th, s_th = math.cos(th), math.sin(th)
        return -s_th * self.mount_x - c_th * self.mount_y, c_th * self.mount_x - s_th * self.mount_y

    def camera_pose(self, X) -> SE2:
        """``T_world_cam`` in the plane: left optical centre and heading ``theta + pan``."""
        cx, cy, psi, _, _ = self._frame(X)
        return SE2(cx, cy, psi)

    def to_camera(self, X, points) -> tuple[np.ndarray, np.ndarray]:
        """Lateral ``X_c`` (right) and depth ``Z_c`` (forward) of world points ``(..., 2)`` in the left camera [m]."""
        p = np.asarray(points, dtype=float)
        cx, cy, _, c, s = self._frame(X)
        dx = p[..., 0] - cx
        dy = p[..., 1] - cy
        return s * dx - c * dy, c * dx + s * dy

    def from_camera(self, X, Xc, Zc) -> np.ndarray:
        """World points ``(..., 2)`` from lateral/depth coordinates in the left camera."""
        cx, cy, _, c, s = self._frame(X)
        Xc = np.asarray(Xc, dtype=float)
        Zc = np.asarray(Zc, dtype=float)
        out = np.empty(np.broadcast(Xc, Zc).shape + (2,))
        out[..., 0] = cx + c * Zc + s * Xc
        out[..., 1] = cy + s * Zc - c * Xc
        return out

    # -------------------------------------------------------------- projection
    def project_columns(self, X, points, *, jacobians: bool = False):
        """Image columns ``I = (u_l, u_r)`` of vertical lines through world points (paper Eq 3).

        Parameters
        ----------
        X : (3,) robot pose ``(x, y, theta)`` in the world.
        points : (..., 2) line positions ``(x, y)`` in the world [m].
        jacobians : also return ``J_I_X`` (..., 2, 3) and ``J_I_p`` (..., 2, 2).

        Returns
        -------
        uv : (..., 2) ``(u_l, u_r)`` [px]; NaN where the point is not in front of the camera
        (``Z_c <= MIN_DEPTH``).
        """
        p = np.asarray(points, dtype=float)
        cx, cy, _, c, s = self._frame(X)
        if not jacobians and p.shape == (2,):
            return self._project_point(float(p[0]) - cx, float(p[1]) - cy, c, s)
        # every other shape by the array code's element-wise operations compiled (_project_kernel): ~3 µs instead of
        # 20-45 µs
        r0, r1 = self._centre_rate(X) if jacobians else (0.0, 0.0)
        flat = np.ascontiguousarray(p).reshape(-1, 2)
        uv, J_X, J_p = _project_kernel(flat, cx, cy, c, s, self.cu, self.f, self.baseline, r0, r1, jacobians)
        shape = p.shape[:-1]
        uv = uv.reshape(*shape, 2)
        if not jacobians:
            return uv
        return uv, J_X.reshape(*shape, 2, 3), J_p.reshape(*shape, 2, 2)

    def _project_point(self, dx: float, dy: float, c: float, s: float) -> np.ndarray:
        """:meth:`project_columns` of one point (2,) without Jacobians, ``(dx, dy)`` its offset from the left optical
        centre: the same operations in the same order on Python floats (IEEE doubles, as NumPy's), without the
        array temporaries of the general case (it is called for single points a few dozen times a frame)."""
        Xc = s * dx - c * dy
        Zc = c * dx + s * dy
        Zs = Zc if Zc > MIN_DEPTH else math.nan
        ul = self.cu + self.f * Xc / Zs
        return np.array([ul, ul - self.f * self.baseline / Zs])

    def project_line(self, X, L, *, jacobians: bool = False):
        """Project a vertical line landmark ``L = (x, y, z_low, z_high)`` (Eq 1) into ``(u_l, u_r, v_top, v_bottom)``.

        Eq 3 extended with the rows of the line's ends. With ``jacobians=True`` also returns
        ``J_I_X`` (4, 3) and ``J_I_L`` (4, 4). Raises :class:`GeometryError` behind the camera.
        """
        X = np.asarray(X, dtype=float)
        L = np.asarray(L, dtype=float).reshape(4)
        Xc, Zc = self.to_camera(X, L[:2])
        if not Zc > MIN_DEPTH:
            raise GeometryError(f"line at ({L[0]:.3f}, {L[1]:.3f}) m is behind the camera (depth {Zc:.3f} m)")
        uv, J_uv_X, J_uv_p = self.project_columns(X, L[:2], jacobians=True)
        h, f = self.mount_height, self.f
        v_top = self.cv + f * (h - L[3]) / Zc
        v_bot = self.cv + f * (h - L[2]) / Zc
        I = np.array([uv[0], uv[1], v_top, v_bot])
        if not jacobians:
            return I
        _, dZc_dX, dZc_dp = self._depth_jacobians(X, L[:2])
        J_I_X = np.zeros((4, 3))
        J_I_L = np.zeros((4, 4))
        J_I_X[:2] = J_uv_X
        J_I_L[:2, :2] = J_uv_p
        for row, z, col in ((2, L[3], 3), (3, L[2], 2)):
            dv_dZc = -f * (h - z) / Zc**2
            J_I_X[row] = dv_dZc * dZc_dX
            J_I_L[row, :2] = dv_dZc * dZc_dp
            J_I_L[row, col] = -f / Zc
        return I, J_I_X, J_I_L

    def _depth_jacobians(self, X, p):
        """``Z_c`` of world points and its Jacobians ``(..., 3)`` w.r.t. X and ``(..., 2)`` w.r.t. p."""
        p = np.asarray(p, dtype=float)
        cx, cy, _, c, s = self._frame(X)
        r0, r1 = self._centre_rate(X)
        dx = p[..., 0] - cx
        dy = p[..., 1] - cy
        Zc = c * dx + s * dy
        dZc_dp = np.empty(p.shape)
        dZc_dp[..., 0] = c
        dZc_dp[..., 1] = s
        dZc_dX = np.empty(p.shape[:-1] + (3,))
        dZc_dX[..., :2] = -dZc_dp
        dZc_dX[..., 2] = -s * dx + c * dy - (c * r0 + s * r1)
        return Zc, dZc_dX, dZc_dp

    def disparity(self, X, points, *, jacobians: bool = False):
        """Disparity ``d = D(X) = f b / Z_c`` of world points ``(..., 2)`` (paper Eqs 8–9) [px].

        With ``jacobians=True`` also returns ``J_d_X`` (..., 3) and ``J_d_p`` (..., 2).
        NaN where the point is not in front of the camera.
        """
        Zc, dZc_dX, dZc_dp = self._depth_jacobians(X, points)
        Zs = np.where(Zc > MIN_DEPTH, Zc, np.nan)
        if not jacobians:
            return self.disparity_at_depth(Zs)
        d, J_d_X = self.disparity_at_depth(Zs, dZc_dX)
        return d, J_d_X, self.disparity_at_depth(Zs, dZc_dp)[1]

    def disparity_at_depth(self, Zc, J_Z=None):
        """Disparity of a point at depth ``Zc`` (...,) [m] in front of the left camera (paper Eq 8,
        ``d = F·2B / c_y`` with ``F = f``, ``2B = baseline``, ``c_y = Zc``) [px].

        With ``J_Z`` (..., k), the Jacobian of the depth with respect to some k parameters (the pose, a point,
        or — for the plane prediction — the pose at a fixed image column), also returns the disparity's
        Jacobian ``J_d`` (..., k) = ``−f b / Zc² · J_Z`` (the chain rule of Eq 9).
        """
        Zc = np.asarray(Zc, dtype=float)
        fb = self.f * self.baseline
        d = fb / Zc
        if J_Z is None:
            return d
        return d, (-fb / Zc**2)[..., None] * np.asarray(J_Z, dtype=float)

    def disparity_variance(self, J_d_X, cov_X, sigma_nu=None) -> np.ndarray:
        """Variance ``σ_d²`` of a predicted disparity (paper Eq 10) [px²]:
        ``σ_d² = (∂D/∂X) Σ_X (∂D/∂X)ᵀ + σ_ν²`` with ``J_d_X`` (..., 3), ``cov_X`` (3, 3) over
        ``(x [m], y [m], theta [rad])`` and ``σ_ν`` [px] the disparity pixel noise (default
        ``sqrt(2)·sigma_img``, Eq 7)."""
        J = np.asarray(J_d_X, dtype=float)
        var_nu = 2.0 * self.sigma_img**2 if sigma_nu is None else float(sigma_nu) ** 2
        return np.einsum("...i,ij,...j->...", J, np.asarray(cov_X, dtype=float), J) + var_nu

    def cov_columns(self, X, cov_X, points, cov_points=None) -> np.ndarray:
        """Covariance ``Σ_I`` (..., 2, 2) of ``(u_l, u_r)`` propagated from the pose and the point.

        Paper Eq 4 (``cov_points`` given, (..., 2, 2) over world ``(x, y)``), Eq 5 (``cov_points=None``:
        a known line such as a reference plane's edge).
        """
        _, J_X, J_p = self.project_columns(X, points, jacobians=True)
        cov = J_X @ np.asarray(cov_X, dtype=float) @ np.swapaxes(J_X, -1, -2)
        if cov_points is not None:
            cov = cov + J_p @ np.asarray(cov_points, dtype=float) @ np.swapaxes(J_p, -1, -2)
        return cov

    def sigma_disparity(self, X, cov_X, points) -> np.ndarray:
        """Standard deviation ``σ_d`` of the disparity of world points (paper Eq 10) [px].

        ``σ_d² = (∂D/∂X) Σ_X (∂D/∂X)ᵀ + σ_ν²`` with ``σ_ν² = 2 σ_img²`` (Eq 7); see :meth:`disparity_variance`.
        """
        _, J_d_X, _ = self.disparity(X, points, jacobians=True)
        return np.sqrt(self.disparity_variance(J_d_X, cov_X))

    # ----------------------------------------------------------- triangulation
    def triangulate(self, u_l, u_r, X=None, cov_X=None, *, sigma_img=None, cov_uv=None):
        """Triangulate image columns ``(u_l, u_r)`` into points on the floor plane with covariance.

        Parameters
        ----------
        u_l, u_r : (...,) columns of the same vertical line in the left and right image [px].
        X : (3,) robot pose; ``None`` returns camera coordinates ``(X_c, Z_c)`` instead of world ``(x, y)``.
        cov_X : (3, 3) pose covariance over ``(x, y, theta)``, added to the result when given.
        sigma_img : column standard deviation [px] (default: the camera's ``sigma_img``, Sec 2.3.1); a scalar
            for both images or ``(..., 2)`` for ``(σ_l, σ_r)`` separately (e.g. a searched boundary, Sec 3.2).
        cov_uv : (..., 2, 2) full covariance of ``(u_l, u_r)`` [px²], for correlated columns; overrides
            ``sigma_img``.

        Returns
        -------
        p : (..., 2) world ``(x, y)`` [m] (or camera ``(X_c, Z_c)``); NaN where ``u_l - u_r <= 0``.
        cov_p : (..., 2, 2) covariance of ``p`` [m²], first-order from ``σ_img`` on both columns
        (independent) and, if given, from ``cov_X``.
        """
        u_l = np.asarray(u_l, dtype=float)
        u_r = np.asarray(u_r, dtype=float)
        if u_l.ndim == u_r.ndim == 0 and X is not None and cov_X is None and np.ndim(cov_uv) == 2:
            return self._triangulate_one(float(u_l), float(u_r), X, np.asarray(cov_uv, dtype=float))
        if X is not None and u_l.ndim == 1 and u_l.shape == u_r.shape:
            # columns (n,) in the world: the element-wise part below compiled (_triangulate_kernel, the same
            # doubles), ~3 µs instead of ~15 µs; the covariance by the same matrix products
            cx, cy, _, c, s = self._frame(X)
            p, J, Xc, Zc = _triangulate_kernel(np.ascontiguousarray(u_l), np.ascontiguousarray(u_r), cx, cy, c, s,
                                               self.cu, self.f, self.baseline)
            return p, self._triangulation_cov(X, J, Xc, Zc, cov_X, sigma_img, cov_uv)
        d = u_l - u_r
        d = np.where(d > 0, d, np.nan)
        fb = self.f * self.baseline
        Zc = fb / d
        Xc = (u_l - self.cu) * Zc / self.f
        # d(Xc, Zc)/d(u_l, u_r)
        dZ_dur = fb / d**2
        dZ_dul = -dZ_dur
        # J (..., 2, 2): d(Xc, Zc)/d(u_l, u_r) in the camera frame, or d(x, y)/d(u_l, u_r) = R_w_c of it
        # in the world, R_w_c = [[s, c], [-c, s]] (columns: world directions of camera x and z)
        J = np.empty(d.shape + (2, 2))
        dX_dul = Zc / self.f + (u_l - self.cu) * dZ_dul / self.f
        dX_dur = (u_l - self.cu) * dZ_dur / self.f
        if X is None:
            J[..., 0, 0] = dX_dul
            J[..., 0, 1] = dX_dur
            J[..., 1, 0] = dZ_dul
            J[..., 1, 1] = dZ_dur
            p = np.empty(d.shape + (2,))
            p[..., 0] = Xc
            p[..., 1] = Zc
        else:
            cx, cy, _, c, s = self._frame(X)
            J[..., 0, 0] = s * dX_dul + c * dZ_dul
            J[..., 0, 1] = s * dX_dur + c * dZ_dur
            J[..., 1, 0] = -c * dX_dul + s * dZ_dul
            J[..., 1, 1] = -c * dX_dur + s * dZ_dur
            p = np.empty(d.shape + (2,))
            p[..., 0] = cx + c * Zc + s * Xc
            p[..., 1] = cy + s * Zc - c * Xc
        return p, self._triangulation_cov(X, J, Xc, Zc, cov_X, sigma_img, cov_uv)

    def _triangulation_cov(self, X, J, Xc, Zc, cov_X, sigma_img, cov_uv) -> np.ndarray:
        """:meth:`triangulate`'s covariance from the columns' Jacobian ``J`` (..., 2, 2) and the points' camera
        coordinates."""
        J_T = np.swapaxes(J, -1, -2)
        if cov_uv is not None:
            cov = J @ np.asarray(cov_uv, dtype=float) @ J_T
        else:
            s_img = np.asarray(self.sigma_img if sigma_img is None else sigma_img, dtype=float)
            cov = s_img**2 * J @ J_T if s_img.ndim == 0 else (J * (s_img**2)[..., None, :]) @ J_T
        if X is not None and cov_X is not None:
            J_p_X = self.triangulation_jacobian_pose(X, Xc, Zc)
            cov = cov + J_p_X @ np.asarray(cov_X, dtype=float) @ np.swapaxes(J_p_X, -1, -2)
        return cov

    def _triangulate_one(self, u_l: float, u_r: float, X, cov_uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`triangulate` of one column pair in the world with a full column covariance (a searched boundary):
        the same element-wise operations on Python floats (squares as products, as NumPy's), the covariance by the
        same matrix products, without the array code's ~30 operations on 0-d arrays."""
        d = u_l - u_r
        d = d if d > 0 else math.nan
        fb = self.f * self.baseline
        Zc = fb / d
        Xc = (u_l - self.cu) * Zc / self.f
        dZ_dur = fb / (d * d)
        dZ_dul = -dZ_dur
        dX_dul = Zc / self.f + (u_l - self.cu) * dZ_dul / self.f
        dX_dur = (u_l - self.cu) * dZ_dur / self.f
        cx, cy, _, c, s = self._frame(X)
        J = np.array([[s * dX_dul + c * dZ_dul, s * dX_dur + c * dZ_dur],
                      [-c * dX_dul + s * dZ_dul, -c * dX_dur + s * dZ_dur]])
        p = np.array([cx + c * Zc + s * Xc, cy + s * Zc - c * Xc])
        return p, J @ cov_uv @ np.swapaxes(J, -1, -2)

    def triangulation_jacobian_pose(self, X, Xc, Zc) -> np.ndarray:
        """``J_p_X`` (..., 2, 3): how a triangulated world point moves with the robot pose."""
        Xc = np.asarray(Xc, dtype=float)
        Zc = np.asarray(Zc, dtype=float)
        _, _, _, c, s = self._frame(X)
        r0, r1 = self._centre_rate(X)
        # p = cam + Zc (c, s) + Xc (s, -c)
        J = np.zeros(np.broadcast(Xc, Zc).shape + (2, 3))
        J[..., 0, 0] = 1.0
        J[..., 1, 1] = 1.0
        J[..., 0, 2] = r0 - s * Zc + c * Xc
        J[..., 1, 2] = r1 + c * Zc + s * Xc
        return J

    def heights(self, v, Zc) -> np.ndarray:
        """Height above the floor [m] of image rows ``v`` at depth ``Zc``."""
        return self.mount_height - (np.asarray(v, dtype=float) - self.cv) * np.asarray(Zc, dtype=float) / self.f

    def triangulate_line(self, u_l, u_r, v_top, v_bottom, X=None, cov_X=None):
        """A vertical line ``L = (x, y, z_low, z_high)`` (Eq 1) from a matched segment pair, with the
        covariance (2, 2) of its ``(x, y)`` (or camera ``(X_c, Z_c)`` when ``X`` is None)."""
        p, cov = self.triangulate(u_l, u_r, X, cov_X)
        d = np.asarray(u_l, dtype=float) - np.asarray(u_r, dtype=float)
        Zc = self.f * self.baseline / np.where(d > 0, d, np.nan)
        z_high = self.heights(v_top, Zc)
        z_low = self.heights(v_bottom, Zc)
        L = np.concatenate([p, np.stack([z_low, z_high], -1)], -1)
        return L, cov

    # ------------------------------------------------------------- visibility
    @property
    def half_fov(self) -> float:
        """Half of the horizontal field of view [rad] (to the outer pixel edge of the left image)."""
        return float(np.arctan2(max(self.cu + 0.5, self.width - 0.5 - self.cu), self.f))

    def in_image(self, u, margin: float = 0.0) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        return (u >= -0.5 + margin) & (u <= self.width - 0.5 - margin)

    def optical_centres(self, X) -> tuple[np.ndarray, np.ndarray]:
        """World ``(x, y)`` of the left and right optical centres for robot pose X."""
        cx, cy, _, c, s = self._frame(X)
        return np.array([cx, cy]), np.array([cx + self.baseline * s, cy - self.baseline * c])

    def column_ray(self, X, u) -> np.ndarray:
        """Unit world directions ``(..., 2)`` of the left camera's rays through image columns ``u``."""
        _, _, _, c, s = self._frame(X)
        xn = (np.asarray(u, dtype=float) - self.cu) / self.f
        d = np.empty(xn.shape + (2,))
        d[..., 0] = c + s * xn
        d[..., 1] = s - c * xn
        return d / np.linalg.norm(d, axis=-1, keepdims=True)
