"""The front end and landmark selection on images from an independent renderer (pybullet's TinyRenderer, headless),
with photographs from ``skimage.data`` as textures (:mod:`tests.independent_render`), not the project's simulator.

Two scenes, each rendered once: a panel 3.5 m ahead seen frontally, its free edge on the left of the image, with a
pole 0.6 m in front of it (``frontal``); a panel turned 20° from the image plane, its free edge on the right, seen
from a pose turned 10° (``oblique``). Both stand 3.5 m in front of a brick back wall 7 m away, on a grass floor,
with two photographs pasted on the panel as posters. The method is given the true pose plus a known error
(+1 cm in x, +0.3° in heading) and a prior σ of (2 cm, 2 cm, 0.5°); points it reports in the map are mapped back
through that error (:func:`_to_true`) before they are compared with the scene, so only the images' part of the
error is measured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import pytest

pytest.importorskip("pybullet")
pytest.importorskip("skimage")

from stablemarks.config import Config  # noqa: E402
from stablemarks.geometry import StereoCamera  # noqa: E402
from stablemarks.maps import Map, ReferencePlane  # noqa: E402
from stablemarks.pipeline import FrameLandmarks, disparity_limits, process_frame  # noqa: E402

from .independent_render import (  # noqa: E402
    BACK_Y,
    POSTERS,
    Disc,
    PanelSetup,
    RenderedPair,
    Scene,
    panel_scene,
    pinhole,
    render_pair,
)

CAMERA = StereoCamera(width=640, height=480, f=500.0, cu=319.5, cv=239.5, baseline=0.12, mount_height=1.0)
POSE_ERROR = np.array([0.01, 0.0, math.radians(0.3)])
"""What the prior given to the method is off the true pose by: (x [m], y [m], theta [rad])."""
COV_PRIOR = np.diag([0.02, 0.02, math.radians(0.5)]) ** 2
SAD_HALF = Config().sad.block_size // 2


@dataclass(frozen=True)
class Frame:
    setup: PanelSetup
    panel: ReferencePlane
    world_map: Map
    X_true: np.ndarray
    X_given: np.ndarray
    pair: RenderedPair
    res: FrameLandmarks


def _frame(setup: PanelSetup, free: str, X_true) -> Frame:
    """Render ``setup`` from ``X_true`` and run :func:`process_frame` on it. The map: the panel (its free edge
    ``free``, ``p1`` or ``p2``, at ``setup.free_end``) and the back wall as an occluder."""
    ends = (setup.free_end, setup.other_end) if free == "p1" else (setup.other_end, setup.free_end)
    panel = ReferencePlane("panel", *ends, free_edges=(free,), z=(0.0, setup.height))
    back = ReferencePlane("back", (-8.0, BACK_Y), (8.0, BACK_Y), z=(0.0, 6.0), reference=False)
    world_map = Map((panel, back))
    X_true = np.asarray(X_true, dtype=float)
    pair = render_pair(panel_scene(setup, X_true[:2]), CAMERA, X_true, supersample=3, noise_sigma=1.5, seed=7)
    X_given = X_true + POSE_ERROR
    res = process_frame(pair.left, pair.right, CAMERA, world_map, X_given, COV_PRIOR, Config())
    return Frame(setup, panel, world_map, X_true, X_given, pair, res)


@pytest.fixture(scope="module")
def frontal() -> Frame:
    setup = PanelSetup(free_end=(-0.4, 3.5), other_end=(3.0, 3.5), pole=(0.75, 2.9))
    return _frame(setup, "p1", (0.0, 0.0, math.pi / 2))


@pytest.fixture(scope="module")
def oblique() -> Frame:
    a = math.radians(20.0)
    setup = PanelSetup(free_end=(0.5, 3.3), other_end=(0.5 - 3.6 * math.cos(a), 3.3 + 3.6 * math.sin(a)))
    return _frame(setup, "p2", (0.2, -0.2, math.radians(80.0)))


@pytest.fixture(params=["frontal", "oblique"])
def frame(request) -> Frame:
    return request.getfixturevalue(request.param)


def _to_true(fr: Frame, P) -> np.ndarray:
    """Map points (..., 2) the method placed in the map from the pose it was given into the map as seen from the
    true pose: the same camera coordinates (the known pose error taken out)."""
    Xc, Zc = CAMERA.to_camera(fr.X_given, P)
    return CAMERA.from_camera(fr.X_true, Xc, Zc)


def _fit(fr: Frame):
    (fit,) = [f for f in fr.res.fits if f.plane.id == "panel"]
    return fit


def _depth_on_panel(fr: Frame, X, u) -> np.ndarray:
    """Depth ``Z_c`` [m] at which the left camera's columns ``u`` meet the map's panel from pose ``X`` (a vertical
    plane: the same for every row)."""
    pose = CAMERA.camera_pose(X)
    fwd, right = np.array([math.cos(pose.theta), math.sin(pose.theta)]), np.array([math.sin(pose.theta),
                                                                                    -math.cos(pose.theta)])
    ray = fwd + ((np.asarray(u, float) - CAMERA.cu) / CAMERA.f)[..., None] * right  # per unit depth
    n = fr.panel.normal
    return ((fr.panel.P1 - pose.translation) @ n) / (ray @ n)


# ------------------------------------------------------------------ the renderer's camera
def test_pybullet_images_follow_the_projects_pinhole_model():
    """Measured: the centroid of black discs (8 cm, fronto-parallel) rendered on white at known 3-D points, in
    both images, against ``u = cu + f X/Z``, ``u_r = u − f b/Z``, ``v = cv + f Y/Z`` of the project's camera, from a
    pose turned 20° off the axes. Found within 0.03 px; asserted within 0.1 px — a half-pixel convention slip
    (what a projection matrix from the field of view alone gives in TinyRenderer: +0.5 px in u, −0.5 px in v)
    fails it."""
    X = np.array([0.7, -0.4, 0.35])
    targets = [(100.3, 400.2, 3.0), (560.7, 80.6, 4.5), (430.1, 330.8, 2.2), (250.0, 150.0, 3.0)]
    points = []
    for u, v, Z in targets:
        xy = CAMERA.from_camera(X, (u - CAMERA.cu) * Z / CAMERA.f, Z)
        points.append((xy[0], xy[1], CAMERA.mount_height - (v - CAMERA.cv) * Z / CAMERA.f))
    psi = float(CAMERA.camera_pose(X).theta)
    discs = tuple(Disc(f"d{i}", p, 0.08, psi) for i, p in enumerate(points))
    pair = render_pair(Scene(discs=discs), CAMERA, X, supersample=3, noise_sigma=0.0)
    vv, uu = np.mgrid[: CAMERA.height, : CAMERA.width]
    errors = []
    for p in points:
        expect = pinhole(CAMERA, X, np.array(p))
        for image, col in ((pair.left, 0), (pair.right, 1)):
            w = (255.0 - image) * ((np.abs(uu - expect[col]) < 35) & (np.abs(vv - expect[2]) < 35))
            errors.append(((w * uu).sum() / w.sum() - expect[col], (w * vv).sum() / w.sum() - expect[2]))
    errors = np.array(errors)
    assert np.abs(errors).max() < 0.1, errors


# ------------------------------------------------------------------ the method on the rendered pairs
def test_the_scene_is_rendered_as_intended(frame):
    """Sanity of the scene, not of the method: the renderer's panel pixels (those it covers whole) run from its free
    edge's column projected from the true pose to the image border, and 30 cm inside the edge from its top's row to
    its foot's (within 1.4 px: a pixel covered whole begins up to 1 px plus a sub-sample, 1/3 px, past the edge)."""
    fr = frame
    panel = fr.pair.labels_left == fr.pair.label("panel")
    inner = fr.panel.point_at(0.3, fr.panel.free_edges[0])  # 30 cm inside the free edge
    u_edge, u_inner = (pinhole(CAMERA, fr.X_true, np.array([*xy, 1.0]))[0] for xy in (fr.setup.free_end, inner))
    cols = np.flatnonzero(panel.any(axis=0))
    assert abs((cols[0] if u_inner > u_edge else cols[-1]) - u_edge) < 1.4
    assert (cols[-1] == CAMERA.width - 1) if u_inner > u_edge else (cols[0] == 0)
    rows = np.flatnonzero(panel[:, int(round(u_inner))])
    v_top, v_bottom = (pinhole(CAMERA, fr.X_true, np.array([*inner, z]))[2] for z in (fr.setup.height, 0.0))
    assert abs(rows[0] - v_top) < 1.4 and abs(rows[-1] - v_bottom) < 1.4


