import json
import math

import numpy as np
import pytest

from stablemarks.geometry import SE2
from stablemarks.sim import Renderer, parse_scenario

from .test_sim_render import edge_column

# A wall 5 m ahead of a robot at the origin facing +y, with features in view, out of view, hidden by a
# tall box, half hidden by a low box, and one on a wall behind the robot. Small images keep it fast.
SCENARIO = {
    "name": "occlusion",
    "camera": {"width": 320, "height": 240, "f": 250.0, "baseline": 0.12, "mount_height": 1.0, "image_noise": 1.0},
    "walls": [
        {"id": "w", "p1": [-2.0, 5.0], "p2": [6.0, 5.0], "z": [0.0, 2.0], "free_edges": ["p1", "p2"],
         "texture": {"base": 128, "contrast": 8, "scale": 0.04}},
        {"id": "behind", "p1": [-2.0, -3.0], "p2": [2.0, -3.0], "in_map": False},
    ],
    "features": [
        {"id": "a", "wall": "w", "s": 2.0, "z": [0.3, 1.2], "contrast": 60},     # x = 0, in view
        {"id": "b", "wall": "w", "s": 2.5, "z": [0.3, 1.2], "contrast": 60},     # x = 0.5, behind the tall box
        {"id": "c", "wall": "w", "s": 1.0, "z": [0.2, 1.0], "contrast": -60},    # x = -1.0, low box in front
        {"id": "bar", "wall": "w", "s": 4.0, "z": [0.5, 1.5], "kind": "bar", "width": 0.2, "contrast": 50},
        {"id": "far", "wall": "w", "s": 7.5, "z": [0.3, 1.2], "contrast": 60},   # x = 5.5: 48° off axis
        {"id": "back", "wall": "behind", "s": 2.0, "z": [0.3, 1.2], "contrast": 60},
    ],
    "clutter": {
        "boxes": [
            {"id": "tall", "center": [0.5, 3.0], "size": [0.6, 0.4], "height": 1.5},
            {"id": "low", "center": [-0.65, 3.0], "size": [0.6, 0.4], "height": 0.7},
        ],
    },
}
X = SE2(0.0, 0.0, math.pi / 2)


@pytest.fixture(scope="module")
def scene():
    scenario = parse_scenario(SCENARIO, "occlusion.yaml")
    renderer = Renderer(scenario)
    frame = renderer.render(X.as_array(), 0.0, np.random.default_rng(0))
    return scenario, renderer, frame


def test_a_box_in_front_of_a_wall_occludes_its_features(scene):
    _, _, frame = scene
    a, b = frame.truth.edge("a"), frame.truth.edge("b")
    assert a.in_view_l and a.visible_l and a.visible_r and a.visible_fraction_l == pytest.approx(1.0)
    assert b.in_view_l and b.in_view_r  # in the image ...
    assert not b.visible_l and not b.visible_r  # ... but behind the box
    assert b.visible_fraction_l == 0.0 and b.visible_fraction_r == 0.0
    # The image agrees: a strong edge where feature a is, none where the hidden feature b would be.
    _, strength_a = edge_column(frame.left, a.u_l, a.v_top, a.v_bottom, a.polarity)
    _, strength_b = edge_column(frame.left, b.u_l, b.v_top, b.v_bottom, b.polarity, search=1)
    assert strength_a > 100 and strength_b < 30


def test_a_low_box_hides_the_lower_part_of_a_feature(scene):
    _, _, frame = scene
    c = frame.truth.edge("c")
    # Rows whose sight line passes over the box's far top edge (depth 3.2 m, height 0.7 m) are seen:
    # z > 1 - 0.3 * 5 / 3.2 = 0.531 of the feature's 0.2 .. 1.0 m.
    expected = (1.0 - (1.0 - 0.3 * 5.0 / 3.2)) / 0.8
    assert c.visible_fraction_l == pytest.approx(expected, abs=0.03)
    assert c.visible_l


def test_features_outside_the_field_of_view_or_behind_are_not_in_view(scene):
    scenario, _, frame = scene
    far, back = frame.truth.edge("far"), frame.truth.edge("back")
    assert far.u_l > scenario.camera.width and not far.in_view_l and not far.in_view_r
    assert not far.visible_l and far.visible_fraction_l == 0.0
    assert math.isnan(back.u_l) and not back.in_view_l and not back.in_view_r
    record = back.to_dict()
    assert record["u_l"] is None and record["visible_l"] is False


def test_a_bar_makes_two_edges_of_opposite_polarity(scene):
    _, _, frame = scene
    ea, eb = frame.truth.edge("bar-a"), frame.truth.edge("bar-b")
    assert ea.polarity == 1 and eb.polarity == -1
    assert ea.visible_l and ea.visible_r and eb.visible_l and eb.visible_r
    assert eb.u_l - ea.u_l == pytest.approx(250.0 * 0.2 / 5.0)
    for e in (ea, eb):
        for image, u in ((frame.left, e.u_l), (frame.right, e.u_r)):
            assert abs(edge_column(image, u, e.v_top, e.v_bottom, e.polarity)[0] - u) < 1.0


def test_free_edges_are_boundary_edges(scene):
    _, _, frame = scene
    p1, p2 = frame.truth.edge("w-p1"), frame.truth.edge("w-p2")
    assert p1.boundary and p1.kind == "boundary" and p1.z == (0.0, 2.0)
    assert (p1.x, p1.y) == (-2.0, 5.0) and p1.s == 0.0 and p2.s == 8.0
    assert p1.visible_l and p1.visible_r
    assert p1.polarity == 1  # dark background on its left, the wall on its right
    assert not p2.in_view_l and p2.polarity == 0
    for image, u in ((frame.left, p1.u_l), (frame.right, p1.u_r)):
        assert abs(edge_column(image, u, p1.v_top, p1.v_bottom, p1.polarity)[0] - u) < 1.0
    # Walls that are not in the map have no boundary edges.
    assert not any(e.wall == "behind" and e.boundary for e in frame.truth.edges)


def test_truth_matches_the_camera_projection(scene):
    scenario, _, frame = scene
    cam = scenario.camera
    a = frame.truth.edge("a")
    expected = cam.project_line(X.as_array(), a.line)
    np.testing.assert_allclose([a.u_l, a.u_r, a.v_top, a.v_bottom], expected)


def test_truth_is_json_serialisable(scene):
    _, _, frame = scene
    text = json.dumps(frame.truth.to_dict(), allow_nan=False)
    back = json.loads(text)
    assert back["pose"] == pytest.approx([0.0, 0.0, math.pi / 2])
    assert {e["id"] for e in back["edges"]} == {"a", "b", "c", "bar-a", "bar-b", "far", "back", "w-p1", "w-p2"}
