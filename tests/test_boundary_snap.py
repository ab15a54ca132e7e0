"""A boundary moved onto the outermost member segment takes one segment *pair* in both images (Sec 3.2).

Moving each image's region border to its own outermost line could take two different lines; their disparity
then put the edge off the wall (the hall's screens at 10 m: 3–6 px off the plane's disparity, the boundary
0.1 m along the wall from the true edge).
"""

from dataclasses import dataclass

import numpy as np
import pytest

from stablemarks.config import Config
from stablemarks.pipeline import run_front_end, select_landmarks
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


@pytest.fixture(scope="module")
def hall_boundaries():
    sc = load_scenario("hall")
    cfg = Config()
    out = []
    for k, f in enumerate(SimulatedSource(simulate_run(sc), frames=4)):
        if k % 3:
            continue
        T = np.asarray(f.true_pose)
        cam = sc.camera.with_pan(f.pan)
        model = select_landmarks(run_front_end(f.left, f.right, cfg), cam, sc.map, T,
                                 np.diag([0.02, 0.02, 0.005]) ** 2, cfg)
        out += [(pm.fit, b, T, cam) for pm in model.planes for b in pm.boundaries]
    return out


def test_a_snapped_boundary_has_the_disparity_of_its_wall(hall_boundaries):
    snapped = [(fit, b) for fit, b, _, _ in hall_boundaries if b.snapped]
    assert snapped, "no boundary snapped in the hall's first frames"
    for fit, b in snapped:
        d_plane = float(fit.prediction.disparity_at(b.u[0])[0])
        assert abs((b.u[0] - b.u[1]) - d_plane) < 1.0, (fit.plane.id, b.edge, b.u, d_plane)


def test_snapped_boundaries_lie_at_the_true_edge_within_their_sigma(hall_boundaries):
    for fit, b, _, _ in hall_boundaries:
        if b.snapped:
            off = float((b.P - fit.plane.edge(b.edge)) @ b.inward)
            assert abs(off) < 3.0 * b.sigma_along, (fit.plane.id, b.edge, off, b.sigma_along)


def test_a_free_boundary_keeps_the_disparity_of_its_wall():
    """Where no segment marks the edge, the left and right borders are found apart. A right border far from the
    wall's disparity is another edge (the hall's south wall at 9 m, the door jamb beside its free edge: with the
    pose as uncertain as in the run, the right border 10–26 px off, the left within 1 px); the right column is
    then where the fitted plane puts the left one."""
    sc = load_scenario("hall")
    from stablemarks.evaluation import trial_seeds

    run = simulate_run(sc, trial_seeds(sc.seed, 1)[0])
    source = SimulatedSource(run)
    cfg = Config()
    w = cfg.sad.block_size
    checked = 0
    # the pans the localizer chose in the evaluation's first trial
    for k, pan in ((84, 0.599), (85, 0.341), (87, 0.082), (88, 0.084)):
        f = source.frame(k, pan)
        T = np.asarray(f.true_pose)
        cam = sc.camera.with_pan(f.pan)
        model = select_landmarks(run_front_end(f.left, f.right, cfg), cam, sc.map, T,
                                 np.diag([0.05, 0.05, 0.01]) ** 2, cfg)
        for pm in model.planes:
            for b in pm.boundaries:
                d_plane = float(pm.fit.prediction.disparity_at(b.u[0])[0])
                assert abs((b.u[0] - b.u[1]) - d_plane) <= w / 2.0 + 1e-9, (k, b.plane_id, b.edge, b.u, d_plane)
                checked += b.plane_id == "south-a"
    assert checked >= 2


