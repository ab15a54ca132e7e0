import copy
import math

import numpy as np
import pytest
import yaml

from stablemarks.errors import ConfigError
from stablemarks.motion import Forward
from stablemarks.sim import builtin_scenarios, load_scenario, parse_scenario
from stablemarks.sim.scenario import SCENARIO_DIR

# Table 1 of the paper: x [mm] and l [mm] of features 1..7 of each plane (feature 1 = the free edge).
PARTITION = [(0.1, 1309.0), (109.4, 487.0), (177.8, 270.0), (411.0, 258.0), (483.0, 490.0), (605.1, 1542.0),
             (643.7, 1557.0)]
WHITEBOARD = [(-550.2, 584.0), (-622.6, 279.0), (-698.3, 841.0), (-1004.3, 245.0), (-1076.0, 261.0),
              (-1309.9, 361.0), (-1380.9, 376.0)]


@pytest.fixture(scope="module")
def lab_data():
    return yaml.safe_load((SCENARIO_DIR / "lab.yaml").read_text())


def parse(data):
    return parse_scenario(data, "lab.yaml")


def test_lab_is_built_in_and_matches_the_paper():
    assert "lab" in builtin_scenarios()
    sc = load_scenario("lab")
    cam = sc.camera
    assert (cam.width, cam.height, cam.f, cam.baseline, cam.mount_height) == (640, 480, 500.0, 0.12, 1.0)
    assert sc.robot.start.as_array() == pytest.approx([0.0, 0.0, math.pi / 2])
    assert sc.robot.path == (Forward(2.0),)
    assert sc.robot.pan.policy == "look_at_free_edges"
    assert not sc.boxes and not sc.poles
    # The map: the two reference planes with their free edges where the paper puts them.
    m = sc.map
    assert {p.id for p in m.reference_planes} == {"partition", "whiteboard"}
    np.testing.assert_allclose(m["partition"].edge("p1"), [0.0, 4.0])
    np.testing.assert_allclose(m["whiteboard"].edge("p1"), [-0.55, 6.0])
    assert m["partition"].free_edges == ("p1", "p2") and m["whiteboard"].free_edges == ("p1", "p2")
    # Features 2..7 of Table 1 at their x positions and lengths.
    for wall, table in (("partition", PARTITION), ("whiteboard", WHITEBOARD)):
        plane = m[wall]
        for index, (x_mm, l_mm) in enumerate(table[1:], start=2):
            feat = next(f for f in sc.features if f.id == f"{wall}-{index}")
            assert feat.kind == "edge"
            p = plane.point_at(feat.s)
            assert p[0] == pytest.approx(x_mm / 1000.0, abs=1e-9)
            assert p[1] == pytest.approx(plane.p1[1])
            assert feat.z[1] - feat.z[0] == pytest.approx(l_mm / 1000.0, abs=1e-9)


def test_lab_features_fit_in_the_image_at_4_and_6_m():
    sc = load_scenario("lab")
    cam = sc.camera
    for f in sc.features:
        if f.wall in ("partition", "whiteboard"):
            for depth in (2.0, 4.0, 6.0):  # 2 m: the partition at the end of the path
                v_top = cam.cv + cam.f * (cam.mount_height - f.z[1]) / depth
                v_bottom = cam.cv + cam.f * (cam.mount_height - f.z[0]) / depth
                assert 0 <= v_top < v_bottom <= cam.height - 1


def test_load_by_path_and_by_name_agree(tmp_path, lab_data):
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(lab_data))
    assert load_scenario(path) == load_scenario("lab")
    assert load_scenario(path).source == str(path)


def test_unknown_name_lists_the_built_ins():
    with pytest.raises(ConfigError, match=r"scenario: expected a scenario file or a built-in name \(.*lab.*\)"):
        load_scenario("no-such-scenario")


def test_missing_file():
    with pytest.raises(ConfigError, match=r"no such scenario file"):
        load_scenario("/nonexistent/dir/s.yaml")


