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
    assert choose_pan(PanConfig(), MAP, CAM, X) == pytest.approx(0.0, abs=1e-9)  # midpoint of the two edges


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
