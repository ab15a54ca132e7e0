"""Planar trajectories in the formats evaluation tools read: TUM (read and write) and KITTI (write).

TUM RGB-D benchmark format (what ``evo_ape tum`` / ``evo_traj tum`` read): one pose per line, eight numbers
separated by single spaces, lines starting with ``#`` are comments::

    # timestamp tx ty tz qx qy qz qw
    0.000000000 0.000000 0.000000 0 0 0 0.707106781 0.707106781

``timestamp`` in seconds; ``tx ty tz`` the position of the robot in the world [m]; ``qx qy qz qw`` the unit
quaternion of its orientation (Hamilton, scalar last). A planar pose ``(x, y, theta)`` is written as
``x y 0`` and the rotation ``theta`` about ``z``: ``0 0 sin(theta/2) cos(theta/2)``. Reading takes the
yaw of any unit quaternion, ``atan2(2 (qw qz + qx qy), 1 - 2 (qy² + qz²))``, and drops ``tz``, so a 3D
ground truth (motion capture) reads as its projection on the floor.

KITTI odometry format (write only): one pose per line, the 3×4 matrix ``[R | t]`` row-major (12 numbers),
no stamps; as KITTI's odometry ground truth, the poses of the LEFT CAMERA relative to its first pose, in
the camera frame (``x`` right, ``y`` down, ``z`` forward): see :func:`write_kitti`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError, expected
from ..geometry import wrap_angle

TUM_HEADER = "# timestamp tx ty tz qx qy qz qw"
"""The comment line :func:`write_tum` puts first (evo and the TUM tools skip it)."""

QUATERNION_TOLERANCE = 1e-3
"""Largest ``| |q| - 1 |`` :func:`read_tum` accepts (the TUM benchmark's own files keep 4 decimals)."""


def _check_poses(stamps, poses) -> tuple[np.ndarray, np.ndarray]:
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise InputError(expected("poses of shape (n, 3): x [m], y [m], theta [rad]", poses.shape, where="poses"))
    if not np.all(np.isfinite(poses)):
        raise InputError("poses: expected finite numbers, got NaN or infinity")
    if stamps is None:
        return None, poses
    stamps = np.asarray(stamps, dtype=float)
    if stamps.shape != (len(poses),):
        raise InputError(expected(f"stamps of shape ({len(poses)},), one per pose", stamps.shape, where="stamps"))
    if not np.all(np.isfinite(stamps)):
        raise InputError("stamps: expected finite numbers, got NaN or infinity")
    return stamps, poses


def _write_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` to a temporary sibling of ``path`` and rename it, so a failure leaves no half file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def write_tum(path: str | Path, stamps, poses) -> Path:
    """Write planar poses (n, 3) ``(x [m], y [m], theta [rad])`` at ``stamps`` (n,) [s] as a TUM file.

    Lines ``"stamp x y 0 0 0 sin(θ/2) cos(θ/2)"`` after a :data:`TUM_HEADER` comment; stamps keep 9 decimals
    (ns), positions 9 (nm), quaternion components 12 (a loop's poses read back to 1e-9). Written under a
    temporary name and renamed.
    """
    stamps, poses = _check_poses(stamps, poses)
    half = 0.5 * poses[:, 2]
    lines = [
        f"{t:.9f} {x:.9f} {y:.9f} 0 0 0 {qz:.12f} {qw:.12f}"
        for t, x, y, qz, qw in zip(stamps, poses[:, 0], poses[:, 1], np.sin(half), np.cos(half), strict=True)
    ]
    return _write_atomic(path, "\n".join([TUM_HEADER, *lines]) + "\n")


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory file: ``(stamps (n,) [s], poses (n, 3) (x [m], y [m], theta [rad]))``.

    Lines are kept in file order. Empty lines and ``#`` comments are skipped. Errors are
    :class:`InputError` naming the file and line: not 8 numbers, a non-numeric or non-finite value, a
    quaternion whose norm is off 1 by more than :data:`QUATERNION_TOLERANCE`, no pose at all.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise InputError(f"{path}: no such trajectory file") from None
    except (IsADirectoryError, PermissionError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read trajectory file: {exc.__class__.__name__}") from None
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{path} line {number}"
        fields = line.split()
        if len(fields) != 8:
            raise InputError(expected("8 numbers: timestamp tx ty tz qx qy qz qw", line, where=where))
        try:
            values = [float(v) for v in fields]
        except ValueError:
            raise InputError(expected("8 numbers: timestamp tx ty tz qx qy qz qw", line, where=where)) from None
        if not all(np.isfinite(values)):
            raise InputError(expected("finite numbers", line, where=where))
        norm = float(np.linalg.norm(values[4:]))
        if abs(norm - 1.0) > QUATERNION_TOLERANCE:
            raise InputError(expected("a unit quaternion qx qy qz qw", f"norm {norm:.6g}", where=where))
        rows.append(values)
    if not rows:
        raise InputError(f"{path}: no poses (expected lines 'timestamp tx ty tz qx qy qz qw')")
    m = np.array(rows)
    qx, qy, qz, qw = (m[:, 4:] / np.linalg.norm(m[:, 4:], axis=1, keepdims=True)).T
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy**2 + qz**2))
    return m[:, 0], np.column_stack([m[:, 1], m[:, 2], wrap_angle(yaw)])


def kitti_camera_poses(poses, pans=None, *, mount=(0.0, 0.0)) -> np.ndarray:
    """Poses (n, 3, 4) ``[R | t]`` of the left camera relative to its first pose, as KITTI gives them.

    ``poses`` (n, 3) are planar robot poses ``(x [m], y [m], theta [rad])`` in the map (z up; robot ``x``
    forward, ``y`` left); ``pans`` (n,) [rad] the head's pan per frame about the vertical, positive to the
    left (default 0); ``mount`` ``(x, y)`` [m] the left optical centre (the pan axis) in the robot frame.
    The camera optical frame has ``z`` forward, ``x`` right, ``y`` down: with the camera heading
    ``psi = theta + pan`` its axes in the map are ``x_c = (sin psi, −cos psi, 0)``, ``y_c = (0, 0, −1)``,
    ``z_c = (cos psi, sin psi, 0)``, its centre ``(x, y) + R(theta) mount`` (the height cancels). Frame ``k``
    gives ``T_0⁻¹ T_k``, the first is the identity.
    """
    _, poses = _check_poses(None, poses)
    n = len(poses)
    pans = np.zeros(n) if pans is None else np.asarray(pans, dtype=float)
    if pans.shape != (n,):
        raise InputError(expected(f"pans of shape ({n},), one per pose", pans.shape, where="pans"))
    if not np.all(np.isfinite(pans)):
        raise InputError("pans: expected finite numbers, got NaN or infinity")
    mount = np.asarray(mount, dtype=float)
    if mount.shape != (2,) or not np.all(np.isfinite(mount)):
        raise InputError(expected("mount (x, y): two finite numbers [m]", mount.tolist(), where="mount"))
    th = poses[:, 2]
    psi = th + pans
    c, s = np.cos(psi), np.sin(psi)
    zero, one = np.zeros(n), np.ones(n)
    # columns: the camera's x (right), y (down), z (forward) in the map
    R = np.stack([np.stack([s, zero, c], axis=1),
                  np.stack([-c, zero, s], axis=1),
                  np.stack([zero, -one, zero], axis=1)], axis=1)  # (n, 3, 3), rows = map x, y, z
    centre = np.column_stack([poses[:, 0] + np.cos(th) * mount[0] - np.sin(th) * mount[1],
                              poses[:, 1] + np.sin(th) * mount[0] + np.cos(th) * mount[1], zero])
    R0 = R[0]
    rel_R = np.einsum("ji,njk->nik", R0, R)  # R0ᵀ R_k
    rel_t = (centre - centre[0]) @ R0  # R0ᵀ (c_k − c_0)
    return np.concatenate([rel_R, rel_t[:, :, None]], axis=2)


def write_kitti(path: str | Path, poses, pans=None, *, mount=(0.0, 0.0)) -> Path:
    """Write the left camera's trajectory as KITTI odometry ground truth is given (``poses/XX.txt``).

    One line per frame: the 3×4 matrix ``[R | t]`` row-major, 12 numbers, of the left camera's pose at that
    frame relative to its pose at the first frame (the first line is the identity), in the camera
    optical frame: ``x`` right, ``y`` down, ``z`` forward (a robot driving straight ahead 1 m gives
    ``t = (0, 0, 1)``; a turn to the left is a rotation about the camera's ``−y``). See
    :func:`kitti_camera_poses` for the frames.

    Parameters
    ----------
    poses : (n, 3) planar robot poses ``(x [m], y [m], theta [rad])`` in the map.
    pans : optional (n,) head pan per frame [rad], positive to the left (default 0: the camera looks
        along the robot's heading).
    mount : ``(x, y)`` [m] of the left optical centre (the pan axis) in the robot frame, as in the
        stereo head's ``mount.yaml`` (default ``(0, 0)``); its height cancels out.

    Written under a temporary name and renamed. Raises :class:`InputError` for malformed input.
    """
    T = kitti_camera_poses(poses, pans, mount=mount).reshape(-1, 12)
    return _write_atomic(path, "".join(" ".join(f"{v:.9e}" for v in row) + "\n" for row in T))
