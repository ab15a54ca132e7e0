import json

import cv2
import numpy as np
import pytest
import yaml

from stablemarks.cli import main
from stablemarks.errors import ConfigError
from stablemarks.io.mapfiles import (
    WallExtraction,
    load_any_map,
    load_occupancy_map,
    map_to_geojson,
    occupancy_from_image,
    save_geojson,
    skeleton,
    walls_from_occupancy,
)
from stablemarks.maps import Map, ReferencePlane, load_map

RES = 0.05  # m per cell
H, W = 160, 200  # cells
THICK = 0.15  # wall thickness [m] = 3 cells
X0, X1, Y0, Y1 = 1.025, 9.025, 1.025, 7.025  # room wall centre lines, on cell centres
DOOR = (4.0, 4.9)  # doorway in the bottom wall, x range [m]
PART = (np.array([3.0, 3.0]), np.array([3.0, 3.0]) + 2.5 * np.array([np.cos(np.deg2rad(20)), np.sin(np.deg2rad(20))]))
H_ = THICK / 2
_PT = (PART[1] - PART[0]) / np.linalg.norm(PART[1] - PART[0])
_PN = np.array([-_PT[1], _PT[0]]) * H_
# the faces a camera sees: (p1, p2, free edges); the room's walls have unknown space behind them (their
# inner faces only, meeting at the inner corners), the doorway's jambs and the partition's ends are free
# and the partition is seen from both sides (one face each)
TRUE = [
    ((X0 + H_, Y0 + H_), (DOOR[0], Y0 + H_), ("p2",)),
    ((DOOR[1], Y0 + H_), (X1 - H_, Y0 + H_), ("p1",)),
    ((X1 - H_, Y0 + H_), (X1 - H_, Y1 - H_), ()),
    ((X0 + H_, Y1 - H_), (X1 - H_, Y1 - H_), ()),
    ((X0 + H_, Y0 + H_), (X0 + H_, Y1 - H_), ()),
    (tuple(PART[0] + _PN), tuple(PART[1] + _PN), ("p1", "p2")),
    (tuple(PART[0] - _PN), tuple(PART[1] - _PN), ("p1", "p2")),
]


def to_px(p) -> np.ndarray:
    """Map point [m] → pixel position (u, v) of a grid of height H with origin (0, 0, 0)."""
    return np.array([p[0] / RES - 0.5, H - 0.5 - p[1] / RES])


def draw_wall(img, p1, p2, value=0):
    """A wall of thickness THICK ending exactly at p1 and p2 (no caps)."""
    a, b = to_px(p1), to_px(p2)
    t = (b - a) / np.linalg.norm(b - a)
    n = np.array([-t[1], t[0]]) * THICK / RES / 2
    cv2.fillConvexPoly(img, np.round(np.array([a + n, b + n, b - n, a - n]) * 16).astype(np.int32), value,
                       lineType=cv2.LINE_8, shift=4)


def room_image() -> np.ndarray:
    """A map_server image: unknown outside (205), a free room (254) with black walls, a doorway, a partition."""
    img = np.full((H, W), 205, np.uint8)
    (u0, v1), (u1, v0) = np.round(to_px((X0, Y0))).astype(int), np.round(to_px((X1, Y1))).astype(int)
    img[v0:v1 + 1, u0:u1 + 1] = 254
    h = THICK / 2
    for p1, p2 in [((X0 - h, Y0), (X1 + h, Y0)), ((X1, Y0 - h), (X1, Y1 + h)),
                   ((X1 + h, Y1), (X0 - h, Y1)), ((X0, Y1 + h), (X0, Y0 - h))]:
        draw_wall(img, p1, p2)
    draw_wall(img, *PART)
    # the doorway: free through the wall and a little beyond (the laser saw through it)
    ua, ub = int(np.ceil(to_px((DOOR[0], 0))[0])), int(np.floor(to_px((DOOR[1], 0))[0]))
    va, vb = np.round(to_px((0, Y0 + 3 * h))[1]).astype(int), np.round(to_px((0, Y0 - 3 * h))[1]).astype(int)
    img[va:vb + 1, ua:ub + 1] = 254
    return img


