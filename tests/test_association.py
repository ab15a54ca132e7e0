"""Data association of wall landmarks (online.py): polarity along the wall, pattern matching along a wall,
the polarity cost of the image-space association, per-wall joint compatibility, and the polarity kept
with each landmark through a saved map."""

from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from stablemarks.errors import ConfigError, InputError
from stablemarks.estimation import JointEKF, NewLandmark, associate_frame, match_along_wall, wall_polarity
from stablemarks.estimation import polarity_cost as _polarity_cost
from stablemarks.geometry import StereoCamera
from stablemarks.landmarks import Candidate
from stablemarks.maps import Map, ReferencePlane
from stablemarks.pipeline import run_front_end
from stablemarks.sim.render import render_stereo
from stablemarks.sim.scenario import parse_scenario

CAMERA = StereoCamera()
X0 = np.array([0.0, 0.0, np.pi / 2])  # looking along +y
COV_POSE = np.diag([0.02, 0.02, np.deg2rad(0.5)]) ** 2
WALL = ReferencePlane("w", (-1.5, 4.0), (1.5, 4.0), free_edges=("p1", "p2"))  # normal +y: X0 on its right side
RIGHT_SIDE, LEFT_SIDE = np.array([0.0, 0.0]), np.array([0.0, 8.0])
Z = (0.4, 1.5)  # heights of every feature [m]


def _ekf(plane=WALL, s=(0.5, 0.9, 1.3, 1.7), polarity=(1, -1, 1, -1), sigma_b=0.03, sigma_f=0.003, ekf=None):
    """A filter at X0 holding wall landmarks modelled from one boundary (``σ_b² 11ᵀ + diag(σ_f²)``)."""
    ekf = ekf or JointEKF(CAMERA, X0, COV_POSE)
    new = [NewLandmark.wall(plane, si, "p1", *Z, polarity=p) for si, p in zip(s, polarity, strict=True)]
    ekf.add_landmarks(new, sigma_b**2 * np.ones((len(s), len(s))) + sigma_f**2 * np.eye(len(s)))
    return ekf


def _cand(plane, s, pair, sigma_b=0.2, sigma_f=0.003):
    """A candidate on ``plane`` at ``s`` from p1 (its boundary uncertain by ``sigma_b``), segment pair ``pair``."""
    P = plane.point_at(np.array([s]))[0]
    return Candidate(plane.id, plane.id, pair + 1, pair, "p1", s, sigma_b, sigma_f, P, np.zeros((2, 2)), *Z, 1.0,
                     0.0, 0.0, 0.0, 0.0, P_observed=P)


class _Pairs:
    """The rows of segment pairs (all the association looks at besides the measured columns)."""

    def __init__(self, n):
        self.v_top, self.v_bottom = np.full(n, 150.0), np.full(n, 300.0)

    def __len__(self):
        return len(self.v_top)


# ---------------------------------------------------------------- wall_polarity
def test_wall_polarity_keeps_the_sign_from_the_right_side_and_flips_it_from_the_left():
    assert wall_polarity(1, WALL, RIGHT_SIDE) == 1
    assert wall_polarity(-1, WALL, RIGHT_SIDE) == -1
    assert wall_polarity(1, WALL, LEFT_SIDE) == -1
    assert wall_polarity(0, WALL, LEFT_SIDE) == 0
    reversed_wall = ReferencePlane("r", WALL.p2, WALL.p1)  # the same wall drawn p2 → p1: the other side is "right"
    assert wall_polarity(1, reversed_wall, RIGHT_SIDE) == -1
    image = np.array([1, -1, 0, 1], dtype=np.int8)
    np.testing.assert_array_equal(wall_polarity(image, WALL, RIGHT_SIDE), [1, -1, 0, 1])
    np.testing.assert_array_equal(wall_polarity(image, WALL, LEFT_SIDE), [-1, 1, 0, -1])


