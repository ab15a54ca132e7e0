"""Issue 13, the per-frame pipeline faster (fourteenth pass): every rewritten function against the former
implementation (kept here as the reference) on frames of the simulated scenarios ``lab``, ``corridor``, ``office``
and ``hall`` and on random inputs — the same values, bit for bit.

:func:`~stablemarks.landmarks.edge_lines` tests its pairs in one numba pass; :func:`~stablemarks.maps.visible_parts`
walks only the tested pieces of each wall; :func:`~stablemarks.landmarks.nearer_silhouettes` takes the other walls'
ends and offsets from the map once (its reference is in ``test_speedups_5.py``)."""

from __future__ import annotations

import math

import numpy as np

from stablemarks import landmarks as L
from stablemarks import maps as M
from stablemarks.vision.segment_stereo import SegmentPairs

COV_PRIOR = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2


# ------------------------------------------------------------------ edge_lines
def edge_lines_reference(camera, fit, edge, pairs, disparity_left, window_px, min_step_px=1.0, box=None):
    """The former :func:`~stablemarks.landmarks.edge_lines`: per pair, its samples as arrays."""
    none = np.zeros((0, 2))
    if len(pairs) == 0:
        return none
    inner = float(L._inner_columns(camera, fit.X, fit.plane, edge)[0])
    e = fit.prediction.edges[edge]
    outward = -1 if e.u[0] < inner else 1
    H, W = disparity_left.shape
    (r_lo, r_hi), (c_lo, c_hi) = (0, H), (0, W)
    if box is not None:
        r_lo, r_hi, _ = box[0].indices(H)
        c_lo, c_hi, _ = box[1].indices(W)
    keep = []
    columns = (np.asarray(a, dtype=float).tolist() for a in (pairs.u_left, pairs.u_right, pairs.v_top, pairs.v_bottom))
    for ul, ur, vt, vb in zip(*columns, strict=True):
        d = ul - ur
        offsets = np.arange(int(window_px // 2) + 1, int(window_px // 2) + 2 + int(np.ceil(d)) + int(window_px))
        cols = np.rint(ul + outward * offsets).astype(int)
        cols = cols[(cols >= c_lo) & (cols < c_hi)]
        rows = np.arange(max(r_lo, int(np.ceil(vt))), min(r_hi, int(np.floor(vb)) + 1))
        if len(cols) == 0 or len(rows) < 5:
            continue
        block = disparity_left[np.ix_(rows, cols)]
        valid = np.isfinite(block)
        held = valid.any(axis=1)
        if held.sum() < len(rows) / 3:
            continue
        first = block[held, np.argmax(valid[held], axis=1)]
        if np.sum(first < d - min_step_px) > 0.5 * held.sum():
            keep.append((ul, ur))
    return np.array(keep, dtype=float).reshape(-1, 2)


def _pairs_near(fit, edge, rng, n, disparity):
    """``n`` made-up segment pairs around a wall's edge: columns near the edge's, disparities near the wall's there
    (some exactly 1 px above a disparity of the image: the threshold's tie), rows over the wall's band."""
    e = fit.prediction.edges[edge]
    u = float(e.u[0]) + rng.normal(0, 25, n)
    d = np.interp(u, fit.prediction.columns, fit.prediction.d) + rng.normal(0, 2, n)
    H, W = disparity.shape
    vals = disparity[np.isfinite(disparity)]
    if len(vals):
        tie = rng.random(n) < 0.3
        d[tie] = vals[rng.integers(0, len(vals), tie.sum())].astype(float) + 1.0
    top = rng.uniform(-20, H / 2, n)
    bottom = top + rng.uniform(0, H / 2, n)
    k = np.arange(n)
    one = np.ones(n)
    return SegmentPairs(k, k, one, one, one, one, u, u - np.abs(d), top, bottom, bottom - top, bottom - top)


def test_edge_lines_equal_the_former(scenario_frames, scenario_models):
    """Every free edge of every fitted wall, with the frame's dropped pairs on the wall and made-up pairs near the
    edge, in the band box and over the whole image, float32 and float64 images, several steps: the same lines."""
    from stablemarks.config import Config

    config = Config()
    rng = np.random.default_rng(14)
    kept = tested = 0
    for (*_, camera, _map, _X), (_name, _k, front, model) in zip(scenario_frames, scenario_models, strict=True):
        camera = config.camera(camera)  # as select_landmarks takes it
        disp = front.disparity.left
        for plane in model.planes:
            fit = plane.fit
            for edge in fit.plane.free_edges:
                if not np.all(np.isfinite(fit.prediction.edges[edge].u)):
                    continue
                box = fit.prediction.box(disp.shape[0], config.planes.row_margin_px)
                dropped = front.pairs.subset(~np.asarray(front.kept))
                for pairs in (dropped, _pairs_near(fit, edge, rng, 40, disp)):
                    for image in (disp, disp.astype(np.float64)):
                        for b in (box, None):
                            for step in (1.0, 0.5):
                                got = L.edge_lines(camera, fit, edge, pairs, image, 15.0, step, b)
                                want = edge_lines_reference(camera, fit, edge, pairs, image, 15.0, step, b)
                                assert got.shape == want.shape and got.dtype == want.dtype
                                assert np.array_equal(got, want)
                                kept += len(got)
                                tested += len(pairs)
    assert tested > 500 and kept > 10


def test_edge_lines_kernel_on_random_images():
    """The kernel against the former code on random images with NaN holes, random pairs and boxes."""
    from types import SimpleNamespace

    rng = np.random.default_rng(3)
    for trial in range(60):
        H, W = 60, 90
        img = rng.uniform(0, 30, (H, W)).astype(np.float32 if trial % 2 else np.float64)
        n = 25
        ul = rng.uniform(-10, W + 10, n)
        d = rng.uniform(0.5, 25, n)
        d[::4] = np.floor(d[::4])  # whole disparities
        if trial % 4 < 2:
            d[:] = d[1]  # one disparity for all: its threshold's ties decide every row
        # pixels that are a pair's threshold rounded to the image's type: the float32 comparison's ties
        tie = rng.random((H, W)) < 0.5
        img[tie] = (d[rng.integers(0, n, tie.sum())] - 1.0).astype(img.dtype)
        img[rng.random((H, W)) < rng.uniform(0, 0.9)] = np.nan
        top = rng.uniform(-10, H, n)
        pairs = SimpleNamespace(u_left=ul, u_right=ul - d, v_top=top, v_bottom=top + rng.uniform(0, H, n))
        r0, c0 = int(rng.integers(0, 20)), int(rng.integers(0, 30))
        r_lo, r_hi, c_lo, c_hi = r0, r0 + int(rng.integers(0, 40)), c0, c0 + int(rng.integers(0, 60))
        for outward in (-1, 1):
            want = []
            for i in range(n):
                offsets = np.arange(8, 9 + int(np.ceil(d[i])) + 15)
                cols = np.rint(ul[i] + outward * offsets).astype(int)
                cols = cols[(cols >= c_lo) & (cols < min(c_hi, W))]
                rows = np.arange(max(r_lo, int(np.ceil(top[i]))),
                                 min(min(r_hi, H), int(np.floor(pairs.v_bottom[i])) + 1))
                if len(cols) == 0 or len(rows) < 5:
                    continue
                block = img[np.ix_(rows, cols)]
                valid = np.isfinite(block)
                held = valid.any(axis=1)
                if held.sum() < len(rows) / 3:
                    continue
                first = block[held, np.argmax(valid[held], axis=1)]
                if np.sum(first < float(d[i]) - 1.0) > 0.5 * held.sum():  # a Python float
                    want.append(i)
            below = np.asarray(d - 1.0, dtype=img.dtype)
            got = L._edge_lines_kept(img, ul, d, top, pairs.v_bottom, below, outward, 7, 15, r_lo, min(r_hi, H),
                                     c_lo, min(c_hi, W))
            assert got.tolist() == want


# ------------------------------------------------------------------ visible_parts
def visible_parts_reference(world_map, camera, X, *, max_range=12.0, margin_px=0.0, edge_tol=0.02, planes=None):
    """The former :func:`~stablemarks.maps.visible_parts`: the map's segments made anew, every piece walked."""
    centre, _ = camera.optical_centres(X)
    index = {p.id: i for i, p in enumerate(world_map.planes)}
    targets = [p for p in (planes if planes is not None else world_map.planes) if p.faces(centre)]
    if not targets:
        return []
    walls = world_map.segments()
    own = np.array([index[p.id] for p in targets])
    P1 = walls[own, 0]
    length = np.array([p.length for p in targets])
    t = (walls[own, 1] - P1) / length[:, None]
    q = P1 - centre
    psi = camera.camera_pose(X).theta
    c, s = math.cos(psi), math.sin(psi)
    sides = np.array([-0.5 + margin_px, camera.width - 0.5 - margin_px])[:, None] - camera.cu
    g = np.concatenate([[[c, s]], camera.f * np.array([[s, -c]]) - sides * np.array([[c, s]])])
    k = np.array([M._MIN_DEPTH_VISIBLE, 0.0, 0.0])
    qt = (q * t).sum(-1)[:, None]
    tips = walls.reshape(-1, 2) - centre
    e = walls[:, 1] - walls[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        b = np.concatenate([
            np.zeros_like(qt),
            (k - q @ g.T) / (t @ g.T),
            -qt + np.sqrt(qt**2 - (q * q).sum(-1)[:, None] + max_range**2) * np.array([-1.0, 1.0]),
            M._cross(q[:, None, :], tips[None]) / M._cross(tips[None], t[:, None, :]),
            M._cross(walls[None, :, 0] - P1[:, None], e[None]) / M._cross(t[:, None, :], e[None]),
        ], axis=1)  # fmt: skip
    L_ = length[:, None]
    b = np.where((b > 0) & (b < L_), b, L_)
    b[:, 0] = 0.0
    b.sort(axis=1)
    lo = np.concatenate([np.zeros_like(L_), b[:, :-1], L_], axis=1)
    hi = np.concatenate([np.zeros_like(L_), b[:, 1:], L_], axis=1)
    test = hi > lo
    test[:, [0, -1]] = True
    row, col = np.nonzero(test)
    mid = 0.5 * (lo[row, col] + hi[row, col])
    pts = P1[row] + mid[:, None] * t[row]
    Xc, Zc = camera.to_camera(X, pts)
    uv = camera.project_columns(X, pts)
    ok = (Zc > M._MIN_DEPTH_VISIBLE) & (np.hypot(Xc, Zc) <= max_range) & camera.in_image(uv[:, 0], margin_px)
    if ok.any():
        lam = M._crossings(centre, pts[ok] - centre, walls)
        lam[np.arange(len(lam)), own[row[ok]]] = np.nan
        ok[ok] = ~M._blocked(lam)
    seen = np.zeros(test.shape, dtype=bool)
    seen[row, col] = ok
    out = []
    for plane, lo_i, hi_i, test_i, seen_i in zip(targets, lo.tolist(), hi.tolist(), test.tolist(), seen.tolist(),
                                                strict=True):
        intervals = []
        run = False
        for a, z, tested, v in zip(lo_i, hi_i, test_i, seen_i, strict=True):
            if not tested:
                continue
            if v and run:
                intervals[-1][1] = z
            elif v:
                intervals.append([a, z])
            run = v
        if not intervals:
            continue
        free = tuple(e for e in plane.free_edges
                     if any(abs((0.0 if e == "p1" else plane.length) - v) <= edge_tol for iv in intervals for v in iv))
        out.append(M.VisiblePart(plane, tuple((a, z) for a, z in intervals), free))
    return out


def test_visible_parts_equal_the_former(scenario_frames):
    """Every scenario frame's map from its true pose and from poses moved and turned far, with margins and planes
    as the plane prediction asks: the same parts (walls, intervals bit for bit, free edges)."""
    rng = np.random.default_rng(21)
    seen = 0
    for _name, _k, _l, _r, camera, world_map, X in scenario_frames:
        for trial in range(12):
            Xt = X + (rng.normal(0, [1.0, 1.0, 1.0]) if trial else 0.0)
            for kw in ({}, {"margin_px": -20.0, "max_range": 8.0, "planes": world_map.reference_planes}):
                got = M.visible_parts(world_map, camera, Xt, **kw)
                want = visible_parts_reference(world_map, camera, Xt, **kw)
                assert got == want
                seen += sum(len(p.intervals) for p in got)
    assert seen > 100
