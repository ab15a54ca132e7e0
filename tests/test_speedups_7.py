"""Issue 13, the per-frame pipeline faster (seventh pass): every replaced computation against the former
implementation (kept here as the reference) on frames of several simulated scenarios and on random inputs — the
same values, bit for bit."""

from __future__ import annotations

from dataclasses import FrozenInstanceError

import cv2
import numpy as np
import pytest
from numba import njit

from stablemarks import landmarks as L
from stablemarks import pipeline
from stablemarks import planes as P
from stablemarks.config import Config
from stablemarks.geometry import StereoCamera
from stablemarks.maps import ray_distances
from stablemarks.vision import area_stereo as A

from .conftest import COV_PRIOR
from .helpers import assert_same_candidate, boundary_model_inputs, disparity_variants


# ------------------------------------------------------------------ the SAD kernel's choice of the dense plan
def test_regions_with_overlapping_runs_equal_the_dense_images():
    """The kernel takes the dense plan for a row from the lanes its own plan needs (overlapping left and right runs
    counted once): rows whose left plane window and right search windows overlap, and scattered bands, now take the
    planned path. Whatever the plan, the requested pixels hold the dense values bit for bit."""
    rng = np.random.default_rng(5)
    H, W = 120, 320
    base = cv2.GaussianBlur(rng.uniform(0, 255, (H, W + 60)), (0, 0), 1.5)
    base = np.clip((base - base.mean()) * 4 + 128, 0, 255)
    left = np.ascontiguousarray(base[:, 40:W + 40]).astype(np.uint8)
    right = base[:, 52:W + 52] + rng.normal(0, 1.0, (H, W))  # a disparity of 12 px, with noise
    right = np.clip(right, 0, 255).astype(np.uint8)
    config = A.SADConfig(num_disparities=32)
    dense = A.compute_disparity(left, right, config)
    cases = [
        # a left window with right windows inside its disparity band (the lab's plane rows)
        (np.array([[10, 100, 150, 260]]), np.array([[8, 102, 140, 180], [8, 102, 230, 270]])),
        # narrow bands starting and ending on different rows, and a right window across them
        (np.array([[5, 60, 40, 52], [20, 90, 70, 82], [30, 110, 100, 112], [50, 115, 200, 215]]),
         np.array([[15, 80, 60, 100]])),
        # the same left window with and without the right windows, a mask
        (rng.random((H, W)) < 0.05, rng.random((H, W)) < 0.02),
    ]
    n = 0
    for lr, rr in cases:
        res = A.compute_disparity_regions(left, right, config, lr, rr)
        for got, want, mask in ((res.left, dense.left, A._runs_mask(*A._region_runs(lr, (H, W), "l"), (H, W))),
                                (res.right, dense.right, A._runs_mask(*A._region_runs(rr, (H, W), "r"), (H, W)))):
            assert np.array_equal(got[mask], want[mask], equal_nan=True)
            assert np.isnan(got[~mask]).all()
            n += int(np.isfinite(got[mask]).sum())
        lmask = A._runs_mask(*A._region_runs(lr, (H, W), "l"), (H, W))
        assert np.array_equal(res.valid[lmask], dense.valid[lmask])
    assert n > 1000


def test_lab_regions_equal_the_dense_images(scenario_frames, scenario_models):
    """The front end's regions of every scenario frame (plane windows, right search windows, pair bands) with what
    the landmark stage added: the dense values bit for bit wherever computed."""
    config = Config()
    n = 0
    for frame, (_, _, front, _) in zip(scenario_frames, scenario_models, strict=True):
        if front.lazy is None:
            continue
        dense = A.compute_disparity(frame[2], frame[3], config.sad)
        for got, want, done in ((front.disparity.left, dense.left, front.lazy.done[0]),
                                (front.disparity.right, dense.right, front.lazy.done[1])):
            assert np.array_equal(got[done], want[done], equal_nan=True)
            n += int(done.sum())
        assert np.array_equal(front.disparity.valid[front.lazy.done[0]], dense.valid[front.lazy.done[0]])
    assert n > 100_000