def edited(data, edit):
    d = copy.deepcopy(data)
    edit(d)
    return d


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["walls"][1]["texture"].update(scale=-2),
     r"^lab\.yaml: walls\[1\]\.texture\.scale: expected a positive number, got -2$"),
    (lambda d: d["walls"][0].update(colour="red"),
     r"^lab\.yaml: walls\[0\]\.colour: unknown field \(known: id, name, p1, p2"),
    (lambda d: d.update(extra=1), r"^lab\.yaml: extra: unknown field"),
    (lambda d: d["camera"].update(f="500"), r"^lab\.yaml: camera\.f: expected a positive number, got '500'$"),
    (lambda d: d["camera"].update(width=640.5), r"camera\.width: expected an integer >= 1, got 640\.5"),
    (lambda d: d["walls"][0].update(p1="abc"), r"walls\[0\]\.p1: expected a list of 2 numbers"),
    (lambda d: d["walls"][0].update(gloss=2), r"walls\[0\]\.gloss: expected a number in \[0, 1\], got 2"),
    (lambda d: d["walls"][0]["texture"].update(kind="wood"), r"texture\.kind: expected one of noise, plain"),
    (lambda d: d["walls"][0].update(in_map="yes"), r"walls\[0\]\.in_map: expected true or false, got 'yes'"),
    (lambda d: d["walls"][1].update(id="partition"), r"duplicate id 'partition'"),
    (lambda d: d["features"][0].update(wall="nowhere"), r"features\[0\]\.wall: expected one of the wall ids"),
    (lambda d: d["features"][0].update(s=5.0), r"features\[0\]\.s: expected a distance along wall 'partition'"),
    (lambda d: d["features"][0].update(z=[1.0, 2.5]), r"features\[0\]\.z: expected bottom < top inside wall"),
    (lambda d: d["features"][0].update(contrast=0), r"features\[0\]\.contrast: expected a non-zero"),
    (lambda d: d["features"][0].update(width=0.1), r"features\[0\]\.width: applies to kind bar only"),
    (lambda d: d["features"][-1].pop("width"), r"features\[12\]\.width: missing field"),
    (lambda d: d["features"][1].update(id="partition-2"), r"features: duplicate id 'partition-2'"),
    (lambda d: d["robot"]["path"].append({"jump": 1}), r"robot\.path\[1\]\.jump: unknown field"),
    (lambda d: d["robot"]["path"].append({"forward": -1}), r"robot\.path\[1\]\.forward: expected a positive"),
    (lambda d: d["robot"]["path"].append({"forward": 1, "turn_deg": 3}), r"robot\.path\[1\]: expected one of"),
    (lambda d: d["robot"]["pan"].update(policy="random"), r"robot\.pan\.policy: expected one of fixed, look_at"),
    (lambda d: d["robot"]["odometry"].update(trans_per_m=-0.1),
     r"robot\.odometry\.trans_per_m: expected a non-negative number, got -0\.1"),
    (lambda d: d["robot"]["pan"].update(angle_deg=120), r"robot\.pan\.angle_deg: expected an angle inside"),
    (lambda d: d["camera"].update(pan_limits_deg=[30, -30]), r"camera\.pan_limits_deg: expected -180 <= min"),
    (lambda d: d.update(clutter={"boxes": [{"center": [0, 1], "size": [0.5, -1], "height": 1}]}),
     r"clutter\.boxes\[0\]\.size: expected a list \[sx, sy\] of positive metres"),
    (lambda d: d.update(clutter={"poles": [{"center": [0, 1], "radius": 0.1}]}),
     r"clutter\.poles\[0\]\.height: missing field"),
    (lambda d: d.update(walls=[]), r"lab\.yaml: walls: expected at least one wall"),
    (lambda d: d.update(walls="none"), r"lab\.yaml: walls: expected a list, got 'none'"),
])
def test_validation_messages(lab_data, edit, message):
    with pytest.raises(ConfigError, match=message):
        parse(edited(lab_data, edit))


def test_top_level_must_be_a_mapping():
    with pytest.raises(ConfigError, match=r"^lab\.yaml: expected a mapping with camera, walls and robot"):
        parse([1, 2])


def test_defaults_fill_a_minimal_scenario():
    sc = parse_scenario({"walls": [{"id": "w", "p1": [0, 1], "p2": [1, 1]}]}, "mini.yaml", default_name="mini")
    assert sc.name == "mini" and sc.seed == 0
    assert sc.robot.path == () and sc.features == ()
    assert sc.map["w"].reference


def test_world_only_walls_stay_out_of_the_map(lab_data):
    sc = parse(edited(lab_data, lambda d: d["walls"][2].update(in_map=False)))
    assert "back-wall" not in {p.id for p in sc.map}
    assert sc.wall("back-wall").in_map is False


def test_a_folder_named_like_a_builtin_scenario_does_not_shadow_it(tmp_path, monkeypatch):
    """`stablemarks eval office --out office` leaves a folder `office`; the next `eval office` still means the
    built-in scenario (a file of that name would win)."""
    from stablemarks.sim.scenario import load_scenario

    monkeypatch.chdir(tmp_path)
    (tmp_path / "office").mkdir()
    assert load_scenario("office").name == "office"
