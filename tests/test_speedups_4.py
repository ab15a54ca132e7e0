"""Issue 13, the per-frame pipeline faster (fourth pass): every replaced function against the former
implementation (kept here as the reference) on frames of several simulated scenarios and on random inputs — the
same values, bit for bit where the arithmetic is the same, else to 1e-9."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stablemarks.config import Config
from stablemarks.landmarks import _boundary_columns
from stablemarks.pipeline import plane_regions, run_front_end, select_landmarks
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario

SCENARIOS = ("lab", "corridor", "office", "hall")
COV_PRIOR = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2


@pytest.fixture(scope="module")
def frames():
    """Two frames of each scenario: (name, k, left, right, camera, map, true pose)."""
    out = []
    for name in SCENARIOS:
        run = simulate_run(load_scenario(name))
        for k in (0, len(run) // 2):
            f = run.render(k)
            out.append((name, k, f.left, f.right, run.scenario.camera.with_pan(run.pans[k]), run.scenario.map,
                        run.poses[k].as_array()))
    return out


@pytest.fixture(scope="module")
def models(frames):
    """The landmark model of every frame (the pipeline in regions, from the true pose)."""
    config = Config()
    out = []
    for name, k, left, right, camera, world_map, X in frames:
        reg = plane_regions(camera, X, COV_PRIOR, world_map, config, left.shape)
        front = run_front_end(left, right, config, reg)
        out.append((name, k, front, select_landmarks(front, camera, world_map, X, COV_PRIOR, config)))
    return out


# ------------------------------------------------------------------ the region's end per row
def boundary_columns_reference(region, lo, hi, outward, max_hole=2):
    """The former :func:`_boundary_columns`, in whole-array steps: holes filled from the last region column at
    or before each column and the next one at or after it, then each row's first run and the first gap after
    it."""
    W = region.shape[1]
    c0 = math.floor(min(max(lo, 0), W - 1))
    c1 = math.ceil(min(max(hi, 0), W - 1))
    if c1 < c0:
        return np.zeros(0, int), np.zeros(0)
    sub = region[:, c0 : c1 + 1]
    if outward < 0:
        sub = sub[:, ::-1]  # index 0 on the inner side
    rows = np.flatnonzero(sub.any(axis=1))
    if len(rows) == 0:
        return rows, np.zeros(0)
    run = sub[rows]
    n = run.shape[1]
    cols_idx = np.arange(n)
    prev = np.maximum.accumulate(np.where(run, cols_idx, -1), axis=1)
    nxt = np.minimum.accumulate(np.where(run, cols_idx, n)[:, ::-1], axis=1)[:, ::-1]
    run = run | ((prev >= 0) & (nxt < n) & (nxt - prev - 1 <= max_hole))
    start = np.argmax(run, axis=1)
    after = ~run & (np.arange(n)[None, :] > start[:, None])
    ends = after.any(axis=1)
    last = np.argmax(after, axis=1) - 1
    cols = (c1 - last) if outward < 0 else (c0 + last)
    return rows[ends], cols[ends].astype(float)


def _same_columns(got, want, where=""):
    for g, w in zip(got, want, strict=True):
        assert g.dtype == w.dtype, where
        assert np.array_equal(g, w), where


def test_boundary_columns_equal_the_array_reference_on_random_regions():
    """Random regions (sparse to dense, so holes of every width), windows inside, across and beyond the image,
    both directions and hole widths from 0 to 12."""
    rng = np.random.default_rng(4)
    for trial in range(300):
        H, W = int(rng.integers(1, 40)), int(rng.integers(1, 90))
        region = rng.random((H, W)) < rng.uniform(0.05, 0.95)
        if trial % 3 == 0:  # long runs with a few holes, as a plane's region has
            region = np.cumsum(rng.random((H, W)) < 0.1, axis=1) % 3 != 1
        lo = float(rng.uniform(-10, W + 5))
        hi = lo + float(rng.uniform(-3, W))
        for outward in (-1, 1):
            for hole in (0, 1, 2, 7, 12):
                _same_columns(_boundary_columns(region, lo, hi, outward, hole),
                              boundary_columns_reference(region, lo, hi, outward, hole), (trial, outward, hole))


def test_boundary_columns_equal_the_array_reference_on_plane_regions(models):
    """The fitted planes' regions of the simulated frames, every edge's search window, both directions."""
    config = Config()
    n = 0
    for name, k, _front, model in models:
        for fit in (f for f in model.fits if f):
            for e in fit.prediction.edges.values():
                if not np.all(np.isfinite(e.u)):
                    continue
                for img in (0, 1):
                    lo, hi = e.window(img, config.landmarks.search_sigma)
                    for outward in (-1, 1):
                        for hole in (2, 7, int(np.ceil(hi - lo))):
                            got = _boundary_columns(fit.region, lo, hi, outward, hole)
                            _same_columns(got, boundary_columns_reference(fit.region, lo, hi, outward, hole),
                                          (name, k, img, outward, hole))
                            n += len(got[0])
    assert n > 1000
