"""Disparity only where it is needed: :func:`compute_disparity_regions` against the dense :func:`compute_disparity`.

At every requested pixel the restricted computation must give exactly the dense values (the same costs, winners,
tests and sub-pixel refinement: compared bit for bit, NaN where the dense result is NaN), and NaN / False
elsewhere. The scenes are rendered frames of the built-in simulator scenarios and Middlebury's Motorcycle; the
regions are random rectangles (some touching the image borders), random blobs, and bands around vertical lines
like the ones the method asks for around candidate segment pairs.
"""

from __future__ import annotations

import zlib
from dataclasses import replace
from functools import cache

import cv2
import numpy as np
import pytest

from stablemarks.errors import InputError
from stablemarks.vision.area_stereo import SADConfig, compute_disparity, compute_disparity_regions

SCENES = [("lab", 0), ("lab", 12), ("corridor", 0), ("corridor", 40), ("room", 6), ("loop", 150), ("middlebury", 0)]


@cache
def scene(name: str, k: int) -> tuple[np.ndarray, np.ndarray]:
    """A rectified uint8 pair: frame ``k`` of a built-in scenario, or Middlebury 2014 Motorcycle (quarter size)."""
    if name == "middlebury":
        data = pytest.importorskip("skimage.data")
        left, right, _ = data.stereo_motorcycle()
        return cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), cv2.cvtColor(right, cv2.COLOR_RGB2GRAY)
    from stablemarks.sim import load_scenario, simulate_run

    frame = simulate_run(load_scenario(name), 1).render(k)
    return frame.left, frame.right


def random_rectangles(rng: np.random.Generator, shape: tuple[int, int], n: int) -> np.ndarray:
    """(n, 4) rectangles (row0, row1, col0, col1), every other one pinned to an image border."""
    H, W = shape
    rects = []
    for i in range(n):
        h, w = rng.integers(1, H // 2), rng.integers(1, W // 2)
        r0, c0 = rng.integers(0, H - h + 1), rng.integers(0, W - w + 1)
        side = i % 5
        if side == 1:
            r0 = 0
        elif side == 2:
            r0 = H - h
        elif side == 3:
            c0 = 0
        elif side == 4:
            c0 = W - w
        rects.append((r0, r0 + h, c0, c0 + w))
    return np.array(rects, dtype=np.int64)


def random_blobs(rng: np.random.Generator, shape: tuple[int, int], fraction: float) -> np.ndarray:
    """(H, W) bool: smooth random blobs covering about ``fraction`` of the image (many runs per row)."""
    noise = cv2.GaussianBlur(rng.standard_normal(shape), (0, 0), 12.0)
    return noise > np.quantile(noise, 1.0 - fraction)


def segment_bands(rng: np.random.Generator, shape: tuple[int, int], n: int, half_width: int) -> np.ndarray:
    """(H, W) bool: bands of ±``half_width`` columns around ``n`` slanted vertical segments."""
    H, W = shape
    mask = np.zeros(shape, bool)
    for _ in range(n):
        v0, v1 = np.sort(rng.integers(0, H, 2))
        u0, slope = rng.uniform(0, W), rng.uniform(-0.2, 0.2)
        for v in range(v0, v1 + 1):
            u = int(round(u0 + slope * (v - v0)))
            mask[v, max(0, u - half_width) : max(0, u + half_width + 1)] = True
    return mask


def as_mask(regions, shape) -> np.ndarray:
    regions = np.asarray(regions)
    if regions.dtype == bool:
        return regions
    mask = np.zeros(shape, bool)
    for r0, r1, c0, c1 in regions:
        mask[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)] = True
    return mask


def check_against_dense(left, right, config, dense, regions, right_regions=None):
    """The region result equals ``dense`` at the requested pixels and is NaN / False elsewhere."""
    res = compute_disparity_regions(left, right, config, regions, right_regions)
    lmask = as_mask(regions, left.shape)
    rmask = np.zeros(left.shape, bool) if right_regions is None else as_mask(right_regions, left.shape)
    for a in (res.left, res.right, res.valid):
        assert a.shape == left.shape and not a.flags.writeable
    np.testing.assert_array_equal(res.left[lmask], dense.left[lmask])  # NaN where the dense one is NaN
    np.testing.assert_array_equal(res.valid[lmask], dense.valid[lmask])
    np.testing.assert_array_equal(res.right[rmask], dense.right[rmask])
    assert np.isnan(res.left[~lmask]).all() and not res.valid[~lmask].any() and np.isnan(res.right[~rmask]).all()
    assert np.array_equal(res.valid, np.isfinite(res.left))
    return res


