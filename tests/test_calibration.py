"""Stereo calibration: ROS and OpenCV files, the mount, chessboard calibration and rectification.

The chessboard views are rendered here with a known, distorted stereo camera: every supersampled pixel's
ray (undistorted with the true lens) is intersected with the board plane and coloured by its square.
"""

from __future__ import annotations

from functools import cache

import cv2
import numpy as np
import pytest

from stablemarks.cli import main
from stablemarks.errors import CalibrationError, ConfigError, ImageError, InputError
from stablemarks.geometry import StereoCamera
from stablemarks.io.calibration import (
    Mount,
    StereoCalibration,
    board_points,
    calibrate_stereo,
    find_board,
    load_calibration,
    load_camera_info_pair,
    load_mount,
    load_opencv_calibration,
    save_calibration,
    save_camera_info_pair,
    save_opencv_calibration,
)
from stablemarks.io.images import load_stereo_pair

# ------------------------------------------------------------ the true camera
W, H = 640, 480
BOARD = (9, 6)
SQUARE = 0.035
SS = 2  # supersampling factor of the renderer
K_LEFT = np.array([[520.0, 0.0, 322.5], [0.0, 518.0, 236.8], [0.0, 0.0, 1.0]])
D_LEFT = np.array([-0.08, 0.03, 5e-4, -3e-4, 0.0])
K_RIGHT = np.array([[515.0, 0.0, 316.0], [0.0, 514.0, 242.0], [0.0, 0.0, 1.0]])
D_RIGHT = np.array([-0.06, 0.02, -4e-4, 2e-4, 0.0])
R_TRUE = cv2.Rodrigues(np.array([0.004, -0.015, 0.003]))[0]
T_TRUE = np.array([-0.12, 0.0015, -0.001])
BASELINE = float(np.linalg.norm(T_TRUE))


@cache
def _rays(camera: str) -> tuple[np.ndarray, np.ndarray]:
    """Normalized ray coordinates x, y (H·SS, W·SS) of the supersampled pixel grid of one camera."""
    K, D = (K_LEFT, D_LEFT) if camera == "left" else (K_RIGHT, D_RIGHT)
    jj, ii = np.meshgrid(np.arange(W * SS), np.arange(H * SS))
    pix = np.stack([(jj + 0.5) / SS - 0.5, (ii + 0.5) / SS - 0.5], -1).reshape(-1, 1, 2)
    rays = cv2.undistortPoints(pix.astype(np.float64), K, D).reshape(H * SS, W * SS, 2).astype(np.float32)
    return rays[..., 0], rays[..., 1]


def render(camera: str, R_cam_board: np.ndarray, t_cam_board: np.ndarray, rng) -> np.ndarray:
    """8-bit image (H, W) of the board at pose (R, t) in ``camera``'s frame (+ noise, σ = 2 gray levels).

    Each supersampled pixel's ray ``λ·(x, y, 1)`` meets the board plane at board coordinates
    ``(X, Y) = Rᵀ(λ·ray − t)``; the squares are coloured by the parity of ``⌊X/s⌋ + ⌊Y/s⌋``. Only the
    pixels in the bounding box of the board (with its white margin) are traced.
    """
    K, D = (K_LEFT, D_LEFT) if camera == "left" else (K_RIGHT, D_RIGHT)
    cols, rows = BOARD
    img = np.full((H * SS, W * SS), 110.0, np.float32)
    outline = np.array([[x, y, 0.0] for x in np.linspace(-2, cols + 1, 12) for y in np.linspace(-2, rows + 1, 12)])
    uv = cv2.projectPoints(outline * SQUARE, cv2.Rodrigues(R_cam_board)[0], t_cam_board, K, D)[0].reshape(-1, 2)
    (j0, i0), (j1, i1) = (np.floor((uv.min(0) - 2) * SS), np.ceil((uv.max(0) + 3) * SS))
    box = np.s_[int(np.clip(i0, 0, H * SS)):int(np.clip(i1, 0, H * SS)),
                int(np.clip(j0, 0, W * SS)):int(np.clip(j1, 0, W * SS))]
    x, y = (r[box] for r in _rays(camera))
    R = R_cam_board.astype(np.float32)
    t = t_cam_board.astype(np.float32)
    lam = (R[:, 2] @ t) / (R[0, 2] * x + R[1, 2] * y + R[2, 2])
    rt = R.T @ t
    X = (lam * (R[0, 0] * x + R[1, 0] * y + R[2, 0]) - rt[0]) / SQUARE
    Y = (lam * (R[0, 1] * x + R[1, 1] * y + R[2, 1]) - rt[1]) / SQUARE
    patch = img[box]
    margin = (X >= -2) & (X <= cols + 1) & (Y >= -2) & (Y <= rows + 1) & (lam > 0)
    patch[margin] = 220.0
    black = margin & (X >= -1) & (X <= cols) & (Y >= -1) & (Y <= rows)
    black &= (np.floor(X) + np.floor(Y)) % 2 == 0
    patch[black] = 30.0
    small = cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA)
    return np.clip(np.rint(small + rng.normal(0.0, 2.0, small.shape)), 0, 255).astype(np.uint8)


