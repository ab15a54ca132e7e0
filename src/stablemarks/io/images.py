"""Reading camera images as 8-bit grayscale, and stereo pairs ready for the front end.

Any image OpenCV reads is accepted: gray, BGR, BGRA (alpha dropped), 8- or 16-bit, or float in [0, 1].
16-bit images are scaled by their full range (``v / 257``), the same for both images of a pair, so a
pair stays photometrically consistent.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..errors import ImageError
from ..vision.gray import to_gray8

__all__ = ["load_image_gray", "load_stereo_pair", "to_gray8"]


def load_image_gray(path: str | Path) -> np.ndarray:
    """Read an image file as 8-bit grayscale (H, W) ``uint8``; :class:`ImageError` naming the file if it fails."""
    path = Path(path)
    if not path.is_file():
        raise ImageError(f"{path}: no such image file")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageError(f"{path}: cannot read image (not an image format OpenCV reads)")
    return to_gray8(img, str(path))


def load_stereo_pair(left_path: str | Path, right_path: str | Path, calibration=None) -> tuple[np.ndarray, np.ndarray]:
    """Read a stereo pair as 8-bit grayscale images (H, W), rectified when the calibration asks for it.

    ``calibration`` is a :class:`~stablemarks.io.calibration.StereoCalibration` (or None).

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
