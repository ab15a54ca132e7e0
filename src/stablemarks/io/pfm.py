"""Middlebury PFM images: float32 disparity maps, as the Middlebury stereo benchmark stores them.

Grayscale PFM: a header ``Pf``, ``width height``, and a scale whose sign gives the byte order (negative:
little-endian), then float32 rows stored bottom to top. Invalid pixels are ``+inf`` (Middlebury's
convention); NaN is written as ``+inf``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ImageError, InputError, expected

MAX_PFM_SIDE = 8192
"""Largest width and height of a PFM image read [px] (the camera images' limit)."""


def write_pfm(path: str | Path, array: np.ndarray) -> Path:
    """Write a 2-D array as a little-endian grayscale PFM (NaN → +inf)."""
    a = np.asarray(array, dtype=np.float32)
    if a.ndim != 2:
        raise InputError(expected("a 2-D array", f"shape {a.shape}", where=str(path)))
    a = np.where(np.isnan(a), np.float32(np.inf), a)
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("wb") as fh:
        fh.write(f"Pf\n{a.shape[1]} {a.shape[0]}\n-1.0\n".encode("ascii"))
        fh.write(np.ascontiguousarray(a[::-1]).astype("<f4").tobytes())
    tmp.replace(path)
    return path


def read_pfm(path: str | Path) -> np.ndarray:
    """Read a grayscale PFM into a float32 (H, W) array (row 0 at the top; inf kept as stored)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ImageError(f"{path}: cannot read: {exc.strerror or exc}") from None
    parts, pos = [], 0
    while len(parts) < 4 and pos < len(data):
        end = data.find(b"\n", pos)
        if end < 0:
            break
        parts += data[pos:end].split()
        pos = end + 1
    if len(parts) < 4 or parts[0] not in (b"Pf", b"PF"):
        raise ImageError(f"{path}: not a PFM file (expected a 'Pf' header with width, height and scale)")
    if parts[0] == b"PF":
        raise ImageError(f"{path}: colour PFM ('PF'); expected a grayscale disparity map ('Pf')")
    try:
        w, h, scale = int(parts[1]), int(parts[2]), float(parts[3])
    except (ValueError, OverflowError):
        raise ImageError(f"{path}: PFM header: expected width, height and scale numbers") from None
    if not (0 < w <= MAX_PFM_SIDE and 0 < h <= MAX_PFM_SIDE) or scale == 0 or scale != scale:
        raise ImageError(f"{path}: PFM header: expected a size of 1 to {MAX_PFM_SIDE} px each way and a non-zero "
                         f"scale, got {w}x{h}, {scale}")
    n = w * h * 4
    if len(data) - pos < n:
        raise ImageError(f"{path}: PFM data: expected {n} bytes for {w}x{h} floats, got {len(data) - pos}")
    dtype = "<f4" if scale < 0 else ">f4"
    return np.frombuffer(data[pos : pos + n], dtype=dtype).reshape(h, w)[::-1].astype(np.float32)