def test_the_panel_is_fitted(frame):
    """The panel's PlaneFit is present. Measured: the fitted wall line, mapped through the known pose error, against
    the true panel at 9 columns across its predicted window: at most 5.6 mm (frontal) and 8.4 mm (oblique) off;
    asserted within 2 cm (0.1 px of disparity at 3.5 m)."""
    fit = _fit(frame)
    assert fit, getattr(fit, "reason", "")
    lo, hi = fit.prediction.window
    u = np.linspace(max(lo, 80), min(hi, CAMERA.width - 20), 9)
    Z = _depth_on_panel(frame, frame.X_given, u)
    s = frame.panel.along(CAMERA.from_camera(frame.X_given, (u - CAMERA.cu) * Z / CAMERA.f, Z))
    off = frame.panel.offset(_to_true(frame, fit.point_on_line(s)))
    assert np.abs(off).max() < 0.02, off


@pytest.mark.parametrize("name", [
    pytest.param("frontal", marks=pytest.mark.xfail(strict=True, reason=(
        "measured: left-image boundary column 264.88 px against 262.36 px true (+2.52 px, inward: the planar "
        "region's per-row border lies at 261-268 px, 10-90 %, mean 264.9), right image 245.17 px against "
        "245.21 px (-0.04 px). Consistent with the left-reference SAD windows taking in the background strip "
        "half-occluded in the right image, which lies left of a panel's left end; the method's own sigma of this "
        "column is 8.5 px"))),
    "oblique",
])
def test_the_free_edge_is_found_at_its_column(name, request):
    """Measured: the columns of the boundary found at the panel's free edge against the free edge's columns projected
    from the TRUE pose; asserted within 2 px in both images. Oblique (free edge on the right of the panel in the
    image): left 274.56 px against 274.87 px (−0.30 px), right +0.06 px. Frontal (free edge on the left): left
    264.88 px against 262.36 px (+2.52 px), right −0.04 px: xfail."""
    fr = request.getfixturevalue(name)
    (model,) = [m for m in fr.res.planes if m.fit.plane.id == "panel"]
    (b,) = model.boundaries
    u_true = pinhole(CAMERA, fr.X_true, np.array([*fr.setup.free_end, 1.0]))
    assert abs(b.u[1] - u_true[1]) < 2.0, (b.u, u_true)
    assert abs(b.u[0] - u_true[0]) < 2.0, (b.u, u_true)


