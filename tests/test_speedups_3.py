"""Issue 13, the whole per-frame pipeline faster: every faster stage against the former implementation (kept
here as the reference where it was replaced) on frames of several simulated scenarios — the same values, bit
for bit where the arithmetic is the same, else to 1e-9."""

from __future__ import annotations

import numpy as np
import pytest

from stablemarks.config import Config
from stablemarks.pipeline import (
    RegionDisparity,
    _pair_sobel,
    pair_bands,
    plane_regions,
    prediction_regions,
    run_front_end,
)
from stablemarks.vision.area_stereo import (
    SADConfig,
    _xsobel,
    compute_disparity,
    compute_disparity_regions,
    prepare_pair,
    regions_on_prepared,
)
from stablemarks.vision.segment_stereo import match_segments
from stablemarks.vision.segments import extract_vertical_segments

from .test_regions_pipeline import assert_same

COV_PRIOR = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2


def _same_disparity(a, b, where=""):
    for x, y in ((a.left, b.left), (a.right, b.right), (a.valid, b.valid)):
        assert x.dtype == y.dtype, where
        assert np.array_equal(x, y, equal_nan=True), where


# ------------------------------------------------------------------ the x-Sobel computed once per image
def test_shared_sobel_gives_the_same_segments_and_disparity(scenario_frames):
    """The front end computes each image's x-Sobel once for the segments and the SAD prefilter: the same
    segments and disparity images as each computing its own."""
    sad = SADConfig()
    for name, k, left, right, *_ in scenario_frames:
        sobel = _pair_sobel(left, right)
        for img, sob in zip((left, right), sobel, strict=True):
            assert_same(extract_vertical_segments(img, sobel=sob), extract_vertical_segments(img), f"{name} {k}")
        _same_disparity(compute_disparity(left, right, sad, sobel=sobel), compute_disparity(left, right, sad))
    assert _pair_sobel(left.astype(np.float64) / 255, right.astype(np.float64) / 255) is None


def test_segments_reject_a_sobel_of_another_shape():
    from stablemarks.errors import ImageError

    img = np.zeros((20, 30), np.uint8)
    with pytest.raises(ImageError, match="sobel"):
        extract_vertical_segments(img, sobel=np.zeros((20, 31), np.int16))


# ------------------------------------------------------------------ the pair prepared once
def test_regions_on_a_prepared_pair_equal_compute_disparity_regions(scenario_frames):
    """SAD in regions on a pair prefiltered once (:func:`prepare_pair`), into fresh arrays or written in place
    into arrays holding earlier pixels: the values of :func:`compute_disparity_regions`."""
    config = Config()
    for name, k, left, right, camera, world_map, X in scenario_frames:
        reg = plane_regions(camera, X, COV_PRIOR, world_map, config, left.shape)
        sl = extract_vertical_segments(left)
        pairs = match_segments(sl, extract_vertical_segments(right))
        want_l = np.concatenate([reg.left, pair_bands(pairs, sl, config.filter.search_radius)])
        for sad in (config.sad, SADConfig(texture_threshold=0.0), SADConfig(prefilter="none", min_disparity=-3,
                                                                               num_disparities=40)):
            prep = prepare_pair(left, right, sad, *_pair_sobel(left, right))
            got = regions_on_prepared(prep, want_l, reg.right)
            _same_disparity(got, compute_disparity_regions(left, right, sad, want_l, reg.right), f"{name} {k}")
            # in place, on top of the first result: the second regions' pixels added, the others kept
            more_l = np.array([[100, 200, 0, 640]])
            more_r = np.array([[300, 400, 100, 300]])
            out = tuple(np.array(a) for a in (got.left, got.right, got.valid))
            regions_on_prepared(prep, more_l, more_r, out=out)
            mask_l = np.zeros(left.shape, bool)
            mask_r = np.zeros(left.shape, bool)
            for m, rects in ((mask_l, np.concatenate([want_l, more_l])), (mask_r, np.concatenate([reg.right, more_r]))):
                for v0, v1, u0, u1 in np.clip(rects, 0, None):
                    m[v0:v1, u0:u1] = True
            both = compute_disparity_regions(left, right, sad, mask_l, mask_r)
            _same_disparity(type(both)(*out), both, f"{name} {k} in place")


