"""Selection rules beyond the paper and the boundary search near walls in line (Sec 3.2, Sec 4).

The contrast rule (``LandmarkConfig.min_contrast``), the end of a region's run from the wall's inner side
(``_boundary_columns``), the wall's own columns (``wall_columns``, the member filter of
``landmarks_on_plane``), boundary snapping within one SAD window, and ends hidden behind another wall
(``edge_occluded``).
"""

from types import SimpleNamespace

import numpy as np
import pytest

from stablemarks.config import Config
from stablemarks.errors import InputError
from stablemarks.geometry import StereoCamera
from stablemarks.landmarks import (
    REASON_CONTRAST,
    REASON_LENGTH,
    REASON_NEAR_BOUNDARY,
    REASON_OUTSIDE,
    Boundary,
    Candidate,
    LandmarkConfig,
    _boundary_columns,
    edge_incidence,
    edge_occluded,
    select,
    wall_columns,
)
from stablemarks.maps import Map, ReferencePlane
from stablemarks.pipeline import run_front_end, select_landmarks
from stablemarks.planes import PlaneConfig, predict_plane
from stablemarks.sim.render import render_stereo
from stablemarks.sim.scenario import parse_scenario

CAMERA = {"width": 640, "height": 480, "f": 500.0, "baseline": 0.12, "mount_height": 1.0, "image_noise": 2.0}
TEXTURE = {"kind": "noise", "base": 110, "contrast": 14, "scale": 0.03}
BACK = {"id": "back", "p1": [-6.0, 7.5], "p2": [6.0, 7.5], "z": [0.0, 2.8], "reference": False,
        "texture": {"kind": "noise", "base": 150, "contrast": 10, "scale": 0.05}}


def _cand(s, contrast=np.inf, ls=1.0, sigma_f=0.003):
    return Candidate("w", "w", 0, 0, "p1", s, 0.035, sigma_f, np.array([s, 4.0]), np.zeros((2, 2)), 0.0, 1.0, ls,
                     0.0, 0.0, 0.0, 0.0, P_observed=np.array([s, 4.0]), contrast=contrast)


BOUNDARY = Boundary("w", "p1", np.zeros(2), np.ones(2), np.array([0.0, 4.0]), np.eye(2), 0.035, False, 100,
                    np.array([1.0, 0.0]))


IDEAL = {"blur_sigma": 0, "vignetting": 0, "motion_blur": 0, "gain_sigma": 0, "shot_noise": 0}
"""The rules are tested on a pinhole camera's sharp images: the contrast is then exactly what was painted."""


def _scene(walls, features, start):
    return parse_scenario({"name": "rules", "camera": CAMERA, "walls": walls, "features": features,
                           "optics": IDEAL, "robot": {"start": start}}, "test")


# ------------------------------------------------------------------ contrast
def test_low_contrast_candidates_are_rejected_with_their_reason():
    cands = [_cand(0.5, contrast=10.0), _cand(0.6, contrast=50.0), _cand(0.7, contrast=30.0), _cand(0.8),
             _cand(0.9, contrast=29.9)]
    out = select(cands, [BOUNDARY])
    assert [c.selected for c in out] == [False, True, True, True, False]
    assert [c.reason for c in out] == [REASON_CONTRAST, "", "", "", REASON_CONTRAST]
    assert out[0].contrast == 10.0  # the decision keeps the measurement


def test_boundary_and_length_reasons_come_before_contrast():
    cands = [_cand(0.05, contrast=5.0), _cand(-0.3, contrast=5.0), _cand(0.6, contrast=5.0, ls=0.5)]
    out = select(cands, [BOUNDARY])
    assert [c.reason for c in out] == [REASON_NEAR_BOUNDARY, REASON_OUTSIDE, REASON_LENGTH]
    assert not any(c.selected for c in out)


def test_min_contrast_zero_keeps_every_edge():
    cands = [_cand(0.5, contrast=0.0), _cand(0.6, contrast=3.0), _cand(0.7, contrast=1e3)]
    out = select(cands, [BOUNDARY], LandmarkConfig(min_contrast=0.0))
    assert all(c.selected for c in out)
    assert [c.selected for c in select(cands, [BOUNDARY], LandmarkConfig(min_contrast=5.0))] == [False, False, True]


