"""``ekf.update_selection: joint``: the k landmarks that update the pose chosen for what they give together."""

from __future__ import annotations

import numpy as np
import pytest

from stablemarks.config import Config, parse_config
from stablemarks.errors import ConfigError
from stablemarks.estimation import EKFConfig, JointEKF, NewLandmark

from .test_estimation import CAM, WALL, X0, random_filter


def test_joint_observation_covariance_is_the_dense_one():
    """``S = H P Hᵀ + R`` and ``C = P_X· Hᵀ`` of the stacked observations, cross terms included."""
    rng = np.random.default_rng(3)
    ekf, _ = random_filter(rng)
    ids = ekf.landmark_ids
    P_XX, C, S = ekf._observation_joint(ids, 0.2)
    _, H = ekf.observation_model(ids, 0.2)
    P = ekf.cov
    np.testing.assert_allclose(S, H @ P @ H.T + CAM.sigma_img**2 * np.eye(len(S)), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(C, P[:3] @ H.T, rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(P_XX, P[:3, :3])


def test_joint_information_is_the_stacked_updates_log_det_reduction():
    rng = np.random.default_rng(4)
    ekf, _ = random_filter(rng)
    ids = ekf.landmark_ids
    # one landmark: the individual gain
    for i, g in zip(ids, ekf.information_gain(ids, 0.1), strict=True):
        assert ekf.joint_information([i], 0.1) == pytest.approx(g, rel=1e-9)
    # several: the reduction of log det P_XX by one update with all of them
    some = ids[:3]
    f = ekf.copy()
    f.update([(i, f.predict_observation([i], 0.1).uv[0]) for i in some], pan=0.1)
    reduction = 0.5 * (np.linalg.slogdet(ekf.cov_pose)[1] - np.linalg.slogdet(f.cov_pose)[1])
    assert ekf.joint_information(some, 0.1) == pytest.approx(reduction, rel=1e-7)


def redundant_filter(selection="joint"):
    """Two landmarks at almost the same place, each known to 2 mm, and one elsewhere known to 3 mm: each of the
    pair alone gives more than the third, but the second of the pair adds little to the first."""
    ekf = JointEKF(CAM, X0, np.diag([0.05, 0.05, 0.02]) ** 2, EKFConfig(update_selection=selection))
    ids = ekf.add_landmarks([NewLandmark.wall(WALL, s) for s in (1.20, 1.22, 2.6)], np.diag([0.002, 0.002, 0.003]) ** 2)
    return ekf, ids


def test_joint_selection_takes_what_the_chosen_do_not_already_give():
    ekf, ids = redundant_filter()
    pairs = [(i, j) for j, i in enumerate(ids)]
    gains = ekf.information_gain(ids)
    assert gains[2] < min(gains[0], gains[1])  # the third ranks last on its own
    individual, _ = redundant_filter("individual")
    alone = [i for i, _ in individual.select_for_update(pairs, k=2)]
    joint = [i for i, _ in ekf.select_for_update(pairs, k=2)]
    assert set(alone) == {ids[0], ids[1]}
    assert joint[0] == alone[0] and joint[1] == ids[2]
    assert ekf.joint_information(joint) > ekf.joint_information(alone) + 0.1
    # with room for every pair the choice is every pair, as the individual ranking gives them
    assert ekf.select_for_update(pairs, k=3) == individual.select_for_update(pairs, k=3)


def test_joint_selection_is_greedy_on_random_filters():
    """Each pick is the best conditional gain: no other candidate adds more to those chosen before it."""
    rng = np.random.default_rng(11)
    for _ in range(5):
        ekf, _ = random_filter(rng)
        ids = ekf.landmark_ids
        order = ekf.joint_selection(ids, 0.0, 3)
        assert order is not None and len(set(order)) == 3
        for n in range(3):
            before = [ids[j] for j in order[:n]]
            base = ekf.joint_information(before) if before else 0.0
            best = ekf.joint_information(before + [ids[order[n]]]) - base
            for j in set(range(len(ids))) - set(order[: n + 1]):
                assert ekf.joint_information(before + [ids[j]]) - base <= best + 1e-9


def test_update_selection_is_checked():
    with pytest.raises(ConfigError, match="ekf.update_selection"):
        EKFConfig(update_selection="best")
    with pytest.raises(ConfigError, match="ekf.update_selection"):
        parse_config({"ekf": {"update_selection": 3}})
    assert parse_config({"ekf": {"update_selection": "joint"}}).ekf.update_selection == "joint"
    assert Config().ekf.update_selection == "individual"


def test_the_information_pan_policy_weighs_what_the_update_would_take():
    """With the joint choice, a view's expected information is what the k landmarks the filter would update with
    give together (:func:`stablemarks.viewing.expected_information`), not the sum of their gains alone."""
    from stablemarks.viewing import expected_information

    from .test_estimation import WORLD

    ekf, ids = redundant_filter()
    ekf_k2 = JointEKF(CAM, X0, ekf.cov_pose, EKFConfig(update_selection="joint", max_updates_per_frame=2))
    ekf_k2.add_landmarks([NewLandmark.wall(WALL, s) for s in (1.20, 1.22, 2.6)], np.diag([0.002, 0.002, 0.003]) ** 2)
    got = expected_information(ekf_k2, WORLD, CAM, X0, 0.0, 0.0)
    picks = [ids[j] for j in ekf_k2.joint_selection(ids, 0.0, 2)]
    assert got == pytest.approx(ekf_k2.joint_information(picks), rel=1e-12)
    individual, _ = redundant_filter("individual")
    alone = expected_information(individual, WORLD, CAM, X0, 0.0, 0.0)
    assert alone == pytest.approx(float(np.sum(np.sort(individual.information_gain(ids))[::-1][:6])), rel=1e-12)
