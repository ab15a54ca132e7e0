"""Fuzz tests of every loader of user files (issue 15): whatever a file holds, the loader either returns or
raises a :class:`~stablemarks.errors.StablemarksError` whose message is one printable line.

Each loader gets two kinds of broken input, starting from a valid file: *structural* mutations of the parsed
document (a value replaced by junk of any type and size, a field removed, an unknown key added, a list
emptied) written back as YAML/JSON, and *textual* mutations of the file (truncated, a line replaced, bytes
overwritten or inserted). The junk includes what broke the loaders before: integers beyond int64, NaN and
infinities, keys of mixed types (``~:`` next to ``foo:``), strings with line breaks and escape sequences,
dates, deep nesting, paths that leave the folder.
"""

from __future__ import annotations

import copy
import json
import math
import os
import re
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stablemarks.config import load_config
from stablemarks.errors import StablemarksError
from stablemarks.geometry import StereoCamera
from stablemarks.io.calibration import (
    StereoCalibration,
    load_calibration,
    load_camera_info_pair,
    load_mount,
    load_opencv_calibration,
    save_calibration,
    save_opencv_calibration,
)
from stablemarks.io.mapfiles import load_any_map, load_occupancy_map, map_to_geojson
from stablemarks.io.recorded import read_odometry_csv
from stablemarks.io.sequence import load_sequence, write_sequence
from stablemarks.maps import Map, ReferencePlane, load_map
from stablemarks.sim.scenario import SCENARIO_DIR, load_scenario

EXAMPLES = 300
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# ------------------------------------------------------------------ the junk
_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.sampled_from([0, -1, 1, 2**63, -(2**63) - 1, 10**30, 2**31, 99999, 100000, 1e308, -1e308, 1e-320])
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=12)
    | st.sampled_from(["", "p1", "both", "a\nb", "\x1b[31mred", "x" * 400, "../outside", "/etc/passwd",
                       "nan", "1e400", "-0", "\u2028", "plumb_bob", "noise", "look_at_free_edges"])
    | st.dates()
)
_KEYS = st.none() | st.integers(-3, 3) | st.booleans() | st.text(max_size=6) | st.sampled_from(["~", "foo", "a\nb"])
JUNK = st.recursive(
    _SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_KEYS, inner, max_size=3),
    max_leaves=8,
)


def _paths(doc, prefix=()):
    """Every path (tuple of keys and indices) into a document, the root excluded."""
    out = []
    if isinstance(doc, dict):
        items = list(doc.items())
    elif isinstance(doc, list):
        items = list(enumerate(doc))
    else:
        return out
    for key, value in items:
        out.append((*prefix, key))
        out += _paths(value, (*prefix, key))
    return out


def mutate(doc, data):
    """A copy of ``doc`` with one structural change drawn by hypothesis (``data``)."""
    doc = copy.deepcopy(doc)
    paths = _paths(doc)
    action = data.draw(st.sampled_from(["replace", "replace", "replace", "delete", "add", "root"]))
    if action == "root" or not paths:
        return data.draw(JUNK)
    path = data.draw(st.sampled_from(paths))
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    last = path[-1]
    if action == "replace":
        parent[last] = data.draw(JUNK)
    elif action == "delete":
        del parent[last]
    else:
        target = parent[last]
        if isinstance(target, dict):  # one to three keys: unknown keys of mixed types (`~:` and `foo:`)
            for key in data.draw(st.lists(_KEYS, min_size=1, max_size=3)):
                target[key] = data.draw(JUNK)
        elif isinstance(target, list):
            target.insert(data.draw(st.integers(0, len(target))), data.draw(JUNK))
        else:
            parent[last] = [target, data.draw(JUNK)]
    return doc


def dump_yaml(doc) -> str:
    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)


def mutate_text(text: str, data) -> str:
    """``text`` with one textual change: truncated, a line replaced or duplicated, characters inserted."""
    lines = text.splitlines(keepends=True) or [""]
    action = data.draw(st.sampled_from(["truncate", "line", "duplicate", "insert", "junk line"]))
    if action == "truncate":
        return text[: data.draw(st.integers(0, max(0, len(text) - 1)))]
    i = data.draw(st.integers(0, len(lines) - 1))
    if action == "line":
        lines[i] = data.draw(st.text(max_size=40)) + "\n"
    elif action == "duplicate":
        lines.insert(i, lines[i])
    elif action == "junk line":
        lines.insert(i, data.draw(st.sampled_from(
            ["~: 1\n", "foo: bar\n", "  - [\n", "a: &a [*a]\n", "x: 123456789012345678901234567890\n",
             "y: .nan\n", "<<: {}\n", "\t\n", "%YAML 1.1\n", "---\n", "!!python/object:os.system {}\n"])))
    else:
        at = data.draw(st.integers(0, len(text)))
        return text[:at] + data.draw(st.text(max_size=8)) + text[at:]
    return "".join(lines)