def write_map(tmp_path, img=None, name="room", **fields) -> str:
    doc = {"image": f"{name}.pgm", "resolution": RES, "origin": [0.0, 0.0, 0.0], "negate": 0,
           "occupied_thresh": 0.65, "free_thresh": 0.196}
    doc.update(fields)
    cv2.imwrite(str(tmp_path / f"{name}.pgm"), room_image() if img is None else img)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def match(walls: Map, p1, p2):
    """The extracted wall on the true face p1 → p2 (within 1.5 cells of its line and 2° of its angle), flipped alike."""
    p1, p2 = np.asarray(p1), np.asarray(p2)
    t = (p2 - p1) / np.linalg.norm(p2 - p1)
    n = np.array([-t[1], t[0]])
    for plane in walls:
        ends = np.array([plane.P1, plane.P2])
        # within 1.5 cells of the face: cv2.fillConvexPoly draws a wall of 3 cells 3 or 4 cells wide
        if np.abs((ends - p1) @ n).max() > 1.5 * RES or abs(plane.direction @ t) < np.cos(np.deg2rad(2.0)):
            continue
        s = (ends - p1) @ t
        if s.max() < 0 or s.min() > np.linalg.norm(p2 - p1):
            continue  # the other piece of the same line
        return plane if s[0] <= s[1] else ReferencePlane(plane.id, plane.p2, plane.p1, free_edges=tuple(
            {"p1": "p2", "p2": "p1"}[e] for e in plane.free_edges))
    raise AssertionError(f"no wall found on {p1} → {p2}: {[(p.p1, p.p2) for p in walls]}")


# ------------------------------------------------------------ reading map_server maps
def test_thresholds_as_map_server():
    values = np.array([[0, 89, 90, 204, 205, 206, 254, 255]], np.uint8)
    # p = (255 - v) / 255: 1, 0.651, 0.647, 0.2, 0.1961, 0.1922, 0.004, 0; occupied > 0.65, free < 0.196
    np.testing.assert_array_equal(occupancy_from_image(values, False, 0.65, 0.196)[0],
                                  [100, 100, -1, -1, -1, 0, 0, 0])
    # negate: p = v / 255
    np.testing.assert_array_equal(occupancy_from_image(values, True, 0.65, 0.196)[0],
                                  [0, -1, -1, 100, 100, 100, 100, 100])
    # strict inequalities: p equal to a threshold is neither occupied nor free (negate: p = 51 / 255 = 0.2)
    assert occupancy_from_image(np.array([[51]], np.uint8), True, 0.2, 0.1)[0, 0] == -1
    assert occupancy_from_image(np.array([[51]], np.uint8), True, 0.5, 0.2)[0, 0] == -1
    # scale: between the thresholds linearly onto 0..100
    scaled = occupancy_from_image(np.array([[0, 90, 255]], np.uint8), False, 0.65, 0.196, "scale")[0]
    np.testing.assert_array_equal(scaled, [100, np.rint((165 / 255 - 0.196) / (0.65 - 0.196) * 100), 0])
    # raw: round(255 * shade) when in 0..100, otherwise unknown
    np.testing.assert_array_equal(occupancy_from_image(np.array([[0, 37, 100, 101, 255]], np.uint8), False,
                                                       0.65, 0.196, "raw")[0], [0, 37, 100, -1, -1])
    # colour: the channels' mean; trinary averages alpha in, scale calls transparent pixels unknown
    bgra = np.array([[[0, 0, 0, 255], [0, 0, 0, 0], [255, 255, 255, 0], [255, 255, 255, 255]]], np.uint8)
    # white transparent in trinary: shade (3·255 + 0) / (4·255) = 0.75 → p = 0.25 → unknown
    np.testing.assert_array_equal(occupancy_from_image(bgra, False, 0.65, 0.196)[0], [100, 100, -1, 0])
    np.testing.assert_array_equal(occupancy_from_image(bgra, False, 0.65, 0.196, "scale")[0], [100, -1, -1, 0])