def test_a_painted_edge_has_one_polarity_along_the_wall_from_both_faces():
    """A thin partition seen from both faces: the edge's image polarity flips, its polarity along the wall
    does not."""
    doc = {
        "name": "two-faces",
        "camera": {"width": 640, "height": 480, "f": 500.0, "baseline": 0.12, "mount_height": 1.0,
                   "image_noise": 2.0},
        "walls": [{"id": "part", "p1": [0.0, 3.5], "p2": [1.5, 3.5], "z": [0.0, 1.8], "free_edges": ["p1", "p2"],
                   "texture": {"kind": "noise", "base": 110, "contrast": 14, "scale": 0.03}}],
        "features": [{"id": "f", "wall": "part", "s": 0.6, "z": [0.4, 1.4], "kind": "edge", "contrast": 60,
                      "fade": 0.3}],
        "robot": {"start": {"x": 0.75, "y": 0.0, "theta_deg": 90.0}},
    }
    sc = parse_scenario(doc, "test")
    plane = sc.map["part"]
    image_pol, along = [], []
    for X in (np.array([0.75, 0.0, np.pi / 2]), np.array([0.75, 7.0, -np.pi / 2])):
        frame = render_stereo(sc, X, 0.0, np.random.default_rng(0))
        front = run_front_end(frame.left, frame.right)
        pairs = front.kept_pairs
        e = frame.truth.edge("f")
        j = int(np.argmin(np.abs(pairs.u_left - e.u_l) + np.abs(pairs.u_right - e.u_r)))
        assert abs(pairs.u_left[j] - e.u_l) < 1.0 and abs(pairs.u_right[j] - e.u_r) < 1.0
        pol = int(front.left_segments.polarity[pairs.left_index][j])
        image_pol.append(pol)
        along.append(int(wall_polarity(pol, plane, sc.camera.optical_centres(X)[0])))
    assert image_pol == [1, -1]  # brighter towards p2: to the right from the front, to the left from behind
    assert along == [1, 1]


# ------------------------------------------------------------- match_along_wall
def test_pattern_matching_does_not_shift_onto_features_of_opposite_polarity():
    """Regularly spaced edges of alternating polarity. Seen again with a boundary error of −0.4 m (one
    feature's spacing), features 2–4 are measured where features 1–3 were mapped: by position alone the
    unshifted match is the likelier, but its polarities all disagree."""
    ekf = _ekf()
    ids = ekf.landmark_ids
    cands = [_cand(WALL, s, k) for k, s in enumerate((0.5, 0.9, 1.3))]
    shifted = np.array([-1, 1, -1])  # the polarities of features 2–4, along the wall
    got = match_along_wall(ekf, WALL, cands, polarity=shifted)
    assert sorted(got, key=lambda q: q[1]) == [(ids[1], 0), (ids[2], 1), (ids[3], 2)]
    # the same pattern with the mapped polarities is features 1–3, unshifted
    got = match_along_wall(ekf, WALL, cands, polarity=np.array([1, -1, 1]))
    assert sorted(got, key=lambda q: q[1]) == [(ids[0], 0), (ids[1], 1), (ids[2], 2)]
    # without polarities the shifted pattern is taken for the unshifted one: the case the polarity is for
    assert sorted(match_along_wall(ekf, WALL, cands), key=lambda q: q[1]) == [(ids[0], 0), (ids[1], 1), (ids[2], 2)]


def test_pattern_matching_ignores_unknown_polarity():
    ekf = _ekf(polarity=(0, 0, 0, 0))
    ids = ekf.landmark_ids
    cands = [_cand(WALL, s, k) for k, s in enumerate((0.5, 0.9, 1.3))]
    got = match_along_wall(ekf, WALL, cands, polarity=np.array([-1, 1, -1]))
    assert sorted(got, key=lambda q: q[1]) == [(ids[0], 0), (ids[1], 1), (ids[2], 2)]


