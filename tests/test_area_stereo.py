"""Area-based SAD stereo (paper Sec 2.2, Eq 2): the numba kernel against the exact NumPy oracle, synthetic
pairs with known disparity, the left-right check, the texture test, input validation, the OpenCV backend
and the real Middlebury pair that ships with scikit-image."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from stablemarks.errors import ConfigError, ImageError, InputError
from stablemarks.vision.area_stereo import (
    DisparityResult,
    SADConfig,
    compute_disparity,
    sad_cost_volume,
    sad_reference,
)

# ------------------------------------------------------------------------------------------------
# helpers


def texture(shape, rng, blur=1.5):
    """Band-limited random texture, (H, W) float64 with zero mean and unit standard deviation."""
    t = cv2.GaussianBlur(rng.standard_normal(shape), (0, 0), blur)
    return (t - t.mean()) / t.std()


def to8(t, contrast=40.0):
    return np.clip(np.rint(128.0 + contrast * t), 0, 255).astype(np.uint8)


def shifted_pair(shape, d, rng):
    """A fronto-parallel textured plane at (possibly fractional) disparity ``d``: left(u) = right(u − d).

    The right image is the texture shifted by ``d`` in the Fourier domain, exact for a band-limited
    periodic signal; both images are quantized to 8 bits.
    """
    H, W = shape
    pad = 64
    base = texture((H, W + 2 * pad), rng)
    f = np.fft.rfftfreq(W + 2 * pad)
    right = np.fft.irfft(np.fft.rfft(base, axis=1) * np.exp(2j * np.pi * f * d), n=W + 2 * pad, axis=1)
    return to8(base[:, pad : pad + W]), to8(right[:, pad : pad + W])


def square_scene(rng, H=120, W=220, d_bg=8, d_fg=24, top=30, left_col=100, size=60):
    """Background plane at ``d_bg`` with a textured square at ``d_fg`` in front (integer disparities)."""
    wide = to8(texture((H, W + d_bg), rng))
    left, right = wide[:, :W].copy(), wide[:, d_bg:].copy()  # left(u) = wide(u) = right(u - d_bg)
    fg = to8(texture((size, size), rng))
    left[top : top + size, left_col : left_col + size] = fg
    right[top : top + size, left_col - d_fg : left_col - d_fg + size] = fg
    return left, right


def oracle(left, right, config: SADConfig):
    """The expected result of :func:`compute_disparity` with ``prefilter='none'``, ``subpixel=False`` and
    ``texture_threshold=0``, built from the brute-force Eq 2 volumes: winners (ties to the smaller
    disparity), the uniqueness test and the left-right check, for both images."""
    D, dmin = config.num_disparities, config.min_disparity
    volumes = sad_reference(left, right, config.block_size, D, dmin)
    winners = []
    for vol in volumes:
        j = np.argmin(vol, axis=2)
        best = np.take_along_axis(vol, j[..., None], axis=2)[..., 0]
        outside = np.abs(np.arange(D)[None, None, :] - j[..., None]) > 1
        second = np.where(outside, vol, np.inf).min(axis=2)
        unique = second * 100 > best * (100 + config.uniqueness_ratio) if config.uniqueness_ratio else True
        d = np.where(np.isfinite(best), j + dmin, np.nan)
        winners.append((d, np.isfinite(vol).all(axis=2) & unique))
    (d_left, ok_left), (d_right, ok_right) = winners
    H, W = d_left.shape
    rows, cols = np.indices((H, W))

    def consistent(d, other, sign):
        match = np.floor(cols + sign * np.nan_to_num(d, nan=-1e9) + 0.5).astype(int)
        inside = (match >= 0) & (match < W) & np.isfinite(d)
        with np.errstate(invalid="ignore"):
            return inside & (np.abs(d - other[rows, np.clip(match, 0, W - 1)]) <= config.lr_tolerance)

    valid = ok_left & consistent(d_left, d_right, -1)
    valid_right = ok_right & consistent(d_right, d_left, 1)
    return np.where(valid, d_left, np.nan), np.where(valid_right, d_right, np.nan), valid


def exact(**kwargs) -> SADConfig:
    return SADConfig(prefilter="none", subpixel=False, texture_threshold=0.0, **kwargs)


# ------------------------------------------------------------------------------------------------
# the kernel against the Eq 2 oracle


@pytest.mark.parametrize("block_size,num_disparities,min_disparity", [(5, 8, 0), (3, 5, 2), (7, 6, -3), (5, 1, 4)])
def test_kernel_costs_equal_the_eq2_oracle(block_size, num_disparities, min_disparity):
    rng = np.random.default_rng(block_size * 10 + num_disparities)
    left = rng.integers(0, 256, (19, 37), dtype=np.uint8)
    right = rng.integers(0, 256, (19, 37), dtype=np.uint8)
    lr_ref, rl_ref = sad_reference(left, right, block_size, num_disparities, min_disparity)
    lr, rl = sad_cost_volume(left, right, block_size, num_disparities, min_disparity)
    np.testing.assert_array_equal(lr, lr_ref)
    np.testing.assert_array_equal(rl, rl_ref)
    assert np.isfinite(lr_ref).any() and np.isinf(lr_ref).any()


def test_oracle_costs_are_eq2_and_symmetric():
    rng = np.random.default_rng(7)
    left = rng.integers(0, 256, (9, 14), dtype=np.uint8)
    right = rng.integers(0, 256, (9, 14), dtype=np.uint8)
    lr, rl = sad_reference(left, right, 3, 4, 1)
    v, u, j = 4, 8, 2  # d = 3
    L, R = left.astype(int), right.astype(int)
    assert lr[v, u, j] == np.abs(L[3:6, 7:10] - R[3:6, 4:7]).sum()
    assert rl[v, u - 3, j] == np.abs(R[3:6, 4:7] - L[3:6, 7:10]).sum() == lr[v, u, j]
    assert np.isinf(lr[v, 3, j]) and np.isinf(lr[0, u, j])  # right window at u - d leaves the image; top row


@pytest.mark.parametrize(
    "seed,shape,block_size,num_disparities,min_disparity,uniqueness,tol",
    [
        (0, (20, 48), 5, 8, 0, 0, 0.0),
        (1, (24, 50), 5, 10, 0, 15, 1.0),
        (2, (17, 40), 3, 7, -4, 5, 0.0),
        (3, (22, 45), 7, 6, 3, 20, 2.0),
        (4, (15, 30), 5, 3, -1, 10, 1.0),
    ],
)
def test_winners_and_tests_equal_the_oracle(seed, shape, block_size, num_disparities, min_disparity, uniqueness, tol):
    rng = np.random.default_rng(seed)
    H, W = shape
    base = rng.integers(0, 256, (H, W + 20))
    left = base[:, 10 : 10 + W].astype(np.uint8)  # a shift of 3 px plus noise: many consistent matches
    right = np.clip(base[:, 13 : 13 + W] + rng.integers(-30, 30, (H, W)), 0, 255).astype(np.uint8)
    config = exact(
        block_size=block_size,
        num_disparities=num_disparities,
        min_disparity=min_disparity,
        uniqueness_ratio=uniqueness,
        lr_tolerance=tol,
    )
    res = compute_disparity(left, right, config)
    want_left, want_right, want_valid = oracle(left, right, config)
    np.testing.assert_array_equal(res.valid, want_valid)
    np.testing.assert_array_equal(res.left, want_left)
    np.testing.assert_array_equal(res.right, want_right)
    assert res.valid.any() and not res.valid.all()


def test_left_border_winners_ignore_the_padding():
    """A left column near the left border has lanes whose right window leaves the image (they read the zero
    padding); its winner, which the right image's left-right check reads, is taken over the lanes that fit only.
    A black strip on the left of the left image against a bright right image makes the padding the cheapest
    match, so a winner taken over every lane would differ from the oracle's."""
    rng = np.random.default_rng(7)
    H, W = 30, 90
    left = rng.integers(0, 256, (H, W)).astype(np.uint8)
    left[:, :40] = 0
    right = rng.integers(100, 256, (H, W)).astype(np.uint8)
    config = exact(block_size=5, num_disparities=16, uniqueness_ratio=0, lr_tolerance=1.0)
    res = compute_disparity(left, right, config)
    want_left, want_right, want_valid = oracle(left, right, config)
    np.testing.assert_array_equal(res.valid, want_valid)
    np.testing.assert_array_equal(res.left, want_left)
    np.testing.assert_array_equal(res.right, want_right)
    assert np.isfinite(want_right[:, : config.num_disparities]).any()  # right pixels that check a border column


