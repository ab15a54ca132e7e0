import cv2
import numpy as np
import pytest

from stablemarks.errors import ConfigError, ImageError, InputError
from stablemarks.vision.segments import SegmentConfig, Segments, extract_vertical_segments

# ---------------------------------------------------------------- synthetic images


def textured_background(shape, *, level=100.0, texture=3.0, offset=0, seed=0):
    """A smooth random texture (std ``texture`` grey levels around ``level``), float64 (H, W).

    The texture field is drawn 64 px wider than the image and cropped at column ``offset``: the
    crops at ``0`` and ``d`` are a rectified stereo pair of a fronto-parallel plane at disparity ``d``.
    """
    rng = np.random.default_rng(seed)
    H, W = shape
    field = cv2.GaussianBlur(rng.standard_normal((H, W + 64)), (0, 0), 3.0)
    field *= texture / field.std()
    return level + field[:, offset : offset + W]


def paint(img, rows, x0, x1, value):
    """Paint ``value`` between the sub-pixel columns ``x0[k] < x1[k]`` of row ``rows[k]``, with exact
    area coverage of each pixel ``[c - 0.5, c + 0.5]`` (an anti-aliased, box-filtered edge)."""
    cols = np.arange(img.shape[1])[None, :]
    x0, x1 = np.asarray(x0, float)[:, None], np.asarray(x1, float)[:, None]
    cover = np.clip(np.minimum(cols + 0.5, x1) - np.maximum(cols - 0.5, x0), 0.0, 1.0)
    img[rows] = img[rows] * (1.0 - cover) + value * cover


def render_bars(bars, shape=(240, 320), *, noise=0.0, seed=0, dtype=np.uint8, **background):
    """An image of bars ``(u_left, u_right, v_top, v_bottom, value[, slope])`` on a textured
    background: rows ``v_top..v_bottom``, columns ``u_left + slope (v - v_mid)`` to
    ``u_right + slope (v - v_mid)`` (sub-pixel, anti-aliased); plus white noise of std ``noise``."""
    img = textured_background(shape, seed=seed, **background)
    for u_left, u_right, v_top, v_bottom, value, *slope in bars:
        rows = np.arange(v_top, v_bottom + 1)
        shift = (slope[0] if slope else 0.0) * (rows - 0.5 * (v_top + v_bottom))
        paint(img, rows, u_left + shift, u_right + shift, value)
    img += np.random.default_rng(seed + 1).normal(0.0, noise, img.shape) if noise else 0.0
    return np.clip(np.rint(img), 0, 255).astype(dtype) if dtype == np.uint8 else img.astype(dtype)


def true_edges(bars, background=100.0):
    """(u at middle row, v_top, v_bottom, polarity, slope) of both edges of every bar, (2B, 5)."""
    rows = []
    for u_left, u_right, v_top, v_bottom, value, *slope in bars:
        s = slope[0] if slope else 0.0
        pol = 1 if value > background else -1
        rows += [(u_left, v_top, v_bottom, pol, s), (u_right, v_top, v_bottom, -pol, s)]
    return np.array(rows)


def match_edges(segments, edges, tol):
    """Index of the segment nearest (at the edge's middle row) to each true edge, -1 if beyond tol."""
    idx = np.full(len(edges), -1)
    for k, (u, v_top, v_bottom, _, _) in enumerate(edges):
        if len(segments) == 0:
            continue
        du = np.abs(segments.u_at(0.5 * (v_top + v_bottom)) - u)
        du[(segments.v_bottom < v_top) | (segments.v_top > v_bottom)] = np.inf
        if du.min() <= tol:
            idx[k] = int(np.argmin(du))
    return idx


def column_error(segments, idx, edges):
    """Segment ``idx[k]``'s column minus edge ``k``'s true column, at the edge's middle row."""
    return segments.subset(idx).u_at(0.5 * (edges[:, 1] + edges[:, 2])) - edges[:, 0]


# ---------------------------------------------------------------- accuracy

FRACTIONS = np.linspace(0.0, 0.9, 10)


