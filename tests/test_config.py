"""One home for each physical parameter: set once in the configuration, read by every stage."""

from types import SimpleNamespace

import numpy as np
import pytest

from stablemarks.config import DERIVED, Config, load_config, parse_config
from stablemarks.errors import ConfigError
from stablemarks.geometry import StereoCamera
from stablemarks.localizer import Localizer
from stablemarks.maps import Map, ReferencePlane
from stablemarks.motion import OdometryNoise
from stablemarks.pipeline import select_landmarks
from stablemarks.planes import predict_planes

WALL = ReferencePlane("wall", (-1.0, 4.0), (1.5, 4.0), free_edges=("p1",))
MAP = Map((WALL,))
X = np.array([0.0, 0.0, np.pi / 2])
COV = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2


def test_the_sad_window_sets_the_filter_radius_and_the_fits_correlation_length():
    config = Config().with_overrides({"sad": {"block_size": 9}}, "--set")
    assert config.filter.search_radius == 4 and config.planes.correlation_px == 9.0
    assert Config().filter.search_radius == 7 and Config().planes.correlation_px == 15.0


def test_the_disparity_range_sets_the_segment_matchers_range():
    config = Config().with_overrides({"sad": {"num_disparities": 96, "min_disparity": 2}}, "--set")
    assert (config.matching.min_disparity, config.matching.max_disparity) == (2.0, 98.0)


@pytest.mark.parametrize(("section", "key"), sorted(DERIVED))
def test_a_derived_setting_cannot_be_set_on_its_own(section, key):
    with pytest.raises(ConfigError, match=rf"config: {section}\.{key}: set from .* set that instead"):
        parse_config({section: {key: 1}})


def test_sigma_img_reaches_the_plane_gates_the_feature_model_and_the_filter():
    camera = StereoCamera()
    wide = Config().with_overrides({"noise": {"sigma_img": 2.0}})
    assert wide.camera(camera).sigma_img == 2.0 and Config.preset("paper").camera(camera) is camera
    # the filter's observation noise
    loc = Localizer(MAP, camera, start_pose=X, config=wide)
    assert loc.ekf.camera.sigma_img == 2.0
    # the plane prediction's disparity band (Eq 10): σ_d grows with σ_img
    narrow = predict_planes(camera, X, COV, MAP, Config().planes)[0]
    wide_pred = predict_planes(wide.camera(camera), X, COV, MAP, wide.planes)[0]
    common, i, j = np.intersect1d(narrow.columns, wide_pred.columns, return_indices=True)
    assert len(common) > 100 and np.all(wide_pred.sigma_d[j] > narrow.sigma_d[i])


def test_select_landmarks_reads_sigma_img_from_the_configuration(monkeypatch):
    """select_landmarks hands the stages the camera with the configuration's σ_img, whatever camera it gets."""
    import stablemarks.pipeline as pipeline

    seen = []
    monkeypatch.setattr(pipeline, "predict_planes", lambda cam, *a, **k: seen.append(cam.sigma_img) or [])
    wide = Config().with_overrides({"noise": {"sigma_img": 1.5}})
    empty = np.full((4, 4), np.inf)
    front = SimpleNamespace(kept_pairs=None, left_segments=[], disparity=SimpleNamespace(left=empty, right=empty))
    select_landmarks(front, StereoCamera(), MAP, X, COV, wide)
    assert seen == [1.5]


def test_the_odometry_noise_model_drives_the_prediction():
    camera = StereoCamera()
    noisy = Config().with_overrides({"odometry": {"trans_per_m": 0.2}})
    covs = []
    for config in (Config(), noisy):
        loc = Localizer(MAP, camera, start_pose=X, config=config, method="dead_reckoning")
        img = np.zeros((camera.height, camera.width), np.uint8)
        loc.step(0.0, img, img, odometry=[0.0, 0.0, 0.0])
        covs.append(loc.step(1.0, img, img, odometry=[1.0, 0.0, 0.0]).record.cov_odometry)
    assert covs[1][0, 0] == pytest.approx(16 * covs[0][0, 0])  # σ of the distance driven: 4 times
    assert noisy.odometry == OdometryNoise(trans_per_m=0.2)


def test_source_defaults_fill_only_what_the_user_left_at_the_default():
    source = {"odometry": {"trans_per_m": 0.1, "rot_per_m_deg": 3.0}, "pan": {"policy": "fixed"}}
    mine = Config().with_overrides({"odometry": {"trans_per_m": 0.02}})
    got = mine.with_source_defaults(source)
    assert got.odometry.trans_per_m == 0.02 and got.odometry.rot_per_m_deg == 3.0 and got.pan.policy == "fixed"


def test_the_resolved_configuration_loads_again(tmp_path):
    import yaml

    config = Config().with_overrides({"sad": {"block_size": 11},
                                      "pan": {"limits": [-1.0, 1.0], "policy": "information"}})
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(config.to_dict()))
    assert load_config(path) == config


@pytest.mark.parametrize(("doc", "match"), [
    ({"noise": {"sigma_img": -1}}, r"noise: noise\.sigma_img: expected a positive number"),
    ({"noise": {"sigma_img": "x"}}, r"noise\.sigma_img: expected a number"),
    ({"pan": {"policy": "wander"}}, r"pan\.policy: expected one of fixed, free_edges, information"),
    ({"pan": {"limits": [0.5, -0.5]}}, r"pan\.limits: expected \[min, max\]"),
    ({"odometry": {"trans_per_m": -0.1}}, r"odometry\.trans_per_m: expected a non-negative number"),
    ({"ekf": {"sigma_img": 0.5}}, r"ekf\.sigma_img: unknown setting"),
])
def test_bad_settings_are_one_line_errors(doc, match):
    with pytest.raises(ConfigError, match=match):
        parse_config(doc)
