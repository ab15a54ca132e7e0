"""Reading images as 8-bit gray and loading stereo pairs (rectification itself: test_calibration)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from stablemarks.errors import ImageError
from stablemarks.geometry import StereoCamera
from stablemarks.io.calibration import StereoCalibration
from stablemarks.io.images import load_image_gray, load_stereo_pair, to_gray8


@pytest.fixture
def gray():
    rng = np.random.default_rng(1)
    return rng.integers(0, 256, (48, 64), dtype=np.uint8)


def write(path, image):
    assert cv2.imwrite(str(path), image)
    return path


def test_gray_png_round_trip(tmp_path, gray):
    out = load_image_gray(write(tmp_path / "g.png", gray))
    assert out.dtype == np.uint8 and out.shape == (48, 64)
    np.testing.assert_array_equal(out, gray)


def test_colour_and_alpha_become_gray(tmp_path):
    bgr = np.zeros((10, 20, 3), np.uint8)
    bgr[:, :10] = (255, 0, 0)  # pure blue: 0.114 · 255
    bgr[:, 10:] = (0, 0, 255)  # pure red: 0.299 · 255
    out = load_image_gray(write(tmp_path / "c.png", bgr))
    assert out.shape == (10, 20)
    assert out[0, 0] == 29 and out[0, 15] == 76
    bgra = np.dstack([bgr, np.full((10, 20), 7, np.uint8)])
    np.testing.assert_array_equal(load_image_gray(write(tmp_path / "a.png", bgra)), out)


def test_16_bit_is_scaled_by_full_range(tmp_path, gray):
    deep = gray.astype(np.uint16) * 257
    deep[0, 0] = 65535
    deep[0, 1] = 128  # rounds to 0
    deep[0, 2] = 129  # rounds to 1
    out = load_image_gray(write(tmp_path / "d.png", deep))
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out[1:], gray[1:])
    assert out[0, :3].tolist() == [255, 0, 1]


def test_to_gray8_float_and_bad_input(gray):
    np.testing.assert_array_equal(to_gray8(gray.astype(np.float32) / 255.0), gray)
    np.testing.assert_array_equal(to_gray8(gray[..., None]), gray)
    with pytest.raises(ImageError, match="img: expected 8-bit, 16-bit or float pixels, got int64"):
        to_gray8(gray.astype(np.int64), "img")
    with pytest.raises(ImageError, match="expected 1, 2, 3 or 4 channels, got 5"):
        to_gray8(np.zeros((4, 4, 5), np.uint8))


def test_unreadable_files(tmp_path):
    with pytest.raises(ImageError, match=r"missing\.png: no such image file"):
        load_image_gray(tmp_path / "missing.png")
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(ImageError, match=r"text\.png: cannot read image"):
        load_image_gray(tmp_path / "text.png")
    with pytest.raises(ImageError, match=r"missing\.png: no such image file"):
        load_stereo_pair(write(tmp_path / "l.png", np.zeros((4, 4), np.uint8)), tmp_path / "missing.png")


def test_stereo_pair_size_mismatch(tmp_path, gray):
    left = write(tmp_path / "l.png", gray)
    right = write(tmp_path / "r.png", gray[:40])
    with pytest.raises(ImageError, match=r"sizes differ: .*l\.png is 64×48 px, .*r\.png is 64×40 px"):
        load_stereo_pair(left, right)


def test_stereo_pair_calibration_size_mismatch(tmp_path, gray):
    left, right = write(tmp_path / "l.png", gray), write(tmp_path / "r.png", gray)
    calib = StereoCalibration.from_stereo_camera(StereoCamera(width=640, height=480))
    with pytest.raises(ImageError, match=r"images are 64×48 px but the calibration is for 640×480 px"):
        load_stereo_pair(left, right, calib)


def test_stereo_pair_rectified_calibration_keeps_images(tmp_path, gray):
    left, right = write(tmp_path / "l.png", gray), write(tmp_path / "r.png", gray[::-1])
    calib = StereoCalibration.from_stereo_camera(StereoCamera(width=64, height=48, f=50.0, cu=31.5, cv=23.5))
    assert calib.is_rectified
    out_l, out_r = load_stereo_pair(left, right, calib)
    np.testing.assert_array_equal(out_l, gray)
    np.testing.assert_array_equal(out_r, gray[::-1])


def test_stereo_pair_raw_calibration_rectifies(tmp_path):
    """A pure shift of the principal point: rectification moves the image by whole pixels."""
    img = np.zeros((48, 64), np.uint8)
    img[20:30, 30:40] = 200
    left, right = write(tmp_path / "l.png", img), write(tmp_path / "r.png", img)
    K = np.array([[50.0, 0.0, 31.5], [0.0, 50.0, 25.5], [0.0, 0.0, 1.0]])  # cv 2 px below the rectified one
    P1 = np.array([[50.0, 0.0, 31.5, 0.0], [0.0, 50.0, 23.5, 0.0], [0.0, 0.0, 1.0, 0.0]])
    P2 = P1.copy()
    P2[0, 3] = -5.0
    calib = StereoCalibration((64, 48), K, np.zeros(5), K, np.zeros(5), np.eye(3), np.array([-0.1, 0, 0]),
                              np.eye(3), np.eye(3), P1, P2)
    assert not calib.is_rectified
    out_l, out_r = load_stereo_pair(left, right, calib)
    np.testing.assert_array_equal(out_l[18:28, 30:40], img[20:30, 30:40])
    np.testing.assert_array_equal(out_l, out_r)