def test_region_disparity_possible_pixels_from_the_prepared_texture(scenario_frames):
    """:meth:`RegionDisparity.possible` sums the prepared ``min(|Sobel_x|, 255)``: the pixels the former
    recomputation of the x-Sobel over a strip around the column gave."""
    sad = SADConfig()
    b = sad.block_size
    r = b // 2
    tex_min = int(np.ceil(8.0 * sad.texture_threshold * b * b))
    for name, k, left, right, *_ in scenario_frames[::3]:
        lazy = RegionDisparity(left, right, sad)
        for image, img in enumerate((left, right)):
            H, W = img.shape
            for c in range(lazy.limits[image][0], lazy.limits[image][1] + 1, 7):
                # the former computation
                x0 = max(0, c - r - 1)
                sob = _xsobel(np.ascontiguousarray(img[:, x0 : min(W, c + r + 2)]))
                window = np.minimum(np.abs(sob[:, c - r - x0 : c + r + 1 - x0].astype(np.int64)), 255).sum(axis=1)
                sums = np.concatenate([[0], np.cumsum(window)])
                want = np.zeros(H, bool)
                rows = np.arange(r, H - r)
                want[r : H - r] = (sums[rows + r + 1] - sums[rows - r]) >= tex_min
                assert np.array_equal(lazy.possible(image, c), want), (name, k, image, c)


def test_front_end_in_regions_equals_the_dense_front_end(scenario_frames):
    """The front end with the shared x-Sobel and the prepared pair, in regions, against the dense front end and
    the regions' pixels topped up afterwards (in place) against a fresh dense computation."""
    config = Config()
    topped_up = 0
    for name, k, left, right, camera, world_map, X in scenario_frames:
        reg = plane_regions(camera, X, COV_PRIOR, world_map, config, left.shape)
        front = run_front_end(left, right, config, reg)
        dense = run_front_end(left, right, config)
        assert np.array_equal(front.kept, dense.kept)
        if front.lazy is None:
            continue
        wider = plane_regions(camera, X, COV_PRIOR * 16, world_map, config, left.shape)
        front.require(prediction_regions(wider.predictions, left.shape, config))
        topped_up += front.lazy.calls > 1
        for got, want, done in ((front.disparity.left, dense.disparity.left, front.lazy.done[0]),
                                (front.disparity.right, dense.disparity.right, front.lazy.done[1])):
            assert np.array_equal(got[done], want[done], equal_nan=True), (name, k)
            assert np.isnan(got[~done]).all(), (name, k)
        assert np.array_equal(front.disparity.valid, dense.disparity.valid & front.lazy.done[0])
    assert topped_up >= 2


def test_select_landmarks_reads_the_lazy_images_valid_columns(scenario_frames):
    """:func:`select_landmarks` takes the valid columns of a region front end from its :class:`RegionDisparity`
    (kept up to date as pixels are added) instead of scanning the images: the same columns, and the model equals
    the dense front end's."""
    from stablemarks.pipeline import select_landmarks, valid_columns

    from .test_regions_pipeline import assert_same_model

    config = Config()
    for name, k, left, right, camera, world_map, X in scenario_frames:
        reg = plane_regions(camera, X, COV_PRIOR, world_map, config, left.shape)
        front = run_front_end(left, right, config, reg)
        model = select_landmarks(front, camera, world_map, X, COV_PRIOR, config)
        dense = select_landmarks(run_front_end(left, right, config), camera, world_map, X, COV_PRIOR, config)
        assert_same_model(model, dense, f"{name} {k}")
        if front.lazy is not None:
            assert (front.lazy.found(0), front.lazy.found(1)) == valid_columns(front.disparity)