def board_pose(centre, rvec) -> tuple[np.ndarray, np.ndarray]:
    """Board pose ``(R, t)`` in the left camera with the board's centre at ``centre`` [m]."""
    R = cv2.Rodrigues(np.asarray(rvec, dtype=float))[0]
    mid = np.array([(BOARD[0] - 1) * SQUARE / 2, (BOARD[1] - 1) * SQUARE / 2, 0.0])
    return R, np.asarray(centre, dtype=float) - R @ mid


def right_pose(R, t):
    """The board pose in the right camera: ``p_right = R_TRUE p_left + T_TRUE``."""
    return R_TRUE @ R, R_TRUE @ t + T_TRUE


def corners_px(R, t, K, D) -> np.ndarray:
    obj = board_points(BOARD, SQUARE).astype(np.float64)
    return cv2.projectPoints(obj, cv2.Rodrigues(R)[0], t, K, D)[0].reshape(-1, 2)


def in_view(R, t, K, D, margin=15.0) -> bool:
    uv = corners_px(R, t, K, D)
    return bool(np.all((uv > margin) & (uv < np.array([W, H]) - margin)))


def render_pair(R, t, rng):
    """Raw left and right images of a board at pose ``(R, t)`` in the left camera."""
    return render("left", R, t, rng), render("right", *right_pose(R, t), rng)


def random_poses(n: int, rng) -> list:
    """``n`` board poses seen whole by both cameras, spread over the view, tilted up to ~30°."""
    poses = []
    while len(poses) < n:
        z = rng.uniform(0.6, 1.0)
        u, v = rng.uniform(60, W - 60), rng.uniform(60, H - 60)  # board centre in the left image
        centre = [(u - K_LEFT[0, 2]) / K_LEFT[0, 0] * z, (v - K_LEFT[1, 2]) / K_LEFT[1, 1] * z, z]
        R, t = board_pose(centre, [rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)])
        if in_view(R, t, K_LEFT, D_LEFT) and in_view(*right_pose(R, t), K_RIGHT, D_RIGHT):
            poses.append((R, t))
    return poses


def true_calibration() -> StereoCalibration:
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K_LEFT, D_LEFT, K_RIGHT, D_RIGHT, (W, H), R_TRUE, T_TRUE,
                                           flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
    return StereoCalibration((W, H), K_LEFT, D_LEFT, K_RIGHT, D_RIGHT, R_TRUE, T_TRUE, R1, R2, P1, P2)