def mutate_bytes(raw: bytes, data) -> bytes:
    """``raw`` truncated, with bytes overwritten or inserted."""
    action = data.draw(st.sampled_from(["truncate", "overwrite", "insert"]))
    if action == "truncate":
        return raw[: data.draw(st.integers(0, max(0, len(raw) - 1)))]
    at = data.draw(st.integers(0, len(raw)))
    chunk = data.draw(st.binary(min_size=1, max_size=16))
    if action == "overwrite":
        return raw[:at] + chunk + raw[at + len(chunk):]
    return raw[:at] + chunk + raw[at:]


def assert_only_our_errors(load, *args):
    """``load(*args)`` returns, or raises a StablemarksError with a one-line printable message."""
    try:
        load(*args)
    except StablemarksError as exc:
        message = str(exc)
        assert message.isprintable() and "\n" not in message, repr(message)
        assert len(message) <= 2000


@contextmanager
def fd2_text():
    """What is written to the process's stderr (file descriptor 2) meanwhile, as ``[text]`` afterwards (not
    :func:`stablemarks.io.images.native_stderr`: the loaders take its lock themselves)."""
    said = []
    with tempfile.TemporaryFile() as sink:
        saved = os.dup(2)
        try:
            os.dup2(sink.fileno(), 2)
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            said.append(sink.read().decode("utf-8", "replace"))


@contextmanager
def scratch():
    with tempfile.TemporaryDirectory(prefix="stablemarks-fuzz-") as d:
        yield Path(d)


# ------------------------------------------------------------------ valid inputs
WALLS = Map((ReferencePlane("partition", (0.0, 4.0), (1.2, 4.0), free_edges=("p1",), z=(0.0, 1.8)),
             ReferencePlane("back", (-4.0, 8.5), (4.0, 8.5), reference=False)))
MAP_DOC = WALLS.to_dict()
GEOJSON_DOC = map_to_geojson(WALLS)
SCENARIO_DOC = yaml.safe_load((SCENARIO_DIR / "lab.yaml").read_text())
CAMERA = StereoCamera(width=64, height=48, f=50.0, cu=31.5, cv=23.5, baseline=0.12)
MOUNT_DOC = {"mount": {"x": 0.1, "y": 0.0, "height": 1.05, "pan_deg": 0.0}}
CONFIG_DOC = {"noise": {"sigma_img": 0.5}, "sad": {"block_size": 15, "num_disparities": 64},
              "ekf": {"max_updates_per_frame": 6}, "pan": {"limits": [-1.5, 1.5]}}


def _raw_calibration() -> StereoCalibration:
    K = np.array([[50.0, 0.0, 32.0], [0.0, 51.0, 24.0], [0.0, 0.0, 1.0]])
    D = np.array([0.01, -0.02, 0.001, 0.0, 0.0])
    R = cv2.Rodrigues(np.array([0.01, -0.02, 0.005]))[0]
    T = np.array([-0.12, 0.001, 0.0])
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K, D, K, D, (64, 48), R, T.reshape(3, 1),
                                           flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
    return StereoCalibration((64, 48), K, D, K, D, R, T, R1, R2, P1, P2)


@pytest.fixture(scope="module")
def calib_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("calib")
    save_calibration(_raw_calibration(), out)
    return out


@pytest.fixture(scope="module")
def opencv_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("opencv") / "stereo.yml"
    save_opencv_calibration(_raw_calibration(), out)
    return out


@pytest.fixture(scope="module")
def sequence_dir(tmp_path_factory):
    rng = np.random.default_rng(0)
    images = [(rng.integers(0, 255, (48, 64), dtype=np.uint8), rng.integers(0, 255, (48, 64), dtype=np.uint8))
              for _ in range(3)]
    out = tmp_path_factory.mktemp("seq") / "seq"
    stamps = np.array([0.0, 0.5, 1.0])
    odometry = np.array([[0.0, 0.0, 1.57], [0.0, 0.1, 1.57], [0.0, 0.2, 1.6]])
    write_sequence(out, name="fuzz", camera=CAMERA, world_map=WALLS, stamps=stamps, odometry=odometry,
                   pans=np.zeros(3), images=images, groundtruth=odometry)
    load_sequence(out)
    return out