def test_the_frames_pattern_is_matched_by_polarity_along_the_wall_from_either_side(monkeypatch):
    """The shifted pattern above, seen from the wall's other face: the image polarities are the opposite
    ones, and associate_frame turns them into polarities along the wall before matching."""
    X_behind = np.array([0.0, 8.0, -np.pi / 2])
    ekf = _ekf(ekf=JointEKF(CAMERA, X_behind, COV_POSE))
    ids = ekf.landmark_ids
    cands = [_cand(WALL, s, k) for k, s in enumerate((0.5, 0.9, 1.3))]
    measured = _predicted(ekf, ids[1:])  # features 2–4 ...
    image = np.array([1, -1, 1])  # ... of steps −1, +1, −1 along the wall, seen from behind
    centre = CAMERA.optical_centres(X_behind)[0]
    model = SimpleNamespace(planes=[SimpleNamespace(fit=SimpleNamespace(plane=WALL), candidates=cands)])
    monkeypatch.setattr(ekf, "associate_joint", lambda *args, **kwargs: [])  # the pattern step alone
    assert associate_frame(ekf, _Pairs(3), measured, 0.0, model, image, centre) == [(ids[1], 0), (ids[2], 1),
                                                                                     (ids[3], 2)]


# ---------------------------------------------------------- image-space association
def _predicted(ekf, ids, pan=0.0):
    return ekf.predict_observation(ids, pan).uv


def test_an_infinite_extra_cost_forbids_a_pair():
    ekf = _ekf(s=(0.9,), polarity=(1,))
    measured = _predicted(ekf, ekf.landmark_ids)
    assert ekf.associate_joint(measured) == [(ekf.landmark_ids[0], 0)]
    assert ekf.associate_joint(measured, extra_cost=np.array([[np.inf]])) == []
    assert ekf.associate(measured, extra_cost=np.array([[np.inf]])) == []


def test_polarity_cost_forbids_opposite_wall_polarity_only():
    ekf = _ekf(s=(0.5, 0.9), polarity=(1, 0))
    ekf.add_landmarks([NewLandmark.point((0.3, 4.0), polarity=1)], 1e-4 * np.eye(2))
    image = np.array([1, -1, 0])
    cost = _polarity_cost(ekf, image, RIGHT_SIDE)
    np.testing.assert_array_equal(cost, [[0, np.inf, 0], [0, 0, 0], [0, 0, 0]])  # unknown and points: free
    np.testing.assert_array_equal(_polarity_cost(ekf, image, LEFT_SIDE)[0], [np.inf, 0, 0])


def test_image_association_never_pairs_opposite_polarity_even_when_closest():
    ekf = _ekf(s=(0.9,), polarity=(1,))
    (lm,) = ekf.landmark_ids
    uv = _predicted(ekf, [lm])[0]
    measured = np.stack([uv, uv + 2.0])  # the nearest one has the opposite step
    image = np.array([-1, 1])
    assert associate_frame(ekf, _Pairs(2), measured, 0.0, None, image, RIGHT_SIDE) == [(lm, 1)]
    # polarity unknown: both lines fit its gate, neither is taken (which one it is cannot be told)
    assert associate_frame(ekf, _Pairs(2), measured, 0.0) == []
    # from the wall's other side the same image polarities mean the opposite steps along the wall
    assert associate_frame(ekf, _Pairs(2), measured, 0.0, None, image, LEFT_SIDE) == [(lm, 0)]


