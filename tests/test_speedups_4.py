"""Issue 13, the per-frame pipeline faster (fourth pass): every replaced function against the former
implementation (kept here as the reference) on frames of several simulated scenarios and on random inputs — the
same values, bit for bit where the arithmetic is the same, else to 1e-9."""

from __future__ import annotations

import math

import numpy as np

from stablemarks.config import Config
from stablemarks.landmarks import _boundary_columns

COV_PRIOR = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2


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


def test_boundary_columns_equal_the_array_reference_on_plane_regions(scenario_models):
    """The fitted planes' regions of the simulated frames, every edge's search window, both directions."""
    config = Config()
    n = 0
    for name, k, _front, model in scenario_models:
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


# ------------------------------------------------------------------ joint compatibility, projections once
def associate_joint_reference(ekf, measured, pan=0.0, candidates=None, extra_cost=None):
    """The former :meth:`JointEKF.associate_joint`: each trial set's joint NIS by :meth:`JointEKF.joint_nis`,
    which projects the trial's landmarks again."""
    from scipy.special import chdtri

    ids, z, d2, cost = ekf.association_costs(measured, pan, candidates, extra_cost)
    order = [(r, c) for r, c in zip(*np.nonzero((d2 <= ekf.config.gate) & np.isfinite(cost)), strict=True)]
    order.sort(key=lambda rc: cost[rc])
    chosen, used_r, used_c = [], set(), set()
    for r, c in order:
        if r in used_r or c in used_c:
            continue
        trial = chosen + [(int(ids[r]), int(c))]
        if ekf.joint_nis(trial, z, pan) <= chdtri(2 * len(trial), 1.0 - ekf.config.gate_probability):
            chosen = trial
            used_r.add(r)
            used_c.add(c)
    return sorted(chosen, key=lambda q: q[1])


def test_associate_joint_equals_the_reference(scenario_frames, scenario_models):
    """The filter after each frame (a wall landmark per selected candidate), its pose moved a little and its
    measurements shifted and shuffled so that pairs compete: the same pairs as the former association, and the
    trial sets' joint NIS from the projections made once equal :meth:`JointEKF.joint_nis` bit for bit."""
    from stablemarks.estimation import JointEKF, NewLandmark

    config = Config()
    rng = np.random.default_rng(7)
    compared = 0
    for (name, k, _l, _r, camera, world_map, X), (_, _, front, model) in zip(scenario_frames, scenario_models,
                                                                             strict=True):
        if not model.selected:
            continue
        pairs = front.kept_pairs
        measured = np.stack([pairs.u_left, pairs.u_right], axis=-1)
        for trial in range(4):
            dX = rng.normal(0, [0.02, 0.02, 0.005]) if trial else np.zeros(3)
            ekf = JointEKF(camera, X + dX, COV_PRIOR, config.ekf)
            ekf.add_landmarks([NewLandmark.wall(world_map[c.plane_id], c.s, c.edge) for c in model.selected],
                              np.diag([c.sigma_s**2 for c in model.selected]))
            z = measured + (rng.normal(0, 1.5, measured.shape) if trial > 1 else 0.0)
            if trial == 3:
                z = np.concatenate([z, z[::2] + 3.0])
            got = ekf.associate_joint(z, 0.0)
            assert got == associate_joint_reference(ekf, z, 0.0), (name, k, trial)
            compared += len(got)
            if got:
                rows = ekf._rows([i for i, _ in got], "test")
                ids_all = ekf.landmark_ids
                all_rows = ekf._rows(ids_all, "test")
                uv, J_X, J_l = ekf._project(all_rows, ekf._x, ekf._camera(0.0))
                pos = [ids_all.index(i) for i, _ in got]
                zz = z[[j for _, j in got]]
                assert ekf._joint_nis(rows, zz, uv[pos], J_X[pos], J_l[pos]) == ekf.joint_nis(got, z, 0.0)
    assert compared > 20