@pytest.mark.parametrize("value", [-1.0, -1e-9, float("nan")])
def test_min_contrast_must_be_a_non_negative_number(value):
    with pytest.raises(InputError, match="min_contrast"):
        LandmarkConfig(min_contrast=value)


def test_a_weak_painted_edge_is_rejected_and_a_strong_one_selected():
    """A wall with a weak painted edge (15 gray levels: weaker ones are not even extracted, the segment
    threshold is a step of 10) and a strong one (60): the candidates' contrast is the painted step
    (``|Sobel_x| / 4``, plus the wall's texture), and only the weak one falls to the contrast rule."""
    walls = [{"id": "panel", "p1": [0.0, 3.5], "p2": [1.5, 3.5], "z": [0.0, 1.8], "free_edges": ["p1", "p2"],
              "texture": TEXTURE}, BACK]
    features = [
        {"id": "weak", "wall": "panel", "s": 0.45, "z": [0.5, 1.4], "kind": "edge", "contrast": 15, "fade": 0.3},
        {"id": "strong", "wall": "panel", "s": 0.9, "z": [0.3, 1.2], "kind": "edge", "contrast": 60, "fade": 0.3},
    ]
    sc = _scene(walls, features, {"x": 0.3, "y": 0.0, "theta_deg": 90.0})
    X = np.array([0.3, 0.0, np.pi / 2])
    cov = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
    frame = render_stereo(sc, X, 0.0, np.random.default_rng(0))
    front = run_front_end(frame.left, frame.right)
    res = select_landmarks(front, sc.camera, sc.map, X, cov)

    def near(result, fid):
        e = frame.truth.edge(fid)
        return [c for c in result.candidates if abs(c.u_left - e.u_l) < 1.5 and abs(c.u_right - e.u_r) < 1.5]

    weak, strong = near(res, "weak"), near(res, "strong")
    assert weak and strong
    assert all(8.0 < c.contrast < 25.0 for c in weak), [c.contrast for c in weak]
    assert all(50.0 < c.contrast < 70.0 for c in strong), [c.contrast for c in strong]
    assert not any(c.selected for c in weak)
    assert any(c.reason == REASON_CONTRAST for c in weak)
    assert any(c.selected for c in strong)
    # without the rule the weak edge is a good landmark otherwise
    keep_all = select_landmarks(front, sc.camera, sc.map, X, cov, Config(landmarks=LandmarkConfig(min_contrast=0)))
    assert any(c.selected for c in near(keep_all, "weak"))


# ------------------------------------------------------- _boundary_columns
W = 40
LO, HI = 10.0, 30.0  # the window; going outward (+1) its inner side is column 10, its outer side column 30


def _rows(*rows):
    """Boolean region (len(rows), W) from each row's list of inclusive runs (first, last)."""
    region = np.zeros((len(rows), W), dtype=bool)
    for i, runs in enumerate(rows):
        for a, b in runs:
            region[i, a : b + 1] = True
    return region


def _columns(region, outward, max_hole=2):
    """``_boundary_columns`` over the window [LO, HI] going ``outward``, with the same region mirrored for
    −1, and the columns mapped back: both signs give one answer per row."""
    if outward > 0:
        return _boundary_columns(region, LO, HI, +1, max_hole)
    rows, cols = _boundary_columns(region[:, ::-1], W - 1 - HI, W - 1 - LO, -1, max_hole)
    return rows, W - 1 - cols


@pytest.mark.parametrize("outward", [1, -1])
def test_boundary_is_the_end_of_the_first_run_from_the_inner_side(outward):
    region = _rows(
        [(0, 20)],  # 0: the wall ends inside the window
        [(0, 20), (25, 27)],  # 1: past a gap more region (a wall in line): still the first run's end
        [(0, 20), (25, W - 1)],  # 2: ... even when the second run goes through the window
        [(15, 22)],  # 3: the run starts inside the window
        [(0, 5)],  # 4: the region does not reach into the window
        [(0, W - 1)],  # 5: the run goes through the window: its end is beyond it
        [(0, 30)],  # 6: ends on the window's outer column, the region beyond it unknown
    )
    rows, cols = _columns(region, outward)
    assert rows.tolist() == [0, 1, 2, 3]
    assert cols.tolist() == [20.0, 20.0, 20.0, 22.0]


