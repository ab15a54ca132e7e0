import numpy as np
import pytest
import yaml

from stablemarks.errors import ConfigError
from stablemarks.geometry import StereoCamera
from stablemarks.maps import Map, ReferencePlane, load_map, segments_block, visible_parts

GOOD = {
    "planes": [
        {"id": "partition", "p1": [0.0, 4.0], "p2": [1.2, 4.0], "free_edges": ["p1"], "z": [0.0, 1.8]},
        {"id": "whiteboard", "name": "white board", "p1": [-0.55, 6.0], "p2": [-2.35, 6.0], "free_edges": ["p1"]},
        {"id": "back", "p1": [-4.0, 8.5], "p2": [4.0, 8.5], "reference": False},
    ]
}


def write(tmp_path, data, name="map.yaml"):
    p = tmp_path / name
    p.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return p


def test_load_and_round_trip(tmp_path):
    m = load_map(write(tmp_path, GOOD))
    assert [p.id for p in m] == ["partition", "whiteboard", "back"]
    assert m["whiteboard"].label == "white board"
    assert m["partition"].length == pytest.approx(1.2)
    assert [p.id for p in m.reference_planes] == ["partition", "whiteboard"]
    m.save(tmp_path / "again.yaml")
    assert load_map(tmp_path / "again.yaml") == m


def test_plane_coordinates():
    p = ReferencePlane("w", (1.0, 1.0), (1.0, 3.0), free_edges=("p2",))
    np.testing.assert_allclose(p.point_at(0.5), [1.0, 1.5])
    np.testing.assert_allclose(p.point_at(0.5, edge="p2"), [1.0, 2.5])
    assert p.along([[0.3, 2.2]]) == pytest.approx([1.2])
    assert p.along([[0.3, 2.2]], edge="p2") == pytest.approx([0.8])
    assert p.offset([0.0, 2.0]) == pytest.approx(1.0)  # left of p1->p2 (pointing +y) is -x
    assert p.faces([0.0, 2.0]) and p.faces([2.0, 2.0])
    assert not ReferencePlane("w", (1, 1), (1, 3), visible_from="left").faces([2.0, 2.0])


@pytest.mark.parametrize(
    "mutate,match",
    [
        (lambda d: d.pop("planes"), "missing field 'planes'"),
        (lambda d: d["planes"][0].pop("p1"), r"planes\[0\]: missing field 'p1'"),
        (lambda d: d["planes"][0].update(p1=[0.0]), r"planes\[0\]\.p1: expected a list of 2 numbers"),
        (lambda d: d["planes"][1].update(p2="abc"), r"planes\[1\]\.p2: expected"),
        (lambda d: d["planes"][0].update(free_edges=["p3"]), r"free_edges: expected a list drawn from"),
        (lambda d: d["planes"][0].update(z=[2.0, 1.0]), r"planes\[0\]\.z: expected z_high > z_low"),
        (lambda d: d["planes"][0].update(colour="red"), r"unknown field 'colour'"),
        (lambda d: d["planes"][1].update(id="partition"), "duplicate id 'partition'"),
        (lambda d: d["planes"][0].update(p2=[0.0, 4.0]), "same point"),
        (lambda d: d["planes"][0].update(p1=[float("nan"), 1.0]), r"p1\[0\]: expected a finite number"),
        (lambda d: d["planes"][0].update(visible_from="front"), "visible_from: expected one of"),
    ],
)
def test_bad_map_files_name_the_field(tmp_path, mutate, match):
    import copy

    data = copy.deepcopy(GOOD)
    mutate(data)
    path = write(tmp_path, data)
    with pytest.raises(ConfigError, match=match) as err:
        load_map(path)
    assert str(path) in str(err.value)


def test_unreadable_map_files(tmp_path):
    with pytest.raises(ConfigError, match="no such map file"):
        load_map(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match=r"invalid YAML at line \d+"):
        load_map(write(tmp_path, "planes:\n  - id: [a\n"))
    with pytest.raises(ConfigError, match="expected a mapping"):
        load_map(write(tmp_path, "- 1\n- 2\n"))


def test_segments_block():
    walls = np.array([[[-1.0, 2.0], [1.0, 2.0]]])
    assert segments_block([0, 0], [[0.0, 3.0]], walls).tolist() == [True]
    assert segments_block([0, 0], [[0.0, 1.0]], walls).tolist() == [False]
    assert segments_block([0, 0], [[2.0, 3.0]], walls).tolist() == [False]  # passes beside the wall
    assert segments_block([0, 0], [[0.0, 3.0]], walls, exclude=[0]).tolist() == [False]


def lab_like_map():
    return Map.from_dict(GOOD)


def test_visibility_lab_view():
    cam = StereoCamera(f=500.0, width=640, height=480)
    X = np.array([0.0, 0.0, np.pi / 2])
    parts = {v.plane.id: v for v in visible_parts(lab_like_map(), cam, X)}
    assert set(parts) == {"partition", "whiteboard", "back"}
    part = parts["partition"]
    assert part.intervals[0][0] == pytest.approx(0.0)
    assert part.free_edges_visible == ("p1",)
    assert parts["whiteboard"].free_edges_visible == ("p1",)
    # the back wall is partly hidden behind the partition and the whiteboard: several intervals
    assert len(parts["back"].intervals) >= 2


