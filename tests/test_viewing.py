"""Pan policies (viewing.py): fixed, the paper's free_edges, and information."""

import math

import numpy as np
import pytest

from stablemarks.estimation import JointEKF, NewLandmark
from stablemarks.geometry import StereoCamera
from stablemarks.maps import Map, ReferencePlane
from stablemarks.viewing import PanConfig, choose_pan, expected_information

CAM = StereoCamera()
LEFT = ReferencePlane("left", (-6.0, 3.0), (-3.5, 3.0), free_edges=("p2",))
RIGHT = ReferencePlane("right", (3.5, 3.0), (6.0, 3.0), free_edges=("p1",))
MAP = Map((LEFT, RIGHT))
X = np.array([0.0, 0.0, math.pi / 2])
COV = np.diag([0.05, 0.05, np.radians(1.0)]) ** 2


def test_fixed_and_free_edges():
    assert choose_pan(PanConfig(policy="fixed", angle=0.3), MAP, CAM, X) == pytest.approx(0.3)
    assert choose_pan(PanConfig(policy="fixed", angle=0.3, limits=(-0.2, 0.2)), MAP, CAM, X) == pytest.approx(0.2)
    # two edges that fit in one view: their midpoint (the paper's rule)
    near = Map((ReferencePlane("l", (-6.0, 6.0), (-1.0, 6.0), free_edges=("p2",)),
                ReferencePlane("r", (1.0, 6.0), (6.0, 6.0), free_edges=("p1",))))
    assert choose_pan(PanConfig(), near, CAM, X) == pytest.approx(0.0, abs=1e-9)


def test_free_edges_too_far_apart_for_one_view_look_at_one_of_them():
    # the edges are ±49° off the heading, farther apart than the view (their midpoint would show neither):
    # the head looks at one, the one nearer its previous pan
    half = CAM.half_fov
    assert 2 * math.radians(49.4) > 2 * half
    for previous in (0.5, -0.5):
        pan = choose_pan(PanConfig(), MAP, CAM, X, previous)
        assert pan == pytest.approx(math.copysign(math.atan2(3.5, 3.0), previous), abs=1e-6)
    # three edges: the two that fit together win over the lone one, whatever the previous pan
    three = Map((LEFT, RIGHT, ReferencePlane("far", (4.5, 6.0), (8.0, 6.0), free_edges=("p1",))))
    pan = choose_pan(PanConfig(), three, CAM, X, 1.0)
    assert pan < -0.3


def test_free_edges_on_walls_seen_at_a_grazing_angle_are_not_looked_at():
    # a wall along the line of sight: its free edge is 80° off its normal
    graze = ReferencePlane("graze", (-1.0, 8.0), (-1.0, 3.0), free_edges=("p2",))
    front = ReferencePlane("front", (0.5, 6.0), (3.0, 6.0), free_edges=("p1",))
    m = Map((graze, front))
    with_graze = choose_pan(PanConfig(), m, CAM, X, 0.0)
    without = choose_pan(PanConfig(), m, CAM, X, 0.0, max_incidence=math.radians(60.0))
    assert without == pytest.approx(-math.atan2(0.5, 6.0), abs=1e-6)
    assert with_graze > without


def test_information_looks_at_the_wall_with_landmarks_it_can_use():
    ekf = JointEKF(CAM, X, COV)
    ekf.add_landmarks([NewLandmark.wall(RIGHT, s) for s in (0.2, 0.5, 0.9)], 1e-4 * np.eye(3))
    config = PanConfig(policy="information", new_edge_value=0.0)
    pan = choose_pan(config, MAP, CAM, X, 0.0, ekf=ekf)
    assert pan < -0.2  # towards the right wall (negative pan: to the right)
    assert expected_information(ekf, MAP, CAM, X, pan, 0.0) > expected_information(ekf, MAP, CAM, X, 0.6, 0.0)


def test_information_values_new_edges_and_respects_the_rate():
    ekf = JointEKF(CAM, X, COV)
    ekf.add_landmarks([NewLandmark.wall(RIGHT, s) for s in (0.2, 0.5)], 1e-2 * np.eye(2))
    left_edge = choose_pan(PanConfig(policy="information", new_edge_value=50.0), MAP, CAM, X, 0.0, ekf=ekf)
    assert left_edge > 0.2  # the left wall's free edge has no landmark yet: worth more than the right's few
    slow = choose_pan(PanConfig(policy="information", new_edge_value=50.0, max_rate=0.1), MAP, CAM, X, 0.0, ekf=ekf,
                      dt=0.5)
    assert abs(slow) <= 0.05 + 1e-12


def test_bad_pan_settings():
    with pytest.raises(Exception, match="pan.policy: expected one of fixed, free_edges, information"):
        PanConfig(policy="random")
    with pytest.raises(Exception, match="pan.limits"):
        PanConfig(limits=(0.5, 0.1))
