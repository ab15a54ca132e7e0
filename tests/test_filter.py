import cv2
import numpy as np
import pytest
from skimage import data

from stablemarks.errors import ImageError, InputError
from stablemarks.vision.filter import filter_pairs
from stablemarks.vision.segment_stereo import match_segments
from stablemarks.vision.segments import Segments, extract_vertical_segments

H, W = 240, 320


def disparity_image():
    """Background plane at disparity 8; a box in front at disparity 20 over columns 100-179.5."""
    disp = np.full((H, W), 8.0, np.float32)
    disp[:, 100:180] = 20.0
    return disp, np.ones((H, W), bool)


def scene():
    """The box's two edges (u = 99.5, 179.5) at disparity 20; a third left edge at u = 250 whose
    partner is hidden in the right image, so the matcher pairs it with a stray edge at disparity 35
    (paper Fig 5: false matches)."""
    left = Segments.from_lines([99.5, 179.5, 250.0], [40.0, 40.0, 60.0], [200.0, 200.0, 180.0])
    right = Segments.from_lines([79.5, 159.5, 215.0], [40.0, 40.0, 60.0], [200.0, 200.0, 180.0])
    pairs = match_segments(left, right)
    np.testing.assert_allclose(pairs.disparity, [20.0, 20.0, 35.0])
    return left, pairs


def test_false_pair_is_rejected_and_true_pairs_at_depth_edges_are_kept():
    left, pairs = scene()
    disp, valid = disparity_image()
    np.testing.assert_array_equal(filter_pairs(pairs, left, disp, valid), [True, True, False])


def test_only_the_disparity_within_the_search_radius_counts():
    left, pairs = scene()
    disp, valid = disparity_image()
    disp[:, 97:103] = 8.0  # the box's left edge pixels (u = 100) now read 8 within +-2 columns
    np.testing.assert_array_equal(filter_pairs(pairs, left, disp, valid), [False, True, False])
    np.testing.assert_array_equal(filter_pairs(pairs, left, disp, valid, search_radius=3), [True, True, False])


def test_invalid_and_nan_pixels_do_not_support():
    left, pairs = scene()
    disp, valid = disparity_image()
    valid[:, 90:110] = False
    disp[:, 170:190] = np.nan
    np.testing.assert_array_equal(filter_pairs(pairs, left, disp, valid), [False, False, False])


def test_support_fraction_and_tolerance():
    left, pairs = scene()
    disp, valid = disparity_image()
    disp[:120, 100:180] = 21.5  # upper half of the box reads 1.5 px off; the edges span rows 40-200
    support_lower = np.mean(np.arange(40, 201) >= 120)
    assert support_lower == pytest.approx(81 / 161)
    np.testing.assert_array_equal(filter_pairs(pairs, left, disp, valid, min_support=0.5), [True, True, False])
    np.testing.assert_array_equal(filter_pairs(pairs, left, disp, valid, min_support=0.6), [False, False, False])
    np.testing.assert_array_equal(
        filter_pairs(pairs, left, disp, valid, tolerance=1.5, min_support=1.0), [True, True, False]
    )


def test_no_pairs_gives_an_empty_mask():
    left, pairs = scene()
    disp, valid = disparity_image()
    assert filter_pairs(pairs.subset(np.zeros(3, bool)), left, disp, valid).shape == (0,)


@pytest.mark.parametrize(
    ("change", "error", "message"),
    [
        ({"disparity_left": np.zeros((H, W), np.int16)}, ImageError, "2-D float disparity"),
        ({"valid": np.ones((H, W + 1), bool)}, ImageError, "bool mask of shape"),
        ({"valid": np.ones((H, W), np.uint8)}, ImageError, "bool mask of shape"),
        ({"disparity_left": np.zeros((H, 200), np.float32), "valid": np.ones((H, 200), bool)}, ImageError,
         "inside the 200x240"),
        ({"tolerance": 0.0}, InputError, "tolerance: expected a positive"),
        ({"min_support": 1.5}, InputError, "min_support: expected"),
        ({"search_radius": -1}, InputError, "search_radius: expected"),
    ],
)  # fmt: skip
def test_bad_input(change, error, message):
    left, pairs = scene()
    disp, valid = disparity_image()
    args = {"disparity_left": disp, "valid": valid, **change}
    with pytest.raises(error, match=message):
        filter_pairs(pairs, left, **args)


def test_pairs_of_other_segments_are_refused():
    left, pairs = scene()
    disp, valid = disparity_image()
    with pytest.raises(InputError, match="pairs.left_index: expected left indices in"):
        filter_pairs(pairs, left.subset([0, 1]), disp, valid)


def test_on_a_real_pair_the_filter_removes_the_false_matches():
    """Middlebury "Motorcycle" (scikit-image, with ground truth): paper Fig 5 -> Fig 6."""
    left_rgb, right_rgb, truth = data.stereo_motorcycle()
    left, right = (cv2.cvtColor(x, cv2.COLOR_RGB2GRAY) for x in (left_rgb, right_rgb))
    seg_l = extract_vertical_segments(left)
    pairs = match_segments(seg_l, extract_vertical_segments(right))
    cv2.setNumThreads(1)
    raw = cv2.StereoBM_create(numDisparities=64, blockSize=15).compute(left, right)
    kept = filter_pairs(pairs, seg_l, np.where(raw >= 0, raw / 16.0, np.nan).astype(np.float32), raw >= 0)

    def correct(k):  # the true disparity of most edge pixels (nearest within +-2 columns) is within 1 px
        p = seg_l.pixels(int(pairs.left_index[k]))
        window = truth[p[:, 1, None], np.clip(p[:, 0, None] + np.arange(-2, 3), 0, truth.shape[1] - 1)]
        err = np.min(np.abs(np.where(np.isfinite(window), window, 1e9) - pairs.disparity[k]), axis=1)
        return np.median(err) < 1.0

    ok = np.array([correct(k) for k in range(len(pairs))])
    assert len(pairs) > 100 and kept.sum() > 80
    assert np.mean(~ok) > 0.05, "the segment matcher alone makes mistakes here"
    assert np.mean(ok[kept]) > 0.97
    assert np.mean(ok[~kept]) < 0.8
