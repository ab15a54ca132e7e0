"""Reference planes in the disparity image: prediction with 3σ gates, robust fitting, members.

Paper Sec 2.3–2.4. For every reference plane (a wall of the map) in view of the robot's belief
``(X, Σ_X)``, :func:`predict_plane` gives the image columns where the plane can appear (the projected
ends ±3σ, Eqs 3–6) and, column by column, the disparity the plane would have with its standard deviation
(Eqs 7–10). :func:`fit_plane` turns the disparity pixels inside that band into points and fits the wall's
line (Eq 11) with its covariance. DESIGN.md §4: the paper's ``y = a + b x`` is ill-posed for walls along
the viewing direction, so the line is fitted in the wall's own frame — offset ``o`` along the wall's
normal as a function of the distance ``s`` along it, ``o = a + b (s − s0)`` — with each point weighted by
its depth uncertainty projected on the normal, after rejecting points off the wall (clutter).

Frames: world/map. Points are placed in the world with the *mean* pose: everything downstream
(point-on-plane fusion, boundary, relative model) uses positions relative to the observed plane, so the
pose's uncertainty enters only through the prediction gates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numpy as np
from numba import njit

from .errors import InputError, expected
from .geometry import StereoCamera
from .maps import Map, ReferencePlane, visible_parts

FIT_COVARIANCES = ("clustered", "independent")
"""How :func:`fit_plane` estimates the fitted line's covariance (``PlaneConfig.fit_covariance``)."""


@dataclass(frozen=True)
class PlaneConfig:
    """Thresholds of plane prediction and fitting (paper defaults where the paper gives one)."""

    gate_sigma: float = 3.0
    """Width of every prediction gate in standard deviations (Eq 6)."""
    disparity_noise_px: float | None = None
    """σ_ν of one disparity pixel [px]; default ``sqrt(2)·σ_img`` (Eq 7)."""
    view_margin_px: float = 80.0
    """Planes whose ends project up to this far outside the image are still predicted."""
    max_range: float = 15.0
    """Planes farther than this [m] are not predicted."""
    min_pixels: int = 300
    """Fewer valid disparity pixels in the band than this: no plane this frame."""
    min_columns: int = 10
    """The band's pixels must span at least this many columns."""
    outlier_sigma: float = 3.0
    """Points farther than this many robust standard deviations (1.4826·MAD of the normalised residuals)
    from the line are not on the wall."""
    fit_covariance: str = "clustered"
    """How the fitted line's covariance is estimated. ``independent``: from the weighted least squares with one
    independent measurement per ``correlation_px`` pixels along a row (the paper's model). ``clustered``: never
    smaller than that, and at least the cluster-robust (sandwich) covariance with the band cut into stripes
    ``correlation_px`` columns wide, each stripe one independent cluster: the residuals of one SAD window's
    columns are correlated down the column and across it, and those of a wall seen at a slant change slowly
    along it (pixel locking follows the fractional disparity), which the independent model does not see."""
    correlation_px: float = 15.0
    """Neighbouring disparity pixels are not independent: a window of this size [px] shares its SAD
    support (the block size), so the fitted line's covariance is inflated by ``correlation_px`` (one
    independent measurement per window width along a row)."""
    row_margin_px: float = 4.0
    """Rows this far outside the wall's predicted top/bottom still count."""
    member_min_fraction: float = 0.5
    """A segment belongs to a planar region when this fraction of its pixels lies in the region (Sec 2.4)."""
    member_dilate_px: int = 3
    """The region is dilated by this much before the membership test (edges sit at region borders)."""

    disparity_bias_px: float = 0.0
    """σ of a disparity error shared by every pixel of one wall [px], added to the fitted line's covariance.
    Sub-pixel block matching is biased towards whole disparities (pixel locking), and a wall seen nearly
    frontally has about the same fractional disparity everywhere, so its pixels share that bias and averaging
    them does not remove it. Measured at the true pose on the simulator's walls as the disparity that the fitted
    wall's offset error amounts to, RMS (``python benchmarks/noise_at_true_pose.py lab room corridor office
    hall``): 0.021 px on lab, 0.034 on room, 0.059 on corridor, 0.064 on office, 0.023 on hall. Without it the
    fitted offset is held 2–8 times too certain (median of the normalised squared errors; mean 5–29); with
    0.03 px the mean is 0.4–2.2. Default 0 all the same: tried with 0.03 px (December 2026, together with a
    snapped boundary's σ of 0.5 px from its line and the window's correlation counted down the column too), the
    whole filter became more cautious, not more consistent (pose NEES on lab 1.3 → 0.8, room 2.6 → 1.0, 20
    trials), because the landmarks the fit feeds are already held less certain than their errors (by the
    boundary's σ, ``noise.boundary_px``), and the office then had three trials with NEES peaks of 225–954. Set it
    when the fitted walls themselves are used, or once the boundary's σ can be measured smaller."""

    disparity_tilt_px: float = 0.0
    """σ of a disparity error that changes linearly across one wall's fitted columns [px, at either end of them,
    zero in their middle], added to the fitted line's covariance like ``disparity_bias_px``: the part of the
    wall-shared error that turns the fitted line, whose slope error becomes a scale error along the wall. Measured
    at the true pose by regressing each wall's per-pixel disparity error on its column (``python
    benchmarks/pixel_locking.py``): 0.04–0.11 px RMS on the built-in scenes. Default 0 (see docs/uncertainty.md)."""

    def __post_init__(self) -> None:
        for name in ("disparity_bias_px", "disparity_tilt_px"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v >= 0):
                raise InputError(expected("a non-negative number of pixels", v, where=f"planes.{name}"))
        if self.fit_covariance not in FIT_COVARIANCES:
            raise InputError(expected(f"one of {', '.join(FIT_COVARIANCES)}", self.fit_covariance,
                                      where="planes.fit_covariance"))

    def sigma_nu(self, camera: StereoCamera) -> float:
        return float(self.disparity_noise_px) if self.disparity_noise_px else float(np.sqrt(2.0) * camera.sigma_img)


@dataclass(frozen=True)
class EdgePrediction:
    """Predicted image columns of a wall's end ``(u_l, u_r)`` and their standard deviations (Eqs 3–5)."""

    which: str
    point: np.ndarray
    u: np.ndarray
    sigma: np.ndarray
    free: bool

    def window(self, image: int = 0, gate: float = 3.0) -> tuple[float, float]:
        """Search interval ``u ± gate·σ`` in the left (0) or right (1) image (Eq 6)."""
        return float(self.u[image] - gate * self.sigma[image]), float(self.u[image] + gate * self.sigma[image])


