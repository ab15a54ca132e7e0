import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stablemarks.errors import ConfigError
from stablemarks.vision.segment_stereo import MatchConfig, SegmentPairs, match_segments
from stablemarks.vision.segments import Segments, extract_vertical_segments

from .test_segments import render_bars, true_edges

# ---------------------------------------------------------------- rendered stereo pairs


def test_bars_at_known_disparities_are_all_matched_with_their_disparity():
    disparity = np.array([12.3, 20.6, 31.15, 8.4, 40.7, 25.25])
    bars = [(18.3 + 48 * k, 29.6 + 48 * k, 25 + 7 * k, 215 - 5 * k, 190.0 if k % 2 else 25.0) for k in range(6)]
    left = render_bars(bars, noise=2.0, seed=1, offset=0)
    right_bars = [(a - d, b - d, *rest) for (a, b, *rest), d in zip(bars, disparity, strict=True)]
    right = render_bars(right_bars, noise=2.0, seed=1, offset=6)  # background plane at disparity 6
    sl, sr = extract_vertical_segments(left), extract_vertical_segments(right)
    pairs = match_segments(sl, sr)

    edges = true_edges(bars)
    d_true = np.repeat(disparity, 2)
    assert len(pairs) == len(edges), "every edge matched, nothing else"
    order = np.argsort(edges[:, 0])
    np.testing.assert_allclose(pairs.u_left, edges[order, 0], atol=0.1)
    np.testing.assert_allclose(pairs.disparity, d_true[order], atol=0.1)
    np.testing.assert_array_equal(sl.polarity[pairs.left_index], edges[order, 3])
    np.testing.assert_allclose(pairs.length_similarity, 1.0, atol=0.02)
    assert np.all(np.diff(pairs.u_left) > 0)


# ---------------------------------------------------------------- the dynamic programming


def greedy(left, right, config=MatchConfig()):
    """Best-similarity-first one-to-one matching over the same candidates, without ordering."""
    s = np.full((len(left), len(right)), -np.inf)
    for i in range(len(left)):
        for j in range(len(right)):
            one = match_segments(left.subset([i]), right.subset([j]), config)
            if len(one):
                s[i, j] = one.similarity[0]
    chosen = []
    while np.isfinite(s.max()):
        i, j = np.unravel_index(np.argmax(s), s.shape)
        chosen.append((int(i), int(j)))
        s[i, :], s[:, j] = -np.inf, -np.inf
    return sorted(chosen)


def test_dp_ordering_beats_greedy_on_a_repeated_pattern():
    """Four equal edges every 30 px at disparity 20: the true pairs have length similarity 0.9,
    the pairs shifted by one period (disparity 50) have 1.0. Greedy takes the shifted ones; the DP,
    which must leave two segments unmatched to shift, keeps the true ones."""
    u = 100.0 + 30.0 * np.arange(4)
    left = Segments.from_lines(u, 50.0, 50.0 + np.array([100.0, 90.0, 100.0, 90.0]))
    right = Segments.from_lines(u - 20.0, 50.0, 50.0 + np.array([90.0, 100.0, 90.0, 100.0]))
    assert greedy(left, right) == [(1, 0), (2, 1), (3, 2)]
    pairs = match_segments(left, right)
    assert list(zip(pairs.left_index, pairs.right_index, strict=True)) == [(0, 0), (1, 1), (2, 2), (3, 3)]
    np.testing.assert_allclose(pairs.disparity, 20.0)


def test_stacked_segments_do_not_constrain_each_other():
    """Top: left 100 -> right 80; bottom: left 102 -> right 70. The pairs cross, but on no common row."""
    left = Segments.from_lines([100.0, 102.0], [10.0, 120.0], [100.0, 200.0])
    right = Segments.from_lines([80.0, 70.0], [10.0, 120.0], [100.0, 200.0])
    pairs = match_segments(left, right)
    assert list(zip(pairs.left_index, pairs.right_index, strict=True)) == [(0, 0), (1, 1)]


def test_each_segment_is_used_at_most_once():
    """A long left edge broken into two halves in the right image gets one partner."""
    left = Segments.from_lines([100.0], [0.0], [200.0])
    right = Segments.from_lines([80.0, 80.0], [0.0, 100.0], [90.0, 200.0])
    pairs = match_segments(left, right)
    assert len(pairs) == 1 and pairs.right_index[0] == 1  # the longer half: more similar
    np.testing.assert_allclose(pairs.overlap, 1.0)
    np.testing.assert_allclose([pairs.v_top[0], pairs.v_bottom[0]], [100.0, 200.0])


# ---------------------------------------------------------------- hard constraints and Eq 18


def test_length_similarity_is_eq_18():
    left = Segments.from_lines([100.0, 200.0], [20.0, 20.0], [100.0, 120.0])  # lengths 80, 100
    right = Segments.from_lines([90.0, 180.0], [10.0, 20.0], [110.0, 70.0])  # lengths 100, 50
    pairs = match_segments(left, right)
    np.testing.assert_array_equal(pairs.length_similarity, [80.0 / 100.0, 50.0 / 100.0])
    np.testing.assert_array_equal(pairs.length_left, [80.0, 100.0])
    np.testing.assert_array_equal(pairs.length_right, [100.0, 50.0])
    np.testing.assert_allclose(pairs.overlap, 1.0)
    np.testing.assert_allclose(pairs.similarity, (1.0 + 1.0 + pairs.length_similarity) / 3.0)