def bars_at_fractional_columns():
    """Ten 9.x px wide bars, bright and dark, whose edges cover the sub-pixel phases 0.0 … 0.9."""
    return [
        (20.0 + 30 * k + f, 29.0 + 30 * k + f + 0.45, 30 + 3 * k, 200 - 2 * k, 180.0 if k % 2 else 30.0)
        for k, f in enumerate(FRACTIONS)
    ]


def test_columns_are_subpixel_accurate_and_ends_within_a_row():
    bars = bars_at_fractional_columns()
    segs = extract_vertical_segments(render_bars(bars))
    edges = true_edges(bars)
    idx = match_edges(segs, edges, tol=0.5)
    assert np.all(idx >= 0)
    assert len(set(idx)) == len(edges) == len(segs)
    err = column_error(segs, idx, edges)
    assert np.max(np.abs(err)) < 0.05
    assert np.all(np.abs(segs.v_top[idx] - edges[:, 1]) <= 1)
    assert np.all(np.abs(segs.v_bottom[idx] - edges[:, 2]) <= 1)
    np.testing.assert_array_equal(segs.polarity[idx], edges[:, 3])
    assert np.all(np.abs(segs.slope) < 2e-3)
    assert np.all(np.diff(segs.u) >= 0), "sorted by column"


@pytest.mark.parametrize("slope", [0.01, -0.01, 0.06])
def test_slightly_tilted_edges_are_found_with_their_slope(slope):
    bars = [(60.3, 75.8, 20, 219, 200.0, slope), (160.6, 170.1, 40, 200, 20.0, slope)]
    segs = extract_vertical_segments(render_bars(bars))
    edges = true_edges(bars)
    idx = match_edges(segs, edges, tol=0.5)
    assert np.all(idx >= 0) and len(segs) == len(edges)
    np.testing.assert_allclose(segs.slope[idx], slope, atol=2e-3)
    np.testing.assert_allclose(segs.orientation[idx], np.arctan(slope), atol=2e-3)
    np.testing.assert_allclose(column_error(segs, idx, edges), 0.0, atol=0.15)


def test_noise_and_texture_leave_columns_within_a_sixth_of_a_pixel():
    bars = bars_at_fractional_columns()
    img = render_bars(bars, noise=5.0, texture=8.0, seed=3)
    segs = extract_vertical_segments(img)
    edges = true_edges(bars)
    idx = match_edges(segs, edges, tol=0.5)
    assert np.all(idx >= 0)
    err = column_error(segs, idx, edges)
    assert np.max(np.abs(err)) < 0.15
    assert np.all(segs.length[idx] > 0.9 * (edges[:, 2] - edges[:, 1]))
    others = np.setdiff1d(np.arange(len(segs)), idx)
    assert np.all(segs.length[others] < 60), "no long segment where there is no edge"


def test_float_input_gives_the_same_segments_as_uint8():
    img = render_bars(bars_at_fractional_columns())
    a = extract_vertical_segments(img)
    b = extract_vertical_segments(img.astype(np.float32))
    np.testing.assert_allclose(a.u, b.u, atol=1e-9)
    np.testing.assert_array_equal(a.pixel_uv, b.pixel_uv)


def test_near_vertical_lsd_segments_match_ours():
    """OpenCV's LSD (an independent detector) as the oracle on a synthetic image."""
    bars = [(30.2 + 37 * k, 44.7 + 37 * k, 25 + 5 * k, 215 - 4 * k, 190.0 if k % 2 else 25.0, 0.004 * (k - 3))
            for k in range(7)]  # fmt: skip
    img = render_bars(bars, noise=2.0, texture=4.0, seed=7)
    ours = extract_vertical_segments(img)
    lines = cv2.createLineSegmentDetector().detect(img)[0].reshape(-1, 4)
    x1, y1, x2, y2 = lines.T
    near_vertical = (np.abs(x2 - x1) < np.tan(np.deg2rad(5)) * np.abs(y2 - y1)) & (np.abs(y2 - y1) > 40)
    lines = lines[near_vertical]
    assert len(lines) >= 2 * len(bars)
    for x1, y1, x2, y2 in lines:
        v = 0.5 * (y1 + y2)
        du = np.abs(ours.u_at(v) - 0.5 * (x1 + x2))
        du[(ours.v_top > v) | (ours.v_bottom < v)] = np.inf
        # LSD puts pixel centres at .5 (corner-origin coordinates): allow 1 px.
        assert du.min() < 1.0, f"LSD segment at u={0.5 * (x1 + x2):.2f}, v={v:.0f} has no counterpart"
    long = ours.length > 40
    for u in ours.u[long]:
        assert np.min(np.abs(0.5 * (lines[:, 0] + lines[:, 2]) - u)) < 1.0