# ------------------------------------------------------------------------------------------------
# synthetic pairs with known disparity


@pytest.mark.parametrize("d", [10.0, 10.25, 10.5, 17.3])
def test_constant_disparity_is_recovered_to_a_tenth_of_a_pixel(d):
    rng = np.random.default_rng(int(d * 100))
    left, right = shifted_pair((100, 200), d, rng)
    res = compute_disparity(left, right, SADConfig(num_disparities=32))
    assert res.valid_fraction > 0.5
    err = res.left[res.valid] - d
    assert abs(err.mean()) < 0.05 and np.median(np.abs(err)) < 0.1, (err.mean(), np.median(np.abs(err)))
    err_right = res.right[np.isfinite(res.right)] - d
    assert np.isfinite(res.right).mean() > 0.5 and abs(err_right.mean()) < 0.05
    # on the raw intensities the equiangular fit is unbiased and tight
    raw = compute_disparity(left, right, SADConfig(num_disparities=32, prefilter="none"))
    assert np.percentile(np.abs(raw.left[raw.valid] - d), 95) < 0.1


def test_subpixel_off_gives_the_integer_winner():
    rng = np.random.default_rng(5)
    left, right = shifted_pair((80, 160), 12.3, rng)
    res = compute_disparity(left, right, SADConfig(num_disparities=32, subpixel=False))
    values = res.left[res.valid]
    assert values.size and np.array_equal(values, np.rint(values))
    assert np.mean(values == 12) > 0.9