@dataclass(frozen=True)
class PlanePrediction:
    """Where a reference plane appears in the left image, and with which disparity.

    Attributes
    ----------
    plane : the map's wall.
    columns : (K,) integer columns of the left image inside the 3σ window.
    d : (K,) predicted disparity of the wall at each column [px] (Eqs 8–9).
    sigma_d : (K,) its standard deviation (Eq 10) [px].
    v_top, v_bottom : (K,) rows of the wall's top and bottom at each column.
    edges : the wall's two ends ``{"p1": EdgePrediction, "p2": ...}``.
    gate : gate width in σ.
    """

    plane: ReferencePlane
    columns: np.ndarray
    d: np.ndarray
    sigma_d: np.ndarray
    v_top: np.ndarray
    v_bottom: np.ndarray
    edges: dict[str, EdgePrediction]
    gate: float = 3.0

    @property
    def window(self) -> tuple[int, int]:
        return int(self.columns[0]), int(self.columns[-1])

    @cached_property
    def band_table(self) -> np.ndarray:
        """(K, 8) float64, read-only: per column, ``d``, its difference to the next column's, then the same of
        ``sigma_d``, ``v_top`` and ``v_bottom`` (0 at the last column): the linear interpolation's terms, for the
        per-pixel loop of :func:`~stablemarks.landmarks.right_region` (made once per prediction; the differences
        are those it computed per pixel)."""
        table = np.zeros((len(self.d), 8))
        for q, a in enumerate((self.d, self.sigma_d, self.v_top, self.v_bottom)):
            a = np.asarray(a)
            table[:, 2 * q] = a
            table[:-1, 2 * q + 1] = a[1:] - a[:-1]  # in the array's own dtype, as the loop subtracted them
        table.setflags(write=False)
        return table

    def disparity_at(self, u) -> tuple[np.ndarray, np.ndarray]:
        """Predicted disparity and σ_d at (sub-pixel) left columns ``u`` (linear interpolation)."""
        if type(u) is float or type(u) is np.float64:  # one column (the landmark stage asks for a few a frame)
            return self.interp_two(u, "d", "sigma_d")
        u = np.asarray(u, dtype=float)
        return np.interp(u, self.columns, self.d), np.interp(u, self.columns, self.sigma_d)

    def interp_two(self, u: float, first: str, second: str) -> tuple[np.float64, np.float64]:
        """``(np.interp(u, columns, self.<first>), np.interp(u, columns, self.<second>))`` at one column ``u`` (a
        Python or NumPy float) of two of the per-column arrays (``"d"``, ``"sigma_d"``, ``"v_top"``, ``"v_bottom"``):
        np.interp's operations in one numba call (:func:`_interp_two`), its float64 scalars; np.interp itself for
        arrays that are not 1-D float64 of the columns' length."""
        tables = self._interp_tables
        if first in tables and second in tables:
            x, y = _interp_two(float(u), self._columns_float, tables[first], tables[second])
            return np.float64(x), np.float64(y)
        return (np.interp(np.float64(u), self.columns, getattr(self, first)),
                np.interp(np.float64(u), self.columns, getattr(self, second)))

    @cached_property
    def _columns_float(self) -> np.ndarray:
        """:attr:`columns` as float64 (as np.interp takes them), made once per prediction."""
        return np.ascontiguousarray(self.columns, dtype=np.float64)

    @cached_property
    def _interp_tables(self) -> dict[str, np.ndarray]:
        """The per-column arrays that are contiguous 1-D float64 of the columns' length (those :meth:`interp_two`
        hands to :func:`_interp_two`), by name; made once per prediction."""
        K = np.shape(self.columns)
        if len(K) != 1 or K[0] < 1:
            return {}
        out = {}
        for name in ("d", "sigma_d", "v_top", "v_bottom"):
            a = np.asarray(getattr(self, name))
            if a.dtype == np.float64 and a.shape == K:
                out[name] = np.ascontiguousarray(a)
        return out

    def band(self, disparity: np.ndarray, row_margin: float = 0.0) -> np.ndarray:
        """Pixels (H, W) of a left-reference disparity image inside the plane's 3σ band (Sec 2.3.4)."""
        rows, cols, ok = self.band_box(disparity, row_margin)
        mask = np.zeros(disparity.shape, dtype=bool)
        mask[rows, cols] = ok
        return mask

    def band_box(self, disparity: np.ndarray, row_margin: float = 0.0) -> tuple[slice, slice, np.ndarray]:
        """:meth:`band` inside its bounding box: ``(rows, cols, ok)``, ``ok`` (h, K) the band's pixels of
        ``disparity[rows, cols]`` (the window's K columns, the rows the wall's top and bottom reach); the
        band holds no pixel outside the box."""
        rows, cols = self.box(disparity.shape[0], row_margin)
        ok = _band(disparity[rows, cols], rows.start, self.d, self.sigma_d, self.v_top, self.v_bottom,
                   float(self.gate), float(row_margin))
        return rows, cols, ok

    def box(self, height: int, row_margin: float = 0.0) -> tuple[slice, slice]:
        """The bounding box ``(rows, cols)`` of :meth:`band` in images ``height`` rows high: the window's columns,
        the rows the wall's top and bottom reach (``row_margin`` beyond); empty rows when none is inside."""
        u0, u1 = self.window
        top, bottom = self.rows_reached
        v0 = max(0, int(np.ceil(top - row_margin)))
        v1 = max(v0 - 1, min(height - 1, int(np.floor(bottom + row_margin))))
        return slice(v0, v1 + 1), slice(u0, u1 + 1)

    @cached_property
    def rows_reached(self) -> tuple[float, float]:
        """The highest row of the wall's top and the lowest of its bottom over the window: ``(v_top.min(),
        v_bottom.max())`` (made once per prediction: :meth:`box` is asked for by the fit and the regions)."""
        return float(self.v_top.min()), float(self.v_bottom.max())


@njit(cache=True)
def _interp_two(x, xp, fp1, fp2):  # pragma: no cover - numba
    """``(np.interp(x, xp, fp1), np.interp(x, xp, fp2))`` of one number ``x`` (``xp`` increasing, float64, at least one
    element): NumPy's C loop's operations — for one element its value whatever ``x``, else NaN for NaN, the end values
    outside ``xp`` (and at its last element), at a node its value, else the slope ``(fp[j+1] − fp[j]) / (xp[j+1] −
    xp[j])`` times ``x − xp[j]`` plus ``fp[j]``, with its fallbacks where that is NaN — the node ``j`` found once for
    both."""
    n = xp.shape[0]
    if n == 1:  # whatever x (NaN too): the one value
        return fp1[0], fp2[0]
    if np.isnan(x):
        return x, x
    if x < xp[0]:
        return fp1[0], fp2[0]
    if x > xp[n - 1] or x == xp[n - 1]:
        return fp1[n - 1], fp2[n - 1]
    lo, hi = 0, n - 1  # xp[lo] <= x < xp[hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    j = lo
    if xp[j] == x:
        return fp1[j], fp2[j]
    out = np.empty(2)
    for q in range(2):
        fp = fp1 if q == 0 else fp2
        slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
        y = slope * (x - xp[j]) + fp[j]
        if np.isnan(y):
            y = slope * (x - xp[j + 1]) + fp[j + 1]
            if np.isnan(y) and fp[j] == fp[j + 1]:
                y = fp[j]
        out[q] = y
    return out[0], out[1]


def column_depth_on_wall(camera: StereoCamera, X, plane: ReferencePlane, u, *, jacobian: bool = False):
    """Depth ``Z_c`` [m] at which the left camera's column ``u`` meets the wall's (infinite) line.

    With ``jacobian=True`` also returns ``J_Z_X`` (K, 3), the derivative at a *fixed column* (the wall
    point seen there slides along the wall as the pose moves), which is what Eq 10 needs for a plane.
    NaN where the ray is parallel to the wall or meets it behind the camera.
    """
    X = np.asarray(X, dtype=float)
    u = np.asarray(u, dtype=float)
    cam = camera.camera_pose(X)
    psi = cam.theta
    fwd = np.array([np.cos(psi), np.sin(psi)])
    right = np.array([np.sin(psi), -np.cos(psi)])
    xn = (u - camera.cu) / camera.f
    r = fwd[None, :] + xn[:, None] * right[None, :]  # (K,2): world direction with unit depth
    n = plane.normal
    c0 = float(n @ plane.P1)
    c = cam.translation
    nr = r @ n
    num = c0 - n @ c
    with np.errstate(divide="ignore", invalid="ignore"):
        Z = num / nr
    Z = np.where(Z > 1e-3, Z, np.nan)
    if not jacobian:
        return Z
    th = X[2]
    m = np.array([camera.mount_x, camera.mount_y])
    dc_dth = np.array([[-np.sin(th), -np.cos(th)], [np.cos(th), -np.sin(th)]]) @ m
    dr_dth = np.array([-np.sin(psi), np.cos(psi)])[None, :] + xn[:, None] * np.array([np.cos(psi), np.sin(psi)])[None]
    with np.errstate(divide="ignore", invalid="ignore"):
        dZ_dx = -n[0] / nr
        dZ_dy = -n[1] / nr
        dZ_dth = (-(n @ dc_dth) * nr - num * (dr_dth @ n)) / nr**2
    return Z, np.stack([dZ_dx, dZ_dy, dZ_dth], axis=-1)


def predict_plane(
    camera: StereoCamera,
    X,
    cov_X,
    plane: ReferencePlane,
    config: PlaneConfig = PlaneConfig(),
) -> PlanePrediction | None:
    """Predict where ``plane`` appears in the left image from the belief ``(X, cov_X)`` (Eqs 3–10).

    Returns None when no column of the 3σ window falls in the image or the plane is behind the camera.
    """
    X = np.asarray(X, dtype=float)
    cov_X = np.asarray(cov_X, dtype=float)
    gate = config.gate_sigma
    ends = np.array([plane.P1, plane.P2])  # np.stack of the two ends
    # Eq 5, known wall ends: StereoCamera.cov_columns from the one projection that gives the columns too
    uv, J_X, _ = camera.project_columns(X, ends, jacobians=True)
    cov_I = J_X @ cov_X @ np.swapaxes(J_X, -1, -2)
    # the ends' σ of (u_l, u_r), on Python floats (the same correctly rounded square roots as np.sqrt's)
    var_img = camera.sigma_img**2
    (c_1, _), (_, c_2) = cov_I[0].tolist()
    (e_1, _), (_, e_2) = cov_I[1].tolist()
    sig = np.array([[math.sqrt(c_1 + var_img), math.sqrt(c_2 + var_img)],
                    [math.sqrt(e_1 + var_img), math.sqrt(e_2 + var_img)]])
    edges = {
        w: EdgePrediction(w, ends[i], uv[i], sig[i], w in plane.free_edges) for i, w in enumerate(("p1", "p2"))
    }
    # Column interval of the plane: the visible part of the wall, widened by the ends' 3σ (Eq 6).
    # to_camera's depth of the two ends, on Python floats (the same operations)
    cx, cy, _, c, s = camera._frame(X)
    if not any(c * (px - cx) + s * (py - cy) > 1e-3 for px, py in ends.tolist()):
        return None
    W = camera.width
    u_ends, s_ends = uv[:, 0].tolist(), sig[:, 0].tolist()
    if all(math.isfinite(v) for v in u_ends):
        lo = _nan_extreme(min, [v - gate * s for v, s in zip(u_ends, s_ends, strict=True)])
        hi = _nan_extreme(max, [v + gate * s for v, s in zip(u_ends, s_ends, strict=True)])
    else:  # one end behind the camera: the wall runs out of the image on that side
        inside = np.isfinite(uv[:, 0])
        u_in = uv[inside, 0][0]
        s_in = sig[inside, 0][0]
        # which side of the image does the wall leave by? look at a point just in front of the camera
        parts = visible_parts(Map((plane,)), camera, X, max_range=config.max_range, margin_px=-config.view_margin_px)
        if not parts:
            return None
        probe = plane.point_at(np.array([np.mean(parts[0].intervals[0])]))[0]
        u_probe = camera.project_columns(X, probe)[0]
        lo, hi = (u_in - gate * s_in, W - 0.5) if u_probe >= u_in else (-0.5, u_in + gate * s_in)
    u0 = int(min(max(float(np.ceil(lo)), 0.0), W - 1))  # np.clip of the whole number, on Python floats
    u1 = int(min(max(float(np.floor(hi)), 0.0), W - 1))
    if hi < 0 or lo > W - 1 or u1 < u0:
        return None
    found = _columns_on_wall(camera, X, plane, u0, u1, config.max_range)
    if found is None:
        return None
    columns, d, J_d_X, v_top, v_bottom = found
    var_d = camera.disparity_variance(J_d_X, cov_X, config.sigma_nu(camera))  # Eq 10
    return PlanePrediction(plane, columns, d, np.sqrt(var_d), v_top, v_bottom, edges, gate)