def test_ends_found_too_far_apart_for_the_map_are_not_both_used():
    """The map fixes the distance between a wall's two ends, whatever the pose. In the corridor (first trial,
    frame 5, the localizer's pan) the second poster's far end snaps onto a line of the wall behind it, 6 cm
    beyond the poster; the poster's own edge then passed for a feature. With boundaries known well enough to tell
    (σ_img 0.06 px, ``boundary_px`` 0.5 px, as measured), the end that agrees less with the map is not used and
    the edge is near a boundary again."""
    from stablemarks.evaluation import trial_seeds

    sc = load_scenario("corridor")
    source = SimulatedSource(simulate_run(sc, trial_seeds(sc.seed, 1)[0]))
    cfg = Config().with_overrides({"noise": {"sigma_img": 0.06, "boundary_px": 0.5}})
    cfg = cfg.with_source_defaults(source.config_defaults)
    f = source.frame(5, 0.03213491023225945)
    T = np.asarray(f.true_pose)
    model = select_landmarks(run_front_end(f.left, f.right, cfg), cfg.camera(sc.camera).with_pan(f.pan), sc.map,
                             T, np.diag([0.02, 0.02, 0.005]) ** 2, cfg)
    fired = 0
    for pm in model.planes:
        fired += sum("both ends" in why for _, why in pm.rejected_boundaries)
        if len(pm.boundaries) == 2:
            b1, b2 = pm.boundaries
            length = abs(float((b1.P - b2.P) @ pm.fit.plane.direction))
            assert abs(length - pm.fit.plane.length) <= 3 * np.hypot(b1.sigma_along, b2.sigma_along)
        for c in pm.candidates:
            if c.selected:  # no selected line within 2 cm of a mapped end
                assert 0.02 < c.s < pm.fit.plane.length - 0.02, (pm.fit.plane.id, c.s)
    assert fired >= 1


def _with_and_without_the_silhouette_rule(name: str, k: int, pan: float, wall: str, occluder: str, end: str):
    """Frame ``k`` of ``name``'s first trial at the true pose, modelled with the silhouette rule (default) and
    without it: ``{nearer_fraction: (frame, the candidates on wall, the one within 1 px of the column where
    occluder's end is seen)}``. With the noise of the time the case was found (σ_img 0.25 px, a snapped
    boundary 2 px, no shared disparity error) and the off-wall test of the time (the model's line noise alone:
    with the noise the frame's own lines show, ``landmarks.off_wall_min_lines``, the mixed pair is off its wall):
    with the line noise at its measured 0.05 px the far board's fit,
    half hidden behind the near one, is refused as turned from the map before any line on it is modelled."""
    from stablemarks.evaluation import trial_seeds

    sc = load_scenario(name)
    source = SimulatedSource(simulate_run(sc, trial_seeds(sc.seed, 1)[0]))
    f = source.frame(k, pan)
    T = np.asarray(f.true_pose)
    front = None
    out = {}
    for fraction in (0.5, 1.0):
        cfg = Config().with_overrides({"landmarks": {"nearer_fraction": fraction, "off_wall_min_lines": 0},
                                       "noise": {"sigma_img": 0.25, "boundary_px": 2.0},
                                       "planes": {"disparity_bias_px": 0.0}})
        cfg = cfg.with_source_defaults(source.config_defaults)
        cam = cfg.camera(sc.camera).with_pan(f.pan)
        front = front or run_front_end(f.left, f.right, cfg)
        model = select_landmarks(front, cam, sc.map, T, np.diag([0.02, 0.02, 0.005]) ** 2, cfg)
        silhouette = float(cam.project_columns(T, sc.map[occluder].edge(end))[0])
        on_wall = [c for c in model.candidates if c.plane_id == wall]
        at = [c for c in on_wall if abs(c.u_left - silhouette) < 1.0]
        assert len(at) == 1
        out[fraction] = (f, on_wall, at[0])
    return out


def test_a_line_at_the_silhouette_of_a_nearer_wall_is_not_a_landmark():
    """Corridor, first trial, frame 16: the first poster board's free edge, 4.4 m away, stands in front of the
    second board (8.9 m). Its left line, 0.1 px from where the map puts the silhouette, was matched with a line of
    the second board in the right image; the pair had the board's disparity and was entered as a feature of it
    (no true feature there). With something nearer than the wall on one side of the line, it is rejected."""
    from stablemarks.evaluation import _match_truth
    from stablemarks.landmarks import REASON_BESIDE_NEARER

    by_rule = _with_and_without_the_silhouette_rule("corridor", 16, 0.0785993762118693, "poster-2", "poster-1", "p1")
    for _, on_wall, _ in by_rule.values():
        assert any(c.selected for c in on_wall)  # the board's own features
    f, _, mixed = by_rule[1.0]
    assert _match_truth(f.truth, mixed) is None  # no true feature: the pair mixes two edges
    assert mixed.selected  # what happened without the rule
    _, _, c = by_rule[0.5]
    assert not c.selected and c.reason == REASON_BESIDE_NEARER