def test_negative_disparities_with_a_negative_minimum():
    rng = np.random.default_rng(6)
    right, left = shifted_pair((80, 160), 6.0, rng)  # swapped: left(u) = right(u + 6), d = -6
    res = compute_disparity(left, right, SADConfig(num_disparities=16, min_disparity=-12))
    assert res.valid_fraction > 0.4
    np.testing.assert_allclose(res.left[res.valid], -6.0, atol=0.3)


def test_float_images_in_unit_range_match_their_8bit_version():
    rng = np.random.default_rng(8)
    left, right = shifted_pair((60, 120), 9.0, rng)
    a = compute_disparity(left, right, SADConfig(num_disparities=16))
    b = compute_disparity(left / 255.0, (right / 255.0).astype(np.float32), SADConfig(num_disparities=16))
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)


def test_result_layout_and_borders():
    rng = np.random.default_rng(9)
    left, right = shifted_pair((70, 150), 9.0, rng)
    config = SADConfig(block_size=9, num_disparities=24)
    res = compute_disparity(left, right, config)
    assert isinstance(res, DisparityResult)
    for a in (res.left, res.right):
        assert a.shape == left.shape and a.dtype == np.float32 and not a.flags.writeable
    assert res.valid.dtype == bool and np.array_equal(res.valid, np.isfinite(res.left))
    r, d_max = 4, 23
    assert not res.valid[:r].any() and not res.valid[-r:].any()
    assert not res.valid[:, : r + d_max].any() and not res.valid[:, -r:].any()  # window or range leaves
    assert np.isnan(res.right[:, -(r + d_max) :]).all() and np.isnan(res.right[:, :r]).all()
    assert res.valid[:, r + d_max : -r].any()
    assert res.valid_fraction == pytest.approx(res.valid.mean())


# ------------------------------------------------------------------------------------------------
# the tests: left-right consistency, texture, uniqueness


def test_left_right_check_invalidates_occluded_pixels():
    rng = np.random.default_rng(2)
    left, right = square_scene(rng)  # square at d = 24 over columns 100-159 of the left image, background at 8
    assert compute_disparity(left, right, SADConfig(num_disparities=32)).valid[40:80, 86:98].mean() < 0.1
    # without the uniqueness test, it is the left-right check alone that invalidates them
    config = SADConfig(num_disparities=32, uniqueness_ratio=0)
    res = compute_disparity(left, right, config)
    # background left of the square that the right camera cannot see: columns 100 - 24 + 8 ... 99
    assert res.valid[40:80, 86:98].mean() < 0.1
    unchecked = compute_disparity(left, right, replace(config, lr_tolerance=1e6))
    assert unchecked.valid[40:80, 86:98].mean() > 0.5
    np.testing.assert_allclose(res.left[40:80, 110:150][res.valid[40:80, 110:150]], 24.0, atol=0.5)
    np.testing.assert_allclose(res.left[40:80, 170:200][res.valid[40:80, 170:200]], 8.0, atol=0.5)
    # the right image: background right of the square (columns 136 ... 151) is hidden from the left camera
    assert np.isfinite(res.right[40:80, 138:150]).mean() < 0.1
    assert np.isfinite(unchecked.right[40:80, 138:150]).mean() > 0.5


