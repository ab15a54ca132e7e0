"""Landmark modeling and selection on rendered scenes of other layouts (Sec 3-4)."""

import copy

import numpy as np
import pytest

from stablemarks.landmarks import (
    REASON_LENGTH,
    REASON_NEAR_BOUNDARY,
    Boundary,
    Candidate,
    LandmarkConfig,
    minimum_variance_column,
    robust_rows,
    select,
)
from stablemarks.pipeline import process_frame
from stablemarks.sim.render import render_stereo
from stablemarks.sim.scenario import parse_scenario

from .conftest import COV_PRIOR

BASE = {
    "name": "wall-test",
    "camera": {"width": 640, "height": 480, "f": 500.0, "baseline": 0.12, "mount_height": 1.0, "image_noise": 2.0},
    "walls": [
        {"id": "panel", "p1": [0.0, 3.5], "p2": [1.5, 3.5], "z": [0.0, 1.8], "free_edges": ["p1", "p2"],
         "texture": {"kind": "noise", "base": 110, "contrast": 14, "scale": 0.03}},
        {"id": "back", "p1": [-5.0, 7.0], "p2": [5.0, 7.0], "z": [0.0, 2.8], "reference": False,
         "texture": {"kind": "noise", "base": 140, "contrast": 10, "scale": 0.05}},
    ],
    "features": [
        {"id": "panel-a", "wall": "panel", "s": 0.45, "z": [0.5, 1.4], "kind": "edge", "contrast": 60, "fade": 0.3},
        {"id": "panel-b", "wall": "panel", "s": 0.85, "z": [0.3, 1.2], "kind": "edge", "contrast": -60, "fade": 0.3},
    ],
    "robot": {"start": {"x": 0.3, "y": 0.0, "theta_deg": 90.0}},
}
X0 = np.array([0.3, 0.0, np.pi / 2])


def run_scene(doc, X_prior=X0, cov=COV_PRIOR, seed=0):
    sc = parse_scenario(doc, "test")
    frame = render_stereo(sc, X0, 0.0, np.random.default_rng(seed))
    return process_frame(frame.left, frame.right, sc.camera, sc.map, X_prior, cov), frame


def assert_true_features_selected(result, frame, ids=("panel-a", "panel-b")):
    truth = {e.id: e for e in frame.truth.edges}
    for fid in ids:
        e = truth[fid]
        near = [c for c in result.selected if np.hypot(c.P[0] - e.x, c.P[1] - e.y) <= 3 * c.sigma_s]
        assert near, f"{fid} not selected"


def test_features_on_a_plain_wall_are_selected():
    result, frame = run_scene(BASE)
    assert_true_features_selected(result, frame)


def test_wall_at_an_angle():
    doc = copy.deepcopy(BASE)
    doc["walls"][0].update(p1=[-0.2, 3.0], p2=[1.2, 4.2])  # 40° to the image plane
    result, frame = run_scene(doc)
    assert result.fits[0], result.warnings
    assert_true_features_selected(result, frame)
    for c in result.candidates:  # every candidate lies on the map's wall, with rank-1 covariance along it
        assert abs(result.fits[0].plane.offset(c.P)) < 1e-9
        assert np.linalg.matrix_rank(c.cov, tol=1e-12) == 1


def test_clutter_in_front_of_the_wall_is_not_selected():
    doc = copy.deepcopy(BASE)
    doc["clutter"] = {"poles": [{"id": "pole", "center": [0.65, 2.6], "radius": 0.04, "height": 1.9,
                                 "texture": {"kind": "plain", "base": 30}}]}
    result, frame = run_scene(doc)
    assert result.fits[0]
    assert_true_features_selected(result, frame, ("panel-a",))
    cam = parse_scenario(doc, "test").camera
    d_pole = cam.disparity(X0, np.array([0.65, 2.6]))
    assert (np.abs(result.front.pairs.disparity - d_pole) < 2.0).any()  # the pole's edges are matched ...
    for c in result.candidates:  # ... but none of them is a candidate on the panel
        assert abs((c.u_left - c.u_right) - d_pole) > 2.0, c


def test_plane_without_texture_gives_no_landmarks_and_no_crash():
    doc = copy.deepcopy(BASE)
    doc["walls"][0]["texture"] = {"kind": "plain", "base": 110}
    doc["features"] = []
    doc["camera"]["image_noise"] = 0.0
    result, _ = run_scene(doc)
    assert result.selected == []


