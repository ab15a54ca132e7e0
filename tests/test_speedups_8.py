"""Issue 13, the per-frame pipeline faster (eighth pass): every replaced computation against the former
implementation (kept here as the reference) on frames of several simulated scenarios and on random inputs — the
same values, bit for bit (or where only the order of floating-point operations changed, to 1e-9, with the same
decisions)."""

from __future__ import annotations

import numpy as np

from stablemarks import landmarks as L
from stablemarks.config import Config
from stablemarks.maps import ray_distances


# ------------------------------------------------------------------ the gap to another wall beyond an edge
def other_wall_gap_reference(camera, fit, world_map, edge, search_sigma):
    """The former :func:`~stablemarks.landmarks.other_wall_gap`: a ray cast through every column out to twice the
    window's outer half, all at once."""
    e = fit.prediction.edges[edge]
    u_e = float(e.u[0])
    u_i = float(L._inner_columns(camera, fit.X, fit.plane, edge)[0])
    if not np.isfinite(u_e + u_i):
        return 0.0
    lo, hi = e.window(0, search_sigma)
    outer = lo if u_e < u_i else hi
    outer = u_e + 2.0 * (outer - u_e)
    cols = np.linspace(u_e, outer, max(2, int(abs(outer - u_e)) + 1))
    walls, exclude = L._other_walls(world_map, fit.plane)
    if len(walls) == len(exclude):
        return np.inf
    X = fit.X
    rays = camera.column_ray(X, cols)
    dist = ray_distances(camera.optical_centres(X)[0], rays, walls, exclude=exclude)
    cam = camera.camera_pose(X)
    Z = dist * (rays @ np.array([np.cos(cam.theta), np.sin(cam.theta)]))
    d = np.where(np.isfinite(Z) & (Z > 0), camera.f * camera.baseline / np.where(Z > 0, Z, 1.0), 0.0)
    d_edge, sigma = fit.prediction.disparity_at(u_e)
    hit = np.flatnonzero(np.abs(d - d_edge) <= fit.prediction.gate * sigma + 1.0)
    return float(abs(cols[hit[0]] - u_e)) if len(hit) else np.inf


def test_other_wall_gap_equals_the_reference(scenario_frames, scenario_models):
    """Both ends of every fitted wall of every scenario frame, seen from the fit's pose and from perturbed ones,
    windows of 1 to 12 σ: the same gap (another wall found at the same column, or none)."""
    config = Config()
    rng = np.random.default_rng(47)
    n = n_found = 0
    for frame, (_, _, _, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for fit in model.fits:
            if not fit:
                continue
            for X in [fit.X] + [fit.X + rng.normal(0, [0.3, 0.3, 0.1]) for _ in range(4)]:
                f = L.replace(fit, X=X)
                for edge in ("p1", "p2"):
                    for sigma in (1.0, 3.0, 12.0):
                        got = L.other_wall_gap(camera, f, frame[5], edge, sigma)
                        want = other_wall_gap_reference(camera, f, frame[5], edge, sigma)
                        assert type(got) is type(want) is float and got == want
                        n += 1
                        n_found += bool(np.isfinite(got)) and got > 0
    assert n > 300 and n_found > 20


# ------------------------------------------------------------------ the boundary's rows and column in one call
def robust_minimum_variance_reference(cols, k, lo, hi):
    """What :func:`~stablemarks.landmarks.search_boundary` did with an image's boundary columns: the rows kept by
    :func:`~stablemarks.landmarks.robust_rows`, then :func:`~stablemarks.landmarks.minimum_variance_column`."""
    cols = cols[L.robust_rows(cols, k)]
    if len(cols) == 0:
        return (0,)
    return (len(cols), *L.minimum_variance_column(cols, lo, hi))


def test_pairwise_sum_equals_numpy():
    """:func:`~stablemarks.landmarks._pairwise_sum` against ``np.add.reduce`` on 1 to 1000 numbers of mixed scales
    (all three branches of the pairwise summation) and a few longer arrays: bit for bit."""
    rng = np.random.default_rng(53)
    for n in [*range(0, 300), 511, 1000, 4097]:
        a = rng.normal(size=n) * rng.uniform(1, 1e6) + rng.uniform(-1e3, 1e3)
        assert L._pairwise_sum(a, 0, n) == np.add.reduce(a)
        if n > 3:
            assert L._pairwise_sum(a, 3, n - 3) == np.add.reduce(a[3:])


def test_robust_minimum_variance_equals_the_reference(scenario_frames, scenario_models):
    """Every scenario frame's boundary columns (both edges of every fitted wall, left image) and random columns
    with outliers and whole-pixel ties, through windows around them, beside them and empty: the same number of rows
    kept, the same column and variance, bit for bit."""
    config = Config()
    rng = np.random.default_rng(59)
    cases = []
    for frame, (_, _, _, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(frame[4])
        for fit in model.fits:
            if not fit:
                continue
            H, W = fit.region.shape
            v0, v1, _ = fit.box[0].indices(H)
            for edge in ("p1", "p2"):
                e = fit.prediction.edges[edge]
                if not np.all(np.isfinite(e.u)):
                    continue
                lo, hi = e.window(0, 3.0)
                outward = -1 if e.u[0] < L._inner_columns(camera, fit.X, fit.plane, edge)[0] else 1
                _, cols = L._block_boundary_columns(fit.region[v0:v1], v0, 0, W, lo, hi, outward, 7)
                cases.append((cols, lo, hi))
    for _ in range(300):
        n = int(rng.integers(0, 200))
        cols = np.round(rng.normal(300, rng.uniform(0.5, 5), n) * rng.choice([1, 2])) / rng.choice([1, 2])
        cols[rng.random(n) < 0.1] = rng.uniform(200, 400)  # rows off the edge (floor pixels at the wall's foot)
        centre = float(rng.normal(300, 20))
        cases.append((cols, centre - rng.uniform(0, 30), centre + rng.uniform(-5, 30)))
    n_out = 0
    for cols, lo, hi in cases:
        for k in (1.0, 3.0):
            got = L._robust_minimum_variance(np.asarray(cols, float), k, float(lo), float(hi))
            want = robust_minimum_variance_reference(np.asarray(cols, float), k, lo, hi)
            assert got[0] == want[0]
            if want[0]:
                assert got[1:] == want[1:]
                n_out += not lo <= float(np.mean(cols[L.robust_rows(cols, k)])) <= hi
    assert len(cases) > 300 and n_out > 20