def _columns_on_wall(camera: StereoCamera, X: np.ndarray, plane: ReferencePlane, u0: int, u1: int, max_range: float):
    """:func:`predict_plane`'s columns ``u0 … u1``: :func:`column_depth_on_wall` with its Jacobian, the columns where
    the wall is in front within ``max_range``, and there the disparity with its Jacobian (Eqs 8–9,
    :meth:`~stablemarks.geometry.StereoCamera.disparity_at_depth`) and the rows of the wall's top and bottom:
    ``(columns, d, J_d_X, v_top, v_bottom)``, None when no column is. The same operations as those array
    expressions (the element-wise ones in two numba passes, :func:`_column_rays` and :func:`_wall_depths`; the
    matrix products, which NumPy hands to BLAS, still NumPy's), without their two dozen temporaries."""
    cx, cy, psi, _, _ = camera._frame(X)  # camera_pose's numbers, without the SE2
    cos_p, sin_p = float(np.cos(psi)), float(np.sin(psi))
    r, dr_dth = _column_rays(u0, u1, float(camera.cu), float(camera.f), cos_p, sin_p)
    n = plane.normal
    c0 = float(n @ plane.P1)
    nr = r @ n
    num = float(c0 - n @ np.array([cx, cy]))
    th = X[2]
    m = np.array([camera.mount_x, camera.mount_y])
    dc_dth = np.array([[-np.sin(th), -np.cos(th)], [np.cos(th), -np.sin(th)]]) @ m
    z_low, z_high = plane.z
    out = _wall_depths(u0, nr, dr_dth @ n, num, float(n[0]), float(n[1]), float(n @ dc_dth), float(max_range),
                       float(camera.f * camera.baseline), float(camera.f * (camera.mount_height - z_high)),
                       float(camera.f * (camera.mount_height - z_low)), float(camera.cv))
    return None if len(out[0]) == 0 else out


@njit(cache=True)
def _column_rays(u0, u1, cu, f, cos_p, sin_p):  # pragma: no cover - numba
    """:func:`column_depth_on_wall`'s rays of columns ``u0 … u1``: ``r`` (K, 2), the world direction of unit depth
    ``fwd + (u − cu)/f · right``, and its derivative in the heading ``dr_dth`` (K, 2)."""
    K = u1 - u0 + 1
    r = np.empty((K, 2))
    dr = np.empty((K, 2))
    for k in range(K):
        xn = (float(u0 + k) - cu) / f
        r[k, 0] = cos_p + xn * sin_p
        r[k, 1] = sin_p + xn * -cos_p
        dr[k, 0] = -sin_p + xn * cos_p
        dr[k, 1] = cos_p + xn * sin_p
    return r, dr


@njit(cache=True, error_model="numpy")
def _wall_depths(u0, nr, drn, num, n0, n1, ndc, max_range, fb, f_top, f_bottom, cv):  # pragma: no cover - numba
    """:func:`column_depth_on_wall`'s depth ``Z = num / (r·n)`` and Jacobian, of the columns ``u0 + k`` with a finite
    depth above 1 mm and at most ``max_range``, then the disparity ``fb / Z``, its Jacobian ``−fb / Z² · J_Z`` and
    the rows ``cv + f_top / Z``, ``cv + f_bottom / Z`` there: ``(columns, d, J_d_X (K, 3), v_top, v_bottom)``."""
    K = nr.shape[0]
    Z = np.empty(K)
    m = 0
    for k in range(K):
        z = num / nr[k]
        z = z if z > 1e-3 else np.nan
        Z[k] = z
        m += np.isfinite(z) & (z <= max_range)
    columns = np.empty(m, dtype=np.int64)
    d = np.empty(m)
    J = np.empty((m, 3))
    v_top = np.empty(m)
    v_bottom = np.empty(m)
    j = 0
    for k in range(K):
        z = Z[k]
        if np.isfinite(z) & (z <= max_range):
            q = nr[k]
            g = -fb / (z * z)
            columns[j] = u0 + k
            d[j] = fb / z
            J[j, 0] = g * (-n0 / q)
            J[j, 1] = g * (-n1 / q)
            J[j, 2] = g * (((-ndc) * q - num * drn[k]) / (q * q))
            v_top[j] = cv + f_top / z
            v_bottom[j] = cv + f_bottom / z
            j += 1
    return columns, d, J, v_top, v_bottom


def _nan_extreme(pick, values: list[float]) -> float:
    """``np.nanmin`` (``pick`` = min) or ``np.nanmax`` (max) of a few Python floats, at least one of them not NaN:
    the extreme of those that are not NaN."""
    return pick(v for v in values if v == v)


def predict_planes(camera: StereoCamera, X, cov_X, world_map: Map, config: PlaneConfig = PlaneConfig()):
    """Predictions for every reference plane in view of the belief (see :func:`predict_plane`)."""
    in_view = visible_parts(
        world_map, camera, X, max_range=config.max_range, margin_px=-config.view_margin_px,
        planes=world_map.reference_planes,
    )
    out = []
    for part in in_view:
        pred = predict_plane(camera, X, cov_X, part.plane, config)
        if pred is not None:
            out.append(pred)
    return out


# ------------------------------------------------------------------- fitting
@dataclass(frozen=True)
class FailedFit:
    """No plane this frame (falsy): too few pixels in the band, or a degenerate spread."""

    plane: ReferencePlane
    reason: str
    n_pixels: int = 0

    def __bool__(self) -> bool:
        return False