def test_wrong_pose_prior_puts_the_plane_outside_the_window():
    X_wrong = np.array([0.3, 0.0, np.pi / 2 + np.deg2rad(70)])  # looking far to the left
    result, _ = run_scene(BASE, X_prior=X_wrong, cov=np.diag([0.01, 0.01, np.deg2rad(0.5)]) ** 2)
    assert result.selected == []
    assert result.warnings and "no reference plane" in result.warnings[0]


# --------------------------------------------------------------- units
def test_minimum_variance_column_is_the_mean_inside_the_window():
    cols = np.array([10.0, 11.0, 12.0, 11.0])
    m, var = minimum_variance_column(cols, 5, 20)
    assert m == pytest.approx(11.0) and var == pytest.approx(0.5)
    m, _ = minimum_variance_column(cols, 12, 20)  # mean outside the window: best integer column inside
    assert m == 12.0


def test_robust_rows_drop_floor_rows():
    cols = np.r_[np.full(50, 100.0) + np.random.default_rng(0).normal(0, 1, 50), [70.0, 72.0, 75.0]]
    keep = robust_rows(cols, 3.0)
    assert keep[:50].all() and not keep[50:].any()


def _cand(s, sigma_f=0.003, ls=1.0):
    return Candidate("w", "w", 0, 0, "p1", s, 0.035, sigma_f, np.array([s, 4.0]), np.zeros((2, 2)), 0.0, 1.0, ls,
                     0.0, 0.0, 0.0, 0.0, P_observed=np.array([s, 4.0]))


def test_selection_rules():
    b = Boundary("w", "p1", np.zeros(2), np.ones(2), np.array([0.0, 4.0]), np.eye(2), 0.035, False, 100,
                 np.array([1.0, 0.0]))
    cands = [_cand(0.1094), _cand(0.1778), _cand(0.5, ls=0.5), _cand(-0.2)]
    out = select(cands, [b])
    assert [c.selected for c in out] == [False, True, False, False]
    assert out[0].reason == REASON_NEAR_BOUNDARY and out[2].reason == REASON_LENGTH
    assert out[3].reason == "outside the plane"
    # DESIGN's combined rule would select Table 1's partition 2 (109.4 mm > 3·35.1 mm)
    combined = select(cands[:1], [b], LandmarkConfig(boundary_rule="combined"))
    assert combined[0].selected


def test_landmark_config_validation():
    with pytest.raises(ValueError, match="boundary_rule"):
        LandmarkConfig(boundary_rule="loose")


def test_free_edge_behind_the_camera_does_not_break_the_frame(lab_scenario, lab_sim, lab_first_frame):
    """A wall in view whose free edge is behind the camera (walls from a whole-room map)."""
    from stablemarks.maps import Map, ReferencePlane

    side = ReferencePlane("side", (-2.0, -1.0), (-2.0, 5.0), free_edges=("p1",))
    world = Map(lab_scenario.map.planes + (side,))
    cam = lab_scenario.camera.with_pan(lab_sim.pans[0])
    result = process_frame(lab_first_frame.left, lab_first_frame.right, cam, world, lab_sim.poses[0].as_array(),
                           COV_PRIOR)
    assert len(result.selected) >= 9


def test_a_free_edge_out_of_sight_still_rejects_features_near_it():
    from stablemarks.landmarks import mapped_boundaries
    from stablemarks.maps import ReferencePlane

    plane = ReferencePlane("w", (0.0, 4.0), (1.2, 4.0), free_edges=("p1", "p2"))
    ref = Boundary("w", "p1", np.zeros(2), np.ones(2), np.array([0.0, 4.0]), np.eye(2), 0.035, False, 100,
                   np.array([1.0, 0.0]))
    far = mapped_boundaries(plane, [ref], ref)
    assert len(far) == 1 and far[0].edge == "p2"
    np.testing.assert_allclose(far[0].P, [1.2, 4.0])
    out = select([_cand(1.15), _cand(0.6)], [ref] + far)
    assert [c.selected for c in out] == [False, True]
    assert out[0].reason == REASON_NEAR_BOUNDARY


def test_a_wall_end_against_another_wall_rejects_features_near_it():
    """A door leaf opened against a wall: its hinge end is not free, but features there are near a boundary."""
    from stablemarks.landmarks import mapped_boundaries
    from stablemarks.maps import ReferencePlane

    plane = ReferencePlane("w", (0.0, 4.0), (0.95, 4.0), free_edges=("p1",))
    ref = Boundary("w", "p1", np.zeros(2), np.ones(2), np.array([0.0, 4.0]), np.eye(2), 0.035, False, 100,
                   np.array([1.0, 0.0]))
    far = mapped_boundaries(plane, [ref], ref)
    assert [b.edge for b in far] == ["p2"]
    out = select([_cand(0.93), _cand(1.01), _cand(0.5)], [ref] + far)
    assert [c.selected for c in out] == [False, False, True]


