"""Issue 13, the per-frame pipeline faster (tenth pass): every replaced computation against the former
implementation (kept here as the reference) on frames of several simulated scenarios, bit for bit.

The SAD kernel's second-best costs (the uniqueness test) are taken only where a test reads them: the left pixels'
in the requested left columns, the right pixels' in the columns whose diagonals reach a requested right pixel
(:func:`~stablemarks.vision.area_stereo._seconds`). The reference is the kernel module with the former
``_seconds`` swapped back (compiled afresh, not cached)."""

from __future__ import annotations

import inspect
import sys
import types
from dataclasses import replace

import numpy as np
import pytest

from stablemarks.config import Config
from stablemarks.pipeline import _STEP, _pair_sobel, _planning_runs, _region_runs, pair_bands, plane_regions
from stablemarks.vision import area_stereo as A
from stablemarks.vision.segment_stereo import match_segments
from stablemarks.vision.segments import extract_vertical_segments

from .conftest import COV_PRIOR

FORMER_SECONDS = '''@njit(**_NJ)
def _seconds(costs, key_left, j_right, second_left, second_right, segs, n_seg, off, stride, jlane, mask, top, rneed,
             n_rneed, lneed, n_lneed):  # fmt: skip
    for s in range(n_seg):
        x0, x1, k0, k1 = _u64(segs[s, 0]), _u64(segs[s, 1]), _u64(segs[s, 2]), _u64(segs[s, 3])
        pos = x0
        for t in range(n_rneed):
            a, b = max(pos, _u64(max(rneed[t, 0], 0))), min(x1, _u64(max(rneed[t, 1], 0)))
            if a >= b:
                continue
            if pos < a:
                _second_left(costs, key_left, second_left, pos, a, k0, k1, stride, jlane, mask, top)
            _second_both(costs, key_left, j_right, second_left, second_right, a, b, k0, k1, off, stride, jlane, mask,
                         top)  # fmt: skip
            pos = b
        if pos < x1:
            _second_left(costs, key_left, second_left, pos, x1, k0, k1, stride, jlane, mask, top)


'''
"""The former ``_seconds`` (every column's left second-best cost; the two new arguments ignored)."""


@pytest.fixture(scope="module")
def former():
    """The kernel module with the former ``_seconds``, compiled in this process (no cache)."""
    src = inspect.getsource(A)
    start = src.index("@njit(**_NJ)\ndef _seconds(")
    end = src.index("@njit(**_NJ)\ndef _second_left(")
    src = src[:start] + FORMER_SECONDS + src[end:]
    src = src.replace("cache=True", "cache=False")
    mod = types.ModuleType("stablemarks.vision._area_stereo_former")
    mod.__package__ = "stablemarks.vision"
    sys.modules[mod.__name__] = mod
    try:
        exec(compile(src, "<former area_stereo>", "exec"), mod.__dict__)
    finally:
        del sys.modules[mod.__name__]
    return mod


def _same(a, b) -> None:
    for x, y in zip((a.left, a.right, a.valid), (b.left, b.right, b.valid), strict=True):
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes()


def _cases(scenario_frames, config):
    for name, k, left, right, camera, world_map, X in scenario_frames:
        reg = plane_regions(config.camera(camera), X, COV_PRIOR, world_map, config, left.shape)
        sobel = _pair_sobel(left, right)
        seg_l = extract_vertical_segments(left, config.segments, sobel=sobel[0])
        pairs = match_segments(seg_l, extract_vertical_segments(right, config.segments, sobel=sobel[1]),
                               config.matching)
        want_l = np.concatenate([reg.left, pair_bands(pairs, seg_l, config.filter.search_radius)])
        yield name, k, left, right, sobel, want_l, reg.right


@pytest.mark.parametrize("variant", ["default", "negative", "narrow"])
def test_kernel_same_as_former(scenario_frames, former, variant):
    """The disparity images of the scenario frames in their regions (the front end's: planes, pair bands, right
    search windows), left or right pixels only, dense, and a few sparse masks: bit for bit the former kernel's, with
    the default matching parameters and others (negative disparities, fewer disparities and a smaller window)."""
    config = Config()
    sad = {"default": config.sad, "negative": replace(config.sad, min_disparity=-8),
           "narrow": replace(config.sad, num_disparities=40, block_size=9)}[variant]
    rng = np.random.default_rng(10)
    for _name, _k, left, right, sobel, want_l, want_r in _cases(scenario_frames, config):
        H, W = left.shape
        none = np.zeros((0, 4), np.int64)
        sparse_l = rng.random((H, W)) < 0.02
        sparse_r = rng.random((H, W)) < 0.02
        p_new = A.prepare_pair(left, right, sad, *sobel)
        p_old = former.prepare_pair(left, right, sad, *sobel)
        for lreg, rreg in ((want_l, want_r), (want_l, none), (none, want_r), (None, None), (None, want_r),
                           (sparse_l, sparse_r), (sparse_l, None)):
            _same(A.regions_on_prepared(p_new, lreg, rreg), former.regions_on_prepared(p_old, lreg, rreg))
        _same(A.compute_disparity(left, right, sad), former.compute_disparity(left, right, sad))


def test_kernel_plans_same_as_former(scenario_frames, former):
    """With the planning runs made ahead (as the front end passes them) and with the uniqueness test off."""
    config = Config()
    for sad in (config.sad, replace(config.sad, uniqueness_ratio=0)):
        for _name, _k, left, right, sobel, want_l, want_r in _cases(scenario_frames, config):
            shape = left.shape
            runs = [_region_runs(want_l, shape, "regions"), _region_runs(want_r, shape, "right_regions")]
            plans = [_planning_runs(*rr, sad.num_disparities, _STEP, shape[1]) for rr in runs]
            p_new = A.prepare_pair(left, right, sad, *sobel)
            p_old = former.prepare_pair(left, right, sad, *sobel)
            _same(A._run_prepared(p_new, *runs, plans=plans), former._run_prepared(p_old, *runs, plans=plans))
