"""Closed-form and lower-overhead versions of per-frame work against the sampled / plain references."""

import numpy as np
import pytest

from stablemarks.geometry import StereoCamera
from stablemarks.maps import Map, ReferencePlane, segments_block, visible_parts

STEP = 0.02


def sampled_visibility(world_map, camera, X, max_range, margin_px, planes=None):
    """The former ``visible_parts``: every wall sampled each ``STEP`` m, each sample tested against every
    wall. Returns ``{plane id: (s (n,), ok (n,) bool)}`` for the walls facing the camera."""
    centre, _ = camera.optical_centres(X)
    walls = world_map.segments()
    index = {p.id: i for i, p in enumerate(world_map.planes)}
    out = {}
    for plane in planes if planes is not None else world_map.planes:
        if not plane.faces(centre):
            continue
        n = max(2, int(np.ceil(plane.length / STEP)) + 1)
        s = np.linspace(0.0, plane.length, n)
        pts = plane.point_at(s)
        Xc, Zc = camera.to_camera(X, pts)
        uv = camera.project_columns(X, pts)
        ok = (Zc > 0.05) & (np.hypot(Xc, Zc) <= max_range) & camera.in_image(uv[:, 0], margin_px)
        if ok.any():
            ok[ok] &= ~segments_block(centre, pts[ok], walls, exclude=[index[plane.id]])
        out[plane.id] = (s, ok)
    return out


def runs(s, ok):
    idx = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [(s[a], s[b - 1]) for a, b in zip(idx[::2], idx[1::2], strict=True)]


def random_map(rng, k):
    planes = []
    for i in range(k):
        p1 = rng.uniform(-6, 6, 2)
        p2 = p1 + rng.uniform(0.3, 5.0) * np.array([np.cos(a := rng.uniform(0, np.pi)), np.sin(a)])
        if rng.random() < 0.3:  # walls meeting at a corner
            p1 = np.array(planes[-1].p2) if planes else p1
        planes.append(ReferencePlane(f"w{i}", tuple(p1), tuple(p2), free_edges=("p1", "p2"),
                                     visible_from=rng.choice(["both", "both", "left", "right"]),
                                     reference=bool(rng.random() < 0.8)))
    return Map(tuple(planes))


@pytest.mark.parametrize("seed", range(6))
def test_visible_parts_match_the_sampled_reference(seed):
    rng = np.random.default_rng(seed)
    n_compared = 0
    for _ in range(12):
        m = random_map(rng, int(rng.integers(1, 12)))
        cam = StereoCamera(mount_x=rng.uniform(-0.2, 0.2), pan=rng.uniform(-0.5, 0.5))
        X = np.array([*rng.uniform(-4, 4, 2), rng.uniform(-np.pi, np.pi)])
        max_range = rng.uniform(3.0, 12.0)
        margin = rng.uniform(-40, 40)
        subset = m.reference_planes if rng.random() < 0.5 else None
        new = {v.plane.id: v for v in visible_parts(m, cam, X, max_range=max_range, margin_px=margin, planes=subset)}
        old = sampled_visibility(m, cam, X, max_range, margin, subset)
        assert set(new) <= set(old)  # only walls facing the camera
        for pid, (s, ok) in old.items():
            iv = np.array(new[pid].intervals if pid in new else np.zeros((0, 2)))
            # every sample is classified alike, except those at a break point itself
            inside = ((s[:, None] >= iv[:, 0] - 1e-9) & (s[:, None] <= iv[:, 1] + 1e-9)).any(axis=1)
            near_end = (np.abs(s[:, None] - iv.reshape(1, -1)) < 1e-6).any(axis=1)
            np.testing.assert_array_equal(inside[~near_end], ok[~near_end])
            n_compared += int((~near_end).sum())
            if pid not in new:
                assert not ok.any()
                continue
            # walls the samples miss are seen over less than a sampling step
            if not ok.any():
                assert new[pid].visible_length < STEP
                continue
            # intervals agree within the sampling resolution
            spacing = s[1] - s[0]
            for a, b in runs(s, ok):
                j = np.flatnonzero((iv[:, 0] <= a + 1e-9) & (iv[:, 1] >= b - 1e-9))
                assert len(j) == 1
                assert a - spacing - 1e-9 <= iv[j[0], 0] and iv[j[0], 1] <= b + spacing + 1e-9
            # a free edge the samples see is seen
            plane = m[pid]
            old_free = {e for e in plane.free_edges for a, b in runs(s, ok)
                        if min(abs((0.0 if e == "p1" else plane.length) - v) for v in (a, b)) <= STEP * 1.01}
            assert old_free <= set(new[pid].free_edges_visible)
    assert n_compared > 1000


def test_visible_parts_of_walls_in_a_row_and_a_corner():
    cam = StereoCamera(f=500.0)
    X = np.array([0.0, 0.0, np.pi / 2])
    m = Map((ReferencePlane("front", (-0.5, 3.0), (0.5, 3.0)), ReferencePlane("back", (-4.0, 6.0), (4.0, 6.0)),
             ReferencePlane("side", (0.5, 3.0), (0.5, 2.0))))
    parts = {v.plane.id: v for v in visible_parts(m, cam, X)}
    # the back wall is hidden in the shadows of the front wall (x in [-1, 1] at y = 6) and of the side wall
    # (x in [1, 1.5]): s in [3, 5.5]
    (a0, b0), (a1, b1) = parts["back"].intervals
    half = 6.0 * np.tan(cam.half_fov)
    assert a0 == pytest.approx(4.0 - half) and b0 == pytest.approx(3.0)
    assert a1 == pytest.approx(5.5) and b1 == pytest.approx(4.0 + half)
    assert parts["front"].intervals == ((0.0, pytest.approx(1.0)),)