def test_load_orientation_and_origin(tmp_path):
    img = np.full((4, 6), 254, np.uint8)
    img[0, 0] = 0  # top-left pixel of the image
    occ = load_occupancy_map(write_map(tmp_path, img, origin=[2.0, -1.0, 0.0], resolution=0.5))
    assert occ.shape == (4, 6) and occ.grid[0, 0] == 100 and (occ.grid[1:] == 0).all()
    # row 0 is the TOP: the lower-left corner is at the origin, the top-left cell's centre at y = 4 * 0.5 - 0.25
    np.testing.assert_allclose(occ.cell_to_map([0, 0]), [2.25, -1.0 + 1.75])
    np.testing.assert_allclose(occ.cell_to_map([5, 3]), [2.0 + 2.75, -1.0 + 0.25])
    yawed = load_occupancy_map(write_map(tmp_path, img, origin=[2.0, -1.0, np.pi / 2], resolution=0.5))
    np.testing.assert_allclose(yawed.cell_to_map([5, 3]), [2.0 - 0.25, -1.0 + 2.75])


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"resolution": None}, r"room.yaml: missing field 'resolution'"),
        ({"negate": None}, r"missing field 'negate'"),
        ({"resolution": -0.05}, r"room.yaml: resolution: expected a positive cell size"),
        ({"origin": [0.0, 0.0]}, r"room.yaml: origin: expected \[x, y, yaw\]"),
        ({"negate": 2}, r"room.yaml: negate: expected 0 or 1, got 2"),
        ({"free_thresh": 0.7}, r"expected free_thresh < occupied_thresh, got free_thresh = 0.7"),
        ({"occupied_thresh": 1.5}, r"room.yaml: occupied_thresh: expected a probability in \[0, 1\], got 1.5"),
        ({"mode": "fancy"}, r"room.yaml: mode: expected one of trinary, scale, raw, got 'fancy'"),
    ],
)
def test_broken_map_server_yaml(tmp_path, fields, message):
    path = write_map(tmp_path, **fields)
    doc = yaml.safe_load((tmp_path / "room.yaml").read_text())
    (tmp_path / "room.yaml").write_text(yaml.safe_dump({k: v for k, v in doc.items() if v is not None}))
    with pytest.raises(ConfigError, match=message):
        load_occupancy_map(path)


def test_missing_or_unreadable_image(tmp_path):
    path = write_map(tmp_path, image="maps/nowhere.pgm")
    with pytest.raises(ConfigError, match=r"room.yaml: image: no such file .*maps/nowhere.pgm"):
        load_occupancy_map(path)
    (tmp_path / "junk.pgm").write_text("not an image")
    with pytest.raises(ConfigError, match=r"image: cannot read .*junk.pgm"):
        load_occupancy_map(write_map(tmp_path, image="junk.pgm"))
    with pytest.raises(ConfigError, match=r"absent.yaml: no such map_server map file"):
        load_occupancy_map(tmp_path / "absent.yaml")