@pytest.mark.parametrize("outward", [1, -1])
@pytest.mark.parametrize(("max_hole", "bridged", "not_bridged"), [(2, [1, 2], [3, 4]), (4, [3, 4], [5, 6])])
def test_holes_up_to_max_hole_are_bridged_larger_ones_end_the_run(outward, max_hole, bridged, not_bridged):
    holes = bridged + not_bridged
    region = _rows(*[[(0, 15), (16 + h, 25)] for h in holes])
    rows, cols = _columns(region, outward, max_hole)
    assert rows.tolist() == list(range(len(holes)))
    assert cols.tolist() == [25.0] * len(bridged) + [15.0] * len(not_bridged)


def test_no_region_or_an_empty_window_gives_no_rows():
    rows, cols = _boundary_columns(np.zeros((5, W), dtype=bool), LO, HI, 1)
    assert len(rows) == 0 and len(cols) == 0
    rows, _ = _boundary_columns(np.ones((5, W), dtype=bool), W + 5.0, W + 9.0, 1)  # window beyond the image
    assert len(rows) == 0


# ------------------------------------------------------------ wall_columns
def test_wall_columns_span_the_outer_sides_of_the_ends_windows():
    camera = StereoCamera()
    plane = ReferencePlane("w", (-1.0, 4.0), (1.0, 4.0), free_edges=("p1", "p2"))
    cov = np.diag([0.05, 0.05, np.deg2rad(2.0)]) ** 2
    # From the wall's right side p1 is on the left of the image, from its left side on the right.
    for X, left_end, right_end in ((np.array([0.0, 0.0, np.pi / 2]), "p1", "p2"),
                                   (np.array([0.0, 8.0, -np.pi / 2]), "p2", "p1")):
        pred = predict_plane(camera, X, cov, plane)
        fit = SimpleNamespace(prediction=pred, plane=plane, X=X)
        lo, hi = wall_columns(camera, fit, 3.0)
        assert lo == pytest.approx(pred.edges[left_end].window(0, 3.0)[0])
        assert hi == pytest.approx(pred.edges[right_end].window(0, 3.0)[1])
        assert lo < pred.edges[left_end].u[0] < pred.edges[right_end].u[0] < hi
        assert wall_columns(camera, fit, 1.0)[1] < hi


def test_wall_columns_are_unbounded_beyond_an_end_behind_the_camera():
    camera = StereoCamera()
    plane = ReferencePlane("side", (1.0, -2.0), (1.0, 5.0), free_edges=("p1", "p2"))  # p1 behind the camera
    X = np.array([0.0, 0.0, np.pi / 2])
    pred = predict_plane(camera, X, np.diag([0.02, 0.02, 0.01]) ** 2, plane)
    assert not np.all(np.isfinite(pred.edges["p1"].u))
    lo, hi = wall_columns(camera, SimpleNamespace(prediction=pred, plane=plane, X=X), 3.0)
    assert lo == pytest.approx(pred.edges["p2"].window(0, 3.0)[0])  # the wall runs from p2 to the right
    assert hi == np.inf


# ------------------------------------------- two partitions in a row (scene)
@pytest.fixture(scope="module")
def in_line():
    """Two partitions in line at y = 4 with a 0.8 m gap, seen square-on from (0, 0); features on both."""
    walls = [
        {"id": "left", "p1": [-2.5, 4.0], "p2": [-0.4, 4.0], "z": [0.0, 1.8], "free_edges": ["p1", "p2"],
         "texture": TEXTURE},
        {"id": "right", "p1": [0.4, 4.0], "p2": [2.5, 4.0], "z": [0.0, 1.8], "free_edges": ["p1", "p2"],
         "texture": dict(TEXTURE, base=140)},
        BACK,
    ]
    features = [{"id": f"{w}-{k}", "wall": w, "s": s, "z": [0.4 + 0.1 * k, 1.5], "kind": "edge",
                 "contrast": 60 * (-1) ** k, "fade": 0.25}
                for w in ("left", "right") for k, s in enumerate((0.3, 0.75, 1.2, 1.65))]
    sc = _scene(walls, features, {"x": 0.0, "y": 0.0, "theta_deg": 90.0})
    X = np.array([0.0, 0.0, np.pi / 2])
    frame = render_stereo(sc, X, 0.0, np.random.default_rng(0))
    return sc, X, run_front_end(frame.left, frame.right)