def test_polarity_must_agree():
    left = Segments.from_lines([100.0], [0.0], [100.0], polarity=1)
    right = Segments.from_lines([90.0], [0.0], [100.0], polarity=-1)
    assert len(match_segments(left, right)) == 0
    assert len(match_segments(left, right, MatchConfig(same_polarity=False))) == 1


@pytest.mark.parametrize(
    ("disparity", "matched"), [(-0.5, False), (0.0, True), (64.0, True), (64.5, False), (30.0, True)]
)
def test_disparity_must_lie_in_range(disparity, matched):
    left = Segments.from_lines([100.0], [0.0], [100.0])
    right = Segments.from_lines([100.0 - disparity], [0.0], [100.0])
    pairs = match_segments(left, right)
    assert len(pairs) == int(matched)
    if matched:
        np.testing.assert_allclose(pairs.disparity, disparity)


def test_disparity_is_taken_at_the_middle_row_of_the_overlap():
    left = Segments.from_lines([100.0], [0.0], [100.0], slope=0.02)
    right = Segments.from_lines([80.0], [50.0], [150.0], slope=0.02)
    pairs = match_segments(left, right)
    np.testing.assert_allclose([pairs.v_top[0], pairs.v_bottom[0]], [50.0, 100.0])
    np.testing.assert_allclose(pairs.u_left, 100.0 + 0.02 * 25.0)
    np.testing.assert_allclose(pairs.u_right, 80.0 - 0.02 * 25.0)
    np.testing.assert_allclose(pairs.overlap, 0.5)


def test_orientation_and_overlap_constraints():
    left = Segments.from_lines([100.0], [0.0], [100.0])
    assert len(match_segments(left, Segments.from_lines([90.0], [0.0], [100.0], slope=0.2))) == 0
    assert len(match_segments(left, Segments.from_lines([90.0], [60.0], [160.0]))) == 0  # overlap 0.4
    assert len(match_segments(left, Segments.from_lines([90.0], [40.0], [140.0]))) == 1  # overlap 0.6


def test_empty_inputs_give_empty_pairs():
    some = Segments.from_lines([10.0], [0.0], [50.0])
    for a, b in [(Segments.empty(), some), (some, Segments.empty()), (Segments.empty(), Segments.empty())]:
        pairs = match_segments(a, b)
        assert isinstance(pairs, SegmentPairs) and len(pairs) == 0 and pairs.disparity.shape == (0,)


segment_sets = st.integers(1, 12).flatmap(
    lambda n: st.tuples(
        st.lists(st.floats(0.0, 300.0), min_size=n, max_size=n),
        st.lists(st.floats(0.0, 150.0), min_size=n, max_size=n),
        st.lists(st.floats(5.0, 100.0), min_size=n, max_size=n),
        st.lists(st.sampled_from([-1, 1]), min_size=n, max_size=n),
    )
)


def _segments(spec):
    u, top, length, pol = (np.array(x) for x in spec)
    return Segments.from_lines(u, top, top + length, polarity=pol.astype(np.int8))


@settings(max_examples=60, deadline=None)
@given(segment_sets, segment_sets)
def test_pairs_are_one_to_one_in_range_and_ordered_where_they_overlap(spec_l, spec_r):
    left, right = _segments(spec_l), _segments(spec_r)
    config = MatchConfig()
    pairs = match_segments(left, right, config)
    assert len(set(pairs.left_index)) == len(pairs) == len(set(pairs.right_index))
    assert np.all((pairs.disparity >= config.min_disparity) & (pairs.disparity <= config.max_disparity))
    assert np.all(left.polarity[pairs.left_index] == right.polarity[pairs.right_index])
    assert np.all(pairs.similarity >= config.min_similarity)
    assert np.all(pairs.overlap >= config.min_overlap)
    for p in range(len(pairs)):
        for q in range(p + 1, len(pairs)):
            top, bottom = max(pairs.v_top[p], pairs.v_top[q]), min(pairs.v_bottom[p], pairs.v_bottom[q])
            if bottom <= top:
                continue
            v = 0.5 * (top + bottom)
            il, ir = pairs.left_index[[p, q]], pairs.right_index[[p, q]]
            du_l = np.diff(left.subset(il).u_at(v))[0]
            du_r = np.diff(right.subset(ir).u_at(v))[0]
            assert du_l * du_r >= 0, "pairs cross on rows where both are present"


def test_pairs_subset():
    left = Segments.from_lines([100.0, 200.0], 0.0, 100.0)
    right = Segments.from_lines([90.0, 180.0], 0.0, 100.0)
    pairs = match_segments(left, right)
    sub = pairs.subset(np.array([False, True]))
    assert len(sub) == 1 and sub.left_index[0] == 1 and sub.disparity[0] == pytest.approx(20.0)
    with pytest.raises(IndexError, match="boolean mask"):
        pairs.subset(np.ones(3, bool))


@pytest.mark.parametrize(
    ("field", "value"),
    [("max_disparity", -1.0), ("min_disparity", np.nan), ("min_overlap", 0.0), ("min_overlap", 1.5),
     ("max_orientation_difference", 0.0), ("weight_length", -1.0), ("min_similarity", 1.5),
     ("occlusion_cost", 0.0)],
)  # fmt: skip
def test_bad_config_raises_config_error(field, value):
    with pytest.raises(ConfigError, match="MatchConfig.*expected"):
        MatchConfig(**{field: value})
