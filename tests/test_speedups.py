"""The fast paths of plane fitting and boundary search against plain NumPy references of the same rules."""

import numpy as np
import pytest

from stablemarks.geometry import StereoCamera
from stablemarks.landmarks import right_region
from stablemarks.maps import ReferencePlane
from stablemarks.planes import PlaneConfig, fit_plane, median, plane_members, predict_plane
from stablemarks.vision.segments import Segments

from .test_planes import synthetic_disparity

CAM = StereoCamera(mount_x=0.1, mount_height=1.0)
X0 = np.array([0.0, 0.0, np.pi / 2])
COV0 = np.diag([0.03, 0.03, np.deg2rad(1.0)]) ** 2
WALL = ReferencePlane("w", (-1.0, 4.0), (1.5, 4.4), free_edges=("p1", "p2"), z=(0.0, 1.8))


def noisy_disparity(rng, noise=0.3, holes=0.2):
    disp = synthetic_disparity(CAM, X0, [WALL], noise, rng)
    disp[rng.random(disp.shape) < holes] = np.nan
    disp[rng.random(disp.shape) < 0.02] = 0.0
    return disp


def reference_band(pred, disparity, row_margin):
    """The band as a full-image NumPy expression (Sec 2.3.4)."""
    H, W = disparity.shape
    mask = np.zeros((H, W), dtype=bool)
    u0, u1 = pred.window
    sub = disparity[:, u0 : u1 + 1]
    with np.errstate(invalid="ignore"):
        ok = (np.abs(sub - pred.d[None, :]) <= pred.gate * pred.sigma_d[None, :]) & (sub > 0)
    rows = np.arange(H)[:, None]
    ok &= (rows >= pred.v_top[None, :] - row_margin) & (rows <= pred.v_bottom[None, :] + row_margin)
    mask[:, u0 : u1 + 1] = ok
    return mask


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_band_matches_the_full_image_expression(seed):
    rng = np.random.default_rng(seed)
    X = X0 + np.array([0.0, 0.0, rng.uniform(-0.2, 0.2)])
    pred = predict_plane(CAM, X, COV0, WALL)
    disp = noisy_disparity(rng)
    for margin in (0.0, 4.0, 300.0):
        np.testing.assert_array_equal(pred.band(disp, margin), reference_band(pred, disp, margin))


def reference_fit(pred, disparity, config):
    """Eq 11 on every band pixel converted to the world, then the same robust rounds (NumPy, per pixel)."""
    band = reference_band(pred, disparity, config.row_margin_px)
    vs, us = np.nonzero(band)
    sub = np.flatnonzero((vs % 2 == 0) & (us % 2 == 0))
    d = disparity[vs, us].astype(float)
    fb = CAM.f * CAM.baseline
    Z = fb / d
    P = CAM.from_camera(X0, (us - CAM.cu) * Z / CAM.f, Z)
    cam = CAM.camera_pose(X0)
    w = np.array([np.cos(cam.theta), np.sin(cam.theta)]) + ((us - CAM.cu) / CAM.f)[:, None] * np.array(
        [np.sin(cam.theta), -np.cos(cam.theta)])
    s_all, o_all = WALL.along(P), WALL.offset(P)
    sigma_all = np.abs(w @ WALL.normal) * (Z**2 / fb * config.sigma_nu(CAM)) + 1e-6
    s, o, sig = s_all[sub], o_all[sub], sigma_all[sub]
    inl = np.ones(len(s), dtype=bool)
    a, b, s0 = np.median(o), 0.0, np.median(s)
    for _ in range(4):
        r = (o - a - b * (s - s0)) / sig
        scale = max(1e-3, 1.4826 * np.median(np.abs(r[inl])))
        inl = np.abs(r) <= config.outlier_sigma * scale
        wgt = 1.0 / sig[inl] ** 2
        s0 = np.sum(wgt * s[inl]) / np.sum(wgt)
        A = np.stack([np.ones(inl.sum()), s[inl] - s0], axis=1)
        N = A.T @ (A * wgt[:, None])
        a, b = np.linalg.solve(N, A.T @ (wgt * o[inl]))
    keep = np.abs((o_all - a - b * (s_all - s0)) / sigma_all) <= config.outlier_sigma * scale
    region = np.zeros_like(band)
    region[vs[keep], us[keep]] = True
    return a, b, s0, region


@pytest.mark.parametrize("seed", [0, 1])
def test_fit_matches_the_per_pixel_reference(seed):
    rng = np.random.default_rng(seed)
    config = PlaneConfig()
    pred = predict_plane(CAM, X0, COV0, WALL, config)
    disp = noisy_disparity(rng)
    # clutter in front of part of the wall
    disp[200:260, 300:340] += 6.0
    fit = fit_plane(CAM, X0, disp, pred, config)
    a, b, s0, region = reference_fit(pred, disp, config)
    assert fit
    np.testing.assert_allclose([fit.a, fit.b, fit.s0], [a, b, s0], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fit.region, region)
    rows, cols = fit.box
    outside = fit.region.copy()
    outside[rows, cols] = False
    assert not outside.any()