def test_flat_images_have_no_valid_disparity():
    flat = np.full((80, 120), 128, np.uint8)
    assert not compute_disparity(flat, flat, SADConfig(num_disparities=16)).valid.any()
    # the texture test alone rejects them ...
    no_uniqueness = SADConfig(num_disparities=16, uniqueness_ratio=0)
    res = compute_disparity(flat, flat, no_uniqueness)
    assert not res.valid.any() and np.isnan(res.right).all()
    # ... where without it every pixel "matches" at the first disparity
    assert compute_disparity(flat, flat, replace(no_uniqueness, texture_threshold=0.0)).valid.mean() > 0.5


def test_texture_threshold_is_in_grey_levels_per_pixel():
    ramp = np.tile(np.arange(0, 120, dtype=np.uint8)[None, :] // 2, (60, 1))  # slope 0.5 grey level / px
    noise = np.random.default_rng(3).integers(0, 2, ramp.shape).astype(np.uint8)
    img = ramp + noise
    base = SADConfig(num_disparities=16, uniqueness_ratio=0, lr_tolerance=1e6)
    assert compute_disparity(img, img, replace(base, texture_threshold=0.3)).valid.any()
    assert not compute_disparity(img, img, replace(base, texture_threshold=1.5)).valid.any()


def test_uniqueness_rejects_repetitive_texture():
    rng = np.random.default_rng(4)
    period = to8(texture((60, 8), rng))
    left = np.tile(period, (1, 20))  # period 8 px, searched over 32 disparities: every match is ambiguous
    right = np.roll(left, -3, axis=1)
    assert not compute_disparity(left, right, SADConfig(num_disparities=32)).valid.any()
    assert compute_disparity(left, right, SADConfig(num_disparities=32, uniqueness_ratio=0)).valid.any()


# ------------------------------------------------------------------------------------------------
# inputs


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"block_size": 4}, "block_size"),
        ({"block_size": 1}, "block_size"),
        ({"block_size": 7.0}, "block_size"),
        ({"num_disparities": 0}, "num_disparities"),
        ({"min_disparity": 0.5}, "min_disparity"),
        ({"lr_tolerance": -1.0}, "lr_tolerance"),
        ({"uniqueness_ratio": -5}, "uniqueness_ratio"),
        ({"texture_threshold": float("nan")}, "texture_threshold"),
        ({"prefilter": "sobel"}, "prefilter"),
        ({"prefilter_cap": 64}, "prefilter_cap"),
        ({"subpixel": 1}, "subpixel"),
        ({"backend": "cuda"}, "backend"),
        ({"backend": "opencv", "num_disparities": 40}, "multiple of 16"),
        ({"backend": "opencv", "prefilter": "none"}, "StereoBM always prefilters"),
        ({"backend": "opencv", "block_size": 3}, "block_size >= 5"),
        ({"block_size": 101, "num_disparities": 1024, "prefilter": "none"}, "2\\^31"),
    ],
)
def test_bad_configuration(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        SADConfig(**kwargs)


def test_configuration_errors_are_input_errors():
    with pytest.raises(InputError, match="SADConfig.block_size: expected an odd block size >= 3, got 4"):
        SADConfig(block_size=4)


@pytest.mark.parametrize(
    "left,right,match",
    [
        (np.zeros((20, 30), np.uint8), np.zeros((20, 31), np.uint8), "shape"),
        (np.zeros((20, 30, 3), np.uint8), np.zeros((20, 30, 3), np.uint8), "2-D grayscale"),
        (np.zeros((20, 30), np.int16), np.zeros((20, 30), np.int16), "uint8 or float"),
        (np.full((20, 30), 2.0), np.zeros((20, 30)), "float pixels in \\[0, 1\\]"),
        (np.zeros((20, 30)), np.full((20, 30), np.nan), "right: expected float pixels"),
    ],
)
def test_bad_images(left, right, match):
    with pytest.raises(ImageError, match=match):
        compute_disparity(left, right)


def test_images_smaller_than_the_window_give_no_valid_pixel():
    img = np.zeros((10, 12), np.uint8)
    res = compute_disparity(img, img, SADConfig(block_size=15))
    assert res.left.shape == (10, 12) and not res.valid.any() and np.isnan(res.right).all()


def test_bad_fraction_checks_the_ground_truth_shape():
    rng = np.random.default_rng(1)
    left, right = shifted_pair((60, 120), 9.0, rng)
    res = compute_disparity(left, right, SADConfig(num_disparities=16))
    truth = np.full(left.shape, 9.0)
    truth[:, :60] = np.inf  # unknown: not scored
    assert res.bad_fraction(truth, 0.5) == 0.0
    assert res.bad_fraction(np.full(left.shape, 12.0), 2.0) == 1.0
    assert np.isnan(res.bad_fraction(np.full(left.shape, np.inf), 1.0))
    with pytest.raises(ImageError, match="truth"):
        res.bad_fraction(truth[:, :10], 1.0)


# ------------------------------------------------------------------------------------------------
# the OpenCV backend


def test_opencv_backend_agrees_with_numba():
    rng = np.random.default_rng(11)
    left, right = square_scene(rng, H=120, W=240)
    config = SADConfig(num_disparities=32)
    ours = compute_disparity(left, right, config)
    bm = compute_disparity(left, right, replace(config, backend="opencv"))
    both = ours.valid & bm.valid
    assert both.sum() > 0.8 * max(ours.valid.sum(), bm.valid.sum())
    assert np.mean(np.abs(ours.left[both] - bm.left[both]) <= 0.5) > 0.95
    right_both = np.isfinite(ours.right) & np.isfinite(bm.right)
    assert np.mean(np.abs(ours.right[right_both] - bm.right[right_both]) <= 0.5) > 0.95
    assert not bm.valid[40:80, 86:98].mean() > 0.1  # the same left-right check


def test_opencv_backend_without_subpixel_gives_integers():
    rng = np.random.default_rng(12)
    left, right = shifted_pair((80, 160), 12.3, rng)
    res = compute_disparity(left, right, SADConfig(num_disparities=32, backend="opencv", subpixel=False))
    values = res.left[res.valid]
    assert values.size and np.array_equal(values, np.rint(values))


# ------------------------------------------------------------------------------------------------
# a real pair: Middlebury 2014 Motorcycle at quarter size, shipped with scikit-image


def test_middlebury_motorcycle_accuracy():
    """Valid fraction and bad-pixel rates against the ground truth (``+inf`` unknown; left u matches right
    u − d), for our defaults and for two StereoBM calls with its own defaults and the same 1 px check."""
    data = pytest.importorskip("skimage.data")
    left_rgb, right_rgb, truth = data.stereo_motorcycle()
    left = cv2.cvtColor(left_rgb, cv2.COLOR_RGB2GRAY)
    right = cv2.cvtColor(right_rgb, cv2.COLOR_RGB2GRAY)
    assert np.isinf(truth).any() and not np.isnan(truth).any()

    ours = compute_disparity(left, right, SADConfig(num_disparities=64))
    valid, bad1, bad2 = ours.valid_fraction, ours.bad_fraction(truth, 1.0), ours.bad_fraction(truth, 2.0)
    # measured: 63.4 % valid, 3.55 % off by > 1 px, 2.17 % off by > 2 px; the goals:
    assert valid >= 0.5 and bad1 <= 0.04 and bad2 <= 0.025, (valid, bad1, bad2)

    stereobm = SADConfig(
        num_disparities=64, backend="opencv", prefilter_cap=31, uniqueness_ratio=15, texture_threshold=0
    )
    bm = compute_disparity(left, right, stereobm)  # measured: 70.7 % valid, 7.3 % and 5.5 % bad
    assert bad1 < bm.bad_fraction(truth, 1.0) and bad2 < bm.bad_fraction(truth, 2.0)
    assert bm.bad_fraction(truth, 2.0) > 0.04  # the comparison is against the known figure, not a broken BM


@pytest.mark.parametrize("block_size", [9, 15, 19])
def test_texture_test_equals_the_opencv_box_filter(block_size):
    """The kernel sums the texture itself (uint16 sums up to 16×16 windows, int32 beyond): the same pixels pass
    as with OpenCV's box filter of ``|Sobel_x|`` that the OpenCV backend uses."""
    from stablemarks.vision.area_stereo import _textured, _xsobel

    data = pytest.importorskip("skimage.data")
    left_rgb, right_rgb, _ = data.stereo_motorcycle()
    left = cv2.cvtColor(left_rgb, cv2.COLOR_RGB2GRAY)
    right = cv2.cvtColor(right_rgb, cv2.COLOR_RGB2GRAY)
    config = SADConfig(block_size=block_size, num_disparities=16, uniqueness_ratio=0, lr_tolerance=1e6,
                       texture_threshold=2.0)  # fmt: skip
    res = compute_disparity(left, right, config)
    r = block_size // 2
    inside = (slice(r, left.shape[0] - r), slice(r + 15, left.shape[1] - r))  # every disparity fits
    want = _textured(_xsobel(left), config)[inside]
    assert 0.2 < want.mean() < 0.95  # both outcomes occur
    np.testing.assert_array_equal(res.valid[inside], want)