@pytest.mark.parametrize("kind", ["png", "pgm", "empty"])
def test_truncated_occupancy_image_is_one_quiet_line(tmp_path, capfd, kind):
    """A truncated PNG or PGM (or an empty file) is one ConfigError naming the file and what the decoder said;
    nothing from libpng or OpenCV reaches stderr."""
    ok, png = cv2.imencode(".png" if kind == "png" else ".pgm", room_image())
    data = png.tobytes()
    name = f"room.{'png' if kind == 'png' else 'pgm'}"
    (tmp_path / name).write_bytes(b"" if kind == "empty" else data[: len(data) // 2])
    path = tmp_path / "room.yaml"
    path.write_text(yaml.safe_dump({"image": name, "resolution": RES, "origin": [0.0, 0.0, 0.0], "negate": 0,
                                    "occupied_thresh": 0.65, "free_thresh": 0.196}))
    capfd.readouterr()
    for load in (load_occupancy_map, load_any_map):
        with pytest.raises(ConfigError, match=rf"room.yaml: image: cannot read .*{name} \(truncated, damaged") as e:
            load(path)
        assert "\n" not in str(e.value)
    assert capfd.readouterr().err == ""


def test_geojson_with_a_key_twice_is_refused_naming_the_key(tmp_path):
    """Two members of one GeoJSON object with the same name are an error (not last-one-wins), as in YAML."""
    feature = '{"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 0]]}}'
    (tmp_path / "walls.geojson").write_text('{"type": "FeatureCollection", "features": [' + feature + '],\n'
                                            ' "features": []}')
    with pytest.raises(ConfigError, match=r"^.*walls.geojson: invalid JSON: duplicate key 'features' in one object$"):
        load_any_map(tmp_path / "walls.geojson")
    inner = feature.replace('"type": "LineString"', '"type": "LineString", "type": "Point"')
    (tmp_path / "walls.geojson").write_text('{"type": "FeatureCollection", "features": [' + inner + ']}')
    with pytest.raises(ConfigError, match=r"duplicate key 'type'"):
        load_any_map(tmp_path / "walls.geojson")
    (tmp_path / "walls.geojson").write_text('{"type": "FeatureCollection", "features": [' + feature + ']}')
    assert len(load_any_map(tmp_path / "walls.geojson")) == 1  # the same keys in different objects are fine


@pytest.mark.parametrize("depth, message", [
    (150, r"invalid JSON: nested deeper than 100 levels$"),
    (100_000, r"invalid JSON: nested too deeply \(at most 100 levels\)$"),  # beyond Python's recursion limit
])
def test_deeply_nested_geojson_is_one_line(tmp_path, depth, message):
    (tmp_path / "walls.geojson").write_text('{"type": "FeatureCollection", "features": ' + "[" * depth + "]" * depth
                                            + "}")
    with pytest.raises(ConfigError, match=message) as e:
        load_any_map(tmp_path / "walls.geojson")
    assert str(e.value).startswith(str(tmp_path / "walls.geojson")) and len(str(e.value)) < 200
    (tmp_path / "walls.json").write_text('{"a": ' * 5000 + "1" + "}" * 5000)
    with pytest.raises(ConfigError, match=r"walls.json: invalid JSON: nested too deeply"):
        load_any_map(tmp_path / "walls.json")


def test_geojson_errors_through_the_cli_are_one_line(tmp_path, capfd):
    (tmp_path / "walls.geojson").write_text('{"type": "FeatureCollection", "features": [], "features": []}')
    assert main(["map-walls", str(tmp_path / "walls.geojson"), "--out", str(tmp_path / "out.yaml")]) == 1
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "duplicate key 'features'" in err


# ------------------------------------------------------------ wall extraction
def test_skeleton_of_a_bar_is_its_centre_line():
    mask = np.zeros((11, 30), bool)
    mask[4:7, 3:27] = True
    sk = skeleton(mask)
    assert sk[:, 6:24].sum(axis=0).tolist() == [1] * 18 and sk[5, 6:24].all()
    assert not (sk & ~mask).any()


def test_room_walls_partition_and_doorway(tmp_path):
    occ = load_occupancy_map(write_map(tmp_path))
    walls = walls_from_occupancy(occ.grid, occ.resolution, occ.origin)
    assert len(walls) == len(TRUE)
    for p1, p2, free in TRUE:
        wall = match(walls, p1, p2)
        np.testing.assert_allclose(wall.P1, p1, atol=1.5 * RES)
        np.testing.assert_allclose(wall.P2, p2, atol=1.5 * RES)
        assert wall.free_edges == free, (p1, p2)
    assert sum(len(p.free_edges) for p in walls) == 6
    assert [p.id for p in walls] == [f"wall{i:02d}" for i in range(1, 8)]
    assert [p.length for p in walls] == sorted((p.length for p in walls), reverse=True)
    # only walls of at least min_length: the partition's faces (2.5 m) and the left part of the bottom wall go
    long = walls_from_occupancy(occ.grid, occ.resolution, occ.origin, WallExtraction(min_length=3.5))
    assert len(long) == 4 and min(p.length for p in long) > 3.5


def test_origin_yaw_and_negate(tmp_path):
    base = load_any_map(write_map(tmp_path))
    x, y, yaw = -3.2, 1.5, 0.3
    path = write_map(tmp_path, 255 - room_image(), name="negated", negate=1, origin=[x, y, yaw])
    walls = load_any_map(path)
    R = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    assert len(walls) == len(base)
    for a in base:
        b = walls[a.id]
        moved = np.array([R @ a.P1 + [x, y], R @ a.P2 + [x, y]])
        same = np.abs(np.array([b.P1, b.P2]) - moved).max() <= 1e-3  # ends rounded to 1 mm
        assert same or np.abs(np.array([b.P2, b.P1]) - moved).max() <= 1e-3, (a, b)
        swap = {"p1": "p1", "p2": "p2"} if same else {"p1": "p2", "p2": "p1"}
        assert tuple(sorted(swap[e] for e in a.free_edges)) == b.free_edges
    faces = [p for p in walls if len(p.free_edges) == 2]
    assert len(faces) == 2
    for sign in (1, -1):
        true_ends = np.array([R @ (PART[0] + sign * _PN) + [x, y], R @ (PART[1] + sign * _PN) + [x, y]])
        errors = [min(np.abs(np.array([p.P1, p.P2]) - true_ends).max(),
                      np.abs(np.array([p.P2, p.P1]) - true_ends).max()) for p in faces]
        assert min(errors) < 1.5 * RES


def test_noisy_room():
    rng = np.random.default_rng(1)
    grid = occupancy_from_image(room_image(), False, 0.65, 0.196)
    grid[(grid == 100) & (rng.random(grid.shape) < 0.1)] = 0  # holes in the walls
    grid[(grid == 0) & (rng.random(grid.shape) < 0.003)] = 100  # specks in free space
    walls = walls_from_occupancy(grid, RES, [0.0, 0.0, 0.0])
    assert len(walls) == len(TRUE)
    for p1, p2, free in TRUE:
        wall = match(walls, p1, p2)
        np.testing.assert_allclose([wall.P1, wall.P2], [p1, p2], atol=2 * RES)
        assert wall.free_edges == free


def test_an_end_against_unknown_space_or_the_border_is_not_free():
    grid = np.zeros((30, 80), np.int8)
    grid[:, 60:] = -1  # unknown beyond column 60
    grid[14:17, 10:60] = 100  # a wall from the free space into the unknown
    grid[4:7, 30:80] = 100  # a wall from the free space to the border of the grid
    walls = walls_from_occupancy(grid, RES, [0.0, 0.0, 0.0])
    assert len(walls) == 4  # free space on both sides: two faces each
    for plane in walls:
        assert plane.free_edges == ("p1",)
        assert plane.P1[0] == pytest.approx((10 if plane.P1[1] < 1.0 else 30) * RES, abs=RES)


def test_extraction_parameters_are_checked():
    with pytest.raises(ConfigError, match=r"WallExtraction.min_length: expected a positive number \[m\], got 0"):
        WallExtraction(min_length=0)
    with pytest.raises(ConfigError, match=r"WallExtraction.angle_tol"):
        WallExtraction(angle_tol=2.0)
    with pytest.raises(ConfigError, match=r"expected a 2D occupancy grid"):
        walls_from_occupancy(np.zeros(5), RES, [0, 0, 0])
    empty = walls_from_occupancy(np.zeros((20, 20), np.int8), RES, [0, 0, 0])
    assert len(empty) == 0


# ------------------------------------------------------------ GeoJSON
def test_geojson_round_trip(tmp_path):
    m = Map((
        ReferencePlane("partition", (0.0, 4.0), (1.2, 4.0), "the partition", ("p1",), (0.0, 1.8)),
        ReferencePlane("board", (-0.55, 6.0), (-2.35, 6.0), "board", ("p1", "p2"), visible_from="left"),
        ReferencePlane("back", (-4.0, 8.5), (4.0, 8.5), "back", reference=False),
    ), frame="lab")
    save_geojson(m, tmp_path / "walls.geojson")
    assert json.loads((tmp_path / "walls.geojson").read_text())["features"][0]["geometry"]["type"] == "LineString"
    assert load_any_map(tmp_path / "walls.geojson") == m


def test_geojson_lines_split_with_suffixed_ids(tmp_path):
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": "corridor",
         "geometry": {"type": "LineString", "coordinates": [[0, 0], [2, 0], [2, 3, 0.0]]},
         "properties": {"free_edges": ["p1", "p2"], "stroke": "#ff0000"}},
        {"type": "Feature",
         "geometry": {"type": "MultiLineString", "coordinates": [[[5, 0], [5, 1]], [[5, 2], [5, 4]]]},
         "properties": {"id": "door_wall", "free_edges": ["p2"], "z": [0, 2]}},
        {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[7, 0], [8, 0]]}, "properties": None},
    ]}
    (tmp_path / "walls.json").write_text(json.dumps(doc))
    m = load_any_map(tmp_path / "walls.json")
    assert [p.id for p in m] == ["corridor_1", "corridor_2", "door_wall_1", "door_wall_2", "feature2"]
    assert [p.free_edges for p in m] == [("p1",), ("p2",), ("p2",), ("p2",), ()]
    assert m["corridor_2"].p2 == (2.0, 3.0) and m["corridor_2"].name == "corridor"
    assert m["door_wall_2"].z == (0.0, 2.0)
    assert map_to_geojson(m)["features"][2]["properties"]["id"] == "door_wall_1"


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 0]]}},
            {"type": "Feature", "geometry": {"type": "Point", "coordinates": [1, 2]}}]},
         r"walls.geojson: features\[1\].geometry: expected a LineString or MultiLineString geometry, got 'Point'"),
        ({"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0]]}}]},
         r"features\[0\].geometry.coordinates: expected a line of at least 2 positions"),
        ({"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 0]]},
             "properties": {"free_edges": ["left"]}}]},
         r"features\[0\].properties.free_edges: expected a list drawn from \['p1', 'p2'\]"),
        ({"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0], [0, 0]]}}]},
         r"features\[0\]: p1 and p2 are the same point"),
        ({"type": "Feature"}, r"walls.geojson: not a map file: expected .* got a mapping with keys \['type'\]"),
    ],
)
def test_broken_geojson(tmp_path, doc, message):
    (tmp_path / "walls.geojson").write_text(json.dumps(doc))
    with pytest.raises(ConfigError, match=message):
        load_any_map(tmp_path / "walls.geojson")