# ---------------------------------------------------------------- what is not a segment


def test_min_length_drops_short_edges():
    img = render_bars([(100.3, 110.7, 50, 62, 200.0)])
    assert len(extract_vertical_segments(img)) == 0
    segs = extract_vertical_segments(img, SegmentConfig(min_length=8))
    assert len(segs) == 2


@pytest.mark.parametrize("slope", [0.5, 1.0])
def test_steep_diagonal_edges_and_horizontal_stripes_give_nothing(slope):
    img = render_bars([(100.0, 110.0, 40, 200, 220.0, slope), (20.0, 300.0, 215, 225, 220.0)])
    assert len(extract_vertical_segments(img)) == 0


def test_a_bent_edge_is_split_into_its_straight_pieces():
    img = textured_background((240, 320))
    top, bottom = np.arange(20, 120), np.arange(120, 220)
    paint(img, top, 100.2 + 0.08 * (top - 120), np.full(top.size, 140.0), 200.0)
    paint(img, bottom, 100.2 - 0.08 * (bottom - 120), np.full(bottom.size, 140.0), 200.0)
    segs = extract_vertical_segments(np.rint(img).astype(np.uint8))
    bent = segs.subset(np.abs(segs.u_at(120) - 100.2) < 1.5)
    assert len(bent) == 2
    bent = bent.subset(np.argsort(bent.v_top))
    np.testing.assert_allclose(bent.slope, [0.08, -0.08], atol=0.01)
    np.testing.assert_allclose(bent.u_at(120), 100.2, atol=0.5)
    assert abs(bent.v_bottom[0] - 120) <= 4 and abs(bent.v_top[1] - 120) <= 4


def test_a_missing_row_is_bridged_only_when_gaps_are_allowed():
    img = textured_background((240, 320))
    rows = np.r_[30:119, 122:210]  # rows 119-121 missing: Sobel's smoothing leaves only row 120 empty
    paint(img, rows, np.full(rows.size, 80.4), np.full(rows.size, 120.4), 160.0)
    img = np.rint(img).astype(np.uint8)
    assert len(extract_vertical_segments(img)) == 2
    assert len(extract_vertical_segments(img, SegmentConfig(max_gap=0))) == 4


# ---------------------------------------------------------------- the Segments container


def test_pixels_lie_on_the_fitted_line():
    segs = extract_vertical_segments(render_bars([(60.3, 75.8, 20, 219, 200.0, 0.03)]))
    assert len(segs) == 2
    for i in range(len(segs)):
        p = segs.pixels(i)
        assert p.shape == (segs.n_pixels[i], 2)
        assert np.all(np.diff(p[:, 1]) > 0), "top to bottom, one pixel per row"
        assert p[0, 1] == segs.v_top[i] and p[-1, 1] == segs.v_bottom[i]
        assert np.all(np.abs(p[:, 0] - segs.u_at(p[:, 1, None])[:, i]) <= 1.0)