# ------------------------------------------------------ per-wall compatibility
def test_one_walls_inconsistent_pattern_does_not_throw_out_another_walls(monkeypatch):
    """Two walls, both patterns matched along their walls; wall B's pairs are measured 40 px from where
    its landmarks are predicted (a pattern not compatible with the pose). Wall A's pairs are kept. The
    image-space fallback is switched off so that only the pattern step is seen."""
    wall_a = ReferencePlane("a", (-1.5, 4.0), (-0.2, 4.0), free_edges=("p1", "p2"))
    wall_b = ReferencePlane("b", (0.2, 4.0), (1.8, 4.0), free_edges=("p1", "p2"))
    s_a, s_b = (0.3, 0.7, 1.1), (0.2, 0.5, 0.9, 1.3)  # B has more features: it is tried first
    ekf = _ekf(wall_a, s_a, (0, 0, 0))
    ekf = _ekf(wall_b, s_b, (0, 0, 0, 0), ekf=ekf)
    ids_a, ids_b = ekf.landmark_ids[:3], ekf.landmark_ids[3:]
    cands_a = [_cand(wall_a, s, k, sigma_b=0.03) for k, s in enumerate(s_a)]
    cands_b = [_cand(wall_b, s, 3 + k, sigma_b=0.03) for k, s in enumerate(s_b)]
    measured = np.concatenate([_predicted(ekf, ids_a), _predicted(ekf, ids_b) + 40.0])
    model = SimpleNamespace(planes=[SimpleNamespace(fit=SimpleNamespace(plane=p), candidates=c)
                                    for p, c in ((wall_a, cands_a), (wall_b, cands_b))])
    # both patterns are found along their walls
    assert len(match_along_wall(ekf, wall_a, cands_a)) == 3 and len(match_along_wall(ekf, wall_b, cands_b)) == 4
    assert not ekf.joint_compatible(list(zip(ids_b, range(3, 7), strict=True)), measured)
    monkeypatch.setattr(ekf, "associate_joint", lambda *args, **kwargs: [])  # the pattern step alone
    got = associate_frame(ekf, _Pairs(7), measured, 0.0, model)
    assert got == list(zip(ids_a, range(3), strict=True))


# ---------------------------------------------------------- landmarks and maps
def test_landmark_plane_is_the_wall_or_none_for_points():
    ekf = _ekf(s=(0.5,), polarity=(1,))
    ekf.add_landmarks([NewLandmark.point((0.3, 4.0))], 1e-4 * np.eye(2))
    wall_id, point_id = ekf.landmark_ids
    assert ekf.landmark_plane(wall_id) is WALL
    assert ekf.landmark_plane(point_id) is None
    with pytest.raises(InputError, match="landmark_plane"):
        ekf.landmark_plane(99)


def test_polarity_round_trips_through_a_saved_landmark_map():
    world = Map((WALL,))
    ekf = _ekf(s=(0.5, 0.9, 1.3), polarity=(1, -1, 0))
    ekf.add_landmarks([NewLandmark.point((0.3, 4.0), polarity=-1)], 1e-4 * np.eye(2))
    saved = yaml.safe_load(yaml.safe_dump(ekf.to_dict(joint=True)))
    assert [d["polarity"] for d in saved["landmarks"]] == [1, -1, 0, -1]
    loaded = JointEKF(CAMERA, X0, COV_POSE)
    assert loaded.load_prior_landmarks(saved, world) == ekf.landmark_ids
    assert [loaded.landmark(i).polarity for i in loaded.landmark_ids] == [1, -1, 0, -1]
    del saved["landmarks"][0]["polarity"]  # maps saved before polarity was kept: unknown
    fresh = JointEKF(CAMERA, X0, COV_POSE)
    fresh.load_prior_landmarks(saved, world)
    assert [fresh.landmark(i).polarity for i in fresh.landmark_ids] == [0, -1, 0, -1]


@pytest.mark.parametrize("bad", [2, -2, 0.5, True, "1"])
def test_a_saved_polarity_must_be_minus_one_zero_or_one(bad):
    ekf = _ekf(s=(0.5,), polarity=(1,))
    saved = ekf.landmarks_to_dict()
    saved[0]["polarity"] = bad
    with pytest.raises(ConfigError, match=r"landmarks\[0\]\.polarity"):
        JointEKF(CAMERA, X0, COV_POSE).load_prior_landmarks(saved, Map((WALL,)))


# ------------------------------------------------------------ grazing incidence
SIDE = ReferencePlane("side", (1.0, 1.0), (1.0, 8.0), free_edges=("p1",))  # along the view: seen at a slant


