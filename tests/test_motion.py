import math

import numpy as np
import pytest

from stablemarks.errors import InputError
from stablemarks.geometry import SE2, StereoCamera
from stablemarks.maps import Map, ReferencePlane
from stablemarks.motion import (
    Forward,
    GoTo,
    OdometryNoise,
    Turn,
    decompose,
    increments,
    integrate,
    look_at_free_edges,
    plan_path,
)

from .helpers import assert_psd

LIMITS = (-math.pi / 2, math.pi / 2)


# ------------------------------------------------------------- odometry noise
@pytest.mark.parametrize("delta", [
    SE2(0.1, 0.0, 0.0),                      # straight drive
    SE2(0.3, 0.05, math.radians(12.0)),      # drive while turning
    SE2(0.0, 0.0, math.radians(-30.0)),      # turn on the spot
    SE2(-0.2, 0.01, math.radians(3.0)),      # reverse
])
def test_covariance_matches_monte_carlo(delta):
    noise = OdometryNoise(trans_per_m=0.05, rot_per_m_deg=2.0, rot_per_rad=0.05, trans_per_rad=0.005)
    rng = np.random.default_rng(3)
    samples = noise.samples(delta, rng, 200_000)
    cov = noise.covariance(delta)
    assert_psd(cov)
    sigma_mean = np.sqrt(np.diag(cov).max() / len(samples))
    np.testing.assert_allclose(samples.mean(axis=0), delta.as_array(), atol=4 * sigma_mean + 1e-12)
    sample_cov = np.cov(samples.T)
    scale = np.sqrt(np.outer(np.diag(cov), np.diag(cov))) + 1e-30
    # Linearisation is first order; the noise here is small, so the two agree to a few percent.
    np.testing.assert_allclose(sample_cov / scale, cov / scale, atol=0.03)


def test_covariance_of_a_straight_drive_has_the_readable_figures():
    noise = OdometryNoise(trans_per_m=0.05, rot_per_m_deg=2.0, rot_per_rad=0.0, trans_per_rad=0.0)
    cov = noise.covariance(SE2(1.0, 0.0, 0.0))
    assert math.sqrt(cov[0, 0]) == pytest.approx(0.05)             # 5 % of the distance
    assert math.sqrt(cov[2, 2]) == pytest.approx(math.radians(2.0))  # 2° per metre of heading


def test_zero_noise_sample_is_the_motion():
    delta = SE2(0.4, -0.1, 0.3)
    zero = OdometryNoise(0.0, 0.0, 0.0, 0.0)
    out = zero.sample(delta, np.random.default_rng(0))
    np.testing.assert_allclose(out.as_array(), delta.as_array(), atol=1e-12)
    np.testing.assert_allclose(zero.covariance(delta), 0.0)


def test_decompose_reverse_drive():
    rot1, trans, rot2 = decompose(SE2(-1.0, 0.0, 0.0))
    assert trans == pytest.approx(-1.0)
    assert rot1 == pytest.approx(0.0, abs=1e-12) and rot2 == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("field", ["trans_per_m", "rot_per_m_deg", "rot_per_rad", "trans_per_rad"])
def test_odometry_noise_rejects_negative(field):
    with pytest.raises(InputError, match=rf"odometry\.{field}: expected a non-negative number, got -1"):
        OdometryNoise(**{field: -1.0})


# ------------------------------------------------------------ dead reckoning
def test_integrate_recovers_poses_from_their_increments():
    rng = np.random.default_rng(1)
    poses = [SE2(1.0, 2.0, 0.3)]
    for _ in range(30):
        poses.append(poses[-1] @ SE2(*rng.normal(0, [0.2, 0.05, 0.2])))
    out = integrate(poses[0], increments(poses))
    assert len(out) == len(poses)
    np.testing.assert_allclose([p.as_array() for p in out], [p.as_array() for p in poses], atol=1e-9)


def test_integrate_square_closes():
    step = SE2(1.0, 0.0, math.pi / 2)
    out = integrate(SE2(), [step] * 4)
    np.testing.assert_allclose(out[-1].as_array(), [0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(out[1].as_array(), [1.0, 0.0, math.pi / 2], atol=1e-12)


# --------------------------------------------------------------------- paths
def test_plan_path_forward_spacing():
    poses = plan_path(SE2(0.0, 0.0, math.pi / 2), [Forward(2.0)], frame_spacing=0.1)
    assert len(poses) == 21
    xy = np.array([p.translation for p in poses])
    np.testing.assert_allclose(xy[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(xy[:, 1], np.linspace(0.0, 2.0, 21), atol=1e-12)


def test_plan_path_turn_and_goto():
    poses = plan_path(SE2(), [Turn(math.radians(25.0)), GoTo((1.0, 1.0))], frame_spacing=0.5,
                      frame_turn=math.radians(10.0))
    # 25° in 3 parts, then a turn of 20° (to 45°) in 2 parts, then sqrt(2) m in 3 parts
    assert len(poses) == 1 + 3 + 2 + 3
    assert poses[3].theta == pytest.approx(math.radians(25.0))
    assert poses[5].theta == pytest.approx(math.radians(45.0))
    np.testing.assert_allclose(poses[-1].translation, [1.0, 1.0], atol=1e-12)


# ---------------------------------------------------------------- pan policy
def lab_map(extra=()):
    return Map((
        ReferencePlane("partition", (0.0, 4.0), (1.2, 4.0), free_edges=("p1",)),
        ReferencePlane("whiteboard", (-0.55, 6.0), (-2.3, 6.0), free_edges=("p1",)),
        *extra,
    ))


def test_pan_points_at_midpoint_of_free_edges():
    cam = StereoCamera()
    X = np.array([0.0, 1.0, math.pi / 2])
    pan = look_at_free_edges(lab_map(), cam, X, limits=LIMITS)
    mid = np.array([(0.0 - 0.55) / 2, 5.0])
    heading = X[2] + pan
    direction = mid - X[:2]
    assert math.atan2(direction[1], direction[0]) == pytest.approx(heading)
    # The midpoint then projects on the image centre column.
    assert cam.with_pan(pan).project_columns(X, mid)[0] == pytest.approx(cam.cu)


def test_pan_is_clamped_and_defaults_when_nothing_is_in_sight():
    cam = StereoCamera()
    # Facing away from both planes: nothing within the pan range ± half the field of view.
    X = np.array([0.0, 0.0, -math.pi / 2])
    assert look_at_free_edges(lab_map(), cam, X, limits=(-0.5, 0.5), default=0.2) == pytest.approx(0.2)
    assert look_at_free_edges(lab_map(), cam, X, limits=(-0.5, 0.5), default=0.9) == pytest.approx(0.5)
    # Facing +x: the edges are at ~ +90°, reachable, but the pan stops at the limit.
    X = np.array([0.0, 0.0, 0.0])
    assert look_at_free_edges(lab_map(), cam, X, limits=(-1.2, 1.2)) == pytest.approx(1.2)


def test_pan_ignores_free_edges_hidden_by_walls():
    cam = StereoCamera()
    X = np.array([0.0, 0.0, math.pi / 2])
    wall = ReferencePlane("screen", (-1.5, 5.0), (-0.2, 5.0), reference=False)  # hides the whiteboard's edge
    pan = look_at_free_edges(lab_map([wall]), cam, X, limits=LIMITS)
    # Only the partition's edge at (0, 4) is left: look straight at it.
    assert pan == pytest.approx(0.0, abs=1e-9)