def test_region_disparity_with_the_opencv_backend(scenario_frames):
    """A :class:`RegionDisparity` made with the ``opencv`` backend still computes (its prepared pair holds the 8-bit
    images): the masked OpenCV images, topped up in place, and the same possible pixels as the numba one."""
    name, k, left, right, *_ = scenario_frames[0]
    sad = SADConfig(backend="opencv")
    rects_l, rects_r = np.array([[100, 200, 150, 300]]), np.array([[120, 220, 200, 260]])
    lazy = RegionDisparity(left, right, sad, rects_l, rects_r)
    _same_disparity(lazy.result, compute_disparity_regions(left, right, sad, rects_l, rects_r))
    more = np.zeros(left.shape, bool)
    more[300:350, 100:400] = True
    lazy.compute(more, None)
    want = lazy.done[0]
    full = compute_disparity(left, right, sad)
    assert np.array_equal(lazy.result.left, np.where(want, full.left, np.nan), equal_nan=True)
    numba = RegionDisparity(left, right, SADConfig())
    for c in (100, 320, 500):
        assert np.array_equal(lazy.possible(0, c), numba.possible(0, c))
        assert np.array_equal(lazy.possible(1, c), numba.possible(1, c))


# ------------------------------------------------------------------ point-on-plane fusion (Eqs 12–14)
def fuse_point_reference(fit, P, cov_P):
    """The former :meth:`PlaneFit.fuse_point`, in NumPy."""
    P = np.asarray(P, dtype=float)
    cov_P = np.asarray(cov_P, dtype=float)
    G, H, G_R = fit.constraint(P)
    var_V = np.einsum("...i,ij,...j->...", G_R, fit.cov_R, G_R)
    PH = cov_P @ H
    S = PH @ H + var_V
    K = PH / S[..., None]
    P_hat = P - K * G[..., None]
    IKH = np.eye(2) - K[..., :, None] * H
    KK = K[..., :, None] * K[..., None, :]
    cov_hat = IKH @ cov_P @ np.swapaxes(IKH, -1, -2) + var_V[..., None, None] * KK
    return P_hat, 0.5 * (cov_hat + np.swapaxes(cov_hat, -1, -2))


def test_fuse_point_equals_the_numpy_reference(scenario_frames):
    """:meth:`PlaneFit.fuse_point` (one numba loop) against the former NumPy expressions, on the planes fitted in
    the scenarios' frames, for triangulated points and random ones, single points, stacks and broadcast
    covariances: the same points and covariances to 1e-12 of their scale (rounding: the Joseph form cancels)."""
    from stablemarks.pipeline import process_frame

    rng = np.random.default_rng(3)
    config = Config()
    n_fits = 0
    for name, _k, left, right, camera, world_map, X in scenario_frames:
        model = process_frame(left, right, camera, world_map, X, COV_PRIOR, config)
        cam = config.camera(camera)
        for fit in (f for f in model.fits if f):
            n_fits += 1
            u = rng.uniform(50, 600, 7)
            P, cov = cam.triangulate(u, u - rng.uniform(5, 60, 7), X)
            A = rng.normal(size=(5, 3, 2, 2)) * 0.05
            cases = [(P, cov), (P[0], cov[0]), (P, cov[0]), (P[:1], cov), (rng.normal(size=(5, 3, 2)) * 3,
                                                                             A @ np.swapaxes(A, -1, -2))]
            for P_in, C_in in cases:
                got, want = fit.fuse_point(P_in, C_in), fuse_point_reference(fit, P_in, C_in)
                for g, w in zip(got, want, strict=True):
                    assert g.shape == w.shape
                    np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-12 * np.abs(w).max(), err_msg=name)
    assert n_fits >= 6


# ------------------------------------------------------------------ the disparity filter
def filter_pairs_reference(pairs, left_segments, disp, mask, tolerance, min_support, search_radius):
    """The former :func:`filter_pairs` body (after its checks), in NumPy."""
    n = len(pairs)
    if n == 0:
        return np.zeros(0, bool)
    own = left_segments.subset(pairs.left_index)
    pix, counts = own.pixel_uv, np.diff(own.pixel_offsets)
    H, W = disp.shape
    u, v = pix[:, 0].astype(np.int64), pix[:, 1].astype(np.int64)
    cols = u[:, None] + np.arange(-search_radius, search_radius + 1)[None, :]
    inside = (cols >= 0) & (cols < W)
    flat = v[:, None] * W + np.clip(cols, 0, W - 1)
    window = np.take(disp.reshape(-1), flat)
    usable = inside & np.take(mask.reshape(-1), flat) & np.isfinite(window)
    d_pair = np.repeat(pairs.disparity, counts)[:, None]
    supports = np.any(usable & (np.abs(np.where(usable, window, 0.0) - d_pair) <= tolerance), axis=1)
    owner = np.repeat(np.arange(n), counts)
    support = np.bincount(owner, weights=supports, minlength=n) / np.maximum(counts, 1)
    return (support >= min_support) & (counts > 0)