@pytest.fixture(scope="module")
def occupancy(tmp_path_factory):
    out = tmp_path_factory.mktemp("occ")
    grid = np.full((40, 50), 254, np.uint8)
    grid[5, 5:45] = 0
    grid[5:35, 5] = 0
    grid[20, 15:30] = 0
    cv2.imwrite(str(out / "room.pgm"), grid)
    doc = {"image": "room.pgm", "resolution": 0.05, "origin": [-1.0, -1.0, 0.0], "negate": 0,
           "occupied_thresh": 0.65, "free_thresh": 0.196}
    (out / "room.yaml").write_text(dump_yaml(doc))
    load_occupancy_map(out / "room.yaml")
    return out, doc


# ------------------------------------------------------------------ map YAML, GeoJSON, map_server
def test_valid_inputs_load(calib_dir, opencv_file, sequence_dir, occupancy):
    """The starting points of the fuzzing are valid."""
    with scratch() as d:
        (d / "m.yaml").write_text(dump_yaml(MAP_DOC))
        assert len(load_map(d / "m.yaml")) == 2
        (d / "m.geojson").write_text(json.dumps(GEOJSON_DOC))
        assert len(load_any_map(d / "m.geojson")) == 2
        (d / "s.yaml").write_text(dump_yaml(SCENARIO_DOC))
        assert load_scenario(d / "s.yaml").name == "lab"
        (d / "mount.yaml").write_text(dump_yaml(MOUNT_DOC))
        assert load_mount(d / "mount.yaml").mount_height == 1.05
        (d / "c.yaml").write_text(dump_yaml(CONFIG_DOC))
        assert load_config(d / "c.yaml").sad.block_size == 15
    assert load_camera_info_pair(calib_dir).image_size == (64, 48)
    assert load_opencv_calibration(opencv_file).image_size == (64, 48)
    assert len(load_sequence(sequence_dir)) == 3


@FUZZ
@given(data=st.data())
def test_map_yaml(data):
    with scratch() as d:
        path = d / "map.yaml"
        if data.draw(st.booleans()):
            path.write_text(dump_yaml(mutate(MAP_DOC, data)))
        else:
            path.write_text(mutate_text(dump_yaml(MAP_DOC), data))
        assert_only_our_errors(load_map, path)
        assert_only_our_errors(load_any_map, path)


def mutate_json_text(text: str, data) -> str:
    """``text`` (JSON) with a member repeated in its object or brackets opened deep at one place (closed or not)."""
    members = list(re.finditer(r'"[^"]*": ', text))
    if members and data.draw(st.booleans()):
        m = data.draw(st.sampled_from(members))
        value = data.draw(st.sampled_from(['1, ', '"x", ', '[], ', '{}, ']))
        return text[:m.start()] + m.group(0) + value + text[m.start():]
    depth = data.draw(st.sampled_from([98, 101, 150, 5000, 100_000]))
    opener = data.draw(st.sampled_from(["[", '{"a": ']))
    nested = opener * depth + ("0" + ("]" if opener == "[" else "}") * depth if data.draw(st.booleans()) else "")
    # as the first element of a list (a valid document when closed), or anywhere
    lists = [m.end() for m in re.finditer(r"\[\s*(?=[^\s\]])", text)]
    if lists and data.draw(st.booleans()):
        at = data.draw(st.sampled_from(lists))
        return text[:at] + nested + ", " + text[at:]
    at = data.draw(st.integers(0, len(text)))
    return text[:at] + nested + text[at:]


@FUZZ
@given(data=st.data())
def test_geojson(data):
    with scratch() as d:
        path = d / "walls.geojson"
        kind = data.draw(st.sampled_from(["doc", "text", "json"]))
        if kind == "doc":
            doc = mutate(GEOJSON_DOC, data)
            path.write_text(json.dumps(doc, default=str))
        elif kind == "text":
            path.write_text(mutate_text(json.dumps(GEOJSON_DOC, indent=1), data))
        else:  # keys twice in one object, nesting beyond the limit and beyond Python's recursion limit
            path.write_text(mutate_json_text(json.dumps(GEOJSON_DOC, indent=1), data))
        assert_only_our_errors(load_any_map, path)


