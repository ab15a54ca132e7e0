"""Reading camera images as 8-bit grayscale, and stereo pairs ready for the front end.

Any image OpenCV reads is accepted: gray, BGR, BGRA (alpha dropped), 8- or 16-bit, or float in [0, 1].
16-bit images are scaled by their full range (``v / 257``), the same for both images of a pair, so a
pair stays photometrically consistent.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from ..errors import ImageError
from ..vision.gray import to_gray8

__all__ = ["MAX_IMAGE_SIDE", "check_image_size", "imdecode_quietly", "imread_quietly", "load_image_gray",
           "load_stereo_pair", "native_stderr", "to_gray8"]

MAX_IMAGE_SIDE = 8192
"""Largest width and height of a camera image [px] (and of a calibration's image size)."""

_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def native_stderr() -> Iterator[list[str]]:
    """Capture what native libraries write to the process's stderr (file descriptor 2) meanwhile: OpenCV's
    ``[ WARN:0@...]`` lines and libpng's ``libpng error: ...`` come before our own one-line error otherwise.
    Yields a list that holds the captured lines afterwards (for the error message)."""
    lines: list[str] = []
    with _STDERR_LOCK, tempfile.TemporaryFile() as sink:
        try:
            sys.stderr.flush()
        except (AttributeError, OSError, ValueError):
            pass
        saved = os.dup(2)
        try:
            os.dup2(sink.fileno(), 2)
            try:
                yield lines
            finally:
                os.dup2(saved, 2)
        finally:
            os.close(saved)
        sink.seek(0)
        text = sink.read(64_000).decode("utf-8", "replace")
        lines.extend(line.strip() for line in text.splitlines() if line.strip())


def _reason(lines: list[str]) -> str:
    """The gist of what OpenCV or libpng said, for our message ("" if nothing useful)."""
    for line in reversed(lines):
        m = re.search(r"libpng error: (.*)", line) or re.search(r"\(-?\d+:[^)]*\) (.*?)(?: in function .*)?$", line) \
            or re.search(r"\] global \S+ \S+ (.*)$", line)
        if m and m.group(1).strip():
            return m.group(1).strip()[:120]
    return ""


def imread_quietly(path: str | Path, flags: int = cv2.IMREAD_UNCHANGED) -> tuple[np.ndarray | None, str]:
    """``cv2.imread`` without the native libraries' own lines on stderr: ``(image or None, their reason)``."""
    with native_stderr() as said:
        img = cv2.imread(str(path), flags)
    return img, _reason(said)


def imdecode_quietly(buf: np.ndarray, flags: int = cv2.IMREAD_UNCHANGED) -> tuple[np.ndarray | None, str]:
    """``cv2.imdecode`` without the native libraries' own lines on stderr: ``(image or None, their reason)``."""
    with native_stderr() as said:
        try:
            img = cv2.imdecode(buf, flags)
        except cv2.error as exc:
            img = None
            said.append(str(exc))
    return img, _reason(said)


def check_image_size(img: np.ndarray, where: str) -> np.ndarray:
    """``img`` unless it is larger than :data:`MAX_IMAGE_SIDE` either way (:class:`ImageError` naming ``where``)."""
    h, w = img.shape[:2]
    if h > MAX_IMAGE_SIDE or w > MAX_IMAGE_SIDE:
        raise ImageError(f"{where}: the image is {w}×{h} px; at most {MAX_IMAGE_SIDE}×{MAX_IMAGE_SIDE} px are read")
    return img


def load_image_gray(path: str | Path) -> np.ndarray:
    """Read an image file as 8-bit grayscale (H, W) ``uint8``; :class:`ImageError` naming the file if it fails
    (what OpenCV and libpng would print on stderr goes into the message instead)."""
    path = Path(path)
    if not path.is_file():
        raise ImageError(f"{path}: no such image file")
    img, reason = imread_quietly(path)
    if img is None:
        why = f": {reason}" if reason else ""
        raise ImageError(f"{path}: cannot read image (truncated, damaged or not an image format OpenCV reads{why})")
    return to_gray8(check_image_size(img, str(path)), str(path))


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