# ------------------------------------------------------------------ one point projected
def test_project_one_point_equals_the_array_path():
    """:meth:`StereoCamera.project_columns` of one point (2,) on Python floats against the general (array) path it
    takes for (1, 2): the same columns bit for bit, NaN behind the camera."""
    rng = np.random.default_rng(3)
    n_nan = 0
    for _ in range(3000):
        cam = StereoCamera(f=float(rng.uniform(200, 900)), cu=float(rng.uniform(100, 500)),
                           baseline=float(rng.uniform(0.05, 0.5)), mount_x=float(rng.normal(0, 0.2)),
                           mount_y=float(rng.normal(0, 0.2)), pan=float(rng.uniform(-1, 1)))
        X = np.array([rng.normal(0, 3), rng.normal(0, 3), rng.uniform(-np.pi, np.pi)])
        p = rng.normal(0, 5, 2)
        got = cam.project_columns(X, p)
        want = cam.project_columns(X, p[None])[0]
        assert got.shape == (2,) and got.dtype == np.float64
        assert np.array_equal(got, want, equal_nan=True)
        n_nan += bool(np.isnan(got).any())
    assert n_nan > 100


# ------------------------------------------------------------------ the seen wall's Jacobian
def seen_wall_jacobian_reference(camera, fit):
    """The former :func:`~stablemarks.landmarks.seen_wall_jacobian`, on NumPy arrays."""
    plane, X = fit.plane, np.asarray(fit.X, dtype=float)
    P = plane.point_at(np.array([fit.s0 - 1.0, fit.s0 + 1.0]))
    c0 = camera.camera_pose(X)
    d = P - c0.translation
    cs, sn = np.cos(c0.theta), np.sin(c0.theta)
    q = np.stack([cs * d[:, 0] + sn * d[:, 1], -sn * d[:, 0] + cs * d[:, 1]], axis=-1)  # camera frame

    def seen(Xp):
        c1 = camera.camera_pose(Xp)
        c, s_ = np.cos(c1.theta), np.sin(c1.theta)
        Q = c1.translation + np.stack([c * q[:, 0] - s_ * q[:, 1], s_ * q[:, 0] + c * q[:, 1]], axis=-1)
        o, t = plane.offset(Q), plane.along(Q)
        b = (o[1] - o[0]) / (t[1] - t[0])
        return np.array([o[0] + b * (fit.s0 - t[0]), b])

    J = np.empty((2, 3))
    for i, h in enumerate((1e-4, 1e-4, 1e-5)):
        e = np.zeros(3)
        e[i] = h
        J[:, i] = (seen(X + e) - seen(X - e)) / (2 * h)
    return J


def test_seen_wall_jacobian_equals_the_reference(scenario_frames, scenario_models):
    """Every fitted wall of every scenario frame, and the same walls seen from perturbed poses: the same Jacobian
    (to 1e-9 of its size: the wall frame's two-term dot products may round differently from NumPy's), and the same
    :func:`~stablemarks.landmarks.fit_disagreements`."""
    config = Config()
    rng = np.random.default_rng(11)
    n = n_same = 0
    for frame, (_, _, _, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for fit in model.fits:
            if not fit:
                continue
            for X in [fit.X] + [fit.X + rng.normal(0, [0.1, 0.1, 0.05]) for _ in range(5)]:
                f = L.replace(fit, X=X)
                got, want = L.seen_wall_jacobian(camera, f), seen_wall_jacobian_reference(camera, f)
                assert np.allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())
                n_same += bool(np.array_equal(got, want))
                n += 1
                m2, slope = L.fit_disagreements(camera, f, COV_PRIOR)
                J = want
                S = J @ COV_PRIOR @ J.T + f.cov_R
                r = np.array([f.a, f.b])
                assert np.isclose(m2, float(r @ np.linalg.solve(S, r)), rtol=1e-9)
                assert np.isclose(slope, float(f.b**2 / S[1, 1]), rtol=1e-9)
    assert n > 30 and n_same > n // 2