@FUZZ
@given(data=st.data())
def test_map_server_yaml_and_pgm(occupancy, data):
    src, doc = occupancy
    with scratch() as d:
        shutil.copy(src / "room.pgm", d / "room.pgm")
        path = d / "room.yaml"
        kind = data.draw(st.sampled_from(["doc", "text", "image"]))
        if kind == "doc":
            path.write_text(dump_yaml(mutate(doc, data)))
        elif kind == "text":
            path.write_text(mutate_text(dump_yaml(doc), data))
        else:
            path.write_text(dump_yaml(doc))
            (d / "room.pgm").write_bytes(mutate_bytes((src / "room.pgm").read_bytes(), data))
        with fd2_text() as said:  # a damaged image: OpenCV's own lines stay off stderr
            assert_only_our_errors(load_occupancy_map, path)
            assert_only_our_errors(load_any_map, path)
        assert said == [""], said


# ------------------------------------------------------------------ scenario
@FUZZ
@given(data=st.data())
def test_scenario(data):
    with scratch() as d:
        path = d / "scenario.yaml"
        if data.draw(st.booleans()):
            path.write_text(dump_yaml(mutate(SCENARIO_DOC, data)))
        else:
            path.write_text(mutate_text((SCENARIO_DIR / "lab.yaml").read_text(), data))
        assert_only_our_errors(load_scenario, path)


# ------------------------------------------------------------------ calibrations and the mount
@FUZZ
@given(data=st.data())
def test_camera_info(calib_dir, data):
    with scratch() as d:
        for name in ("left.yaml", "right.yaml"):
            shutil.copy(calib_dir / name, d / name)
        name = data.draw(st.sampled_from(["left.yaml", "right.yaml"]))
        text = (calib_dir / name).read_text()
        if data.draw(st.booleans()):
            (d / name).write_text(dump_yaml(mutate(yaml.safe_load(text), data)))
        else:
            (d / name).write_text(mutate_text(text, data))
        assert_only_our_errors(load_calibration, d)


@FUZZ
@given(data=st.data())
def test_opencv_filestorage(opencv_file, data):
    with scratch() as d:
        path = d / opencv_file.name
        text = opencv_file.read_text()
        if data.draw(st.booleans()):
            path.write_text(mutate_text(text, data))
        else:
            path.write_bytes(mutate_bytes(text.encode(), data))
        assert_only_our_errors(load_calibration, path)


@FUZZ
@given(data=st.data())
def test_mount(data):
    with scratch() as d:
        path = d / "mount.yaml"
        if data.draw(st.booleans()):
            path.write_text(dump_yaml(mutate(MOUNT_DOC, data)))
        else:
            path.write_text(mutate_text(dump_yaml(MOUNT_DOC), data))
        assert_only_our_errors(load_mount, path)


# ------------------------------------------------------------------ sequence folders
CELLS = st.sampled_from(["", "nan", "inf", "-1", "1e400", "1e300", "99999999999999999999999", "0.5", "x",
                         "../outside.png", "/etc/passwd", "left/000000.png", "left", "\x00", " 1 ", "1,2",
                         "-0", "0x10"]) | st.text(max_size=10)


@contextmanager
def sequence_copy(sequence_dir):
    with scratch() as d:
        yield Path(shutil.copytree(sequence_dir, d / "seq"))


@FUZZ
@given(data=st.data())
def test_sequence_yaml(sequence_dir, data):
    with sequence_copy(sequence_dir) as seq:
        path = seq / "sequence.yaml"
        doc = yaml.safe_load(path.read_text())
        doc["initial_pose"] = {"x": 0.0, "y": 0.0, "theta_deg": 90.0}
        if data.draw(st.booleans()):
            path.write_text(dump_yaml(mutate(doc, data)))
        else:
            path.write_text(mutate_text(dump_yaml(doc), data))
        assert_only_our_errors(load_sequence, seq)


def _mutate_csv(text: str, data) -> str:
    rows = [line.split(",") for line in text.splitlines()]
    action = data.draw(st.sampled_from(["cell", "cell", "row", "text"]))
    if action == "text":
        return mutate_text(text, data)
    if action == "row":
        i = data.draw(st.integers(0, len(rows)))
        rows.insert(i, [data.draw(CELLS) for _ in range(data.draw(st.integers(0, 6)))])
    else:
        i = data.draw(st.integers(0, len(rows) - 1))
        j = data.draw(st.integers(0, len(rows[i]) - 1))
        rows[i][j] = data.draw(CELLS)
    return "\n".join(",".join(r) for r in rows) + "\n"