@pytest.mark.parametrize("name,k", SCENES)
def test_regions_equal_the_dense_computation(name, k):
    left, right = scene(name, k)
    config = SADConfig()
    dense = compute_disparity(left, right, config)
    assert dense.valid.mean() > 0.05  # a scene with something to match
    rng = np.random.default_rng(zlib.crc32(f"{name}{k}".encode()))
    shape = left.shape
    H, W = shape
    cases = [
        (random_rectangles(rng, shape, 4), random_rectangles(rng, shape, 3)),
        (random_rectangles(rng, shape, 1), None),
        (random_blobs(rng, shape, 0.3), random_blobs(rng, shape, 0.2)),
        (segment_bands(rng, shape, 6, 12), segment_bands(rng, shape, 4, 8)),
        # the four borders and the corners, single rows and columns
        (np.array([[0, H, 0, 40], [0, H, W - 40, W], [0, 30, 0, W], [H - 30, H, 0, W]]), np.array([[0, H, W - 1, W]])),
        (np.array([[100, 101, 0, W], [0, H, 320, 321]]), np.array([[200, 201, 0, W]])),
    ]
    checked = 0
    for regions, right_regions in cases:
        res = check_against_dense(left, right, config, dense, regions, right_regions)
        checked += int(res.valid.sum())
    assert checked > 1000  # the comparisons covered valid pixels, not only NaN


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(num_disparities=48, min_disparity=-8, block_size=9),
        dict(subpixel=False, uniqueness_ratio=0, texture_threshold=0.0),
        dict(prefilter="none", block_size=7, num_disparities=20, lr_tolerance=0.0),
        dict(num_disparities=5, block_size=3, uniqueness_ratio=10),
    ],
)
def test_regions_equal_the_dense_computation_for_other_configurations(kwargs):
    left, right = scene("lab", 6)
    config = SADConfig(**kwargs)
    dense = compute_disparity(left, right, config)
    rng = np.random.default_rng(len(kwargs))
    shape = left.shape
    check_against_dense(left, right, config, dense, random_rectangles(rng, shape, 5), random_blobs(rng, shape, 0.25))
    check_against_dense(left, right, config, dense, segment_bands(rng, shape, 5, 20), random_rectangles(rng, shape, 2))


def test_masks_whose_runs_change_on_every_row():
    """A diagonal band and a checkerboard of short runs: the column sums are partly carried over from the row
    above and partly summed afresh on every row."""
    left, right = scene("corridor", 20)
    dense = compute_disparity(left, right)
    H, W = left.shape
    rows, cols = np.indices((H, W))
    diagonal = np.abs(cols - rows - 60) < 25
    checker = ((rows // 7 + cols // 23) % 2 == 0) & (cols > 50)
    check_against_dense(left, right, SADConfig(), dense, diagonal, checker)
    check_against_dense(left, right, SADConfig(), dense, checker, diagonal)
    stairs = np.zeros((H, W), bool)  # runs that grow and shrink by a few columns from row to row
    for v in range(H):
        stairs[v, 200 - (v % 37) : 260 + (v % 11)] = True
    check_against_dense(left, right, SADConfig(), dense, stairs, stairs)


def test_region_forms():
    left, right = scene("room", 3)
    dense = compute_disparity(left, right)
    H, W = left.shape
    # None: every left pixel, no right pixel
    every = compute_disparity_regions(left, right)
    np.testing.assert_array_equal(every.left, dense.left)
    np.testing.assert_array_equal(every.valid, dense.valid)
    assert np.isnan(every.right).all()
    both = compute_disparity_regions(left, right, right_regions=np.ones((H, W), bool))
    np.testing.assert_array_equal(both.right, dense.right)
    # nothing requested
    empty = compute_disparity_regions(left, right, regions=np.zeros((0, 4), int))
    assert not empty.valid.any() and np.isnan(empty.left).all() and np.isnan(empty.right).all()
    # rectangles reaching out of the image are clipped; a list of tuples works; empty rectangles are ignored
    rects = [(-20, 50, -10, 80), (400, 9999, 600, 9999), (30, 30, 5, 90)]
    check_against_dense(left, right, SADConfig(), dense, np.array(rects), [(0, H, 100, 140)])
    res = compute_disparity_regions(left, right, regions=rects)
    np.testing.assert_array_equal(res.left[:50, :80], dense.left[:50, :80])
    # the OpenCV backend computes everything and masks it
    cv_config = SADConfig(backend="opencv")
    cv_dense = compute_disparity(left, right, cv_config)
    mask = random_blobs(np.random.default_rng(3), (H, W), 0.4)
    cv_res = compute_disparity_regions(left, right, cv_config, mask, mask)
    np.testing.assert_array_equal(cv_res.left[mask], cv_dense.left[mask])
    np.testing.assert_array_equal(cv_res.right[mask], cv_dense.right[mask])
    assert np.isnan(cv_res.left[~mask]).all() and not cv_res.valid[~mask].any()


@pytest.mark.parametrize(
    "regions,match",
    [
        (np.ones((10, 10), bool), "bool mask of the images' shape"),
        (np.zeros((3, 3)), "integer rectangles"),
        (np.zeros((2, 5), int), "integer rectangles"),
        ([1, 2, 3, 4], "integer rectangles"),
    ],
)
def test_bad_regions(regions, match):
    left, right = scene("lab", 0)
    with pytest.raises(InputError, match=match):
        compute_disparity_regions(left, right, regions=regions)
    with pytest.raises(InputError, match="right_regions"):
        compute_disparity_regions(left, right, right_regions=regions)


def test_float_images_and_a_small_image():
    left, right = scene("lab", 0)
    lf, rf = left / 255.0, right / 255.0
    config = SADConfig(num_disparities=32)
    rects = np.array([[100, 200, 300, 420]])
    a = compute_disparity_regions(lf, rf, config, rects, rects)
    b = compute_disparity_regions(left, right, config, rects, rects)
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)
    tiny = compute_disparity_regions(left[:10, :12], right[:10, :12], SADConfig(block_size=15))
    assert not tiny.valid.any()
    small = replace(config, num_disparities=16, block_size=5)
    crop = (slice(0, 40), slice(0, 60))
    check_against_dense(left[crop], right[crop], small, compute_disparity(left[crop], right[crop], small),
                        np.array([[0, 40, 0, 60]]), np.array([[0, 40, 0, 60]]))  # fmt: skip