def _left_model(sc, X, front, sigma_theta_deg, config=Config()):
    cov = np.diag([0.05, 0.05, np.deg2rad(sigma_theta_deg)]) ** 2
    res = select_landmarks(front, sc.camera, sc.map, X, cov, config)
    (model,) = [m for m in res.planes if m.fit.plane.id == "left"]
    return model


def test_a_wall_keeps_only_the_segments_in_its_own_columns(in_line):
    """The plane window (``planes.gate_sigma`` = 5) reaches over the gap onto the partition in line, which
    fits the same plane; the wall's members stop at its ends' 3σ search windows (``wall_columns``)."""
    sc, X, front = in_line
    model = _left_model(sc, X, front, 3.0, Config(planes=PlaneConfig(gate_sigma=5.0)))
    plane = model.fit.plane
    lo, hi = wall_columns(sc.camera, model.fit, LandmarkConfig().search_sigma)
    other = sc.camera.project_columns(X, sc.map["right"].P1)[0]
    assert hi < other < model.fit.prediction.window[1]  # the other partition's end is in the plane's window
    assert model.candidates
    for c in model.candidates:
        assert lo <= c.u_left <= hi
        s = float(plane.along(c.P_observed))
        assert -3 * c.sigma_s <= s <= plane.length + 3 * c.sigma_s, (s, c)
    (gap_end,) = [b for b in model.boundaries if b.edge == "p2"]
    assert np.linalg.norm(gap_end.P - plane.P2) <= 3 * gap_end.sigma_along


def test_the_boundary_at_a_gap_is_not_found_on_the_wall_in_line(in_line):
    """With a wide prior (σθ = 5°) the search window of the left partition's end at the gap reaches over the
    gap onto the right partition (same plane, same disparity). The region's first run from inside ends at
    the gap, and the boundary is not snapped to the right partition's end segment, more than one SAD
    window beyond it."""
    sc, X, front = in_line
    model = _left_model(sc, X, front, 5.0)
    plane = model.fit.plane
    e = model.fit.prediction.edges["p2"]
    other = sc.camera.project_columns(X, sc.map["right"].P1)[0]
    assert e.window(0, 3.0)[1] > other + 10  # the window reaches well onto the other partition
    (gap_end,) = [b for b in model.boundaries if b.edge == "p2"]
    assert np.linalg.norm(gap_end.P - plane.P2) <= 3 * gap_end.sigma_along
    assert abs(gap_end.u[0] - e.u[0]) < 3.0
    # the other partition's end edge is a candidate of this plane, but never selected: it lies outside it
    beyond = [c for c in model.candidates if float(plane.along(c.P_observed)) > plane.length + 3 * c.sigma_s]
    assert not any(c.selected for c in beyond)


# ------------------------------------------------------------- edge_occluded
def test_an_end_behind_another_wall_is_occluded():
    camera = StereoCamera()
    X = np.array([0.0, 0.0, np.pi / 2])
    plane = ReferencePlane("w", (0.0, 4.0), (1.5, 4.0), free_edges=("p1", "p2"))
    screen = ReferencePlane("screen", (-0.5, 2.0), (0.5, 2.0))  # across the sight line to p1 only
    world = Map((plane, screen))
    assert edge_occluded(camera, X, world, plane, "p1")
    assert not edge_occluded(camera, X, world, plane, "p2")
    # nothing in between: the wall itself, a wall beyond the end, a wall meeting the end, or no other wall
    behind = ReferencePlane("behind", (-1.0, 6.0), (1.0, 6.0))
    hinge = ReferencePlane("hinge", (0.0, 4.0), (0.0, 6.0))
    for other in (Map((plane,)), Map((plane, behind)), Map((plane, hinge))):
        assert not edge_occluded(camera, X, other, plane, "p1")
    # seen from elsewhere the same screen is not in the way
    assert not edge_occluded(camera, np.array([1.5, 0.0, np.pi / 2]), world, plane, "p1")


def test_boundary_columns_hole_sizes_and_window_border():
    """Holes of exactly ``max_hole`` px are bridged (odd sizes too), one more ends the run; a run ending just
    inside the window's outer column is a boundary row, one reaching it is not."""
    r = np.zeros((1, 40), bool)
    r[0, 0:16] = r[0, 19:26] = True  # a 3 px hole
    assert _boundary_columns(r, 5, 35, 1, 3)[1].tolist() == [25.0]
    assert _boundary_columns(r, 5, 35, 1, 2)[1].tolist() == [15.0]
    r = np.zeros((1, 40), bool)
    r[0, 0:30] = True
    assert _boundary_columns(r, 10, 30, 1, 2)[1].tolist() == [29.0]
    assert len(_boundary_columns(r, 10, 29, 1, 2)[0]) == 0