def test_visibility_field_of_view_range_and_side():
    cam = StereoCamera(f=500.0)
    m = lab_like_map()
    # looking away: nothing
    assert visible_parts(m, cam, np.array([0.0, 0.0, -np.pi / 2])) == []
    # short range: nothing within 3 m
    assert visible_parts(m, cam, np.array([0.0, 0.0, np.pi / 2]), max_range=3.0) == []
    # a one-sided wall seen from its back
    one = Map((ReferencePlane("w", (-1.0, 4.0), (1.0, 4.0), visible_from="left"),))
    assert visible_parts(one, cam, np.array([0.0, 0.0, np.pi / 2])) == []
    assert len(visible_parts(one, cam, np.array([0.0, 8.0, -np.pi / 2]))) == 1


def test_visibility_occlusion_hides_wall_behind():
    cam = StereoCamera(f=500.0)
    m = Map((ReferencePlane("front", (-3.0, 2.0), (3.0, 2.0)), ReferencePlane("behind", (-0.5, 5.0), (0.5, 5.0))))
    ids = [v.plane.id for v in visible_parts(m, cam, np.array([0.0, 0.0, np.pi / 2]))]
    assert ids == ["front"]


def test_ray_distances_hit_the_nearest_wall():
    from stablemarks.maps import ray_distances

    walls = np.array([[[-1.0, 2.0], [1.0, 2.0]], [[-1.0, 5.0], [1.0, 5.0]], [[3.0, -1.0], [3.0, 1.0]]])
    origins = np.zeros((4, 2))
    dirs = np.array([[0.0, 1.0], [1.0, 0.0], [-1.0, 0.0], [0.28, 0.96]])
    d = ray_distances(origins, dirs, walls)
    np.testing.assert_allclose(d[:2], [2.0, 3.0])
    assert np.isinf(d[2])
    np.testing.assert_allclose(d[3], 2.0 / 0.96)
    # the nearest wall left out: the next one along the ray
    np.testing.assert_allclose(ray_distances(origins[:1], dirs[:1], walls, exclude=[0]), [5.0])
    assert ray_distances(np.zeros((1, 2)), dirs[:1], np.zeros((0, 2, 2)))[0] == np.inf


def test_a_map_says_how_accurate_its_walls_are(tmp_path):
    """``accuracy`` round-trips through the file (default exact) and is validated; walls extracted from an
    occupancy grid carry what the extraction achieves."""
    import math

    from stablemarks.errors import ConfigError
    from stablemarks.io.mapfiles import walls_from_occupancy
    from stablemarks.maps import load_map, parse_map

    doc = {"planes": [{"id": "a", "p1": [0, 0], "p2": [1, 0]}]}
    assert parse_map(doc).accuracy == (0.0, 0.0)
    m = parse_map({**doc, "accuracy": {"offset": 0.02, "angle_deg": 0.5}})
    assert m.accuracy == pytest.approx((0.02, math.radians(0.5)))
    m.save(tmp_path / "m.yaml")
    assert load_map(tmp_path / "m.yaml").accuracy == pytest.approx(m.accuracy)
    with pytest.raises(ConfigError, match=r"accuracy: expected a mapping \{offset: m, angle_deg: deg\}"):
        parse_map({**doc, "accuracy": {"offset": 0.02, "angle": 1}})
    with pytest.raises(ConfigError, match="accuracy"):
        parse_map({**doc, "accuracy": {"offset": -1}})
    grid = np.zeros((40, 40), dtype=np.int8)
    grid[20:22, 5:35] = 100
    walls = walls_from_occupancy(grid.astype(int), 0.05, (0.0, 0.0, 0.0))
    assert walls.accuracy[0] >= 0.02 and walls.accuracy[1] == pytest.approx(math.radians(0.5))


def test_a_free_edge_is_as_uncertain_as_the_map_says():
    """``Map.edge_cov``: zero for an exact map; across the wall its offset σ plus its angle σ turning it about
    its middle, along it the offset σ; symmetric positive semi-definite."""
    import math

    from stablemarks.maps import parse_map

    doc = {"planes": [{"id": "a", "p1": [0, 0], "p2": [0, 4]}]}  # along y: normal ±x
    assert np.array_equal(parse_map(doc).edge_cov("a", "p1"), np.zeros((2, 2)))
    m = parse_map({**doc, "accuracy": {"offset": 0.02, "angle_deg": 0.5}})
    C = m.edge_cov("a", "p2")
    assert C[0, 0] == pytest.approx(0.02**2 + (math.tan(math.radians(0.5)) * 2.0) ** 2)
    assert C[1, 1] == pytest.approx(0.02**2)
    assert C[0, 1] == pytest.approx(0.0, abs=1e-15)
    assert np.allclose(C, C.T) and np.all(np.linalg.eigvalsh(C) >= 0)