@pytest.fixture(scope="module")
def views():
    """12 pairs with the board in view of both cameras, then one with it out of the right view (only
    partly in it) and one with it out of both."""
    rng = np.random.default_rng(7)
    pairs = [render_pair(R, t, rng) for R, t in random_poses(12, rng)]
    R, t = board_pose([-0.17, 0.0, 0.6], [0.0, 0.0, 0.0])  # whole in the left image, cut in the right one
    assert in_view(R, t, K_LEFT, D_LEFT) and not in_view(*right_pose(R, t), K_RIGHT, D_RIGHT, margin=0.0)
    pairs.append(render_pair(R, t, rng))
    pairs.append(render_pair(*board_pose([1.2, 0.0, 0.7], [0.0, 0.0, 0.0]), rng))
    return pairs


@pytest.fixture(scope="module")
def calibrated(views):
    return calibrate_stereo([v[0] for v in views], [v[1] for v in views], BOARD, SQUARE)


def write_pairs(folder, pairs):
    folder.mkdir(parents=True, exist_ok=True)
    for i, (left, right) in enumerate(pairs):
        cv2.imwrite(str(folder / f"left_{i:02d}.png"), left)
        cv2.imwrite(str(folder / f"right_{i:02d}.png"), right)


# ---------------------------------------------------------------- ROS camera_info
def test_camera_info_round_trip(tmp_path):
    cam = StereoCamera(width=752, height=480, f=431.25, cu=370.1, cv=241.7, baseline=0.1193)
    save_camera_info_pair(tmp_path, cam)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["left.yaml", "right.yaml"]
    calib = load_camera_info_pair(tmp_path)
    assert calib.is_rectified
    assert calib.image_size == (752, 480)
    np.testing.assert_allclose(calib.P2[0, 3], -431.25 * 0.1193)
    np.testing.assert_allclose(calib.T, [-0.1193, 0, 0])
    np.testing.assert_array_equal(calib.R, np.eye(3))
    back = calib.stereo_camera()
    for name in ("width", "height", "f", "cu", "cv", "baseline"):
        assert getattr(back, name) == pytest.approx(getattr(cam, name), rel=1e-12), name


def test_camera_info_round_trip_of_a_raw_calibration(tmp_path):
    calib = true_calibration()
    save_calibration(calib, tmp_path)
    back = load_calibration(tmp_path)
    assert not back.is_rectified
    for name in ("K1", "D1", "K2", "D2", "R1", "R2", "P1", "P2"):
        np.testing.assert_array_equal(getattr(back, name), getattr(calib, name), err_msg=name)
    # The extrinsics follow from the rectification: R = R2ᵀ R1, T = R2ᵀ (Tx/f, 0, 0).
    np.testing.assert_allclose(back.R, R_TRUE, atol=1e-12)
    np.testing.assert_allclose(back.T, T_TRUE, atol=1e-12)
    assert back.baseline == pytest.approx(BASELINE)