def test_a_line_at_the_silhouette_of_a_thin_step_in_the_map_is_not_a_landmark():
    """Hall, first trial, frame 20: a screen stands 1 m in front of the north wall, 10 m away. Its free edge is a
    line 0.85 m in front of the wall, 2.7σ (the off-wall test does not resolve it) and 0.6 px of disparity (nor
    does the disparity beside it); it was entered as a feature of the wall. The map knows the screen: a line where
    a nearer wall's end is seen against this one, within 3σ of the pose's column uncertainty, is rejected."""
    from stablemarks.evaluation import _match_truth
    from stablemarks.landmarks import REASON_BESIDE_NEARER

    by_rule = _with_and_without_the_silhouette_rule("hall", 20, 2.046810728987044, "north-b", "screen-n", "p1")
    for f, on_wall, _ in by_rule.values():
        assert any(c.selected and _match_truth(f.truth, c) == "nb-1" for c in on_wall)  # a true one stays
    f, _, screen = by_rule[1.0]
    assert _match_truth(f.truth, screen) is None
    assert screen.selected
    _, _, c = by_rule[0.5]
    assert not c.selected and c.reason == REASON_BESIDE_NEARER


def test_a_boundary_at_the_silhouette_of_something_nearer_is_not_used():
    """Office, first trial, frame 86: a coat stand's pole, 0.8 m in front of the white board and in no map, hides
    the board's p2 end. The planar region stops at the pole's side, 34 px (11 cm along the board) inside the hidden
    end; modelled from it, four lines came out 6–16 cm from their true features. Beyond that border the disparity
    is nearer than the wall (a free edge has something farther beyond it): the border is not used."""
    from stablemarks.evaluation import _match_truth, trial_seeds

    sc = load_scenario("office")
    source = SimulatedSource(simulate_run(sc, trial_seeds(sc.seed, 1)[0]))
    f = source.frame(86, -1.0401563930651463)  # the pan the localizer chose, and its prior (3.6 cm off)
    X = np.array([-2.176637812410385, 4.39174401185672, -2.703651461864053])
    cov_X = np.array([[3.5039e-04, 1.5912e-04, 1.0174e-05], [1.5912e-04, 9.5226e-05, -3.7595e-06],
                      [1.0174e-05, -3.7595e-06, 1.9793e-04]])
    hidden = next(e for e in f.truth.edges if e.id == "whiteboard-p2")
    assert hidden.visible_fraction_l == 0.0
    front = None
    found = {}
    for fraction in (0.5, 1.0):
        cfg = Config().with_overrides({"landmarks": {"nearer_fraction": fraction}})
        cfg = cfg.with_source_defaults(source.config_defaults)
        front = front or run_front_end(f.left, f.right, cfg)
        model = select_landmarks(front, cfg.camera(sc.camera).with_pan(f.pan), sc.map, X, cov_X, cfg)
        (pm,) = [pm for pm in model.planes if pm.fit.plane.id == "whiteboard"]
        found[fraction] = pm
    without = found[1.0]
    (b,) = [b for b in without.boundaries if b.edge == "p2"]  # without the rule: the pole's side taken for the end
    assert b.u[0] - hidden.u_l > 20.0
    assert any(c.selected and _match_truth(f.truth, c) is None for c in without.candidates)
    with_rule = found[0.5]
    assert not with_rule.boundaries and not any(c.selected for c in with_rule.candidates)
    assert any("silhouette of something nearer" in why for _, why in with_rule.rejected_boundaries)
    # the end is hidden, not missed: it is no evidence of a wrong pan (localizer._edges_missing)
    assert with_rule.hidden == ["p2"] and "p2" in with_rule.searched and without.hidden == []