def test_the_free_edges_column_is_within_its_own_sigma(frame):
    """Honest uncertainty: whatever the boundary's column error (2.5 px on the frontal panel's left end, above),
    it lies within 3 of the σ the method gives that column (``Boundary.sigma_u``), in both images."""
    (model,) = [m for m in frame.res.planes if m.fit.plane.id == "panel"]
    (b,) = model.boundaries
    u_true = pinhole(CAMERA, frame.X_true, np.array([*frame.setup.free_end, 1.0]))
    assert np.all(np.abs(b.u - u_true[:2]) <= 3.0 * b.sigma_u), (b.u, u_true, b.sigma_u)


def test_the_boundary_is_placed_at_the_free_edge(frame):
    """Measured: the boundary's position on the wall (``Boundary.P``, mapped through the known pose error) against
    the true free edge: 7.8 mm (frontal; 5.6 mm along the wall) and 8.4 mm (oblique; 3.1 mm along). Asserted
    within 2 cm: every landmark's ``s`` is measured from it. (The frontal boundary's left column is 2.5 px inside
    the edge, but its position on the wall is not: the fusion with the fitted plane leans on the right column.)"""
    (model,) = [m for m in frame.res.planes if m.fit.plane.id == "panel"]
    (b,) = model.boundaries
    d = _to_true(frame, b.P) - np.asarray(frame.setup.free_end)
    assert np.hypot(*d) < 0.02, d


def test_selected_candidates_lie_on_the_panel(frame):
    """Measured, per selected candidate (8 frontal, 6 oblique): its plane-constrained observation ``P_observed``,
    mapped through the known pose error, is at most 4.9 mm (frontal) / 6.5 mm (oblique) from the true panel's plane
    (10.3 / 9.1 mm with the pose error left in); asserted within 3 cm: three times the fit's allowed error above, a
    twentieth of the pole's 0.6 m (nothing standing in front passes), and 0.15 px of disparity at 3.5 m. Its
    position along the panel lies between the free edge and the other end (1 cm slack). The unconstrained
    triangulation of its two columns from the true pose (what the off-wall test looks at) lies at most 53 mm
    (frontal) / 65 mm (oblique) from the plane, 0.3 px of disparity; asserted within 15 cm, a quarter of the pole's
    distance (the method's own off-wall test allows 3 σ = 0.22 m at 3.5 m with σ_img 0.25 px). And every poster
    side inside the searchable columns has a selected candidate within 2 cm of it along the wall, ``s`` measured
    from the boundary found (measured at most 5.6 mm off)."""
    fr = frame
    sel = fr.res.selected
    assert len(sel) >= 4, [(c.u_left, c.reason) for c in fr.res.candidates]
    P = _to_true(fr, np.array([c.P_observed for c in sel]))
    assert np.abs(fr.panel.offset(P)).max() < 0.03, fr.panel.offset(P)
    s = fr.panel.along(P, fr.panel.free_edges[0])
    assert s.min() > -0.01 and s.max() < fr.panel.length + 0.01, s
    raw, _ = CAMERA.triangulate(np.array([c.u_left for c in sel]), np.array([c.u_right for c in sel]), fr.X_true)
    assert np.abs(fr.panel.offset(raw)).max() < 0.15, fr.panel.offset(raw)
    (lo, hi), _ = disparity_limits(Config().sad, CAMERA.width)
    s_sel = np.array([c.s for c in sel])
    for _, s0, s1, _, _ in POSTERS:
        for s_side in (s0, s1):
            xy = fr.panel.point_at(s_side, fr.panel.free_edges[0])
            u = pinhole(CAMERA, fr.X_true, np.array([*xy, 1.0]))[0]
            if lo + 10 < u < hi - 10:
                assert np.abs(s_sel - s_side).min() < 0.02, (s_side, s_sel)


