"""Camera images to the 8-bit grayscale the stereo front end works on.

Any image layout is accepted: gray, BGR, BGRA (alpha dropped), 8- or 16-bit, or float in [0, 1]. 16-bit
images are scaled by their full range (``v / 257``), the same for both images of a pair, so a pair stays
photometrically consistent.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import ImageError


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