def test_a_wall_landmark_seen_at_a_grazing_angle_is_not_visible_for_association():
    ekf = _ekf(s=(0.9,), polarity=(0,))
    (front,) = ekf.landmark_ids
    ekf = _ekf(plane=SIDE, s=(3.0,), polarity=(0,), ekf=ekf)  # at (1, 4): 76° from the side wall's normal
    side = [i for i in ekf.landmark_ids if i != front][0]
    assert set(ekf.visible()) == {front, side}
    assert set(ekf.visible(0.0, np.radians(80.0))) == {front, side}
    assert ekf.visible(0.0, np.radians(60.0)) == [front]
    measured = _predicted(ekf, [front, side])  # both measured exactly where predicted
    assert sorted(associate_frame(ekf, _Pairs(2), measured, 0.0)) == sorted([(front, 0), (side, 1)])
    assert associate_frame(ekf, _Pairs(2), measured, 0.0, max_incidence=np.radians(60.0)) == [(front, 0)]


# ------------------------------------------------------------------ ambiguity
WIDE = np.diag([0.10, 0.10, np.deg2rad(6.0)]) ** 2  # after a blind stretch: gates span several features


def test_an_image_gate_holding_two_fitting_lines_takes_neither_when_the_pose_is_uncertain():
    for cov, expect in ((COV_POSE, True), (WIDE, False)):
        ekf = _ekf(s=(0.9,), polarity=(0,), ekf=JointEKF(CAMERA, X0, cov))
        (lm,) = ekf.landmark_ids
        uv = _predicted(ekf, [lm])[0]
        measured = np.stack([uv + 1.0, uv + 25.0])  # its line and another feature 25 px away
        report: dict = {}
        got = associate_frame(ekf, _Pairs(2), measured, 0.0, report=report)
        if expect:  # a confident pose: the other line is far outside the gate
            assert got == [(lm, 0)] and not report["ambiguous"]
        else:  # both lines fit: the nearer is as likely the neighbour of a line that was not found
            assert got == [] and report["ambiguous"] == [[(lm, 0)]]


def test_a_walls_pattern_that_fits_at_two_offsets_is_not_taken_when_the_pose_is_uncertain(monkeypatch):
    s = (0.5, 0.9, 1.3, 1.7)  # regularly spaced, same polarity: shifted by one spacing, three still match
    for cov, expect in ((COV_POSE, True), (WIDE, False)):
        ekf = _ekf(WALL, s, (0, 0, 0, 0), ekf=JointEKF(CAMERA, X0, cov))
        ids = ekf.landmark_ids
        measured = _predicted(ekf, ids)
        cands = [_cand(WALL, si, k, sigma_b=0.5) for k, si in enumerate(s)]
        model = SimpleNamespace(planes=[SimpleNamespace(fit=SimpleNamespace(plane=WALL), candidates=cands)])
        assert len(match_along_wall(ekf, WALL, cands, every=True)) >= 2  # several offsets match
        monkeypatch.setattr(ekf, "associate_joint", lambda *args, **kwargs: [])  # the pattern step alone
        report: dict = {}
        got = associate_frame(ekf, _Pairs(4), measured, 0.0, model, report=report)
        if expect:
            assert got == list(zip(ids, range(4), strict=True)) and not report["ambiguous"]
        else:
            assert got == [] and len(report["ambiguous"]) == 1


def test_a_lone_association_reports_its_gate_only_when_alone():
    from stablemarks.estimation.association import lone_gate_px

    tight = _ekf(s=(0.9, 1.3), polarity=(0, 0))
    wide = _ekf(s=(0.9, 1.3), polarity=(0, 0), ekf=JointEKF(CAMERA, X0, WIDE))
    a, b = tight.landmark_ids
    assert lone_gate_px(tight, [], 0.0) == 0.0
    assert lone_gate_px(tight, [(a, 0), (b, 1)], 0.0) == 0.0  # two can be checked against each other
    # at 4 m a 6° heading σ spans tens of pixels, a 0.5° one a few
    assert lone_gate_px(wide, [(a, 0)], 0.0) > 50.0 > 30.0 > lone_gate_px(tight, [(a, 0)], 0.0)