# ------------------------------------------------------------------ the plane fit's per-pixel loops
@njit(cache=False)
def on_line_reference(disp, band, r_s, r_o, c_s, c_o, fb, sigma_nu, a, b, s0, limit):
    """The former :func:`~stablemarks.planes._on_line`: the test only where the band holds."""
    h, K = disp.shape
    keep = np.zeros((h, K), dtype=np.bool_)
    for i in range(h):
        for k in range(K):
            if band[i, k]:
                Z = fb / float(disp[i, k])
                s = c_s + Z * r_s[k]
                o = c_o + Z * r_o[k]
                keep[i, k] = abs((o - a - b * (s - s0)) / (abs(r_o[k]) * (Z * Z / fb * sigma_nu) + 1e-6)) <= limit
    return keep


def fit_plane_reference(camera, X, disparity, prediction, config):
    """The former :func:`~stablemarks.planes.fit_plane` (``test_speedups_13.former_fit_plane``, which takes its
    kernels from the module) with its final classification as the branching loop it was (:func:`on_line_reference`)
    and the band from :meth:`PlanePrediction.band_box` (on a view of the box, not a contiguous copy). The library's
    fit no longer calls ``_on_line`` or ``_band`` itself, so patching them there would compare it with itself."""
    from .test_speedups_13 import former_fit_plane

    fast_on_line, fast_band = P._on_line, P._band

    def band_of_view(disp, v0, *args):  # PlanePrediction.band_box: the band of a view of the box
        assert disp.flags.c_contiguous and not np.shares_memory(disp, disparity)
        rows, cols = prediction.box(disparity.shape[0], config.row_margin_px)
        assert rows.start == v0
        return fast_band(disparity[rows, cols], v0, *args)

    P._on_line, P._band = on_line_reference, band_of_view
    try:
        return former_fit_plane(camera, X, disparity, prediction, config)
    finally:
        P._on_line, P._band = fast_on_line, fast_band


