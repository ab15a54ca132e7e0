"""Issue 13, the per-frame pipeline faster (fifth pass): every replaced function against the former
implementation (kept here as the reference) on frames of several simulated scenarios and on random inputs — the
same values, bit for bit where the arithmetic is the same, else to 1e-9."""

from __future__ import annotations

import numpy as np
import pytest

from stablemarks.landmarks import beside_nearer, beside_nearer_sides

COV_PRIOR = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2


# ------------------------------------------------------------------ beside something nearer
def beside_nearer_reference(fit, disparity_left, c, slope, window_px, fraction, sides=(-1, 1)):
    """The former :func:`beside_nearer` (with ``sides``: main's ``_nearer_side``): per side, the (rows, offsets)
    samples as arrays."""
    pred = fit.prediction
    rows_box, cols_box = pred.box(disparity_left.shape[0])
    v0 = max(int(np.ceil(c.v_top)), rows_box.start)
    v1 = min(int(np.floor(c.v_bottom)), rows_box.stop - 1)
    if v1 - v0 < 4:
        return 0
    rows = np.arange(v0, v1 + 1)
    u_rows = c.u_left + slope * (rows - 0.5 * (c.v_top + c.v_bottom))
    offsets = np.arange(int(window_px // 2) + 1, int(window_px) + 2)
    for side in sides:
        cols = np.rint(u_rows[:, None] + side * offsets[None, :]).astype(int)
        inside = (cols >= cols_box.start) & (cols < cols_box.stop)
        d = np.where(inside, disparity_left[rows[:, None], np.clip(cols, cols_box.start, cols_box.stop - 1)], np.nan)
        d_wall, sigma = pred.disparity_at(cols)
        valid = np.isfinite(d)
        nearer = valid & (np.nan_to_num(d) > d_wall + pred.gate * sigma + 1.0)
        held = valid.sum(axis=1) > 0
        row_nearer = held & (2 * nearer.sum(axis=1) > valid.sum(axis=1))
        if held.sum() >= len(rows) / 3 and row_nearer.sum() >= fraction * held.sum():
            return side
    return 0


def test_beside_nearer_equals_the_reference(scenario_models):
    """Every candidate of every fitted plane (selected or not), with its own slope and others, several windows
    and fractions, on the frames' disparity images and on the same images with a nearer patch painted beside
    the lines: the same side, one line at a time and all lines at once."""
    rng = np.random.default_rng(5)
    sides = {-1: 0, 0: 0, 1: 0}
    for name, k, front, model in scenario_models:
        slopes = front.left_segments.slope[front.kept_pairs.left_index]
        for plane in model.planes:
            fit, cands = plane.fit, plane.candidates
            if not cands:
                continue
            disp = front.disparity.left
            painted = np.array(disp)
            for c in cands[::2]:  # something nearer beside every other line, on one side
                v, u = int(np.clip(c.v_top, 0, disp.shape[0] - 1)), int(np.clip(c.u_left, 0, disp.shape[1] - 1))
                s = int(rng.choice([-1, 1]))
                lo, hi = sorted((u + s * 8, u + s * 16))
                painted[v : v + 60, max(0, lo) : max(0, hi)] += 3.0 + 5.0 * rng.random()
            for image in (disp, painted):
                for window, fraction in ((15.0, 0.5), (9.0, 0.3), (21.0, 0.8)):
                    slope = [float(slopes[c.pair]) + (rng.normal(0, 0.05) if window != 15.0 else 0.0)
                             for c in cands]
                    want = [beside_nearer_reference(fit, image, c, s, window, fraction)
                            for c, s in zip(cands, slope, strict=True)]
                    got = beside_nearer_sides(fit, image, [c.u_left for c in cands], [c.v_top for c in cands],
                                              [c.v_bottom for c in cands], slope, window, fraction)
                    assert got.tolist() == want, (name, k, fit.plane.id, window)
                    one = [beside_nearer(fit, image, c, s, window, fraction) for c, s in zip(cands, slope, strict=True)]
                    assert one == want
                    for s in want:
                        sides[s] += 1
                    for one_side in ((1,), (-1,)):  # occluded_boundary looks on one side
                        got = beside_nearer_sides(fit, image, [c.u_left for c in cands], [c.v_top for c in cands],
                                                  [c.v_bottom for c in cands], slope, window, fraction, one_side)
                        assert got.tolist() == [beside_nearer_reference(fit, image, c, s, window, fraction, one_side)
                                                for c, s in zip(cands, slope, strict=True)]
    assert min(sides.values()) >= 20, sides


def test_beside_nearer_interpolates_as_numpy_between_columns():
    """A prediction whose columns have a gap: the wall's disparity between them interpolated as ``np.interp``."""
    from stablemarks.landmarks import _interp

    rng = np.random.default_rng(2)
    xp = np.sort(rng.choice(np.arange(-5, 60), 30, replace=False)).astype(float)
    fp = rng.normal(size=30)
    x = np.concatenate([np.arange(-8.0, 64.0, 0.25), xp, [np.nan]])
    want = np.interp(x, xp, fp)
    got = np.array([_interp(v, xp, fp) for v in x])
    np.testing.assert_array_equal(got, want)
    assert _interp(3.0, np.array([2.0]), np.array([7.0])) == np.interp(3.0, [2.0], [7.0])


# ------------------------------------------------------------------ boundary search on the regions' blocks
def test_block_boundary_columns_equal_the_full_region():
    """A region empty outside a block (anywhere: inside, across and beyond the window and the image), searched as
    the block: the same rows and columns as :func:`_boundary_columns` of the whole (H, W) mask."""
    from stablemarks.landmarks import _block_boundary_columns, _boundary_columns

    rng = np.random.default_rng(11)
    for trial in range(400):
        H, W = int(rng.integers(1, 40)), int(rng.integers(1, 90))
        v0, u0 = int(rng.integers(0, H)), int(rng.integers(0, W))
        h, w = int(rng.integers(0, H - v0 + 1)), int(rng.integers(0, W - u0 + 1))
        block = rng.random((h, w)) < rng.uniform(0.05, 0.95)
        region = np.zeros((H, W), bool)
        region[v0 : v0 + h, u0 : u0 + w] = block
        lo = float(rng.uniform(-10, W + 5))
        hi = lo + float(rng.uniform(-3, W))
        for outward in (-1, 1):
            for hole in (0, 2, 7):
                got = _block_boundary_columns(block, v0, u0, W, lo, hi, outward, hole)
                want = _boundary_columns(region, lo, hi, outward, hole)
                for g, wnt in zip(got, want, strict=True):
                    assert g.dtype == wnt.dtype and np.array_equal(g, wnt), (trial, outward, hole)


def test_right_block_is_the_right_region(scenario_models):
    """The right-image region of every fitted plane's edge windows (and of the whole image), as a block: the
    same mask as :func:`right_region`, nothing outside the block."""
    from stablemarks.landmarks import _right_block, right_region

    n = 0
    for _name, _k, front, model in scenario_models:
        disp_r = front.disparity.right
        for fit in (f for f in model.fits if f):
            pred = fit.prediction
            windows = [None] + [(int(np.floor(lo)) - 1, int(np.ceil(hi)) + 1) for lo, hi in
                                (e.window(1, 3.0) for e in pred.edges.values() if np.all(np.isfinite(e.u)))]
            for cols in windows:
                full = right_region(pred, disp_r, 4.0, cols)
                v0, c0, block = _right_block(pred, disp_r, 4.0, cols)
                rebuilt = np.zeros_like(full)
                rebuilt[v0 : v0 + block.shape[0], c0 : c0 + block.shape[1]] = block
                assert np.array_equal(rebuilt, full)
                n += int(block.sum())
    assert n > 1000


# ------------------------------------------------------------------ ray/wall crossings
def crossings_reference(origins, rays, walls, exclude=()):
    """The former :func:`stablemarks.maps._crossings`, in NumPy arrays."""
    o = np.asarray(origins, dtype=float).reshape(-1, 2)
    r = np.asarray(rays, dtype=float).reshape(-1, 2)
    walls = np.asarray(walls, dtype=float).reshape(-1, 2, 2)
    if len(exclude):
        walls = np.delete(walls, list(exclude), axis=0)
    a = walls[:, 0, :]
    s = walls[:, 1, :] - a
    r0, r1 = r[:, 0:1], r[:, 1:2]
    denom = r0 * s[:, 1] - r1 * s[:, 0]
    qx = a[:, 0] - o[:, 0:1]
    qy = a[:, 1] - o[:, 1:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (qx * s[:, 1] - qy * s[:, 0]) / denom
        mu = (qx * r1 - qy * r0) / denom
    ok = (np.abs(denom) > 1e-12) & (mu >= 0) & (mu <= 1)
    return np.where(ok, lam, np.nan)


def test_crossings_equal_the_reference(scenario_frames):
    """Random rays against the scenarios' maps (and random walls, some degenerate or parallel to the rays), one
    origin or one per ray, with walls left out: the same intersections bit for bit (NaN where the reference's)."""
    from stablemarks.maps import _crossings

    rng = np.random.default_rng(3)
    maps = [m.segments() for *_, m, _X in scenario_frames[::2]]
    for trial in range(300):
        walls = maps[trial % len(maps)] if trial % 3 else rng.normal(0, 4, (int(rng.integers(1, 9)), 2, 2))
        if trial % 7 == 0:
            walls = np.concatenate([walls, walls[:1, :1].repeat(2, axis=1)])  # a zero-length wall
        n = int(rng.integers(1, 30))
        rays = rng.normal(size=(n, 2))
        if trial % 5 == 0:
            rays[0] = walls[0, 1] - walls[0, 0]  # parallel to a wall
        origins = rng.normal(0, 3, (n, 2)) if trial % 2 else rng.normal(0, 3, 2)
        exclude = [] if trial % 4 else sorted(set(rng.integers(-len(walls), len(walls), 2).tolist()))
        got = _crossings(origins, rays, walls, exclude)
        want = crossings_reference(origins, rays, walls, exclude)
        assert got.shape == want.shape
        np.testing.assert_array_equal(got, want)


# ------------------------------------------------------------------ the candidates' decisions
def test_fast_replace_is_dataclasses_replace(scenario_models):
    """:func:`landmarks._replace` (the selection's decisions on a candidate) gives the object
    ``dataclasses.replace`` gives: equal field by field, arrays the same objects, a Candidate."""
    import dataclasses

    from stablemarks.landmarks import Candidate, _replace

    cands = [c for *_, model in scenario_models for c in model.candidates]
    assert len(cands) > 50
    for c in cands:
        for kw in ({"selected": False, "reason": "beside something nearer"}, {"selected": True, "reason": ""}):
            got, want = _replace(c, **kw), dataclasses.replace(c, **kw)
            assert type(got) is Candidate and got is not c
            for f in dataclasses.fields(Candidate):
                g, w = getattr(got, f.name), getattr(want, f.name)
                assert g is w or g == w or (isinstance(g, float) and np.isnan(g) and np.isnan(w)), f.name
    with pytest.raises(TypeError):
        _replace(cands[0], no_such_field=1)


# ------------------------------------------------------------------ the silhouettes of nearer walls
def nearer_silhouettes_reference(camera, X, cov_X, world_map, plane, min_offset=0.1, max_step_px=np.inf):
    """The former :func:`nearer_silhouettes`: every end of every other wall projected, then tested."""
    out = []
    fb = camera.f * camera.baseline
    centres = camera.optical_centres(X)
    for w in world_map:
        if w.id == plane.id:
            continue
        for E in (w.P1, w.P2):
            oE = float(plane.offset(E))
            uv, J, _ = camera.project_columns(X, E, jacobians=True)
            for img in (0, 1):
                O = centres[img]
                oO = float(plane.offset(O))
                if not np.isfinite(uv[img]) or oO * oE <= 0 or abs(oE) < min_offset or abs(oE) >= abs(oO):
                    continue
                W = O + oO / (oO - oE) * (E - O)
                if fb / np.hypot(*(E - O)) - fb / np.hypot(*(W - O)) > max_step_px:
                    continue
                out.append((img, float(uv[img]), float(np.sqrt(max(J[img] @ cov_X @ J[img], 0.0))), tuple(w.z)))
    return out


def test_nearer_silhouettes_equal_the_reference(scenario_frames):
    """Every wall of every scenario frame's map, from the true pose and moved ones, any step and a small one: the
    same silhouettes (image, column, σ, heights) bit for bit."""
    from stablemarks.landmarks import nearer_silhouettes

    rng = np.random.default_rng(9)
    found = 0
    for _name, _k, _l, _r, camera, world_map, X in scenario_frames:
        for trial in range(3):
            Xt = X + (rng.normal(0, [0.3, 0.3, 0.2]) if trial else 0.0)
            for plane in world_map:
                for step in (np.inf, 0.7):
                    got = nearer_silhouettes(camera, Xt, COV_PRIOR, world_map, plane, max_step_px=step)
                    want = nearer_silhouettes_reference(camera, Xt, COV_PRIOR, world_map, plane, max_step_px=step)
                    assert got == want
                    found += len(got)
    assert found > 20