def test_ends_too_far_apart_that_the_pose_cannot_tell_apart_are_neither_used():
    """The same corridor frame with a pose known only to 10 cm and 3°: both ends lie inside their gates against
    the map's free edges, so the pose cannot tell which one is wrong; neither is used, and nothing is modelled
    from that wall in this frame (office, fourth trial, frame 61: the end kept by the former rule was the wrong
    one, and the seven landmarks modelled from it pulled the pose 3 cm off with NEES 275)."""
    from stablemarks.evaluation import trial_seeds

    sc = load_scenario("corridor")
    source = SimulatedSource(simulate_run(sc, trial_seeds(sc.seed, 1)[0]))
    cfg = Config().with_overrides({"noise": {"sigma_img": 0.06, "boundary_px": 0.5}})
    cfg = cfg.with_source_defaults(source.config_defaults)
    f = source.frame(5, 0.03213491023225945)
    T = np.asarray(f.true_pose)
    model = select_landmarks(run_front_end(f.left, f.right, cfg), cfg.camera(sc.camera).with_pan(f.pan), sc.map,
                             T, np.diag([0.1, 0.1, np.radians(3.0)]) ** 2, cfg)
    fired = 0
    for pm in model.planes:
        whys = [why for _, why in pm.rejected_boundaries if "both ends" in why]
        if whys:
            fired += 1
            assert all("cannot tell" in why for why in whys)
            assert len(whys) == 2 and not pm.boundaries
            assert not any(c.selected for c in pm.candidates)
    assert fired >= 1


def test_boundaries_of_two_walls_whose_distance_the_map_contradicts_are_neither_used():
    """The distance between two free edges seen in one frame does not depend on the pose: two boundaries of
    different walls found where the map's distance between their edges cannot be are not both right, and the pose
    (each already fits it) cannot tell which, so neither is used; both moved together (a pose error) pass."""
    from types import SimpleNamespace

    from stablemarks.landmarks import LandmarkConfig, boundaries_apart

    sc = load_scenario("lab")
    partition, board = sc.map["partition"], sc.map["whiteboard"]
    cov = np.diag([0.01, 0.01]) ** 2

    def models(shift_a, shift_b):
        def model(plane, edge, shift):
            b = SimpleNamespace(P=plane.edge(edge) + np.asarray(shift, float), cov=cov, edge=edge)
            return SimpleNamespace(fit=SimpleNamespace(plane=plane), boundaries=[b])
        return [model(partition, "p1", shift_a), model(board, "p1", shift_b)]

    config = LandmarkConfig()
    assert boundaries_apart(models((0, 0), (0, 0)), config) == {}
    assert boundaries_apart(models((0.12, -0.05), (0.12, -0.05)), config) == {}  # the pose's error: both alike
    u = board.edge("p1") - partition.edge("p1")
    u /= np.hypot(*u)
    n = np.array([-u[1], u[0]])
    assert boundaries_apart(models((0, 0), 0.03 * u), config) == {}  # 3 cm: inside 3 σ of the distance (4.2 cm)
    assert boundaries_apart(models((0, 0), 0.10 * n), config) == {}  # across the line joining them: not seen
    apart = boundaries_apart(models((0, 0), 0.10 * u), config)
    assert set(apart) == {("partition", "p1"), ("whiteboard", "p1")}
    assert all("both are not used" in why for why in apart.values())
    # two ends of one wall are landmarks_on_plane's to check, not this
    one = SimpleNamespace(fit=SimpleNamespace(plane=partition), boundaries=[
        SimpleNamespace(P=partition.edge("p1"), cov=cov, edge="p1"),
        SimpleNamespace(P=partition.edge("p2") + 0.2, cov=cov, edge="p2")])
    assert boundaries_apart([one], config) == {}