def ros_text(**override) -> tuple[str, str]:
    """camera_info YAML texts of a rectified pair, with fields of the right one overridden."""
    def doc(name, tx, extra):
        fields = {
            "image_width": "640", "image_height": "480", "camera_name": name,
            "camera_matrix": "{rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}",
            "distortion_model": "plumb_bob",
            "distortion_coefficients": "{rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}",
            "rectification_matrix": "{rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}",
            "projection_matrix": f"{{rows: 3, cols: 4, data: [500, 0, 320, {tx}, 0, 500, 240, 0, 0, 0, 1, 0]}}",
        }
        fields.update(extra)
        return "".join(f"{k}: {v}\n" for k, v in fields.items() if v is not None)
    return doc("left", 0, {}), doc("right", -60, override)


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ({"camera_matrix": None}, r"right\.yaml: missing field 'camera_matrix'"),
        ({"camera_matrix": "{rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0]}"},
         r"right\.yaml: camera_matrix\.data: expected a list of 9 numbers, got 8"),
        ({"camera_matrix": "{rows: 3, cols: 3, data: [-500, 0, 320, 0, 500, 240, 0, 0, 1]}"},
         r"right\.yaml: camera_matrix\[0,0\]: expected a positive focal length fx, got -500\.0"),
        ({"camera_matrix": "{rows: 3, cols: 3, data: [500, 0, x, 0, 500, 240, 0, 0, 1]}"},
         r"camera_matrix\.data\[2\]: expected a finite number, got 'x'"),
        ({"distortion_coefficients": "{rows: 1, cols: 4, data: [0, 0, 0, 0]}"},
         r"distortion_coefficients\.data: expected a list of 5 numbers, got 4"),
        ({"distortion_model": "equidistant"}, r"distortion_model: expected distortion_model plumb_bob or"),
        ({"rectification_matrix": "{rows: 3, cols: 3, data: [1, 0, 0, 0, 2, 0, 0, 0, 1]}"},
         r"rectification_matrix: expected a rotation matrix"),
        ({"projection_matrix": "{rows: 3, cols: 4, data: [500, 0, 320, 60, 0, 500, 240, 0, 0, 0, 1, 0]}"},
         r"right\.yaml: projection_matrix: expected Tx = P\[0,3\] = −f·baseline < 0"),
        ({"projection_matrix": "{rows: 3, cols: 4, data: [500, 0, 320, -60, 0, 500, 240, 0, 0, 0, 1]}"},
         r"projection_matrix\.data: expected a list of 12 numbers, got 11"),
        ({"image_width": "-640"}, r"right\.yaml: image_width: expected a positive integer"),
        ({"image_height": "240"}, r"image sizes differ: left\.yaml is 640×480, right\.yaml is 640×240"),
    ],
)
def test_broken_camera_info(tmp_path, override, match):
    left, right = ros_text(**override)
    (tmp_path / "left.yaml").write_text(left)
    (tmp_path / "right.yaml").write_text(right)
    with pytest.raises(ConfigError, match=match):
        load_calibration(tmp_path)


def test_valid_camera_info_text_loads(tmp_path):
    """The base text of the broken-file tests is valid: each failure above comes from its override."""
    left, right = ros_text()
    (tmp_path / "left.yaml").write_text(left)
    (tmp_path / "right.yaml").write_text(right)
    assert load_calibration(tmp_path).stereo_camera().baseline == pytest.approx(0.12)


def test_missing_camera_info_file(tmp_path):
    (tmp_path / "left.yaml").write_text(ros_text()[0])
    with pytest.raises(ConfigError, match=r"missing right\.yaml"):
        load_calibration(tmp_path)


# ---------------------------------------------------------------- OpenCV FileStorage
@pytest.mark.parametrize("suffix", [".yml", ".xml"])
def test_opencv_round_trip(tmp_path, suffix):
    calib = true_calibration()
    path = tmp_path / f"stereo{suffix}"
    save_opencv_calibration(calib, path)
    back = load_calibration(path)
    assert back.image_size == (W, H)
    for name in ("K1", "D1", "K2", "D2", "R", "T", "R1", "R2", "P1", "P2"):
        np.testing.assert_allclose(getattr(back, name), getattr(calib, name), rtol=1e-12, err_msg=name)