@dataclass(frozen=True)
class PlaneFit:
    """A wall's line fitted to disparity pixels (Eq 11, in the wall's own frame).

    The observed wall is ``o = a + b (s − s0)``: ``s`` distance along the map wall from ``p1`` [m],
    ``o`` signed offset from the map wall's line along its normal [m]. ``cov_R`` (2, 2) is the covariance
    of ``R = (a, b)`` [m², m·1, 1]. ``region`` (H, W) marks the inlier pixels of the left image
    (the planar region, Sec 2.4); ``box`` ``(rows, cols)`` slices of the image outside which ``region``
    holds no pixel.
    """

    plane: ReferencePlane
    prediction: PlanePrediction
    a: float
    b: float
    s0: float
    cov_R: np.ndarray
    region: np.ndarray
    n_points: int
    n_inliers: int
    chi2_dof: float
    X: np.ndarray = field(repr=False)
    box: tuple[slice, slice] = (slice(None), slice(None))
    J_bias: np.ndarray | None = field(default=None, repr=False)
    """(2,) ``∂(a, b)/∂β``: how a disparity error ``β`` [px] shared by all the wall's pixels moves the fitted line
    (``planes.disparity_bias_px`` is its σ; :class:`~stablemarks.localizer.Localizer` with ``ekf.wall_updates``
    estimates it per wall)."""

    def __bool__(self) -> bool:
        return True

    def constraint(self, P) -> tuple[float, np.ndarray, np.ndarray]:
        """Eq 12 for points ``P`` (..., 2) in the world: ``G = o(P) − a − b (s(P) − s0)`` (...,) with
        ``J_G_P`` (2,) and ``J_G_R`` (..., 2)."""
        P = np.asarray(P, dtype=float)
        ds = self.plane.along(P) - self.s0
        G = self.plane.offset(P) - self.a - self.b * ds
        J_G_P = self.plane.normal - self.b * self.plane.direction
        J_G_R = np.stack([np.full_like(ds, -1.0), -ds], axis=-1)
        return G, J_G_P, J_G_R

    def innovation(self, P, cov_P) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eq 12's innovation for triangulated points ``P`` (k, 2) with covariances ``cov_P`` (k, 2, 2), before
        any fusion: is each on the fitted wall at all? Returns ``G`` (k,) [m], its variance ``var_G`` (k,) from the
        point and the fitted line, and the line's share ``var_G_fit`` (k,) [m²] (the off-wall test of a line)."""
        G, J_G_P, J_G_R = self.constraint(P)
        var_G_fit = np.einsum("ki,ij,kj->k", J_G_R, self.cov_R, J_G_R)
        var_G = np.einsum("i,kij,j->k", J_G_P, cov_P, J_G_P) + var_G_fit
        return G, var_G, var_G_fit

    def fuse_point(self, P, cov_P, b: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Combine triangulated points with the fitted plane by one Kalman update each (Eqs 12–14).

        ``Y = H L + V`` with ``H = ∂G/∂L`` and ``Σ_V = G_R Σ_R G_Rᵀ`` (Eq 14); the covariance uses the Joseph
        form. ``G`` is linear in ``L``, so one update is exact. ``P`` (..., 2), ``cov_P`` (..., 2, 2);
        returns ``(P̂, Σ̂)`` of the same shapes in the world frame. ``b``: fuse with the same line turned to
        this slope instead of the fit's (a derivative's step, without a copy of the fit).
        """
        P = np.asarray(P, dtype=float)
        cov_P = np.asarray(cov_P, dtype=float)
        if P.shape[-1:] != (2,) or cov_P.shape[-2:] != (2, 2):
            raise ValueError(f"fuse_point: expected points (..., 2) and covariances (..., 2, 2), got {P.shape} and "
                             f"{cov_P.shape}")
        shape = P.shape[:-1]
        if shape == cov_P.shape[:-2]:
            flat_P, flat_cov = P.reshape(-1, 2), cov_P.reshape(-1, 2, 2)
        else:
            shape = np.broadcast_shapes(shape, cov_P.shape[:-2])
            n = math.prod(shape)
            flat_P = np.broadcast_to(P, (*shape, 2)).reshape(n, 2)
            flat_cov = np.broadcast_to(cov_P, (*shape, 2, 2)).reshape(n, 2, 2)
        plane = self.plane
        P_hat, cov_hat = _fuse_points(flat_P, flat_cov, plane.P1, plane.direction, plane.normal, float(self.a),
                                      float(self.b if b is None else b), float(self.s0),
                                      np.asarray(self.cov_R, dtype=float))
        return P_hat.reshape(*shape, 2), cov_hat.reshape(*shape, 2, 2)

    def point_on_line(self, s) -> np.ndarray:
        """World points on the fitted line at distances ``s`` along the map wall."""
        s = np.asarray(s, dtype=float)
        o = self.a + self.b * (s - self.s0)
        return self.plane.point_at(s) + o[..., None] * self.plane.normal


def fit_plane(
    camera: StereoCamera,
    X,
    disparity: np.ndarray,
    prediction: PlanePrediction,
    config: PlaneConfig = PlaneConfig(),
) -> PlaneFit | FailedFit:
    """Fit the wall's line to the disparity pixels inside the prediction's band (Sec 2.3.4, Eq 11).

    Robust weighted least squares in the wall frame: weights from each pixel's depth uncertainty
    projected on the wall normal; points farther than ``outlier_sigma`` robust σ from the line are
    dropped and the fit repeated (clutter in front of the wall does not bend it).
    """
    plane = prediction.plane
    # the band's box as one contiguous array (the per-pixel loops vectorize on it): band_box's band of it, with the
    # counts the checks below need (its pixels, its columns, its pixels on every other row and column) in one pass
    rows, cols = prediction.box(disparity.shape[0], config.row_margin_px)
    disp = np.ascontiguousarray(disparity[rows, cols])
    band, n, n_columns, n_half = _band_counts(disp, rows.start, prediction.d, prediction.sigma_d, prediction.v_top,
                                              prediction.v_bottom, float(prediction.gate), float(config.row_margin_px),
                                              rows.start % 2, cols.start % 2)
    if n < config.min_pixels:
        return FailedFit(plane, f"{n} disparity pixels in the predicted band (need {config.min_pixels})", n)
    if n_columns < config.min_columns:
        return FailedFit(plane, "band pixels span too few columns", n)
    # Every pixel of the band's box in the wall frame, placed with the mean pose: the left pixel at column
    # u with depth Z is at c + Z r(u), r(u) = fwd + (u − cu)/f · right the world direction of unit depth.
    X = np.asarray(X, dtype=float)
    cx, cy, psi, _, _ = camera._frame(X)  # the camera's pose (camera_pose's numbers, without the SE2)
    cos_p, sin_p = np.cos(psi), np.sin(psi)
    fwd = np.array([cos_p, sin_p])
    # (K, 2): fwd + (u − cu)/f · right, right = (sin, −cos), the array expression's operations (_column_directions)
    r = _column_directions(np.asarray(prediction.columns), float(camera.cu), float(camera.f), float(cos_p),
                           float(sin_p))
    r_s, r_o = r @ plane.direction, r @ plane.normal
    centre = np.array([cx, cy])
    c_s, c_o = float(plane.along(centre)), float(plane.offset(centre))
    fb = camera.f * camera.baseline
    # Fit on every other row and column (neighbouring pixels share their SAD window anyway), then
    # classify every band pixel with the final line.
    frame = (r_s, r_o, c_s, c_o, fb, config.sigma_nu(camera))
    if n_half < config.min_pixels // 4:
        i0, k0, step = 0, 0, 1
    else:
        i0, k0, step = rows.start % 2, cols.start % 2, 2
    # the points, their weights 1/σ_o² and their box columns (the clusters of the clustered covariance)
    s, o, sigma_o, w_all, column = _wall_points_weights(disp, band, i0, k0, step, *frame)
    # Robust start: the median offset, then reweighted least squares with outlier rejection.
    inl = np.ones(len(s), dtype=bool)
    if len(s) and s.dtype == o.dtype == np.float64:  # both medians in one call: median()'s order statistics
        a, s0 = _two_medians(o, s)
    else:
        a, s0 = median(o), median(s)
    b = 0.0
    scale = 1.0
    min_inliers = max(3, len(s) * config.min_pixels // (2 * n))
    outlier_sigma = float(config.outlier_sigma)
    for _ in range(4):
        # the data's own spread, not the model's σ: disparity noise is often below σ_ν, and clutter
        # a few tens of cm in front of a wall is then still separable (the scale, the new inliers, their
        # weights and points and the weights' sum in one call: _reweight_step, what _reweight_sum computes)
        scale, inl, wgt, s_in, o_in, sum_w = _reweight_step(s, o, sigma_o, w_all, inl, float(a), float(b), float(s0),
                                                            outlier_sigma)
        if len(wgt) < min_inliers:
            return FailedFit(plane, "too few pixels agree on one wall line", n)
        s0 = float(wgt @ s_in) / sum_w
        ds, w_ds, sum_w_ds = _centred(wgt, s_in, s0)
        N_inv = _inverse_spd2(sum_w, sum_w_ds, w_ds @ ds)  # N = [[Σw, Σw·ds], [Σw·ds, Σw·ds²]]
        if N_inv is None:
            return FailedFit(plane, "wall seen over too short a span to fit", n)
        a, b = (N_inv @ np.array([wgt @ o_in, w_ds @ o_in])).tolist()
    # the final line's normalised residuals of the final inliers and, for the clustered covariance, each stripe's
    # score (see _clustered_cov)
    clustered = config.fit_covariance == "clustered"
    res, scores = _final_residuals(s, o, sigma_o, w_all, inl, a, b, s0, column,
                                   float(max(1.0, config.correlation_px)), clustered)
    chi2_dof = float(res @ res) / max(1, len(res) - 2)
    # one independent measurement per `correlation_px` pixels of the full band (the subsample carries
    # len(s)/n of its information). The residuals are correlated down the column as well (13–14 px either way
    # with 15 px windows, measured on the simulator's walls); counting one measurement per window area, with
    # the residuals' own spread, was tried (December 2026, with the snapped boundary's σ taken from its line)
    # and made the whole filter more cautious, not more consistent (room's pose NEES 3.1 → 1.5, 20 trials): the
    # landmarks it feeds are already held less certain than their errors, by the boundary's σ. Not adopted.
    cov_R = N_inv * max(1.0, chi2_dof) * config.correlation_px * len(s) / n
    if clustered:
        cov_R = _at_least(cov_R, _sandwich(N_inv, scores))
    # a disparity error β shared by the wall moves each pixel along its ray: ∂(s, o)/∂β = −Z/(f b) (s − c_s,
    # o − c_o), Z the pixel's depth; the line (a, b) follows through the weighted least squares
    g = _bias_rates(s_in, o_in, c_s, c_o, float(fwd @ plane.direction), float(fwd @ plane.normal), fb, b)
    J_beta = N_inv @ np.array([wgt @ g, w_ds @ g])
    if config.disparity_bias_px > 0 or config.disparity_tilt_px > 0:
        if config.disparity_bias_px > 0:
            cov_R = cov_R + config.disparity_bias_px**2 * np.outer(J_beta, J_beta)
        if config.disparity_tilt_px > 0:
            # the error γ x(u) with x from −1 to 1 across the inliers' columns: each pixel's g times its x
            col = column[inl].astype(np.float64)
            lo, hi = float(col.min()), float(col.max())
            g_x = g * ((col - 0.5 * (lo + hi)) / max(0.5 * (hi - lo), 1.0))
            J_gamma = N_inv @ np.array([wgt @ g_x, w_ds @ g_x])
            cov_R = cov_R + config.disparity_tilt_px**2 * np.outer(J_gamma, J_gamma)
    # every band pixel within the final limit, written into the image-sized region
    region = np.zeros(np.shape(disparity), dtype=bool)
    n_keep = _on_line_region(region, rows.start, cols.start, disp, band, *frame, a, b, s0, config.outlier_sigma * scale)
    return PlaneFit(plane, prediction, a, b, s0, cov_R, region, n, n_keep, chi2_dof, X, (rows, cols), J_beta)


@njit(cache=True)
def _column_directions(columns, cu, f, cos_p, sin_p):  # pragma: no cover - numba
    """:func:`fit_plane`'s world directions of unit depth ``fwd + (u − cu)/f · right`` (K, 2) of the left image's
    ``columns`` (``fwd = (cos, sin)``, ``right = (sin, −cos)``): the array expression's operations per column."""
    K = columns.shape[0]
    r = np.empty((K, 2))
    for k in range(K):
        xn = (float(columns[k]) - cu) / f
        r[k, 0] = cos_p + xn * sin_p
        r[k, 1] = sin_p + xn * -cos_p
    return r