def test_load_any_map_dispatch(tmp_path):
    native = Map((ReferencePlane("w", (0.0, 0.0), (1.0, 0.0), "w"),))
    native.save(tmp_path / "native.yaml")
    assert load_any_map(tmp_path / "native.yaml") == native
    assert len(load_any_map(write_map(tmp_path))) == len(TRUE)
    (tmp_path / "bad.json").write_text("{\"type\": ")
    with pytest.raises(ConfigError, match=r"bad.json: invalid JSON at line 1"):
        load_any_map(tmp_path / "bad.json")
    (tmp_path / "other.yaml").write_text("walls: []\n")
    with pytest.raises(ConfigError, match=r"other.yaml: not a map file: .* got a mapping with keys \['walls'\]"):
        load_any_map(tmp_path / "other.yaml")


# ------------------------------------------------------------ the command
def test_map_walls_command(tmp_path, capsys):
    out = tmp_path / "out" / "walls.yaml"
    assert main(["map-walls", write_map(tmp_path), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Found 7 walls and 6 free edges" in printed
    assert len(load_map(out)) == 7
    png = cv2.imread(str(tmp_path / "out" / "walls.png"))
    assert png is not None and png.shape[0] > 300 and png.std() > 10


def test_map_walls_command_broken_map_writes_nothing(tmp_path, capsys):
    path = write_map(tmp_path, image="gone.pgm")
    out = tmp_path / "out" / "walls.yaml"
    assert main(["map-walls", path, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "stablemarks map-walls: error:" in err and "gone.pgm" in err
    assert not (tmp_path / "out").exists()
    assert main(["map-walls", write_map(tmp_path), "--out", str(tmp_path / "walls.png")]) == 1
    assert "--out: expected a .yaml file name" in capsys.readouterr().err
    assert not (tmp_path / "walls.png").exists()
