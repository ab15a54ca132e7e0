"""Disparity only where the method reads it (issue 13, items 1 and 3): the localizer and ``process_frame`` with SAD
computed in regions give the dense computation's pairs, candidates, selection decisions and poses."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stablemarks.config import Config
from stablemarks.localizer import Localizer
from stablemarks.pipeline import (
    DENSE_ABOVE,
    RegionDisparity,
    Regions,
    disparity_limits,
    plane_regions,
    process_frame,
    region_work,
    run_front_end,
    select_landmarks,
    valid_columns,
)
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource
from stablemarks.vision.area_stereo import SADConfig, compute_disparity

COV_PRIOR = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
SCENARIOS = ("lab", "corridor", "room", "office", "hall")


@pytest.fixture(scope="module")
def runs():
    return {name: simulate_run(load_scenario(name)) for name in SCENARIOS}


# ------------------------------------------------------------------ comparing results
def assert_same(a, b, where: str = "") -> None:
    """Equal values: floats to 1e-9 (NaN equal), everything else exactly; dataclasses, dicts and sequences
    field by field."""
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape, where
        if a.dtype.kind == "f" or b.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9, equal_nan=True, err_msg=where)
        else:
            assert np.array_equal(a, b), where
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert (np.isnan(a) and np.isnan(b)) or abs(a - b) <= 1e-9, (where, a, b)
    else:
        assert a == b, (where, a, b)


def assert_same_model(region, dense, where: str) -> None:
    """Two :class:`FrameLandmarks` (or None) of the same frame: the same plane fits, boundaries, candidates and
    decisions."""
    assert (region is None) == (dense is None), where
    if dense is None:
        return
    assert_same(region.warnings, dense.warnings, f"{where}.warnings")
    assert [bool(f) for f in region.fits] == [bool(f) for f in dense.fits], where
    for i, (fr, fd) in enumerate(zip(region.fits, dense.fits, strict=True)):
        if fd:
            assert_same((fr.a, fr.b, fr.s0, fr.cov_R, fr.n_points, fr.n_inliers, fr.chi2_dof),
                        (fd.a, fd.b, fd.s0, fd.cov_R, fd.n_points, fd.n_inliers, fd.chi2_dof), f"{where}.fits[{i}]")
            assert np.array_equal(fr.region, fd.region), f"{where}.fits[{i}].region"
        else:
            assert (fr.reason, fr.n_pixels) == (fd.reason, fd.n_pixels), f"{where}.fits[{i}]"
    for i, (mr, md) in enumerate(zip(region.planes, dense.planes, strict=True)):
        assert mr.searched == md.searched, f"{where}.planes[{i}].searched"
        assert_same(mr.boundaries, md.boundaries, f"{where}.planes[{i}].boundaries")
        assert np.array_equal(mr.members, md.members), f"{where}.planes[{i}].members"
    assert_same(region.candidates, dense.candidates, f"{where}.candidates")
    assert [(c.selected, c.reason) for c in region.candidates] == [(c.selected, c.reason) for c in dense.candidates]


def assert_same_front(region, dense, where: str) -> None:
    assert np.array_equal(region.kept, dense.kept), f"{where}.kept"
    assert_same(region.pairs, dense.pairs, f"{where}.pairs")
    # every pixel computed holds the dense value bit for bit
    if region.lazy is not None:
        for got, want, done in ((region.disparity.left, dense.disparity.left, region.lazy.done[0]),
                                (region.disparity.right, dense.disparity.right, region.lazy.done[1])):
            assert np.array_equal(got[done], want[done], equal_nan=True), where
            assert np.isnan(got[~done]).all(), where
        assert np.array_equal(region.disparity.valid, dense.disparity.valid & region.lazy.done[0]), where


# ------------------------------------------------------------------ the localizer, frame by frame
def _localizers(source, start, cov=None):
    config = Config().with_source_defaults(source.config_defaults)
    region = Localizer(source.world_map, source.camera, start_pose=start, start_cov=cov, config=config)
    dense = Localizer(source.world_map, source.camera, start_pose=start, start_cov=cov, config=config)
    dense.dense_disparity = True
    return region, dense


def _count_models(loc: Localizer) -> list[int]:
    calls = [0]
    model = loc.method.model

    def counted(*args):
        calls[0] += 1
        return model(*args)

    loc.method.model = counted
    return calls


@pytest.mark.parametrize("name", SCENARIOS)
def test_localizer_with_regions_is_the_dense_localizer(runs, name):
    """Two localizers on the same frames, one computing SAD in regions, one dense: the same pairs, plane fits,
    candidates, selection decisions, associations, landmarks and poses, frame after frame — from the start and
    from a pose in the middle of the run (with a wider prior, so that the widened search runs too)."""
    run = runs[name]
    source = SimulatedSource(run)
    n_frames, stats = 3, {"frames": 0, "regions": 0, "models": 0, "topped_up": 0}
    for k0, cov in ((0, None), (len(run) // 2, COV_PRIOR * 4.0)):
        region, dense = _localizers(source, run.poses[k0].as_array(), cov)
        calls = _count_models(region)
        for k in range(k0, min(len(run), k0 + n_frames)):
            frame = source.frame(k)
            kw = dict(odometry=frame.odometry, pan=frame.pan)
            est_r = region.step(frame.stamp, frame.left, frame.right, **kw)
            est_d = dense.step(frame.stamp, frame.left, frame.right, **kw)
            where = f"{name} frame {k}"
            assert est_d.front.lazy is None
            assert_same_front(est_r.front, est_d.front, where)
            assert_same_model(est_r.model, est_d.model, where)
            np.testing.assert_allclose(est_r.pose, est_d.pose, rtol=0, atol=1e-9, err_msg=where)
            np.testing.assert_allclose(est_r.cov, est_d.cov, rtol=0, atol=1e-9, err_msg=where)
            rec_r, rec_d = est_r.record.to_dict(), est_d.record.to_dict()
            rec_r.pop("timings"), rec_d.pop("timings")
            assert_same(rec_r, rec_d, where)
            assert est_r.pan_command == est_d.pan_command
            assert_same([c.pair for c in est_r.entered.candidates if c is not None],
                        [c.pair for c in est_d.entered.candidates if c is not None], where)
            stats["frames"] += 1
            stats["regions"] += est_r.front.lazy is not None
            stats["topped_up"] += est_r.front.lazy is not None and est_r.front.lazy.calls > 1
        stats["models"] += calls[0]
        assert_same(region.landmarks(), dense.landmarks(), name)
    # most frames are computed in regions (the others dense: regions about as large as the image)
    assert stats["regions"] >= stats["frames"] // 2, stats


def test_the_localizer_runs_the_widened_search_on_region_fronts(runs):
    """When the walls are not where the prediction puts them the localizer looks again with wider gates (office,
    frames 9 and 10): that second model reads disparity the front end did not compute, and computes it."""
    run = runs["office"]
    source = SimulatedSource(run)
    region, dense = _localizers(source, run.poses[0].as_array())
    for k in range(11):
        frame = source.frame(k)
        est_r = region.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        est_d = dense.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        assert_same_front(est_r.front, est_d.front, f"office frame {k}")
        assert_same_model(est_r.model, est_d.model, f"office frame {k}")
        np.testing.assert_allclose(est_r.pose, est_d.pose, rtol=0, atol=1e-9)
        np.testing.assert_allclose(est_r.cov, est_d.cov, rtol=0, atol=1e-9)
    # the widened search itself, forced on the last frame's fronts: the same model from regions as from dense
    cam = region.camera.with_pan(frame.pan)
    wide_r = region.method.model(est_r.front, cam, region.world_map, region.pose, region.cov * 25, region.config)
    wide_d = dense.method.model(est_d.front, cam, dense.world_map, dense.pose, dense.cov * 25, dense.config)
    assert_same_model(wide_r, wide_d, "office frame 10, widened")


# ------------------------------------------------------------------ process_frame
@pytest.mark.parametrize("name", SCENARIOS)
def test_process_frame_with_regions_is_dense(runs, name):
    """``process_frame`` (regions) against ``process_frame(dense=True)`` on frames across the run, with the true
    pose as prior and with a wider, offset prior; also a front end run for another prior (its regions do not fit
    the frame's planes: ``select_landmarks`` computes what is missing) and one with no plane region at all."""
    run = runs[name]
    sc = run.scenario
    config = Config()
    for k in (0, len(run) // 2):
        frame = run.render(k)
        camera = sc.camera.with_pan(run.pans[k])
        X = run.poses[k].as_array()
        for prior, cov in ((X, COV_PRIOR), (X + np.array([0.05, -0.04, 0.01]), COV_PRIOR * 9.0)):
            where = f"{name} frame {k}"
            dense = process_frame(frame.left, frame.right, camera, sc.map, prior, cov, config, dense=True)
            region = process_frame(frame.left, frame.right, camera, sc.map, prior, cov, config)
            assert_same_front(region.front, dense.front, where)
            assert_same_model(region, dense, where)
            assert valid_columns(region.front) == valid_columns(dense.front.disparity), where
        # regions made for another prior, and none: the missing disparity is computed on the way
        other = plane_regions(camera, X + np.array([0.3, 0.2, 0.1]), COV_PRIOR, sc.map, config, frame.left.shape)
        for regions in (other, Regions.none()):
            front = run_front_end(frame.left, frame.right, config, regions)
            got = select_landmarks(front, camera, sc.map, X, COV_PRIOR, config)
            want = select_landmarks(run_front_end(frame.left, frame.right, config), camera, sc.map, X, COV_PRIOR,
                                    config)
            assert_same_front(front, want.front, f"{name} frame {k}, other regions")
            assert_same_model(got, want, f"{name} frame {k}, other regions")


def test_front_end_regions_keep_the_pairs_the_filter_keeps(runs):
    """The pair bands alone (no plane) give the dense filter's decisions, and only a part of the image is
    computed."""
    run = runs["corridor"]
    frame = run.render(0)
    config = Config()
    front = run_front_end(frame.left, frame.right, config, Regions.none())
    dense = run_front_end(frame.left, frame.right, config)
    assert front.lazy is not None and front.lazy.calls == 1
    assert_same_front(front, dense, "corridor 0")
    assert front.lazy.done[0].mean() < 0.5 and not front.lazy.done[1].any()


# ------------------------------------------------------------------ valid_columns
def _pair(seed: int, shape=(120, 200), flat_left: int = 0, flat_right: int = 0, shift: int = 3):
    """A random textured pair (disparity ``shift``), optionally flat over ``flat_left`` columns on the left and
    ``flat_right`` on the right of both images (no valid pixel there)."""
    rng = np.random.default_rng(seed)
    H, W = shape
    base = rng.integers(0, 256, (H, W + shift)).astype(np.uint8)
    left, right = base[:, :W].copy(), base[:, shift:].copy()
    for img in (left, right):
        if flat_left:
            img[:, :flat_left] = 128
        if flat_right:
            img[:, W - flat_right :] = 128
    return left, right


SADS = (SADConfig(block_size=7, num_disparities=16), SADConfig(block_size=5, num_disparities=8, min_disparity=-3),
        SADConfig(block_size=9, num_disparities=16, texture_threshold=0.0, uniqueness_ratio=0))


@pytest.mark.parametrize("sad", SADS)
def test_disparity_limits_bound_the_valid_columns(sad):
    """No pixel outside :func:`disparity_limits` is ever valid, and on texture everywhere the limits are reached."""
    for seed in range(3):
        left, right = _pair(seed)
        d = compute_disparity(left, right, sad)
        (l0, l1), (r0, r1) = disparity_limits(sad, left.shape[1])
        for img, lo, hi in ((d.left, l0, l1), (d.right, r0, r1)):
            cols = np.flatnonzero(np.isfinite(img).any(axis=0))
            assert cols[0] >= lo and cols[-1] <= hi
            assert not np.isfinite(img[:, :lo]).any() and not np.isfinite(img[:, hi + 1 :]).any()
        assert valid_columns(d)[0] == (l0, l1) and valid_columns(d)[1] == (r0, r1)


@pytest.mark.parametrize("sad", SADS)
def test_region_disparity_finds_the_dense_valid_columns(sad):
    """:meth:`RegionDisparity.valid_columns` (from nothing computed) is :func:`valid_columns` of the dense images, also
    when the border columns hold no valid pixel (flat strips), and it needs only a part of the image."""
    for seed, flat in ((0, (0, 0)), (1, (30, 0)), (2, (0, 25)), (3, (40, 40))):
        left, right = _pair(seed, flat_left=flat[0], flat_right=flat[1])
        want = valid_columns(compute_disparity(left, right, sad))
        lazy = RegionDisparity(left, right, sad)
        assert lazy.valid_columns() == want, (seed, flat)
        assert valid_columns(lazy.result) == want
        assert lazy.done[0].mean() < 0.9


def test_decided_columns_decide_every_window_as_the_dense_ones():
    """After :meth:`RegionDisparity.decide_columns`, :func:`valid_columns` of what was computed passes or fails
    each search window as the dense answer does (``landmarks_on_plane``'s test), near the borders too."""
    sad = SADConfig(block_size=7, num_disparities=16)
    rng = np.random.default_rng(5)
    for seed, flat in ((0, (0, 0)), (1, (30, 20)), (2, (60, 0))):
        left, right = _pair(seed, flat_left=flat[0], flat_right=flat[1])
        W = left.shape[1]
        dense = valid_columns(compute_disparity(left, right, sad))
        windows = []
        for _ in range(40):
            u = rng.uniform(-10, W + 10)
            half = rng.uniform(1, 20)
            d = rng.uniform(0, 16)
            windows.append(((u - half, u + half), (u - d - half, u - d + half)))
        windows.append(((np.nan, np.nan), (1.0, 2.0)))
        lazy = RegionDisparity(left, right, sad, np.array([[40, 80, 90, 110]]), np.array([[40, 80, 80, 100]]))
        lazy.decide_columns(windows)
        got = valid_columns(lazy.result)

        def passes(vc, w):
            return all(c[0] + 1 < x[0] and x[1] < c[1] - 1 for x, c in zip(w, vc, strict=True))

        for w in windows:
            assert passes(got, w) == passes(dense, w), (seed, w, got, dense)


def test_possible_pixels_hold_every_valid_one(runs):
    """The texture screen of :meth:`RegionDisparity.possible` is the kernel's test: no valid pixel outside it."""
    frame = runs["lab"].render(0)
    sad = SADConfig(texture_threshold=3.0)  # a screen that removes something on the rendered walls
    d = compute_disparity(frame.left, frame.right, sad)
    lazy = RegionDisparity(frame.left, frame.right, sad)
    (l0, l1), (r0, r1) = disparity_limits(sad, frame.left.shape[1])
    removed = 0
    for image, img, cols in ((0, d.left, (l0, l0 + 40, l1)), (1, d.right, (r0, r1 - 17, r1))):
        for c in cols:
            possible = lazy.possible(image, c)
            assert not (np.isfinite(img[:, c]) & ~possible).any()
            removed += int((~possible).sum())
    assert removed > 0


def test_regions_about_as_large_as_the_image_are_computed_dense(runs):
    frame = runs["lab"].render(0)
    config = Config()
    H, W = frame.left.shape
    everything = Regions(np.array([[0, H, 0, W]]), np.array([[0, H, 0, W]]))
    assert region_work(everything.left, everything.right, config.sad, (H, W)) >= DENSE_ABOVE
    front = run_front_end(frame.left, frame.right, config, everything)
    assert front.lazy is None and front.regions is everything
    assert region_work(np.zeros((0, 4), np.int64), np.zeros((0, 4), np.int64), config.sad, (H, W)) == 0.0
