"""The built-in scenarios made for judging the filter on scenes it was never tuned on: office, hall and atrium."""

import math

import cv2
import numpy as np
import pytest

from stablemarks.motion import Turn
from stablemarks.sim import builtin_scenarios, load_scenario, simulate_run
from stablemarks.sim.render import renderer_for

NEW = ("office", "hall", "atrium")


@pytest.fixture(scope="module")
def office():
    return load_scenario("office")


@pytest.fixture(scope="module")
def hall():
    return load_scenario("hall")


def distances(plane, points):
    """Distance [m] of each point (N, 2) to the nearest point of a wall's floor segment."""
    a, b = plane.P1, plane.P2
    t = np.clip((points - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1)


def free_standing(sc):
    """Reference walls of the map with both ends free."""
    return [p for p in sc.map.planes if p.reference and set(p.free_edges) == {"p1", "p2"}]


def axis_angle_deg(direction):
    """Angle [deg] between a direction and the nearest world axis."""
    a = math.degrees(math.atan2(direction[1], direction[0])) % 90.0
    return min(a, 90.0 - a)


@pytest.mark.parametrize("name", NEW)
def test_built_in_with_a_camera_unlike_the_lab(name):
    assert name in builtin_scenarios()
    sc = load_scenario(name)
    lab = load_scenario("lab")
    assert sc.name == name and sc.robot.pan.policy == "look_at_free_edges"
    assert sc.camera.f != lab.camera.f and sc.camera.baseline != lab.camera.baseline
    assert (sc.camera.width, sc.camera.height) != (lab.camera.width, lab.camera.height)
    # office and hall: two free-standing walls or more; atrium: one, and an opening's two jambs
    assert len(free_standing(sc)) >= (1 if name == "atrium" else 2)
    assert sum(len(p.free_edges) for p in sc.map.planes if p.reference) >= 4
    # the map is the walls in it; clutter and world-only walls (lintels) are in no map
    ids = {p.id for p in sc.map.planes}
    assert not ids & {b.id for b in sc.boxes} and not ids & {p.id for p in sc.poles}
    assert any(not w.in_map for w in sc.walls)


def test_office_camera_path_and_angled_walls(office):
    cam = office.camera
    assert (cam.width, cam.height) == (800, 600)
    run = simulate_run(office)
    assert 80 <= len(run) <= 150
    assert sum(isinstance(s, Turn) for s in office.robot.path) >= 4
    # No wall runs along a world axis: the room is rotated by 25 degrees.
    for w in office.walls:
        assert axis_angle_deg(w.plane.direction) >= 10.0, w.id
    # ... and one partition is at an angle to the room's walls as well.
    room = office.map["east-a"].direction
    assert any(0.1 < abs(float(np.dot(p.direction, room))) < 0.9 for p in free_standing(office))


def test_office_door_gap_between_two_mapped_walls(office):
    a, b = office.map["east-a"], office.map["east-b"]
    assert a.reference and b.reference and "p2" in a.free_edges and "p1" in b.free_edges
    assert abs(float(np.dot(a.direction, b.direction))) == pytest.approx(1.0)
    assert abs(float(a.offset(b.P1))) < 1e-3  # in line (to the file's 0.1 mm)
    gap = float(np.linalg.norm(a.P2 - b.P1))
    assert 0.7 <= gap <= 1.2
    # Door frames: dark bars right next to both jambs.
    frames = [f for f in office.features if f.kind == "bar" and f.contrast <= -50]
    assert any(f.wall == "east-a" and a.length - (f.s + f.width) <= 0.05 for f in frames)
    assert any(f.wall == "east-b" and f.s <= 0.05 for f in frames)


def test_office_strong_texture_just_inside_a_free_end(office):
    joints = []
    for f in office.features:
        plane = office.map[f.wall] if f.wall in {p.id for p in office.map.planes} else None
        if plane is None or f.kind != "bar" or abs(f.contrast) < 50 or plane not in free_standing(office):
            continue
        inside = min(f.s, plane.length - (f.s + f.width))
        if inside <= 0.05 and f.z[1] - f.z[0] >= 1.0:
            joints.append(f.id)
    assert joints


def test_office_clutter_in_front_of_mapped_walls(office):
    board = office.map["whiteboard"]
    pole = next(p for p in office.poles if p.radius <= 0.04)
    assert pole.radius == pytest.approx(0.03) and pole.height == pytest.approx(2.0)
    assert abs(float(board.offset(pole.center))) == pytest.approx(0.8, abs=0.1)
    assert 0.0 < float(board.along(pole.center)) < board.length
    # a cabinet whose front is about 5 cm off a mapped reference wall, along that wall
    flat = []
    for box in office.boxes:
        corners = box.corners()
        for plane in office.map.planes:
            off = np.abs(plane.offset(corners))
            along = plane.along(corners)
            if plane.reference and 0.03 <= off.max() <= 0.08 and along.min() > 0 and along.max() < plane.length:
                flat.append((box.id, plane.id, box.height))
    assert [(b, h >= 1.5) for b, _, h in flat] == [("cabinet", True)]
    # boxes in front of reference walls, in the room
    assert len(office.boxes) >= 3


def test_office_features_are_irregular(office):
    feats = [f for f in office.features if f.wall in {p.id for p in office.map.planes if p.reference}]
    assert {f.kind for f in feats} == {"edge", "bar"}
    contrasts = np.abs([f.contrast for f in feats])
    assert contrasts.min() <= 30 and contrasts.max() >= 80
    heights = [f.z[1] - f.z[0] for f in feats]
    assert min(heights) <= 0.15 and max(heights) >= 1.4
    for wall in ("partition-a", "partition-b", "whiteboard"):
        s = np.sort([f.s for f in feats if f.wall == wall])
        gaps = np.diff(s)
        assert len(s) >= 5 and gaps.std() > 0.03  # not evenly spaced


def test_hall_walls_are_6_to_12_m_from_the_path(hall):
    cam = hall.camera
    assert (cam.width, cam.height, cam.f, cam.baseline) == (752, 480, 450.0, 0.2)
    run = simulate_run(hall)
    assert 60 <= len(run) <= 120
    centres = np.array([cam.optical_centres(X.as_array())[0] for X in run.poses])
    for plane in hall.map.planes:
        d = distances(plane, centres)
        assert d.min() >= 6.0 and d.max() <= 12.0, (plane.id, d.min(), d.max())
    # free-standing screens and pillars far away
    assert len(free_standing(hall)) >= 3
    assert sum(1 for p in hall.map.planes if p.id.startswith("pillar") and not p.reference) >= 8


@pytest.mark.parametrize("name, k", [("office", 0), ("office", 20), ("hall", 30)])
def test_a_frame_renders_with_its_true_edges_in_view(name, k):
    sc = load_scenario(name)
    run = simulate_run(sc)
    frame = run.render(k, renderer_for(sc))
    assert frame.left.shape == (sc.camera.height, sc.camera.width) == frame.right.shape
    refs = {p.id for p in sc.map.planes if p.reference}
    seen = [e for e in frame.truth.edges if e.visible_l and e.visible_r and e.wall in refs]
    assert sum(e.kind == "feature" for e in seen) >= 5
    assert any(e.kind == "boundary" for e in seen)
    # The images show the features where the truth puts them: a gradient of the right sign at the true column.
    found = 0
    features = [e for e in seen if e.kind == "feature" and e.v_bottom - e.v_top >= 20]
    for e in features:
        r0 = max(0, int(math.ceil(e.v_top + 0.2 * (e.v_bottom - e.v_top))))
        r1 = min(sc.camera.height - 1, int(math.floor(e.v_bottom - 0.2 * (e.v_bottom - e.v_top))))
        g = cv2.Sobel(frame.left[r0:r1 + 1].astype(np.float64), cv2.CV_64F, 1, 0, ksize=3).mean(axis=0)
        c = int(round(e.u_l))
        window = g[max(0, c - 2):c + 3] * e.polarity
        found += window.max() > 30
    assert found >= 0.7 * len(features), (found, len(features))


@pytest.mark.slow
@pytest.mark.parametrize("name", NEW)
def test_runs_through_the_whole_loop(name):
    from stablemarks.evaluation import make_trials, run_trial

    for trial in make_trials([name], 1, ["dead_reckoning", "stablemarks"], frames=12):
        result = run_trial(trial)
        assert result["scenario"] == name and result["method"] == trial.method


def test_atrium_walls_clutter_and_door_frames():
    sc = load_scenario("atrium")
    refs = [p for p in sc.map.planes if p.reference]
    # no wall parallel to an axis, nor two walls parallel to each other but the two halves of the north wall
    assert min(axis_angle_deg(p.direction) for p in refs) > 5.0
    dirs = [p.direction for p in refs if p.id not in ("north-a", "north-b")]  # one wall with an opening
    for i, a in enumerate(dirs):
        for b in dirs[i + 1:]:
            assert abs(float(a[0] * b[1] - a[1] * b[0])) > 0.1
    # a dark strip within 10 cm of each jamb of the opening
    for wall, edge in (("north-a", "p2"), ("north-b", "p1")):
        plane = sc.map[wall]
        assert edge in plane.free_edges
        length = plane.length
        near = [f for f in sc.features if f.wall == wall and f.kind == "bar" and f.contrast <= -50
                and min(abs(f.s - (length if edge == "p2" else 0.0)),
                        abs(f.s + f.width - (length if edge == "p2" else 0.0))) <= 0.1]
        assert near, wall
    # a board 5 cm in front of a mapped wall, in no map
    board = next(b for b in sc.boxes if b.id == "poster-board")
    d = min(distances(p, np.array([board.center]))[0] for p in refs)
    assert 0.03 < d < 0.08


@pytest.mark.slow
def test_atrium_recovered_pose_is_kept_when_the_edges_missed_before_it_are_found_after():
    """Atrium, trial 4 of `stablemarks eval atrium`: blind in a turn (frames 138-145, heading 4° off with σ 2.7°),
    the edges predicted in view were missed (edges_not_found from frame 145); at frame 146 four landmarks
    recovered the pose to 12 mm and 0.1°. At frame 147 one wall fitted turned 8° from the map's was taken for edges
    still missing, and the recovery for unconfirmed: the rest of the run fell back on dead reckoning, 0.6 m off. A
    recovery is now unconfirmed only when the edges are missed in health.edges_frames frames after it."""
    from stablemarks.evaluation import make_trials, run_trial

    (trial,) = [t for t in make_trials(["atrium"], 5, ["stablemarks"]) if t.index == 4]
    result = run_trial(trial)
    assert result["final_error"] < 0.05, result["final_error"]
    assert max(result["nees_pose"][-30:]) < 11.34  # χ²₃ 99 %
