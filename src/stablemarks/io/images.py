"""Reading camera images as 8-bit grayscale, and stereo pairs ready for the front end.

Any image OpenCV reads is accepted: gray, BGR, BGRA (alpha dropped), 8- or 16-bit, or float in [0, 1].
16-bit images are scaled by their full range (``v / 257``), the same for both images of a pair, so a
pair stays photometrically consistent.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..errors import ImageError

if TYPE_CHECKING:  # pragma: no cover
    from .calibration import StereoCalibration


def to_gray8(image: np.ndarray, name: str = "image") -> np.ndarray:
    """Convert an image (H, W[, C]) to 8-bit grayscale (H, W) ``uint8``; ``name`` is used in messages."""
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim == 3 and img.shape[2] == 2:  # gray + alpha
        img = img[..., 0]
    if img.ndim == 3:
        codes = {3: cv2.COLOR_BGR2GRAY, 4: cv2.COLOR_BGRA2GRAY}
        if img.shape[2] not in codes:
            raise ImageError(f"{name}: expected 1, 2, 3 or 4 channels, got {img.shape[2]}")
        img = cv2.cvtColor(img, codes[img.shape[2]])
    if img.ndim != 2:
        raise ImageError(f"{name}: expected a 2D image (H, W[, C]), got shape {img.shape}")
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    if img.dtype == np.uint16:
        return ((img.astype(np.uint32) + 128) // 257).astype(np.uint8)
    if img.dtype in (np.float32, np.float64):
        return np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)
    raise ImageError(f"{name}: expected 8-bit, 16-bit or float pixels, got {img.dtype}")


def load_image_gray(path: str | Path) -> np.ndarray:
    """Read an image file as 8-bit grayscale (H, W) ``uint8``; :class:`ImageError` naming the file if it fails."""
    path = Path(path)
    if not path.is_file():
        raise ImageError(f"{path}: no such image file")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageError(f"{path}: cannot read image (not an image format OpenCV reads)")
    return to_gray8(img, str(path))


def load_stereo_pair(
    left_path: str | Path, right_path: str | Path, calibration: StereoCalibration | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Read a stereo pair as 8-bit grayscale images (H, W), rectified when the calibration asks for it.

    With a ``calibration`` whose images are not already rectified (distortion, rectifying rotations or
    ``K ≠ P``), the raw images are rectified with it; otherwise they are returned as read.
    Raises :class:`ImageError` for an unreadable file, images of different sizes, or images whose size
    differs from the calibration's.
    """
    left = load_image_gray(left_path)
    right = load_image_gray(right_path)
    if left.shape != right.shape:
        raise ImageError(
            f"stereo pair sizes differ: {left_path} is {left.shape[1]}×{left.shape[0]} px, "
            f"{right_path} is {right.shape[1]}×{right.shape[0]} px"
        )
    if calibration is None:
        return left, right
    w, h = calibration.image_size
    if left.shape != (h, w):
        cal = f"calibration {calibration.source}" if calibration.source else "calibration"
        raise ImageError(
            f"{left_path}, {right_path}: images are {left.shape[1]}×{left.shape[0]} px but the {cal} "
            f"is for {w}×{h} px"
        )
    if calibration.is_rectified:
        return left, right
    return calibration.rectify(left, right)