def test_associations_within_one_sad_window_count_as_one_line():
    """Two associations whose lines lie within ``within`` px of each other (the two edges of a narrow bar) are one
    line to the pose: the widest of their gates is reported, as for a lone one; lines farther apart are not."""
    from stablemarks.estimation.association import lone_gate_px

    wide = _ekf(s=(0.9, 1.3), polarity=(0, 0), ekf=JointEKF(CAMERA, X0, WIDE))
    a, b = wide.landmark_ids
    alone = max(lone_gate_px(wide, [(a, 0)], 0.0), lone_gate_px(wide, [(b, 1)], 0.0))
    close, apart = np.array([300.0, 310.0]), np.array([300.0, 360.0])
    assert lone_gate_px(wide, [(a, 0), (b, 1)], 0.0, close, 15.0) == pytest.approx(alone)
    assert lone_gate_px(wide, [(a, 0), (b, 1)], 0.0, apart, 15.0) == 0.0
    assert lone_gate_px(wide, [(a, 0), (b, 1)], 0.0, close, 5.0) == 0.0
    assert lone_gate_px(wide, [(a, 0), (b, 1)], 0.0) == 0.0  # without the lines' columns: two lines


# ---------------------------------------------------------------- a landmark beside its wall's end
def _beside_end(merge_px):
    """A filter with a landmark 3 px inside the wall's end p1 and one far from it; the frame's lines: the wall's
    end (where the detector merges the end and the landmark's line) and the far landmark's line."""
    from stablemarks.estimation import EKFConfig

    s_near = 3.0 * 4.0 / CAMERA.f  # 3 px at the wall's 4 m
    ekf = JointEKF(CAMERA, X0, COV_POSE, EKFConfig(merge_px=merge_px))
    ekf = _ekf(s=(s_near, 1.3), polarity=(0, 0), ekf=ekf)
    end = CAMERA.project_columns(X0, WALL.point_at(np.array([0.0])))
    far = CAMERA.project_columns(X0, WALL.point_at(np.array([1.3])))
    measured = np.concatenate([end, far])
    model = SimpleNamespace(planes=[], predictions=[SimpleNamespace(
        edges={"p1": SimpleNamespace(free=True, u=end[0]), "p2": SimpleNamespace(free=False, u=end[0] * 0)})])
    return ekf, measured, model


def test_a_landmark_on_the_line_of_its_wall_s_end_is_not_associated():
    ids = None
    for merge_px, expect_near in ((0.0, True), (5.0, False)):
        ekf, measured, model = _beside_end(merge_px)
        ids = ekf.landmark_ids
        got = associate_frame(ekf, _Pairs(len(measured)), measured, 0.0, model)
        assert (ids[1], 1) in got  # the landmark far from the end is found either way
        assert ((ids[0], 0) in got) == expect_near
    # the test is on the predicted columns: both images count, and only free edges
    from stablemarks.estimation import merged_with_edges

    ekf, measured, model = _beside_end(5.0)
    assert merged_with_edges(ekf, ekf.landmark_ids, 0.0, model.predictions, 5.0) == {ekf.landmark_ids[0]}
    assert merged_with_edges(ekf, ekf.landmark_ids, 0.0, model.predictions, 2.0) == set()
    model.predictions[0].edges["p1"].free = False
    assert merged_with_edges(ekf, ekf.landmark_ids, 0.0, model.predictions, 5.0) == set()


def test_merge_px_must_be_a_non_negative_number():
    from stablemarks.estimation import EKFConfig

    for bad in (-1.0, float("nan"), True, "5"):
        with pytest.raises(ConfigError, match="ekf.merge_px"):
            EKFConfig(merge_px=bad)