# ------------------------------------------------------------- edge_incidence
def test_edge_incidence_is_the_angle_from_the_walls_normal():
    camera = StereoCamera()
    plane = ReferencePlane("w", (-1.0, 4.0), (1.0, 4.0), free_edges=("p1", "p2"))
    X = np.array([-1.0, 0.0, np.pi / 2])  # straight in front of p1, 4 m away
    assert edge_incidence(camera, X, plane, "p1") == pytest.approx(0.0, abs=1e-12)
    assert edge_incidence(camera, X, plane, "p2") == pytest.approx(np.arctan2(2.0, 4.0))


def test_a_free_edge_seen_more_obliquely_than_the_entry_limit_is_not_searched():
    """A side wall running away from the camera: its far end is seen 79° from the wall's normal, beyond
    ``landmarks.max_incidence_deg`` (60°), so no boundary is searched there and nothing is placed from it; the
    log says why. With the limit raised the same end is searched."""
    walls = [{"id": "side", "p1": [0.8, 1.0], "p2": [0.8, 4.0], "z": [0.0, 1.8], "free_edges": ["p2"],
              "texture": TEXTURE}, BACK]
    features = [{"id": "f", "wall": "side", "s": 1.5, "z": [0.4, 1.4], "kind": "edge", "contrast": 60, "fade": 0.3}]
    sc = _scene(walls, features, {"x": 0.0, "y": 0.0, "theta_deg": 90.0})
    X = np.array([0.0, 0.0, np.pi / 2])
    assert np.degrees(edge_incidence(sc.camera, X, sc.map["side"], "p2")) == pytest.approx(78.7, abs=0.1)
    cov = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
    frame = render_stereo(sc, X, 0.0, np.random.default_rng(0))
    front = run_front_end(frame.left, frame.right)
    res = select_landmarks(front, sc.camera, sc.map, X, cov)
    side = [m for m in res.planes if m.fit.plane.id == "side"]
    assert side, "the side wall is fitted"
    assert side[0].searched == [] and side[0].boundaries == [] and not side[0].candidates
    assert any("p2 is seen 79° from the wall's normal" in why and "not searched" in why
               for _, why in side[0].rejected_boundaries)
    wide = select_landmarks(front, sc.camera, sc.map, X, cov, Config(landmarks=LandmarkConfig(max_incidence_deg=85.0)))
    assert [m.searched for m in wide.planes if m.fit.plane.id == "side"] == [["p2"]]


# ---------------------------------------------------------------- a line beside another (landmarks.min_line_gap_px)
def test_a_candidate_with_another_line_a_few_pixels_away_is_not_entered():
    from dataclasses import replace

    from stablemarks.landmarks import REASON_BESIDE_LINE, beside_another_line

    base = select([_cand(0.5), _cand(0.9), _cand(1.3)], [])
    assert all(c.selected for c in base)
    cands = [replace(c, u_left=u) for c, u in zip(base, (300.0, 340.0, 380.0), strict=True)]
    # the left image's lines: each candidate's own (300.2: the same edge in another piece, under 1 px), one 3 px
    # beside the second, one 6 px beside the third
    columns = [300.0, 300.2, 340.0, 343.0, 380.0, 386.0]
    out = beside_another_line(cands, columns, 4.0)
    assert [c.selected for c in out] == [True, False, True]
    assert out[1].reason == REASON_BESIDE_LINE
    out = beside_another_line(cands, columns, 7.0)
    assert [c.selected for c in out] == [True, False, False]
    # a candidate already rejected keeps its reason
    rejected = replace(cands[1], selected=False, reason=REASON_CONTRAST)
    assert beside_another_line([rejected], columns, 4.0)[0].reason == REASON_CONTRAST


def test_min_line_gap_px_must_be_a_non_negative_number():
    for bad in (-1.0, float("inf"), True, "4"):
        with pytest.raises(InputError, match="landmarks.min_line_gap_px"):
            LandmarkConfig(min_line_gap_px=bad)
    assert LandmarkConfig().min_line_gap_px == 0.0