def test_from_lines_u_at_orientation_and_subset():
    segs = Segments.from_lines([10.0, 50.0, 30.0], [0.0, 10.0, 20.0], [100.0, 30.0, 21.0],
                               slope=[0.1, 0.0, -0.2], polarity=[1, -1, 1])  # fmt: skip
    assert len(segs) == 3
    np.testing.assert_allclose(segs.length, [100.0, 20.0, 1.0])
    np.testing.assert_allclose(segs.u_at(50.0), [10.0, 50.0, 30.0 - 0.2 * 29.5])
    assert segs.orientation[0] > 0 > segs.orientation[2]
    np.testing.assert_array_equal(segs.pixels(0)[[0, -1]], [[5, 0], [15, 100]])
    sub = segs.subset(np.array([2, 0]))
    np.testing.assert_allclose(sub.u, [30.0, 10.0])
    np.testing.assert_array_equal(sub.pixels(1), segs.pixels(0))
    np.testing.assert_array_equal(sub.pixels(0), segs.pixels(2))
    masked = segs.subset(np.array([False, True, False]))
    assert len(masked) == 1 and masked.polarity[0] == -1
    np.testing.assert_array_equal(masked.pixels(-1), segs.pixels(1))
    assert len(Segments.empty()) == 0 and len(segs.subset(np.zeros(3, bool))) == 0
    with pytest.raises(IndexError, match="segment index"):
        segs.pixels(3)
    with pytest.raises(IndexError, match="boolean mask"):
        segs.subset(np.ones(2, bool))


def test_segments_reject_inconsistent_arrays():
    with pytest.raises(InputError, match=r"Segments.slope: expected shape \(2,\)"):
        Segments(u=np.zeros(2), slope=np.zeros(3), v_top=np.zeros(2), v_bottom=np.ones(2),
                 polarity=np.ones(2, np.int8), contrast=np.ones(2), n_pixels=np.ones(2, np.int64),
                 pixel_offsets=np.arange(3), pixel_uv=np.zeros((2, 2), np.int32))  # fmt: skip
    with pytest.raises(InputError, match="v_bottom > v_top"):
        Segments.from_lines([1.0], [5.0], [5.0])


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((20, 20, 3), np.uint8), "2-D grayscale"),
        (np.zeros((2, 20), np.uint8), "at least 3x3"),
        (np.zeros((20, 20), np.int32), "dtype uint8 or float"),
        (np.full((20, 20), np.nan), "finite"),
    ],
)
def test_bad_images_raise_image_error(image, message):
    with pytest.raises(ImageError, match=message):
        extract_vertical_segments(image)


@pytest.mark.parametrize(
    ("field", "value"),
    [("gradient_threshold", 0.0), ("min_length", 0.5), ("max_drift", -1), ("max_gap", 1.5),
     ("max_residual", 0.0), ("max_angle", 2.0)],
)  # fmt: skip
def test_bad_config_raises_config_error(field, value):
    with pytest.raises(ConfigError, match=f"SegmentConfig.{field}: expected"):
        SegmentConfig(**{field: value})


# ---------------------------------------------------------------- two edges close together
def _two_steps(sep, levels, blur=1.0, seed=0, H=120, W=200, x=100.3):
    """Three vertical bands (``levels``) with anti-aliased steps at ``x`` and ``x + sep`` [px], blurred, with noise."""
    img = np.full((H, W), float(levels[0]))
    rows = np.arange(H)
    paint(img, rows, np.full(H, x), np.full(H, W + 1.0), levels[1])
    paint(img, rows, np.full(H, x + sep), np.full(H, W + 1.0), levels[2])
    img = cv2.GaussianBlur(img, (0, 0), blur)
    img += np.random.default_rng(seed).normal(0.0, 1.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8), x


@pytest.mark.parametrize("levels", [(40, 110, 180), (150, 60, 150)], ids=["same-sign", "bar"])
def test_the_detector_resolves_two_edges_from_about_four_pixels(levels):
    """The resolution ``ekf.merge_px`` and docs/uncertainty.md quote: with a 1 px blur, two edges 2 px apart are
    never two lines placed within 0.1 px of their columns; from 5 px apart each is found within 0.05 px."""
    for sep, close in ((2.0, False), (5.0, True), (8.0, True)):
        img, x = _two_steps(sep, levels)
        u = np.sort(extract_vertical_segments(img).u)
        both = len(u) >= 2 and min(abs(u - x)) < 0.1 and min(abs(u - x - sep)) < 0.1
        assert both == close, (sep, u)
        if close:
            assert min(abs(u - x)) < 0.05 and min(abs(u - x - sep)) < 0.05, (sep, u)