@pytest.fixture(scope="module")
def office_partition_ends():
    """The office's partition B in frames 28 and 34 of its run (the scenario's pans, the true pose): its end p1 is
    an occluding edge of a plain panel, where block matching fails for a window either side."""
    sc = load_scenario("office")
    cfg = Config()
    source = SimulatedSource(simulate_run(sc))
    out = []
    for k in (28, 34):
        f = source.frame(k)
        T = np.asarray(f.true_pose)
        cam = sc.camera.with_pan(f.pan)
        front = run_front_end(f.left, f.right, cfg)
        model = select_landmarks(front, cam, sc.map, T, np.diag([0.02, 0.02, 0.01]) ** 2, cfg)
        truth = {e.id: e for e in f.truth.edges}
        out.append((k, front, model, truth, cam, cfg))
    return out


def test_an_end_whose_pair_the_disparity_check_dropped_is_found_on_its_line(office_partition_ends):
    """The pair of the end's own lines is dropped by the disparity check for want of support, and the region's
    border stops 7–13 px inside: the boundary used to be that border (σ 4–5 cm). The pair lies on the fitted wall,
    so the boundary is moved onto it and found at the true edge."""
    for k, front, model, truth, _, _ in office_partition_ends:
        dropped = front.pairs.subset(~front.kept)
        ends = [b for pm in model.planes for b in pm.boundaries if b.plane_id == "partition-b" and b.edge == "p1"]
        assert len(ends) == 1, k
        b = ends[0]
        assert b.snapped, k
        assert np.any((dropped.u_left == b.u[0]) & (dropped.u_right == b.u[1])), k
        assert abs(b.u[0] - truth["partition-b-p1"].u_l) < 0.5, (k, b.u, truth["partition-b-p1"].u_l)


@dataclass
class _Pairs:
    u_left: np.ndarray
    u_right: np.ndarray
    v_top: np.ndarray
    v_bottom: np.ndarray

    def __len__(self) -> int:
        return len(self.u_left)


def test_edge_lines_are_dropped_pairs_on_the_wall_with_something_farther_beyond(office_partition_ends):
    """A dropped pair is a line to move a boundary onto only if it lies on the fitted wall — not the same left line
    matched 3 px off in the right image (the wall some 0.3 m nearer or farther), nor a line whose rows miss the
    wall's region — and the disparity beyond it, outward of the edge, is farther than the wall: looked at from
    the other end (outward into the partition itself) the same line shows nothing farther."""
    from stablemarks.landmarks import edge_lines, on_wall_pairs

    k, front, model, truth, cam, cfg = office_partition_ends[0]
    fit = next(pm.fit for pm in model.planes if pm.fit.plane.id == "partition-b")
    dropped = front.pairs.subset(~front.kept)
    at_end = np.abs(dropped.u_left - truth["partition-b-p1"].u_l) < 0.5
    assert at_end.any()
    on = on_wall_pairs(cam, fit, dropped, cfg.landmarks)
    assert on[at_end].all() and not on.all()
    j = int(np.flatnonzero(at_end)[0])

    def one(shift=0.0, rows=None):
        top, bottom = (dropped.v_top[j], dropped.v_bottom[j]) if rows is None else rows
        return _Pairs(dropped.u_left[j:j + 1], dropped.u_right[j:j + 1] + shift, np.array([top], float),
                      np.array([bottom], float))

    for shift, expect in ((0.0, True), (3.0, False), (-3.0, False)):
        assert on_wall_pairs(cam, fit, one(shift), cfg.landmarks)[0] == expect, shift
    r0, r1, _ = fit.box[0].indices(fit.region.shape[0])
    rows = (r0 - 12.0, r0 - 2.0) if r0 >= 12 else (r1 + 2.0, r1 + 12.0)
    assert not on_wall_pairs(cam, fit, one(rows=rows), cfg.landmarks)[0]
    w = float(cfg.sad.block_size)
    ends = dropped.subset(at_end)
    assert len(edge_lines(cam, fit, "p1", ends, front.disparity.left, w)) >= 1
    assert len(edge_lines(cam, fit, "p2", ends, front.disparity.left, w)) == 0