def write_fs(path, **entries):
    """A FileStorage file as a user's stereoCalibrate script writes it (T as a 3×1 matrix)."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in entries.items():
        fs.write(key, value)
    fs.release()


def test_opencv_file_without_rectification_is_rectified_on_load(tmp_path):
    path = tmp_path / "intrinsics_extrinsics.yaml"
    write_fs(path, imageSize=np.array([W, H]), M1=K_LEFT, D1=D_LEFT[None], M2=K_RIGHT, D2=D_RIGHT[:, None],
             R=R_TRUE, T=T_TRUE[:, None])
    back = load_opencv_calibration(path)
    truth = true_calibration()
    for name in ("R1", "R2", "P1", "P2"):
        np.testing.assert_allclose(getattr(back, name), getattr(truth, name), atol=1e-9, err_msg=name)


@pytest.mark.parametrize(
    ("entries", "match"),
    [
        ({"M2": None}, r"missing field 'M2'"),
        ({"T": np.array([[-0.12, 0.0]])}, r"T: expected a vector of 3 numbers, got '1×2'"),
        ({"M1": np.diag([-520.0, 518.0, 1.0])}, r"M1\[0,0\]: expected a positive focal length fx, got -520\.0"),
        ({"T": np.array([[0.12], [0.0], [0.0]])}, r"T: expected T\[0\] < 0 .*swapped"),
        ({"image_width": None, "image_height": None}, r"missing image_width and image_height"),
        ({"image_height": None}, r"missing field 'image_height'"),
        ({"image_width": -3}, r"image_width/image_height: expected a positive integer width and height"),
        ({"R1": np.eye(3)}, r"missing field 'P1' \(give all of R1, R2, P1, P2 or none of them\)"),
        ({"R": np.eye(2)}, r"calib\.yml: R: expected a 3×3 matrix, got '2×2'"),
        ({"D1": np.zeros((1, 3))}, r"D1: expected a vector of 4, 5, 8, 12 or 14 distortion coefficients"),
        ({"P1": np.eye(3, 4), "P2": np.eye(3, 4), "R1": np.eye(3), "R2": np.eye(3)},
         r"calib\.yml: P2: expected Tx = P\[0,3\] = −f·baseline < 0 .*got 0\.0"),
    ],
)
def test_broken_opencv_file(tmp_path, entries, match):
    base = {"image_width": W, "image_height": H, "M1": K_LEFT, "D1": D_LEFT[None], "M2": K_RIGHT,
            "D2": D_RIGHT[None], "R": R_TRUE, "T": T_TRUE[:, None]}
    base.update(entries)
    path = tmp_path / "calib.yml"
    write_fs(path, **{k: v for k, v in base.items() if v is not None})
    with pytest.raises(ConfigError, match=match):
        load_calibration(path)


def test_load_calibration_rejects_other_paths(tmp_path):
    with pytest.raises(ConfigError, match="no such calibration file or directory"):
        load_calibration(tmp_path / "nope")
    (tmp_path / "calib.txt").write_text("hello")
    with pytest.raises(ConfigError, match=r"expected a directory with left\.yaml and right\.yaml or an OpenCV"):
        load_calibration(tmp_path / "calib.txt")
    (tmp_path / "left.yaml").write_text(ros_text()[0])
    with pytest.raises(ConfigError, match=r"a ROS camera_info file: pass the directory"):
        load_calibration(tmp_path / "left.yaml")


# ---------------------------------------------------------------- mount
@pytest.mark.parametrize(
    "text",
    ["mount: {x: 0.1, y: -0.02, height: 1.05, pan_deg: 30}\n",
     "mount_x: 0.1\nmount_y: -0.02\nmount_height: 1.05\npan_deg: 30\n"],
)
def test_load_mount_nested_and_flat(tmp_path, text):
    (tmp_path / "mount.yaml").write_text(text)
    mount = load_mount(tmp_path / "mount.yaml")
    assert mount == Mount(0.1, -0.02, 1.05, float(np.deg2rad(30.0)))
    cam = StereoCalibration.from_stereo_camera(StereoCamera()).stereo_camera(mount)
    assert (cam.mount_x, cam.mount_y, cam.mount_height, cam.pan) == (0.1, -0.02, 1.05, pytest.approx(np.pi / 6))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("mount: {x: 0.1}\n", r"missing field mount\.height"),
        ("mount: {x: 0.1, height: -1}\n", r"mount\.height: expected a positive height \[m\], got -1\.0"),
        ("mount: {x: abc, height: 1}\n", r"mount\.x: expected a finite number, got 'abc'"),
        ("mount: {height: 1, pan: 0.3}\n", r"unknown field mount\.pan \(known: x, y, height, pan_deg\)"),
        ("mount_height: 1\nheight: 2\n", r"unknown field height \(known: mount_x, mount_y, mount_height, pan_deg\)"),
        ("mount: [1, 2]\n", r"mount\.yaml: mount\.: expected a mapping with x, y, height, pan_deg, got \[1, 2\]"),
    ],
)
def test_broken_mount(tmp_path, text, match):
    (tmp_path / "mount.yaml").write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_mount(tmp_path / "mount.yaml")


# ---------------------------------------------------------------- chessboard calibration
def test_calibrate_stereo_recovers_the_camera(calibrated):
    calib, report = calibrated
    assert report.used == tuple(range(12))
    assert calib.K1[0, 0] == pytest.approx(K_LEFT[0, 0], rel=0.01)
    assert calib.K1[1, 1] == pytest.approx(K_LEFT[1, 1], rel=0.01)
    assert calib.K2[0, 0] == pytest.approx(K_RIGHT[0, 0], rel=0.01)
    assert calib.baseline == pytest.approx(BASELINE, rel=0.02)
    np.testing.assert_allclose(calib.T, T_TRUE, atol=0.003)
    assert np.degrees(np.linalg.norm(cv2.Rodrigues(calib.R @ R_TRUE.T)[0])) < 0.5
    cam = calib.stereo_camera()
    assert cam.f == pytest.approx(true_calibration().P1[0, 0], rel=0.01)
    assert report.rms < 0.3
    assert report.epipolar_error < 0.5


def test_calibrate_stereo_skips_pairs_without_the_board(calibrated):
    _, report = calibrated
    assert report.n_pairs == 14
    assert [s.index for s in report.skipped] == [12, 13]
    assert report.warnings == (
        "pair 12 (left image 12, right image 12) skipped: 9x6 board not found in the right image",
        "pair 13 (left image 13, right image 13) skipped: 9x6 board not found in either image",
    )


def test_calibrate_stereo_too_few_pairs(views):
    few = views[:3] + views[13:]
    with pytest.raises(CalibrationError, match=r"found in both images of 3 of 4 pairs; at least 5 are needed"):
        calibrate_stereo([v[0] for v in few], [v[1] for v in few], BOARD, SQUARE)


def test_calibrate_stereo_input_errors(views):
    left, right = [v[0] for v in views[:6]], [v[1] for v in views[:6]]
    with pytest.raises(InputError, match="as many left as right images, got 6 and 5"):
        calibrate_stereo(left, right[:5], BOARD, SQUARE)
    with pytest.raises(InputError, match="square: expected a positive square size"):
        calibrate_stereo(left, right, BOARD, -0.03)
    with pytest.raises(InputError, match=r"board: expected \(cols, rows\), at least 2×2 inner corners, got \(9, 1\)"):
        calibrate_stereo(left, right, (9, 1), SQUARE)
    with pytest.raises(ImageError, match=r"right image 3: expected 640×480 px like the first image, got 320×240"):
        calibrate_stereo(left, right[:3] + [cv2.resize(right[3], (320, 240))] + right[4:], BOARD, SQUARE)


def test_swapped_cameras_are_reported(views):
    with pytest.raises(CalibrationError, match="swapped"):
        calibrate_stereo([v[1] for v in views[:8]], [v[0] for v in views[:8]], BOARD, SQUARE)


# ---------------------------------------------------------------- rectification
def rectified_row_error(left, right) -> float:
    c_l, c_r = find_board(left, BOARD), find_board(right, BOARD)
    assert c_l is not None and c_r is not None
    return float(np.mean(np.abs(c_l[:, 1] - c_r[:, 1])))


def test_rectification_makes_corresponding_rows_equal(tmp_path):
    rng = np.random.default_rng(11)
    R, t = board_pose([0.02, 0.01, 0.8], [0.3, -0.2, 0.1])
    left, right = render_pair(R, t, rng)
    write_pairs(tmp_path, [(left, right)])
    assert rectified_row_error(left, right) > 2.0  # raw: rows differ
    calib = true_calibration()
    rect = load_stereo_pair(tmp_path / "left_00.png", tmp_path / "right_00.png", calib)
    assert rectified_row_error(*rect) < 0.15
    c_l, c_r = find_board(rect[0], BOARD), find_board(rect[1], BOARD)
    # Disparity of the rectified corners matches depth: d = f b / Z (board nearly fronto-parallel).
    Z = (R @ board_points(BOARD, SQUARE).T.astype(float) + t[:, None])[2]
    d_true = calib.P1[0, 0] * BASELINE / Z
    assert np.mean(np.abs((c_l[:, 0] - c_r[:, 0]) - d_true)) < 0.5


def test_rectify_maps_are_cached_and_checked():
    calib = true_calibration()
    assert calib.rectify_maps() is calib.rectify_maps()
    with pytest.raises(ImageError, match=r"left image is 320×240 px but the calibration is for 640×480 px"):
        calib.rectify(np.zeros((240, 320), np.uint8), np.zeros((480, 640), np.uint8))


def test_stereo_calibration_validates_shapes():
    calib = true_calibration()
    with pytest.raises(InputError, match=r"calibration\.P2: expected an array of shape \(3, 4\)"):
        StereoCalibration((W, H), K_LEFT, D_LEFT, K_RIGHT, D_RIGHT, R_TRUE, T_TRUE, calib.R1, calib.R2,
                          calib.P1, calib.P2[:, :3])
    assert calib.K1.flags.writeable is False


# ---------------------------------------------------------------- the command
def test_calibrate_command(tmp_path, views, capsys):
    write_pairs(tmp_path / "img", views[:12] + views[13:])  # the board out of view in the last pair
    out = tmp_path / "calib"
    code = main(["calibrate", "--left", str(tmp_path / "img" / "left_*.png"),
                 "--right", str(tmp_path / "img" / "right_*.png"), "--board", "9x6", "--square", "0.035",
                 "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == ["left.yaml", "right.yaml"]
    assert load_calibration(out).baseline == pytest.approx(BASELINE, rel=0.02)
    assert "12 of 13 pairs" in text
    assert text.count("warning") == 1
    assert "right_12.png) skipped: 9x6 board not found in either image" in text
    assert "RMS reprojection error" in text and "epipolar error" in text


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--board", "9-6"], "--board: expected COLSxROWS inner corners, e.g. 9x6, got '9-6'"),
        (["--board", "1x6"], "--board: expected COLSxROWS inner corners, e.g. 9x6, got '1x6'"),
        (["--square", "0"], "--square: expected a positive square size [m], got 0.0"),
        (["--right", "nothing_*.png"], "--right: no file matches"),
    ],
)
def test_calibrate_command_errors(tmp_path, views, capsys, args, match):
    write_pairs(tmp_path / "img", views[:3])
    out = tmp_path / "calib"
    base = {"--left": str(tmp_path / "img" / "left_*.png"), "--right": str(tmp_path / "img" / "right_*.png"),
            "--board": "9x6", "--square": "0.035", "--out": str(out)}
    base.update(dict(zip(args[::2], args[1::2], strict=True)))
    code = main(["calibrate", *[x for kv in base.items() for x in kv]])
    err = capsys.readouterr().err
    assert code == 1
    assert err.count("\n") == 1 and match in err
    assert not out.exists()


def test_calibrate_command_writes_nothing_on_failure(tmp_path, views, capsys):
    write_pairs(tmp_path / "img", views[:2] + views[13:])
    out = tmp_path / "calib"
    code = main(["calibrate", "--left", str(tmp_path / "img" / "left_*.png"),
                 "--right", str(tmp_path / "img" / "right_*.png"), "--board", "9x6", "--square", "0.035",
                 "--out", str(out)])
    assert code == 1
    assert "at least 5 are needed" in capsys.readouterr().err
    assert not out.exists()