@FUZZ
@given(data=st.data())
def test_frames_csv(sequence_dir, data):
    with sequence_copy(sequence_dir) as seq:
        path = seq / "frames.csv"
        path.write_text(_mutate_csv(path.read_text(), data))
        assert_only_our_errors(load_sequence, seq)


@FUZZ
@given(data=st.data())
def test_odometry_csv(sequence_dir, data):
    with sequence_copy(sequence_dir) as seq:
        path = seq / "odometry.csv"
        path.write_text(_mutate_csv(path.read_text(), data))
        assert_only_our_errors(load_sequence, seq)
        assert_only_our_errors(read_odometry_csv, path)


@settings(max_examples=100, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_sequence_images(sequence_dir, data):
    """A damaged PNG is an ImageError naming it; OpenCV's and libpng's own lines stay off stderr."""
    with sequence_copy(sequence_dir) as seq:
        path = seq / "left" / "000000.png"
        path.write_bytes(mutate_bytes(path.read_bytes(), data))
        assert_only_our_errors(load_sequence, seq)


# ------------------------------------------------------------------ --config and --set
@FUZZ
@given(data=st.data())
def test_config_file(data):
    with scratch() as d:
        path = d / "config.yaml"
        if data.draw(st.booleans()):
            path.write_text(dump_yaml(mutate(CONFIG_DOC, data)))
        else:
            path.write_text(mutate_text(dump_yaml(CONFIG_DOC), data))
        assert_only_our_errors(load_config, path)


SETTINGS = st.sampled_from(["sad.block_size", "sad.num_disparities", "noise.sigma_img", "noise.boundary_px",
                            "ekf.max_updates_per_frame", "pan.limits", "pan.policy", "odometry.trans_per_m",
                            "landmarks.boundary_rule", "matching.min_disparity", "nosuch.key", "sad.nosuch"])


@FUZZ
@given(key=SETTINGS, value=st.text(max_size=30) | JUNK.map(lambda v: yaml.safe_dump(v).strip()))
def test_set_overrides(key, value):
    from stablemarks.commands._common import parse_overrides
    from stablemarks.config import Config

    def load():
        return Config().with_overrides(parse_overrides([f"{key}={value}"]), "--set")

    assert_only_our_errors(load)


# ------------------------------------------------------------------ the YAML limits themselves
@pytest.mark.parametrize("text, message", [
    ("a: 1\nb: 2\na: 3\n", r"line 3, column 1: duplicate key 'a' \(first at line 1\)"),
    ("a: 9223372036854775808\n", "out of range"),
    ("a: " + "9" * 5000 + "\n", "out of range"),
    ("a: 2001-13-45\n", "not a valid date"),
    ("a: &x [*x]\n", "recursive"),
    ("a: " + "[" * 150 + "]" * 150 + "\n", "nested deeper than 100 levels"),
    ("a: " + "[" * 5000 + "]" * 5000 + "\n", "nest"),
])
def test_strict_yaml(tmp_path, text, message):
    import re

    path = tmp_path / "x.yaml"
    path.write_text(text)
    with pytest.raises(StablemarksError) as info:
        load_map(path)
    assert re.search(message, str(info.value)) and "\n" not in str(info.value)


def test_alias_bomb_is_refused_quickly(tmp_path):
    lines = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for prev, name in zip("abcdefgh", "bcdefghi", strict=True):
        lines.append(f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 9) + "]")
    lines.append("planes: *i")
    path = tmp_path / "bomb.yaml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(StablemarksError, match="aliases expand it to .* nodes") as info:
        load_map(path)
    assert len(str(info.value)) < 300


def test_huge_numbers_are_one_line_errors(tmp_path):
    """An integer beyond int64 in any numeric field of any format (it used to reach np.isfinite)."""
    from stablemarks.maps import parse_map

    doc = copy.deepcopy(MAP_DOC)
    doc["planes"][0]["p1"] = [10**400, 4.0]
    with pytest.raises(StablemarksError, match=r"planes\[0\]\.p1\[0\]: expected a finite number") as info:
        parse_map(doc)
    assert len(str(info.value)) < 300
    for big in (2e6, 10**30):
        doc["planes"][0]["p1"] = [big, 4.0]
        with pytest.raises(StablemarksError, match=r"p1\[0\]: expected a number within ±1e\+06"):
            parse_map(doc)
    assert not math.isfinite(float("nan"))