def test_no_selected_candidate_on_the_pole(frontal):
    """Measured: the pole (radius 3 cm, 0.6 m in front of the panel) spans columns 443.5–454.2 from the true pose;
    the nearest selected candidate is at 469.4 px (a poster's side). Asserted: no selected candidate within 8 px of
    the pole's silhouette. Not vacuous: both of the pole's sides are matched as segment pairs with the pole's
    disparity (20.7 px, within 1 px) — the disparity filter then drops them (no candidate lies near the pole)."""
    fr = frontal
    (x, y), r = fr.setup.pole, fr.setup.pole_radius
    Xc, Zc = (float(v) for v in CAMERA.to_camera(fr.X_true, np.array([x, y])))
    half = math.asin(r / math.hypot(Xc, Zc))
    sides = CAMERA.cu + CAMERA.f * np.tan(math.atan2(Xc, Zc) + np.array([-half, half]))
    u_sel = np.array([c.u_left for c in fr.res.selected])
    assert not np.any((u_sel > sides[0] - 8) & (u_sel < sides[1] + 8)), (sides, u_sel)
    pairs = fr.res.front.pairs
    d_pole = CAMERA.f * CAMERA.baseline / Zc
    for side in sides:
        near = (np.abs(pairs.u_left - side) < 2.0) & (np.abs(pairs.u_left - pairs.u_right - d_pole) < 1.0)
        assert near.any(), (side, pairs.u_left[np.abs(pairs.u_left - side) < 5])


def test_disparity_on_the_panel(frame):
    """Measured: ``res.front.disparity.left`` on the panel's pixels (the renderer's labels of pixels covered whole
    by the panel, eroded by half the SAD window so that no window reaches another object, inside the columns where
    SAD can match) against the true disparity ``f b / Z`` of the true panel from the true pose: frontal (82,134 px)
    median |error| 0.038 px, 98.1 % valid, 95th percentile 0.12 px, none off by more than 1 px (max 0.53);
    oblique (45,951 px) 0.047 px, 96.7 % valid, 95th percentile 0.19 px, none off by more than 1 px. Asserted:
    all computed, at least 85 % valid, median |error| below 0.2 px, fewer than 2 % off by more than 1 px."""
    fr = frame
    pan = fr.pair.labels_left == fr.pair.label("panel")
    k = 2 * SAD_HALF + 1
    inner = cv2.erode(pan.astype(np.uint8), np.ones((k, k), np.uint8), borderValue=0).astype(bool)
    (lo, hi), _ = disparity_limits(Config().sad, CAMERA.width)
    inner[:, :lo] = inner[:, hi + 1 :] = False
    D = fr.res.front.disparity.left
    lazy = fr.res.front.lazy
    computed = lazy.done[0] if lazy is not None else np.ones_like(inner)
    assert computed[inner].mean() > 0.99
    v, u = np.nonzero(inner)
    truth = CAMERA.f * CAMERA.baseline / _depth_on_panel(fr, fr.X_true, u)
    d = D[v, u]
    ok = np.isfinite(d)
    err = np.abs(d[ok] - truth[ok])
    print(f"panel pixels {inner.sum()}, valid {ok.mean():.3f}, median |err| {np.median(err):.3f} px, "
          f">1 px {np.mean(err > 1):.4f}")
    assert ok.mean() > 0.85
    assert np.median(err) < 0.2
    assert np.mean(err > 1.0) < 0.02