def test_fit_plane_equals_the_reference(scenario_frames, scenario_models):
    """Every predicted plane of every frame, on its disparity image, cluttered and thinned: the same fit bit for bit
    (the region of inliers, the line, its covariance) or the same failure."""
    rng = np.random.default_rng(17)
    config = Config()
    n_fits = 0
    for frame, (_, _, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for pred in model.predictions:
            disp = np.array(front.disparity.left)
            for d in disparity_variants(disp, rng):
                new = P.fit_plane(camera, model.X, d, pred, config.planes)
                ref = fit_plane_reference(camera, model.X, d, pred, config.planes)
                assert type(new) is type(ref)
                if not new:
                    assert (new.reason, new.n_pixels) == (ref.reason, ref.n_pixels)
                    continue
                for name in ("a", "b", "s0", "n_points", "n_inliers", "chi2_dof"):
                    assert getattr(new, name) == getattr(ref, name), name
                assert np.array_equal(new.cov_R, ref.cov_R) and np.array_equal(new.region, ref.region)
                n_fits += 1
    assert n_fits > 20


def test_on_line_equals_the_reference_on_random_boxes():
    """:func:`~stablemarks.planes._on_line` against the branching loop on random boxes with NaN, zero and negative
    disparities outside the band (which holds positive ones only, as :func:`~stablemarks.planes._band` makes it), on
    contiguous boxes and on views."""
    rng = np.random.default_rng(19)
    for _ in range(200):
        h, K = (int(v) for v in rng.integers(1, 40, 2))
        disp = rng.uniform(-2, 40, (h + 3, K + 5)).astype(np.float32)
        disp[rng.random(disp.shape) < 0.2] = np.nan
        disp[rng.random(disp.shape) < 0.05] = 0.0
        view = disp[1 : h + 1, 2 : K + 2]
        band = (rng.random((h, K)) < 0.7) & (view > 0)  # as _band: finite positive disparities only
        args = (rng.normal(0, 1, K), rng.normal(0, 1, K), float(rng.normal()), float(rng.normal()), 60.0, 0.2,
                float(rng.normal(0, 0.05)), float(rng.normal(0, 0.05)), float(rng.normal()), float(rng.uniform(0.5, 5)))
        for d in (view, np.ascontiguousarray(view)):
            assert np.array_equal(P._on_line(d, band, *args), on_line_reference(d, band, *args))


# ------------------------------------------------------------------ the pair bands the disparity filter reads
def pair_bands_reference(pairs, left_segments, search_radius):
    """The former :func:`~stablemarks.pipeline.pair_bands`: the pairs' segments copied out
    (:meth:`Segments.subset`), their boxes by ``reduceat``."""
    if not len(pairs):
        return np.zeros((0, 4), np.int64)
    own = left_segments.subset(np.unique(pairs.left_index))
    counts = np.diff(own.pixel_offsets)
    own_pix = own.pixel_uv.astype(np.int64)
    starts = own.pixel_offsets[:-1][counts > 0]
    if not len(starts):
        return np.zeros((0, 4), np.int64)
    u, v = own_pix[:, 0], own_pix[:, 1]
    return np.stack([np.minimum.reduceat(v, starts), np.maximum.reduceat(v, starts) + 1,
                     np.minimum.reduceat(u, starts) - search_radius,
                     np.maximum.reduceat(u, starts) + search_radius + 1], axis=1)


def test_pair_bands_equal_the_reference(scenario_models):
    """Every scenario frame's pairs, all of them, the kept ones, random subsets with repeated segments and none: the
    same rectangles in the same order, int64."""
    rng = np.random.default_rng(23)
    n = 0
    for _, _, front, _ in scenario_models:
        seg = front.left_segments
        for pairs in (front.pairs, front.kept_pairs, front.pairs.subset(rng.random(len(front.pairs)) < 0.3),
                      front.pairs.subset(np.zeros(len(front.pairs), bool))):
            for radius in (0, 7):
                got = pipeline.pair_bands(pairs, seg, radius)
                want = pair_bands_reference(pairs, seg, radius)
                assert got.dtype == want.dtype == np.int64 and np.array_equal(got, want)
                n += len(got)
    assert n > 100


# ------------------------------------------------------------------ a point inside the wall, projected
def inner_columns_reference(camera, X, plane, edge, depth=0.3):
    """The former :func:`~stablemarks.landmarks._inner_columns`: :meth:`ReferencePlane.point_at` of a (1,) array."""
    inner = plane.point_at(np.array([min(depth, 0.5 * plane.length)]), edge)[0]
    return camera.project_columns(X, inner)


def test_inner_columns_equal_the_reference(scenario_frames):
    """Both ends of every wall of every scenario map, from every frame's pose and perturbed ones, at several depths
    (short walls: half the wall): the same columns bit for bit."""
    config = Config()
    rng = np.random.default_rng(29)
    n = 0
    for frame in scenario_frames:
        camera = config.camera(frame[4])
        for X in [frame[6]] + [frame[6] + rng.normal(0, [0.5, 0.5, 0.3]) for _ in range(3)]:
            for plane in frame[5]:
                for edge in ("p1", "p2"):
                    for depth in (0.1, 0.3, 5.0):
                        got = L._inner_columns(camera, X, plane, edge, depth)
                        assert np.array_equal(got, inner_columns_reference(camera, X, plane, edge, depth),
                                              equal_nan=True)
                        n += 1
    assert n > 500


# ------------------------------------------------------------------ candidates made without the dataclass __init__
def model_features_reference(*args, **kwargs):
    """The former :func:`~stablemarks.landmarks.model_features`: its candidates made by ``Candidate(**fields)``."""
    fast = L._new_candidate
    L._new_candidate = lambda values: L.Candidate(**values)
    try:
        return L.model_features(*args, **kwargs)
    finally:
        L._new_candidate = fast


def test_model_features_equal_the_reference(scenario_frames, scenario_models):
    """The candidates of every plane of every scenario frame from each of its boundaries: the same fields, values and
    order, as made by the dataclass; and the selection and the frozen dataclass's behaviour on them."""
    config = Config()
    n = 0
    for camera, plane, b, pairs, idx, step in boundary_model_inputs(scenario_frames, scenario_models, config):
        got = L.model_features(camera, plane.fit, b, pairs, idx, step, config.landmarks)
        want = model_features_reference(camera, plane.fit, b, pairs, idx, step, config.landmarks)
        assert len(got) == len(want)
        for a, c in zip(got, want, strict=True):
            assert_same_candidate(a, c)
            assert repr(a) == repr(c)
        for a, c in zip(L.select(got, plane.boundaries, config.landmarks),
                        L.select(want, plane.boundaries, config.landmarks), strict=True):
            assert_same_candidate(a, c)
        n += len(got)
    assert n > 20
    c = got[0]
    with pytest.raises(FrozenInstanceError):
        c.s = 1.0
    with pytest.raises(TypeError):
        L._new_candidate({"s": 1.0})


# ------------------------------------------------------------------ the prepared pair, written once
@njit(cache=False)
def prepare_reference(image8, sobel, cap, pad_l, pad_r, texture):
    """The former :func:`~stablemarks.vision.area_stereo._prepare`: zeroed arrays, then the image written into them."""
    n_rows, n_cols = image8.shape
    width = pad_l + n_cols + pad_r
    out = np.zeros((n_rows, width), np.int16)
    asat = np.zeros((n_rows, n_cols) if texture else (1, 1), np.uint8)
    lo, hi = np.int16(-cap), np.int16(cap)
    for y in range(n_rows):
        for x in range(n_cols):
            if cap > 0:
                out[y, pad_l + x] = min(max(sobel[y, x], lo), hi) + hi
            else:
                out[y, pad_l + x] = image8[y, x]
            if texture:
                asat[y, x] = min(abs(np.int32(sobel[y, x])), 255)
    return out, asat


def test_prepare_equals_the_reference():
    """Random images (and their x-Sobel), every padding, prefilter on and off, with and without the texture image:
    the same arrays, padding zero."""
    rng = np.random.default_rng(31)
    for _ in range(60):
        H, W = (int(v) for v in rng.integers(1, 50, 2))
        img = rng.integers(0, 256, (H, W)).astype(np.uint8)
        sob = A._xsobel(img) if min(H, W) > 1 else rng.integers(-1020, 1021, (H, W)).astype(np.int16)
        for cap in (0, 1, 5, 63):
            for pad_l, pad_r in ((0, 0), (63, 0), (0, 7), (31, 5)):
                for texture in (False, True):
                    got = A._prepare(img, sob, cap, pad_l, pad_r, texture)
                    want = prepare_reference(img, sob, cap, pad_l, pad_r, texture)
                    for x, y in zip(got, want, strict=True):
                        assert x.dtype == y.dtype and np.array_equal(x, y)


# ------------------------------------------------------------------ the columns holding a computed disparity
def found_reference(lazy, image):
    """The former :meth:`~stablemarks.pipeline.RegionDisparity.found`: over the whole image."""
    cols = np.flatnonzero((lazy._valid if image == 0 else np.isfinite(lazy._images[1])).any(axis=0))
    return (float(cols[0]), float(cols[-1])) if len(cols) else (np.inf, -np.inf)


def test_found_equals_the_reference(scenario_frames):
    """Region disparities of every scenario frame, from rectangles, from masks and from nothing, then grown by
    compute() with masks and by valid_columns(): found() of both images equals the whole image's scan each time."""
    config = Config()
    rng = np.random.default_rng(37)
    n = 0
    for frame in scenario_frames[::2]:
        left8, right8 = frame[2], frame[3]
        H, W = left8.shape
        rects = np.array([[100, 300, 200, 400], [50, 60, -10, 700], [400, 380, 10, 20]])
        for lr, rr in ((rects, rects[:1]), (rng.random((H, W)) < 0.01, None), (None, None)):
            lazy = pipeline.RegionDisparity(left8, right8, config.sad, lr, rr)
            steps = [lambda lz: None, lambda lz, s=(H, W): lz.compute(rng.random(s) < 0.002, rng.random(s) < 0.002),
                     lambda lz: lz.valid_columns()]
            for step in steps:
                step(lazy)
                for image in (0, 1):
                    assert lazy.found(image) == found_reference(lazy, image)
                    n += np.isfinite(lazy.found(image)[0])
    assert n > 10


# ------------------------------------------------------------------ the front end's runs made once
def front_disparity_reference(left, right, config, regions, pairs, left_segments, sobel=None):
    """The former :func:`~stablemarks.pipeline.front_disparity`: the decision by :func:`region_work` of the
    rectangles, then the region disparity from the rectangles (their runs and planning runs made again)."""
    if regions is None or config.sad.backend != "numba":
        return A.compute_disparity(left, right, config.sad, sobel=sobel), None
    want_l = np.concatenate([np.asarray(regions.left, np.int64).reshape(-1, 4),
                             pipeline.pair_bands(pairs, left_segments, config.filter.search_radius)])
    want_r = np.asarray(regions.right, np.int64).reshape(-1, 4)
    if pipeline.region_work(want_l, want_r, config.sad, np.shape(left)) >= pipeline.DENSE_ABOVE:
        return A.compute_disparity(left, right, config.sad, sobel=sobel), None
    lazy = pipeline.RegionDisparity(left, right, config.sad, want_l, want_r, sobel=sobel)
    return lazy.result, lazy


def test_front_disparity_equals_the_reference(scenario_frames, scenario_models):
    """Every scenario frame with its regions, with none and with the whole image asked for: the same decision
    (regions or dense), the same images bit for bit, the same pixels computed."""
    config = Config()
    n_lazy = 0
    for frame, (_, _, front, _) in zip(scenario_frames, scenario_models, strict=True):
        left, right = frame[2], frame[3]
        H, W = left.shape
        everything = pipeline.Regions(np.array([[0, H, 0, W]]), np.array([[0, H, 0, W]]))
        for regions in (front.regions, pipeline.Regions.none(), everything):
            got, lazy = pipeline.front_disparity(left, right, config, regions, front.pairs, front.left_segments)
            want, ref = front_disparity_reference(left, right, config, regions, front.pairs, front.left_segments)
            assert (lazy is None) == (ref is None)
            for x, y in ((got.left, want.left), (got.right, want.right), (got.valid, want.valid)):
                assert np.array_equal(x, y, equal_nan=True)
            if lazy is not None:
                assert all(np.array_equal(a, b) for a, b in zip(lazy.done, ref.done, strict=True))
                assert lazy._box == ref._box
                assert lazy.found(0) == ref.found(0) and lazy.found(1) == ref.found(1)
                n_lazy += 1
    assert n_lazy >= 8


# ------------------------------------------------------------------ the depth step beyond an edge
def edge_depth_step_reference(camera, X, world_map, plane, edge, offset_px):
    """The former :func:`~stablemarks.landmarks.edge_depth_step`: the edge's depth and the ray past it from
    ``to_camera`` and ``column_ray``."""
    P = plane.edge(edge)
    u_e = float(camera.project_columns(X, P)[0])
    u_i = float(L._inner_columns(camera, X, plane, edge)[0])
    if not np.isfinite(u_e + u_i):
        return 0.0
    u_out = u_e + np.sign(u_e - u_i) * offset_px
    fb = camera.f * camera.baseline
    _, Z_e = camera.to_camera(X, P)
    ray = camera.column_ray(X, u_out)
    walls, exclude = L._other_walls(world_map, plane)
    dist = ray_distances(camera.optical_centres(X)[0], ray, walls, exclude=exclude)[0]
    cam = camera.camera_pose(X)
    Z_bg = dist * (ray @ np.array([np.cos(cam.theta), np.sin(cam.theta)]))
    return float((fb / Z_bg if np.isfinite(Z_bg) and Z_bg > 0 else 0.0) - fb / Z_e)


def test_edge_depth_step_equals_the_reference(scenario_frames):
    """Both ends of every wall of every scenario map, from every frame's pose and perturbed ones, two offsets: the
    same step bit for bit (open space, a nearer wall, an edge behind the camera)."""
    config = Config()
    rng = np.random.default_rng(41)
    n = n_open = 0
    for frame in scenario_frames:
        camera = config.camera(frame[4])
        for X in [frame[6]] + [frame[6] + rng.normal(0, [0.5, 0.5, 0.3]) for _ in range(3)]:
            for plane in frame[5]:
                for edge in ("p1", "p2"):
                    for offset in (8.5, 20.0):
                        got = L.edge_depth_step(camera, X, frame[5], plane, edge, offset)
                        want = edge_depth_step_reference(camera, X, frame[5], plane, edge, offset)
                        assert type(got) is float and got == want
                        n += got != 0.0
                        n_open += got < 0
    assert n > 200 and n_open > 20


# ------------------------------------------------------------------ the boundary search's row ends, read in place
@njit(cache=False)
def row_ends_reference(region, c0, c1, outward, max_hole):
    """The former ``stablemarks.landmarks._row_ends``, the walk of :func:`_boundary_columns` on the window of
    columns ``c0…c1`` of ``region`` (H, W), as :func:`~stablemarks.landmarks._block_row_ends` describes it with
    the region its own block."""
    H = region.shape[0]
    n = c1 - c0 + 1
    first = c1 if outward < 0 else c0  # the image column of position j from the inner side: first + step·j
    step = -1 if outward < 0 else 1
    rows = np.empty(H, dtype=np.int64)
    cols = np.empty(H, dtype=np.float64)
    k = 0
    for i in range(H):
        row = region[i]
        start = n
        for j in range(n):
            if row[first + step * j]:
                start = j
                break
        last = -1  # the run's last pixel, once a hole not crossed ends it
        j = start + 1
        while j < n:
            if row[first + step * j]:
                j += 1
                continue
            q = j + 1  # the next region pixel after the hole that starts at j
            while q < n and not row[first + step * q]:
                q += 1
            if q < n and q - j <= max_hole:
                j = q
            else:
                last = j - 1
                break
        if last >= 0:
            rows[k] = i
            cols[k] = float(first + step * last)
            k += 1
    return rows[:k].copy(), cols[:k].copy()


def block_boundary_columns_reference(block, v0, u0, W, lo, hi, outward, max_hole=2):
    """The former :func:`~stablemarks.landmarks._block_boundary_columns`: the window's columns copied out of the
    block (False off it), then the former ``_row_ends`` (:func:`row_ends_reference`)."""
    import math

    c0 = math.floor(min(max(lo, 0), W - 1))
    c1 = math.ceil(min(max(hi, 0), W - 1))
    if c1 < c0:
        return np.zeros(0, int), np.zeros(0)
    h, w = block.shape
    window = np.zeros((h, c1 - c0 + 1), dtype=np.bool_)
    a, b = max(c0, u0), min(c1, u0 + w - 1)
    if b >= a:
        window[:, a - c0 : b - c0 + 1] = block[:, a - u0 : b - u0 + 1]
    rows, cols = row_ends_reference(window, 0, c1 - c0, int(outward), int(max_hole))
    return rows + v0, cols + c0


def test_block_boundary_columns_equal_the_reference(scenario_models):
    """Random blocks with holes, and every fitted region of the scenario frames, through windows inside, across and
    outside the block, both ways, holes of 0 to 8 px bridged: the same rows and columns, bit for bit."""
    rng = np.random.default_rng(43)
    blocks = []
    for _ in range(40):
        h, w = (int(v) for v in rng.integers(1, 30, 2))
        blk = rng.random((h, w)) < rng.uniform(0.3, 0.95)
        blocks.append((blk, int(rng.integers(0, 50)), int(rng.integers(0, 100)), 200))
    for _, _, _, model in scenario_models:
        for fit in model.fits:
            if fit:
                H, W = fit.region.shape
                v0, v1, _ = fit.box[0].indices(H)
                blocks.append((fit.region[v0:max(v0, v1)], v0, 0, W))
    n = 0
    for blk, v0, u0, W in blocks:
        for _ in range(15):
            lo = float(rng.uniform(-20, W + 20))
            hi = lo + float(rng.uniform(-5, 80))
            for outward in (-1, 1):
                hole = int(rng.integers(0, 9))
                got = L._block_boundary_columns(blk, v0, u0, W, lo, hi, outward, hole)
                want = block_boundary_columns_reference(blk, v0, u0, W, lo, hi, outward, hole)
                for x, y in zip(got, want, strict=True):
                    assert x.dtype == y.dtype and np.array_equal(x, y)
                n += len(got[0])
    assert n > 1000


# ------------------------------------------------------------------ plane members counted in one pass
def plane_members_reference(fit, pairs, left_segments, config):
    """The former :func:`~stablemarks.planes.plane_members`: the agreeing pairs' pixels gathered by ``np.repeat``,
    their hits counted by ``np.bincount`` (the gate and the dilated region are the production's, unchanged)."""
    out = np.zeros(len(pairs), dtype=bool)
    agree, region, v0, c0 = P.member_candidates(fit, pairs, config)
    if len(agree) == 0:
        return out
    H, W = fit.region.shape
    seg = np.asarray(pairs.left_index)[agree].astype(np.int64)
    starts = left_segments.pixel_offsets[seg]
    counts = left_segments.pixel_offsets[seg + 1] - starts
    ends = np.cumsum(counts)
    pix = left_segments.pixel_uv[np.repeat(starts - ends + counts, counts) + np.arange(ends[-1])]
    u = np.clip(pix[:, 0], 0, W - 1) - c0
    v = np.clip(pix[:, 1], 0, H - 1) - v0
    ok = (u >= 0) & (u < region.shape[1]) & (v >= 0) & (v < region.shape[0])
    hit = np.zeros(len(pix))
    hit[ok] = region[v[ok], u[ok]]
    n_in = np.bincount(np.repeat(np.arange(len(seg)), counts), weights=hit, minlength=len(seg))
    frac = np.where(counts > 0, n_in / np.maximum(counts, 1), 0.0)
    out[agree] = frac >= config.member_min_fraction
    return out


def test_plane_members_equal_the_reference(scenario_models):
    """Every fit of every scenario frame with all the frame's pairs and the kept ones, the least fraction (0 to 1: a
    fraction equal to it is decided alike) and the dilation varied: the same members."""
    n = 0
    for _, _, front, model in scenario_models:
        for fit in model.fits:
            if not fit:
                continue
            for pairs in (front.pairs, front.kept_pairs):
                for frac in (0.0, 0.3, 0.5, 0.75, 1.0):
                    for dil in (0, 3):
                        pc = P.PlaneConfig(member_min_fraction=frac, member_dilate_px=dil)
                        got = P.plane_members(fit, pairs, front.left_segments, pc)
                        assert np.array_equal(got, plane_members_reference(fit, pairs, front.left_segments, pc))
                        n += int(got.sum())
    assert n > 200