def _poster_scene(gap):
    """A poster board across the view whose far end is ``gap`` metres in front of a perpendicular side wall."""
    doc = copy.deepcopy(BASE)
    doc["walls"][0].update(p1=[0.0, 3.5], p2=[-1.5 + gap, 3.5])
    doc["walls"].append({"id": "side", "p1": [-1.5, 0.0], "p2": [-1.5, 7.0], "z": [0.0, 2.8], "reference": False,
                         "texture": {"kind": "noise", "base": 100, "contrast": 10, "scale": 0.05}})
    doc["features"] = [
        {"id": "panel-a", "wall": "panel", "s": 0.3, "z": [0.5, 1.4], "kind": "edge", "contrast": 60, "fade": 0.3},
        {"id": "panel-b", "wall": "panel", "s": 0.6, "z": [0.3, 1.2], "kind": "edge", "contrast": -60, "fade": 0.3},
    ]
    doc["robot"] = {"start": {"x": -0.6, "y": 0.0, "theta_deg": 90.0}}
    return doc


@pytest.mark.parametrize("gap", [0.04, 0.8])
def test_edge_depth_step_from_the_map(gap):
    from stablemarks.landmarks import edge_depth_step

    sc = parse_scenario(_poster_scene(gap), "test")
    X = np.array([-0.6, 0.0, np.pi / 2])
    plane = sc.map["panel"]
    fb = sc.camera.f * sc.camera.baseline
    # open side: beyond p1 the back wall at y = 7 (0.6 + 5 px left of the edge hardly changes its depth)
    step_p1 = edge_depth_step(sc.camera, X, sc.map, plane, "p1", 5.0)
    assert step_p1 == pytest.approx(fb / 7.0 - fb / 3.5, abs=0.05)
    step_p2 = edge_depth_step(sc.camera, X, sc.map, plane, "p2", 5.0)
    if gap < 0.1:  # the side wall right behind the far end, at nearly the board's depth
        assert abs(step_p2) < 0.5
    else:
        assert step_p2 < -3.0


def test_an_edge_without_a_depth_step_is_not_searched():
    """Beyond the board's far end the side wall continues at the board's depth: the disparity region runs on
    over it, so that end cannot be found from disparity. It is not searched; the near edge is, and the
    features are modelled from it."""
    doc = _poster_scene(0.04)
    sc = parse_scenario(doc, "test")
    X = np.array([-0.6, 0.0, np.pi / 2])
    frame = render_stereo(sc, X, 0.0, np.random.default_rng(3))
    res = process_frame(frame.left, frame.right, sc.camera, sc.map, X, COV_PRIOR)
    (model,) = [m for m in res.planes if m.fit.plane.id == "panel"]
    assert [b.edge for b in model.boundaries] == ["p1"]
    assert abs(model.boundaries[0].P[0] - 0.0) < 3 * model.boundaries[0].sigma_along
    assert_true_features_selected(res, frame)
    # Without the map's help the far end is "found" where the region ends, on the side wall.
    from stablemarks.landmarks import landmarks_on_plane
    from stablemarks.pipeline import valid_columns

    blind = landmarks_on_plane(sc.camera, model.fit, res.front.kept_pairs, res.front.left_segments,
                               res.front.disparity.right, window_px=15.0,
                               valid_columns=valid_columns(res.front.disparity))
    (far,) = [b for b in blind.boundaries if b.edge == "p2"]
    assert abs(far.P[0] - (-1.46)) > max(2 * far.sigma_along, 0.05)


def test_measured_boundary_sigma_only_on_request(lab_scenario, lab_sim, lab_first_frame):
    """``filter_boundary_sigma: measured`` gives each candidate the boundary's σ without the window term (smaller
    than the selection's σ_b); by default it is not computed."""
    from stablemarks.config import Config

    cam = lab_scenario.camera.with_pan(lab_sim.pans[0])
    X0 = lab_sim.poses[0].as_array()
    args = (lab_first_frame.left, lab_first_frame.right, cam, lab_scenario.map, X0, COV_PRIOR)
    default = process_frame(*args)
    assert default.candidates and all(np.isnan(c.sigma_b_measured) for c in default.candidates)
    measured = process_frame(*args, Config().with_overrides({"landmarks": {"filter_boundary_sigma": "measured"}}))
    assert all(0.0 < c.sigma_b_measured < c.sigma_b for c in measured.candidates)
    # the selection itself does not change
    assert [c.selected for c in measured.candidates] == [c.selected for c in default.candidates]