def test_filter_pairs_equals_the_numpy_reference(scenario_frames):
    """:func:`filter_pairs` (one numba loop over the pairs' pixels) keeps the pairs the former NumPy code kept, on
    the scenarios' dense and region disparity images, with several tolerances, supports and radii."""
    from stablemarks.errors import ImageError
    from stablemarks.vision.filter import filter_pairs

    config = Config()
    n_dropped = n_kept = 0
    for name, k, left, right, camera, world_map, X in scenario_frames:
        sl, sr = extract_vertical_segments(left), extract_vertical_segments(right)
        pairs = match_segments(sl, sr)
        reg = plane_regions(camera, X, COV_PRIOR, world_map, config, left.shape)
        for disp in (compute_disparity(left, right), run_front_end(left, right, config, reg).disparity):
            for tol, support, radius in ((1.0, 0.5, 2), (0.3, 0.8, 0), (2.0, 0.2, 5)):
                got = filter_pairs(pairs, sl, disp.left, disp.valid, tol, support, search_radius=radius)
                want = filter_pairs_reference(pairs, sl, disp.left, disp.valid, tol, support, radius)
                assert np.array_equal(got, want), (name, k, tol, support, radius)
                n_kept += int(got.sum())
                n_dropped += int((~got).sum())
            # float64 and float16 images: the same decisions as the reference on them
            for dtype in (np.float64, np.float16):
                d = disp.left.astype(dtype)
                assert np.array_equal(filter_pairs(pairs, sl, d, disp.valid),
                                      filter_pairs_reference(pairs, sl, d, disp.valid, 1.0, 0.5, 2))
    assert n_kept > 50 and n_dropped > 50
    with pytest.raises(ImageError, match="outside"):
        filter_pairs(pairs, sl, disp.left[:100], disp.valid[:100])


# ------------------------------------------------------------------ segments sorted by column
def test_segments_are_sorted_as_by_subset(scenario_frames):
    """:func:`extract_vertical_segments` puts the segments in column order with their pixel blocks in one pass:
    the same :class:`Segments`, field by field and dtype by dtype, as the former ``subset(argsort(u))`` of the
    unsorted ones."""
    from stablemarks.vision import segments as S

    for name, k, left, right, *_ in scenario_frames:
        for img in (left, right, left.astype(np.float32)):
            got = extract_vertical_segments(img)
            # the former way: the unsorted segments, then subset
            gx = S.cv2.Sobel(img, S.cv2.CV_16S if img.dtype == np.uint8 else S.cv2.CV_32F, 1, 0, ksize=3)
            c = S.SegmentConfig()
            thr = np.int16(np.ceil(c.gradient_threshold)) if img.dtype == np.uint8 else np.float32(c.gradient_threshold)
            edges = S._detect_and_link(gx, thr, int(c.max_drift), int(c.max_gap))
            u, slope, v_top, v_bottom, pol, con, off, pix = S._fit_segments(
                gx, *edges, float(c.min_length), float(c.max_residual), float(np.tan(c.max_angle)))
            unsorted = S.Segments(u=u, slope=slope, v_top=v_top, v_bottom=v_bottom, polarity=pol, contrast=con,
                                  n_pixels=np.diff(off), pixel_offsets=off, pixel_uv=pix)
            want = unsorted.subset(np.argsort(u, kind="stable"))
            assert len(got) > 5
            for f in ("u", "slope", "v_top", "v_bottom", "polarity", "contrast", "n_pixels", "pixel_offsets",
                      "pixel_uv"):
                a, b = getattr(got, f), getattr(want, f)
                assert a.dtype == b.dtype and np.array_equal(a, b), (name, k, f)