def reference_right_region(pred, disparity_right, row_margin, c0, c1):
    """The right image's band with one np.interp per quantity."""
    H, W = disparity_right.shape
    out = np.zeros((H, W), dtype=bool)
    v0 = max(0, int(np.floor(pred.v_top.min() - row_margin)))
    v1 = min(H - 1, int(np.ceil(pred.v_bottom.max() + row_margin)))
    sub = disparity_right[v0 : v1 + 1, c0 : c1 + 1]
    u_left = np.arange(c0, c1 + 1, dtype=float)[None, :] + sub
    with np.errstate(invalid="ignore"):
        d_pred = np.interp(u_left, pred.columns, pred.d, left=np.nan, right=np.nan)
        s_pred = np.interp(u_left, pred.columns, pred.sigma_d, left=np.nan, right=np.nan)
        ok = np.abs(sub - d_pred) <= pred.gate * s_pred
        vt = np.interp(u_left, pred.columns, pred.v_top)
        vb = np.interp(u_left, pred.columns, pred.v_bottom)
    rows = np.arange(v0, v1 + 1, dtype=float)[:, None]
    out[v0 : v1 + 1, c0 : c1 + 1] = ok & (rows >= vt - row_margin) & (rows <= vb + row_margin)
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_right_region_matches_np_interp(seed):
    rng = np.random.default_rng(seed)
    pred = predict_plane(CAM, X0, COV0, WALL)
    H, W = CAM.height, CAM.width
    d_mid = float(np.median(pred.d))
    disp_r = (d_mid + rng.normal(0.0, 3.0, (H, W))).astype(np.float32)
    disp_r[rng.random((H, W)) < 0.1] = np.nan
    # right pixels landing exactly on window columns, and on its last column
    cols = np.arange(W)
    disp_r[100, :] = (pred.columns[-1] - cols).astype(np.float32)
    disp_r[101, :] = np.round(disp_r[101, :])
    for c0, c1 in ((0, W - 1), (150, 260), (pred.columns[0] - 40, pred.columns[0] + 10)):
        got = right_region(pred, disp_r, 4.0, (c0, c1))
        np.testing.assert_array_equal(got, reference_right_region(pred, disp_r, 4.0, max(0, c0), min(W - 1, c1)))


def test_members_match_the_per_segment_rule():
    rng = np.random.default_rng(3)
    config = PlaneConfig()
    pred = predict_plane(CAM, X0, COV0, WALL, config)
    fit = fit_plane(CAM, X0, noisy_disparity(rng), pred, config)
    assert fit
    # vertical segments across the image, some reaching outside it, one without pixels
    n = 60
    u = rng.uniform(-5, CAM.width + 5, n)
    v_top = rng.uniform(-10, 300, n)
    v_bottom = v_top + rng.uniform(5, 200, n)
    pix = [np.stack([np.full(int(b) - int(t), int(c)), np.arange(int(t), int(b))], -1)
           for c, t, b in zip(u, v_top, v_bottom, strict=True)]
    pix[7] = np.zeros((0, 2), int)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in pix])]).astype(np.int64)
    segs = Segments(u=u, slope=np.zeros(n), v_top=v_top, v_bottom=v_bottom, polarity=np.ones(n, np.int8),
                    contrast=np.ones(n), n_pixels=np.diff(offsets), pixel_offsets=offsets,
                    pixel_uv=np.concatenate(pix).astype(np.int32))

    class Pairs:
        u_left = u
        disparity = np.interp(u, pred.columns, pred.d) + rng.normal(0, 0.5, n)
        left_index = np.arange(n)

        def __len__(self):
            return n

    got = plane_members(fit, Pairs(), segs, config)
    region = cv2_free_dilate(fit.region, config.member_dilate_px)
    d_pred, s_pred = pred.disparity_at(u)
    agree = ((u >= pred.window[0] - 0.5) & (u <= pred.window[1] + 0.5)
             & (np.abs(Pairs.disparity - d_pred) <= pred.gate * s_pred))
    want = np.zeros(n, dtype=bool)
    for k in np.flatnonzero(agree):
        p = pix[k]
        if len(p):
            vv = np.clip(p[:, 1], 0, CAM.height - 1)
            uu = np.clip(p[:, 0], 0, CAM.width - 1)
            want[k] = region[vv, uu].mean() >= config.member_min_fraction
    assert agree.sum() > 5 and want.any()
    np.testing.assert_array_equal(got, want)


def cv2_free_dilate(region, px):
    """Binary dilation by a (2 px + 1)² square with shifted ORs."""
    H, W = region.shape
    pad = np.pad(region, px)
    out = np.zeros_like(region)
    for dv in range(2 * px + 1):
        for du in range(2 * px + 1):
            out |= pad[dv : dv + H, du : du + W]
    return out


def test_median_is_numpys():
    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 10, 11, 1000):
        x = rng.normal(size=n)
        assert median(x) == np.median(x)