@njit(cache=True)
def _two_medians(x, y):  # pragma: no cover - numba
    """:func:`median` of two 1-D float64 arrays (at least one number each) in one call: the same order statistics
    (:func:`_kth_and_below`) and the same mean of the middle two, as Python floats."""
    out = np.empty(2)
    for q in range(2):
        a = x if q == 0 else y
        n = a.shape[0]
        kth, below = _kth_and_below(a, n // 2)
        out[q] = kth if n % 2 else (below + kth) / 2
    return out[0], out[1]


@njit(cache=True)
def _bias_rates(s_in, o_in, c_s, c_o, fwd_s, fwd_o, fb, b):  # pragma: no cover - numba
    """:func:`fit_plane`'s ``g = −(depth / fb) · ((o − c_o) − b (s − c_s))`` of the inliers, ``depth = (s − c_s) fwd_s +
    (o − c_o) fwd_o``: the array expressions' element-wise operations in one pass, without their temporaries."""
    n = s_in.shape[0]
    g = np.empty(n)
    for i in range(n):
        ds = s_in[i] - c_s
        do = o_in[i] - c_o
        depth = ds * fwd_s + do * fwd_o
        g[i] = -(depth / fb) * (do - b * ds)
    return g


@njit(cache=True)
def _residuals(s, o, sigma_o, inl, a, b, s0):  # pragma: no cover - numba
    """The normalised residuals ``res = (o − a − b (s − s0)) / σ_o`` (n,) of the line ``(a, b, s0)`` and ``|res|`` of
    the inliers ``inl`` (:func:`_reweight`)."""
    n = s.shape[0]
    res = np.empty(n)
    absres = np.empty(n)
    m = 0
    for i in range(n):
        r = ((o[i] - a) - b * (s[i] - s0)) / sigma_o[i]
        res[i] = r
        if inl[i]:
            absres[m] = abs(r)
            m += 1
    return res, absres[:m]


@njit(cache=True)
def _inliers(res, limit, w_all, s, o):  # pragma: no cover - numba
    """The points with ``|res| <= limit``: their mask and their weights and points (:func:`_reweight`)."""
    n = res.shape[0]
    new = np.empty(n, dtype=np.bool_)
    count = 0
    for i in range(n):
        keep = abs(res[i]) <= limit
        new[i] = keep
        count += keep
    wgt = np.empty(count)
    s_in = np.empty(count)
    o_in = np.empty(count)
    j = 0
    for i in range(n):
        if new[i]:
            wgt[j] = w_all[i]
            s_in[j] = s[i]
            o_in[j] = o[i]
            j += 1
    return new, wgt, s_in, o_in


def _reweight(s, o, sigma_o, w_all, inl, a: float, b: float, s0: float, outlier_sigma: float):
    """One reweighting step of :func:`fit_plane`: the normalised residuals ``res = (o − a − b (s − s0)) / σ_o`` of
    the line ``(a, b, s0)``, the robust scale ``max(1e-3, 1.4826 · median |res[inl]|)`` (``inl`` the inliers so
    far), the new inliers ``|res| <= outlier_sigma · scale`` and their weights and points; returns ``(scale, inl,
    w_all[inl], s[inl], o[inl])``. Two passes over the points (:func:`_residuals`, :func:`_inliers`) with the
    same element-wise operations in the same order as the NumPy expressions they replaced, and the same
    :func:`median` between them: the same values bit for bit, without a dozen array temporaries (~60 µs an
    iteration for a wall of 8000 points). (NumPy's partition, not numba's: 4× faster.)"""
    res, absres = _residuals(s, o, sigma_o, inl, a, b, s0)
    scale = max(1e-3, 1.4826 * median(absres))
    return (scale, *_inliers(res, outlier_sigma * scale, w_all, s, o))


def _reweight_sum(s, o, sigma_o, w_all, inl, a: float, b: float, s0: float, outlier_sigma: float):
    """:func:`_reweight` and the sum of the new inliers' weights as NumPy's ``wgt.sum()`` adds them
    (:func:`_pairwise_sum`): ``(scale, inl, wgt, s_in, o_in, sum_w)``."""
    scale, new, wgt, s_in, o_in = _reweight(s, o, sigma_o, w_all, inl, a, b, s0, outlier_sigma)
    return scale, new, wgt, s_in, o_in, _pairwise_sum(wgt, 0, wgt.shape[0])


@njit(cache=True)
def _reweight_step(s, o, sigma_o, w_all, inl, a, b, s0, outlier_sigma):  # pragma: no cover - numba
    """:func:`_reweight_sum` in one call (its four numba calls and the Python between them cost ~10 µs an iteration
    of :func:`fit_plane`): :func:`_residuals`' arithmetic, with the extremes of the inliers' ``|res|`` taken on the
    way (what :func:`_kth_and_below` first looks for), :func:`median`'s order statistics of them
    (:func:`_kth_and_below_in`), the same scale, :func:`_inliers`' test with the mask and the kept weights and points
    written in one pass (the arrays returned are the first ``count`` of arrays ``n`` long), and
    :func:`_pairwise_sum` of the weights: the same values bit for bit."""
    n = s.shape[0]
    res = np.empty(n)
    absres = np.empty(n)
    m = 0
    lo = 0.0
    hi = 0.0
    for i in range(n):
        r = ((o[i] - a) - b * (s[i] - s0)) / sigma_o[i]
        res[i] = r
        if inl[i]:
            v = abs(r)
            absres[m] = v
            if m == 0:
                lo = v
                hi = v
            else:
                lo = min(lo, v)
                hi = max(hi, v)
            m += 1
    kth, below = _kth_and_below_in(absres[:m], m // 2, lo, hi)
    med = kth if m % 2 else (below + kth) / 2
    scale = max(1e-3, 1.4826 * med)
    limit = outlier_sigma * scale
    new = np.empty(n, dtype=np.bool_)
    wgt = np.empty(n)
    s_in = np.empty(n)
    o_in = np.empty(n)
    count = 0
    for i in range(n):
        keep = abs(res[i]) <= limit
        new[i] = keep
        if keep:
            wgt[count] = w_all[i]
            s_in[count] = s[i]
            o_in[count] = o[i]
            count += 1
    return scale, new, wgt[:count], s_in[:count], o_in[:count], _pairwise_sum(wgt, 0, count)


@njit(cache=True)
def _centred(wgt, s_in, s0):  # pragma: no cover - numba
    """``ds = s_in − s0``, ``w_ds = wgt · ds`` and ``w_ds.sum()`` (NumPy's summation order, :func:`_pairwise_sum`) in
    one call: :func:`fit_plane`'s normal equations, the same element-wise operations as the array expressions."""
    n = s_in.shape[0]
    ds = np.empty(n)
    w_ds = np.empty(n)
    for i in range(n):
        d = s_in[i] - s0
        ds[i] = d
        w_ds[i] = wgt[i] * d
    return ds, w_ds, _pairwise_sum(w_ds, 0, n)


@njit(cache=True)
def _pairwise_block(a, lo, n):  # pragma: no cover - numba
    """NumPy's pairwise summation of ``a[lo : lo + n]`` for ``n <= 128``: below 8 elements left to right from 0,
    else in eight interleaved partial sums combined pairwise, the rest added after."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        q = lo + i
        r0 += a[q]
        r1 += a[q + 1]
        r2 += a[q + 2]
        r3 += a[q + 3]
        r4 += a[q + 4]
        r5 += a[q + 5]
        r6 += a[q + 6]
        r7 += a[q + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise_sum(a, lo, n):  # pragma: no cover - numba
    """The sum of ``a[lo : lo + n]`` (contiguous float64) as NumPy's ``add.reduce`` sums it, bit for bit: blocks of at
    most 128 (:func:`_pairwise_block`), a longer stretch split in two halves (the first a multiple of 8) summed apart
    and added. The recursion unrolled on a stack (a stretch's start, length, and the sum of its first half once
    known): numba's cache does not load recursive functions safely. (:mod:`stablemarks.landmarks` uses it too.)"""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    starts = np.empty(64, np.int64)
    lengths = np.empty(64, np.int64)
    firsts = np.empty(64)
    halves = np.zeros(64, np.int64)  # 0: neither half summed, 1: the first
    starts[0], lengths[0], sp = lo, n, 1
    while True:
        top = sp - 1
        m = lengths[top]
        if m > 128:  # split: its first half first (a stretch on top has neither half summed yet)
            h = m // 2
            h -= h % 8
            starts[sp], lengths[sp], halves[sp] = starts[top], h, 0
            sp += 1
            continue
        val = _pairwise_block(a, starts[top], m)
        sp -= 1
        # hand the sum up: the first half of its parent waits for the second, the second completes the parent
        while sp > 0:
            parent = sp - 1
            h = lengths[parent] // 2
            h -= h % 8
            if halves[parent] == 0:
                firsts[parent], halves[parent] = val, 1
                starts[sp], lengths[sp], halves[sp] = starts[parent] + h, lengths[parent] - h, 0
                sp += 1
                break
            val = firsts[parent] + val
            sp -= 1
        if sp == 0:
            return val


@njit(cache=True, error_model="numpy")
def _final_residuals(s, o, sigma_o, w_all, inl, a, b, s0, column, width, clustered):  # pragma: no cover - numba
    """After :func:`fit_plane`'s last reweighting: the normalised residuals ``(o − a − b (s − s0)) / σ_o`` of the
    inliers ``inl`` (m,) and, when ``clustered``, the scores (G, 2) of the stripes ``column // width`` that hold an
    inlier, in increasing stripe order: ``Σ w r (1, s − s0)`` over the stripe's inliers, ``r = o − a − b (s − s0)``
    (what :func:`_clustered_cov` sums with ``np.bincount``, element by element in the points' order; empty (0, 2)
    otherwise). The residuals are :func:`_residuals`' arithmetic, the scores that of the array expressions
    ``w_in * (o_in − a − b * ds)`` (then times ``ds``) they replaced."""
    n = s.shape[0]
    m = 0
    top_column = 0
    for i in range(n):
        m += inl[i]
        top_column = max(top_column, column[i])
    # each column's stripe, once per column: the same floor division as on every point
    stripe = np.empty(top_column + 1 if clustered else 0, dtype=np.int64)
    for k in range(stripe.shape[0]):
        stripe[k] = np.int64(float(k) // width)
    res = np.empty(m)
    sigma_in = np.empty(m)
    r_in = np.empty(m)
    ds_in = np.empty(m)
    g_in = np.empty(m, dtype=np.int64)
    j = 0
    top = -1
    for i in range(n):
        if inl[i]:
            ds = s[i] - s0
            r = (o[i] - a) - b * ds
            res[j] = r
            sigma_in[j] = sigma_o[i]
            if clustered:
                r_in[j] = w_all[i] * r
                ds_in[j] = ds
                g = stripe[column[i]]
                g_in[j] = g
                top = max(top, g)
            j += 1
    for j in range(m):  # the divisions in a loop of their own: it vectorizes
        res[j] = res[j] / sigma_in[j]
    if not clustered:
        return res, np.zeros((0, 2))
    count = np.zeros(top + 1, dtype=np.int64)
    sums = np.zeros((top + 1, 2))
    for j in range(m):
        g = g_in[j]
        count[g] += 1
        sums[g, 0] += r_in[j]
        sums[g, 1] += r_in[j] * ds_in[j]
    G = 0
    for g in range(top + 1):
        G += count[g] > 0
    scores = np.empty((G, 2))
    q = 0
    for g in range(top + 1):
        if count[g] > 0:
            scores[q, 0] = sums[g, 0]
            scores[q, 1] = sums[g, 1]
            q += 1
    return res, scores


# Per-pixel loops of the band and the fit, over the band's box (see PlanePrediction.band_box). A left pixel
# at column u with disparity d is at depth Z = f b / d, at distance c_s + Z r_s(u) along the wall and
# offset c_o + Z r_o(u) from it, with σ of the offset |r_o(u)| Z² σ_ν / (f b) (depth σ on the normal).
@njit(cache=True)
def _band(disp, v0, d, sigma_d, v_top, v_bottom, gate, row_margin):  # pragma: no cover - numba
    """Band mask (h, K) of the disparity box ``disp`` whose first row is ``v0``."""
    h, K = disp.shape
    ok = np.empty((h, K), dtype=np.bool_)
    for i in range(h):
        v = v0 + i
        for k in range(K):
            x = float(disp[i, k])
            # a zero disparity is a point at infinity: never on a wall
            ok[i, k] = ((abs(x - d[k]) <= gate * sigma_d[k]) & (x > 0)
                        & (v >= v_top[k] - row_margin) & (v <= v_bottom[k] + row_margin))
    return ok


def _clustered_cov(N_inv, w, r, ds, cluster) -> np.ndarray:
    """Cluster-robust (sandwich) covariance of the weighted line fit ``(a, b)``: ``N⁻¹ M N⁻¹ G/(G−1)`` with
    ``M = Σ_g g_g g_gᵀ``, ``g_g = Σ_{i∈g} w_i r_i (1, ds_i)`` the score of cluster ``g`` (Liang & Zeger); zero
    with fewer than two clusters. (:func:`fit_plane` makes the scores in :func:`_final_residuals`.)"""
    ids, inv = np.unique(cluster, return_inverse=True)
    G = len(ids)
    if G < 2:
        return np.zeros((2, 2))
    wr = w * r
    S = np.stack([np.bincount(inv, weights=wr, minlength=G), np.bincount(inv, weights=wr * ds, minlength=G)], axis=1)
    return _sandwich(N_inv, S)


def _sandwich(N_inv, S) -> np.ndarray:
    """:func:`_clustered_cov` of the clusters' scores ``S`` (G, 2): ``N⁻¹ SᵀS N⁻¹ G/(G−1)``, zero when ``G < 2``."""
    G = len(S)
    if G < 2:
        return np.zeros((2, 2))
    M = S.T @ S
    return N_inv @ M @ N_inv * (G / (G - 1.0))


def _at_least(cov: np.ndarray, other: np.ndarray) -> np.ndarray:
    """``cov`` widened along the principal axes of ``other`` (whitened by ``cov``) where ``other`` is larger:
    at least ``cov`` and at least ``other`` in every direction. Both (2, 2); in closed form (the Cholesky factor
    ``L`` of ``cov``, the eigen-decomposition of ``M = L⁻¹ other L⁻ᵀ``, ``L (M + Σ (1 − wᵢ)⁺ vᵢvᵢᵀ) Lᵀ``): LAPACK
    on 2 × 2 matrices cost 0.1 ms a call in NumPy's overhead."""
    (c11, c12), (_, c22) = cov.tolist()
    (o11, o12), (o21, o22) = other.tolist()
    l11 = math.sqrt(c11)
    l21 = c12 / l11
    l22 = math.sqrt(c22 - l21 * l21)
    # M = L⁻¹ other L⁻ᵀ with L⁻¹ = [[1/l11, 0], [−l21/(l11 l22), 1/l22]]
    i11, i21, i22 = 1.0 / l11, -l21 / (l11 * l22), 1.0 / l22
    m11 = i11 * i11 * o11
    m12 = i11 * (i21 * o11 + i22 * o21)
    m22 = i21 * i21 * o11 + i21 * i22 * (o12 + o21) + i22 * i22 * o22
    half, dev = 0.5 * (m11 + m22), math.hypot(0.5 * (m11 - m22), m12)
    w_hi, w_lo = half + dev, half - dev
    if w_hi <= 1.0:
        return cov  # nowhere larger: ``cov`` itself, bit for bit
    # unit eigenvector of the larger eigenvalue (of the two equivalent forms the longer; any vector when the two
    # eigenvalues are equal); the other is its perpendicular
    v1, v2 = w_hi - m22, m12
    u1, u2 = m12, w_hi - m11
    n, nu = math.hypot(v1, v2), math.hypot(u1, u2)
    if nu > n:
        v1, v2, n = u1, u2, nu
    v1, v2 = (v1 / n, v2 / n) if n > 0.0 else (1.0, 0.0)
    a_hi, a_lo = max(w_hi, 1.0) - w_hi, max(w_lo, 1.0) - w_lo  # what each axis gains
    s11 = m11 + a_hi * v1 * v1 + a_lo * v2 * v2
    s12 = m12 + (a_hi - a_lo) * v1 * v2
    s22 = m22 + a_hi * v2 * v2 + a_lo * v1 * v1
    # L S Lᵀ
    out11 = l11 * l11 * s11
    out12 = l11 * (l21 * s11 + l22 * s12)
    out22 = l21 * l21 * s11 + 2.0 * l21 * l22 * s12 + l22 * l22 * s22
    return np.array([[out11, out12], [out12, out22]])


@njit(cache=True, error_model="numpy")
def _wall_points(disp, band, i0, k0, step, r_s, r_o, c_s, c_o, fb, sigma_nu):  # pragma: no cover - numba
    """``(s, o, σ_o)`` (n,) of the band pixels in rows ``i0, i0 + step, …`` and columns ``k0, k0 + step, …``
    of the box, row by row (:func:`_wall_points_weights` without the weights and columns)."""
    s, o, sigma, _, _ = _wall_points_weights(disp, band, i0, k0, step, r_s, r_o, c_s, c_o, fb, sigma_nu)
    return s, o, sigma


@njit(cache=True)
def _band_counts(disp, v0, d, sigma_d, v_top, v_bottom, gate, row_margin, i_half, k_half):  # pragma: no cover - numba
    """:func:`_band` of the box ``disp`` (first row ``v0``) with what :func:`fit_plane` checks next: the band's pixels,
    the columns holding any, and its pixels in rows ``i_half, i_half + 2, …`` and columns ``k_half, k_half + 2, …``
    (one pass over the mask, in place of three NumPy reductions)."""
    band = _band(disp, v0, d, sigma_d, v_top, v_bottom, gate, row_margin)
    h, K = band.shape
    seen = np.zeros(K, dtype=np.uint8)
    n = 0
    n_half = 0
    for i in range(h):
        row = band[i]
        c = 0
        for k in range(K):
            c += row[k]
            seen[k] |= row[k]
        n += c
        if c and (i - i_half) % 2 == 0:
            for k in range(k_half, K, 2):
                n_half += row[k]
    n_columns = 0
    for k in range(K):
        n_columns += seen[k] != 0
    return band, n, n_columns, n_half


@njit(cache=True, error_model="numpy")
def _wall_points_weights(disp, band, i0, k0, step, r_s, r_o, c_s, c_o, fb, sigma_nu):  # pragma: no cover - numba
    """``(s, o, σ_o, w, column)`` (n,) of the band pixels in rows ``i0, i0 + step, …`` and columns ``k0, k0 + step,
    …`` of the box, row by row: each point's along-wall position and offset, its σ, weight ``1 / σ_o²`` and box
    column, the columns written in the points' own pass (a second pass over the band's pixels, as ragged as the
    first, cost ~10 µs a wall)."""
    h, K = band.shape
    n = 0
    for i in range(i0, h, step):
        for k in range(k0, K, step):
            n += band[i, k]
    s = np.empty(n)
    o = np.empty(n)
    sigma = np.empty(n)
    column = np.empty(n, dtype=np.int64)
    j = 0
    for i in range(i0, h, step):
        for k in range(k0, K, step):
            if band[i, k]:
                Z = fb / float(disp[i, k])
                s[j] = c_s + Z * r_s[k]
                o[j] = c_o + Z * r_o[k]
                sigma[j] = abs(r_o[k]) * (Z * Z / fb * sigma_nu) + 1e-6
                column[j] = k
                j += 1
    w = np.empty(n)
    for j in range(n):  # in a loop of its own: it vectorizes
        w[j] = 1.0 / (sigma[j] * sigma[j])
    return s, o, sigma, w, column


@njit(cache=True, error_model="numpy")
def _on_line(disp, band, r_s, r_o, c_s, c_o, fb, sigma_nu, a, b, s0, limit):  # pragma: no cover - numba
    """Band pixels (h, K) within ``limit`` σ of the line ``o = a + b (s − s0)``. Branch-free (every pixel's test
    computed, kept where in the band): the loop vectorizes, the same arithmetic per band pixel."""
    h, K = disp.shape
    keep = np.empty((h, K), dtype=np.bool_)
    for i in range(h):
        for k in range(K):
            Z = fb / float(disp[i, k])
            s = c_s + Z * r_s[k]
            o = c_o + Z * r_o[k]
            keep[i, k] = band[i, k] & (abs((o - a - b * (s - s0)) / (abs(r_o[k]) * (Z * Z / fb * sigma_nu) + 1e-6))
                                       <= limit)
    return keep


@njit(cache=True, error_model="numpy")
def _on_line_region(region, v0, c0, disp, band, r_s, r_o, c_s, c_o, fb, sigma_nu, a, b, s0,
                    limit):  # pragma: no cover - numba
    """:func:`_on_line` of the box ``disp`` written into ``region`` (the image's, all False; the box's first row
    ``v0`` and column ``c0``); returns how many pixels are kept. The same answer per pixel.

    :func:`_on_line`'s test ``|r / σ| <= limit`` (``r`` the residual, ``σ = |r_o| (Z² / fb · σ_ν) + 1e-6``) takes
    three divisions a pixel, which bound its time. Here ``σ`` is first taken with ``1 / fb`` as a factor (a few
    roundings apart from the exact one, ~1e-15 relative) and ``|r| <= limit · σ`` tested with a margin of 1e-12:
    a pixel inside ``limit (1 − 1e-12)`` passes the exact test, one beyond ``limit (1 + 1e-12)`` fails it, whatever
    the roundings; a row with a band pixel between the two (hardly ever one) is tested again by :func:`_on_line`
    itself. One division a pixel, the loop still branch-free (twice as fast). A limit that is not a
    positive number: the exact test everywhere."""
    h, K = disp.shape
    exact = not (limit > 0.0 and limit < np.inf)
    inv_fb = 1.0 / fb
    lo_limit = limit * (1.0 - 1e-12)
    hi_limit = limit * (1.0 + 1e-12)
    count = 0
    for i in range(h):
        row = region[v0 + i, c0 : c0 + K]
        n_unsure = 0
        for k in range(K):
            Z = fb / float(disp[i, k])
            s = c_s + Z * r_s[k]
            o = c_o + Z * r_o[k]
            r = abs(o - a - b * (s - s0))
            sigma = abs(r_o[k]) * (Z * Z * inv_fb * sigma_nu) + 1e-6
            inside = r <= lo_limit * sigma
            row[k] = band[i, k] & inside
            n_unsure += band[i, k] & ~inside & (r <= hi_limit * sigma)
        if n_unsure or exact:
            row[:] = _on_line(disp[i : i + 1], band[i : i + 1], r_s, r_o, c_s, c_o, fb, sigma_nu, a, b, s0, limit)[0]
        kept = row.view(np.uint8)
        for k in range(K):
            count += kept[k]
    return count


@njit(cache=True, error_model="numpy")
def _fuse_points(P, cov_P, P1, t, nrm, a, b, s0, cov_R):  # pragma: no cover - numba
    """:meth:`PlaneFit.fuse_point` of points ``P`` (n, 2) with covariances ``cov_P`` (n, 2, 2): Eq 12's
    constraint (``G``, ``H = ∂G/∂L``, ``G_R = ∂G/∂R``), ``Σ_V = G_R Σ_R G_Rᵀ`` (Eq 14), one Kalman update each,
    the covariance in Joseph form and symmetrized — the same operations, element by element, as the NumPy
    expressions it replaced (a few small arrays per call cost more than the arithmetic)."""
    n = P.shape[0]
    P_hat = np.empty((n, 2))
    cov_hat = np.empty((n, 2, 2))
    for i in range(n):
        (P_hat[i, 0], P_hat[i, 1]), (cov_hat[i, 0, 0], cov_hat[i, 0, 1], cov_hat[i, 1, 0], cov_hat[i, 1, 1]) = \
            fuse_one(P[i, 0], P[i, 1], cov_P[i, 0, 0], cov_P[i, 0, 1], cov_P[i, 1, 0], cov_P[i, 1, 1], P1, t, nrm,
                     a, b, s0, cov_R)
    return P_hat, cov_hat


@njit(cache=True, error_model="numpy", inline="always")
def fuse_one(p0, p1, c00, c01, c10, c11, P1, t, nrm, a, b, s0, cov_R):  # pragma: no cover - numba
    """:func:`_fuse_points` of one point ``(p0, p1)`` with covariance ``[[c00, c01], [c10, c11]]``, for numba
    callers: ``((p̂0, p̂1), (ĉ00, ĉ01, ĉ10, ĉ11))``."""
    H0 = nrm[0] - b * t[0]
    H1 = nrm[1] - b * t[1]
    px = p0 - P1[0]
    py = p1 - P1[1]
    ds = (px * t[0] + py * t[1]) - s0
    G = (px * nrm[0] + py * nrm[1]) - a - b * ds
    g0 = -1.0
    g1 = -ds
    var_V = g0 * cov_R[0, 0] * g0 + g0 * cov_R[0, 1] * g1 + g1 * cov_R[1, 0] * g0 + g1 * cov_R[1, 1] * g1
    PH0 = c00 * H0 + c01 * H1
    PH1 = c10 * H0 + c11 * H1
    S = (PH0 * H0 + PH1 * H1) + var_V
    K0 = PH0 / S
    K1 = PH1 / S
    A00 = 1.0 - K0 * H0
    A01 = 0.0 - K0 * H1
    A10 = 0.0 - K1 * H0
    A11 = 1.0 - K1 * H1
    M00 = A00 * c00 + A01 * c10
    M01 = A00 * c01 + A01 * c11
    M10 = A10 * c00 + A11 * c10
    M11 = A10 * c01 + A11 * c11
    R00 = (M00 * A00 + M01 * A01) + var_V * (K0 * K0)
    R01 = (M00 * A10 + M01 * A11) + var_V * (K0 * K1)
    R10 = (M10 * A00 + M11 * A01) + var_V * (K1 * K0)
    R11 = (M10 * A10 + M11 * A11) + var_V * (K1 * K1)
    # innovation 0 − G(L̃); the covariance symmetrized
    return (p0 - K0 * G, p1 - K1 * G), (0.5 * (R00 + R00), 0.5 * (R01 + R10), 0.5 * (R10 + R01), 0.5 * (R11 + R11))


_MEDIAN_BUCKETS = 1024


@njit(cache=True)
def _kth_and_below(x, k):  # pragma: no cover - numba
    """The ``k``-th smallest of the finite numbers ``x`` (0-based) and the largest of the others at or below it
    (the ``k − 1``-th; −inf when ``k`` is 0): exact order statistics, so what ``np.partition`` gives. Two passes:
    counts in :data:`_MEDIAN_BUCKETS` equal buckets between the extremes, then only the bucket holding the
    ``k``-th is sorted (and the largest number below that bucket kept in case it is the ``k − 1``-th)."""
    n = x.shape[0]
    lo = x[0]
    hi = x[0]
    for i in range(n):
        v = x[i]
        lo = min(lo, v)
        hi = max(hi, v)
    return _kth_and_below_in(x, k, lo, hi)


@njit(cache=True)
def _kth_and_below_in(x, k, lo, hi):  # pragma: no cover - numba
    """:func:`_kth_and_below` of the numbers ``x`` whose least and largest are ``lo`` and ``hi``."""
    n = x.shape[0]
    scale = _MEDIAN_BUCKETS / (hi - lo) if hi > lo else 0.0
    if not np.isfinite(scale):  # a span too small (or too large) for buckets: sort everything
        srt = np.sort(x)
        return srt[k], (srt[k - 1] if k > 0 else -np.inf)
    counts = np.zeros(_MEDIAN_BUCKETS + 1, np.int64)
    for i in range(n):
        counts[int((x[i] - lo) * scale)] += 1
    before = 0
    kb = 0
    for b in range(_MEDIAN_BUCKETS + 1):
        if before + counts[b] > k:
            kb = b
            break
        before += counts[b]
    bucket = np.empty(counts[kb])
    m = 0
    below = -np.inf
    for i in range(n):
        v = x[i]
        b = int((v - lo) * scale)
        if b == kb:
            bucket[m] = v
            m += 1
        elif b < kb and v > below:
            below = v
    bucket.sort()
    r = k - before
    return bucket[r], (bucket[r - 1] if r > 0 else below)


def median(x: np.ndarray) -> float:
    """``np.median`` of a 1-D array of finite numbers (at least one), bit for bit, without its overhead: the
    middle order statistics by :func:`_kth_and_below` (about 4× NumPy's partition on a wall's 8000 residuals)."""
    x = np.ravel(x)
    k = x.size // 2
    if x.dtype != np.float64:  # NumPy's arithmetic in other dtypes: its own partition
        p = np.partition(x, k)
        return float(p[k]) if x.size % 2 else float((p[:k].max() + p[k]) / 2)
    kth, below = _kth_and_below(x, k)
    return float(kth) if x.size % 2 else float((below + kth) / 2)


def _inverse_spd2(p, q, r, max_cond: float = 1e12) -> np.ndarray | None:
    """Inverse of the symmetric positive semi-definite 2×2 matrix ``[[p, q], [q, r]]`` (given by its three numbers,
    taken as float64), None when its condition number (ratio of its eigenvalues) exceeds ``max_cond``."""
    p, q, r = float(p), float(q), float(r)  # the same IEEE arithmetic as on np.float64, without its overhead
    det = p * r - q * q
    lam_max = 0.5 * (p + r) + np.hypot(0.5 * (p - r), q)
    if not lam_max > 0 or not det / lam_max * max_cond >= lam_max:  # the smaller eigenvalue is det / lam_max
        return None
    return np.array([[r, -q], [-q, p]]) / det


def plane_members(fit: PlaneFit, pairs, left_segments, config: PlaneConfig = PlaneConfig()) -> np.ndarray:
    """Segment pairs that belong to a fitted planar region (Sec 2.4): boolean mask over ``pairs``.

    A pair belongs when at least ``member_min_fraction`` of its left segment's pixels lie in the region
    (dilated by ``member_dilate_px``: an edge pixel sits on the region's border; pixels outside the
    image count at the nearest border pixel), and its own disparity agrees with the plane's predicted
    disparity at its column within the 3σ gate.
    """
    out = np.zeros(len(pairs), dtype=bool)
    agree, box = _member_agree(fit, pairs, config)
    if len(agree) == 0:
        return out
    # every pixel of the agreeing pairs' left segments, segment after segment, tested against the region dilated
    # in the box (member_candidates' dilation) where it is read: each pixel's window in the undilated region
    seg = np.asarray(pairs.left_index)[agree].astype(np.int64)
    H, W = fit.region.shape
    frac = _member_fractions_near(seg, np.asarray(left_segments.pixel_offsets, np.int64), left_segments.pixel_uv,
                                  np.ascontiguousarray(fit.region), *box, max(0, config.member_dilate_px), H, W)
    out[agree] = frac >= config.member_min_fraction
    return out


def _member_agree(fit: PlaneFit, pairs, config: PlaneConfig) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """:func:`member_candidates` without the dilation: the agreeing pairs' indices and the box ``(v0, v1, c0, c1)``
    (half-open) its dilated region covers (empty indices: none agrees)."""
    if len(pairs) == 0:
        return np.zeros(0, dtype=np.int64), (0, 0, 0, 0)
    u0, u1 = fit.prediction.window
    d_pred, s_pred = fit.prediction.disparity_at(pairs.u_left)
    inside = (pairs.u_left >= u0 - 0.5) & (pairs.u_left <= u1 + 0.5)
    agree = np.flatnonzero(inside & (np.abs(pairs.disparity - d_pred) <= fit.prediction.gate * s_pred))
    if len(agree) == 0:
        return agree, (0, 0, 0, 0)
    H, W = fit.region.shape
    px = max(0, config.member_dilate_px)
    v0, v1, _ = fit.box[0].indices(H)
    c0, c1, _ = fit.box[1].indices(W)
    return agree, (max(0, v0 - px), min(H, v1 + px), max(0, c0 - px), min(W, c1 + px))


def member_candidates(fit: PlaneFit, pairs, config: PlaneConfig = PlaneConfig()
                      ) -> tuple[np.ndarray, np.ndarray | None, int, int]:
    """:func:`plane_members`' first steps: the indices of the pairs inside the plane's window whose disparity agrees
    with the prediction (3σ gate), and the region dilated by ``member_dilate_px`` within the fit's box grown by the
    dilation (it is empty elsewhere), with the box's first row and column. No pair agrees: ``(empty, None, 0, 0)``."""
    none = (np.zeros(0, dtype=np.int64), None, 0, 0)
    if len(pairs) == 0:
        return none
    u0, u1 = fit.prediction.window
    d_pred, s_pred = fit.prediction.disparity_at(pairs.u_left)
    inside = (pairs.u_left >= u0 - 0.5) & (pairs.u_left <= u1 + 0.5)
    agree = np.flatnonzero(inside & (np.abs(pairs.disparity - d_pred) <= fit.prediction.gate * s_pred))
    if len(agree) == 0:
        return none
    H, W = fit.region.shape
    px = max(0, config.member_dilate_px)
    v0, v1, _ = fit.box[0].indices(H)
    c0, c1, _ = fit.box[1].indices(W)
    v0, v1, c0, c1 = max(0, v0 - px), min(H, v1 + px), max(0, c0 - px), min(W, c1 + px)
    return agree, dilate(fit.region[v0:v1, c0:c1], px), v0, c0


@njit(cache=True)
def _member_fractions(seg, offsets, pixel_uv, region, c0, v0, H, W):  # pragma: no cover - numba
    """:func:`plane_members`' fraction (n,) of each segment ``seg[i]``'s pixels that lie in ``region`` (the dilated
    region's box, rows ``v0 …``, columns ``c0 …``): each pixel clipped to the image, outside the box not in it;
    0 for a segment without pixels. One pass over the pixels (what the array expressions computed: the counts
    are exact, the same division)."""
    h, w = region.shape
    frac = np.zeros(len(seg))
    for i in range(len(seg)):
        a, b = offsets[seg[i]], offsets[seg[i] + 1]
        if b <= a:
            continue
        n_in = 0.0
        for q in range(a, b):
            u = min(max(np.int64(pixel_uv[q, 0]), 0), W - 1) - c0
            v = min(max(np.int64(pixel_uv[q, 1]), 0), H - 1) - v0
            if u >= 0 and u < w and v >= 0 and v < h and region[v, u]:
                n_in += 1.0
        frac[i] = n_in / float(max(b - a, 1))
    return frac


@njit(cache=True)
def _member_fractions_near(seg, offsets, pixel_uv, region, v0, v1, c0, c1, px, H, W):  # pragma: no cover - numba
    """:func:`_member_fractions` of the region (H, W) dilated by a square of half-size ``px`` inside the box rows
    ``v0 … v1 − 1``, columns ``c0 … c1 − 1`` (:func:`member_candidates`' ``dilate`` of the box: cv2 dilates a box
    without what lies outside it), without making it: a pixel clipped to the image and inside the box is in the
    dilated region when a region pixel lies in its window clipped to the box (its own pixel looked at first). The
    same counts, the same division."""
    frac = np.zeros(len(seg))
    for i in range(len(seg)):
        a, b = offsets[seg[i]], offsets[seg[i] + 1]
        if b <= a:
            continue
        n_in = 0.0
        for q in range(a, b):
            u = min(max(np.int64(pixel_uv[q, 0]), 0), W - 1)
            v = min(max(np.int64(pixel_uv[q, 1]), 0), H - 1)
            if u < c0 or u >= c1 or v < v0 or v >= v1:
                continue
            hit = region[v, u]
            vv = max(v - px, v0)
            while not hit and vv < min(v + px + 1, v1):
                for uu in range(max(u - px, c0), min(u + px + 1, c1)):
                    if region[vv, uu]:
                        hit = True
                        break
                vv += 1
            if hit:
                n_in += 1.0
        frac[i] = n_in / float(max(b - a, 1))
    return frac


def dilate(region: np.ndarray, px: int) -> np.ndarray:
    """Binary dilation by a square of half-size ``px`` (a bool mask's bytes are 0 and 1: it is dilated as uint8 in
    place of a converted copy, and the 0 / 1 result read back as bool)."""
    if px <= 0:
        return region
    k = np.ones((2 * px + 1, 2 * px + 1), np.uint8)
    region = np.asarray(region)
    return cv2.dilate(region.view(np.uint8) if region.dtype == bool else region.astype(np.uint8), k).view(bool)
