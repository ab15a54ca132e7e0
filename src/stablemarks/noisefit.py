"""Noise models calibrated from data: ``stablemarks calibrate-noise`` (issue: honest uncertainty).

From recordings with ground truth (sequence folders with ``groundtruth.tum``, or the simulator's runs) this
estimates, frame by frame at the *true* pose:

``noise.sigma_img``
    the column noise of a matched line in one image [px]. Every kept segment pair that lies on a fitted
    reference plane is triangulated from the true pose; its offset from the *mapped* wall along the wall's
    normal, divided by its σ for ``σ_img = 1 px`` (first order, :meth:`StereoCamera.triangulate`), is a
    sample of ``N(0, σ_img²)``. The estimate is their RMS after gross outliers (lines of clutter standing
    in front of a wall) are clipped (:func:`clipped_rms`). This per-frame line noise is a lower bound for the
    filter: ``calibrate-noise`` then writes the smallest multiple of it with which the filter is consistent.
``noise.boundary_px``, ``noise.free_boundary_px``
    the σ of a boundary's column [px], when a segment marks the edge (snapped, Sec 3.2) and when the planar
    region's border itself does: each boundary found is compared with the column where the true pose projects
    the map's free edge, in both images; the border's σ is what, added to each boundary's own modelled row
    spread and line noise, gives its errors unit mean square (:func:`missing_sigma`).
``odometry``
    the random-walk noise of wheel odometry: each increment's error against the true increment, split into
    Thrun's ``rot1, trans, rot2`` (:func:`stablemarks.motion.decompose`), regressed (non-negative least
    squares) on the motion: ``e_trans² ≈ trans_per_m² |trans| + trans_per_rad² (|rot1| + |rot2|)`` and
    ``e_rot1² + e_rot2² ≈ rot_per_rad² (|rot1| + |rot2|) + rot_per_m² |trans|`` (:class:`OdometryNoise`):
    the per-metre terms from the steps that drive straight, the per-radian terms from turns on the spot (a
    recording without turns leaves them as they are).

:func:`consistency` then runs the filter on the same recordings and reports pose NEES (with the fraction of
frames inside its 95 % bounds), NIS and, where the landmarks' truth is known (simulated runs), landmark NEES.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from .config import Config
from .errors import InputError
from .geometry import SE2
from .landmarks import search_boundary
from .metrics import along_wall_nees, chi2_bounds, fraction_inside, pose_nees
from .motion import decompose
from .pipeline import run_front_end
from .planes import fit_plane, plane_members, predict_planes

SEARCH_POSE_COV = np.diag([0.02, 0.02, np.radians(0.5)]) ** 2
"""Pose covariance with which the planes are predicted from the true pose: the windows (and so the boundary
search) as wide as the filter's own in a typical frame, so that a boundary can be found where the images put
it, not clipped to the true edge by a window a few pixels wide."""


@dataclass
class NoiseSamples:
    """What :func:`collect` measured: normalised line offsets, boundary column errors and odometry errors."""

    line_z: list[float] = field(default_factory=list)
    """Offsets of on-plane lines from the mapped wall divided by their σ at ``σ_img = 1`` px."""
    boundary_err: dict = field(default_factory=lambda: {True: [], False: []})
    """Column errors of found boundaries [px], both images, by whether they were snapped to a segment."""
    boundary_model2: dict = field(default_factory=lambda: {True: [], False: []})
    """Their modelled variance without the border term (row spread and line noise) [px²]."""
    odometry: list[tuple[float, float, float, float, float, float]] = field(default_factory=list)
    """Per increment ``(|rot1|, |trans|, |rot2|, e_rot1, e_trans, e_rot2)`` [rad, m]."""
    frames: int = 0

    def extend(self, other: NoiseSamples) -> None:
        self.line_z += other.line_z
        for k in (True, False):
            self.boundary_err[k] += other.boundary_err[k]
            self.boundary_model2[k] += other.boundary_model2[k]
        self.odometry += other.odometry
        self.frames += other.frames


def collect(source, config: Config = Config(), every: int = 1,
            progress: Callable[[int, int], None] | None = None) -> NoiseSamples:
    """Measure the noise samples of a source whose frames carry their true pose (every ``every``-th frame for
    the images; every increment for the odometry). Raises :class:`InputError` without ground truth."""
    out = NoiseSamples()
    camera0 = config.camera(source.camera)
    unit = replace(camera0, sigma_img=1.0)
    prev = None
    n = len(source)
    for k, frame in enumerate(source):
        if frame.true_pose is None:
            raise InputError(f"{source.name}: frame {k} has no true pose; calibrate-noise needs ground truth "
                             "(groundtruth.tum in the sequence folder, or a simulated scenario)")
        T = np.asarray(frame.true_pose, dtype=float)
        if prev is not None:
            out.odometry.append(_odometry_sample(prev, (T, frame.odometry)))
        prev = (T, frame.odometry)
        if k % every == 0:
            _image_samples(out, frame, T, camera0.with_pan(frame.pan), unit.with_pan(frame.pan), source.world_map,
                           config)
            out.frames += 1
        if progress is not None:
            progress(k + 1, n)
    return out


def _odometry_sample(prev, cur) -> tuple[float, ...]:
    (T0, o0), (T1, o1) = prev, cur
    true = SE2.from_array(T0).between(SE2.from_array(T1))
    odo = SE2.from_array(np.asarray(o0, float)).between(SE2.from_array(np.asarray(o1, float)))
    r1, tr, r2 = decompose(true)
    q1, qt, q2 = decompose(odo)
    wrap = lambda a: (a + math.pi) % (2 * math.pi) - math.pi  # noqa: E731
    return abs(r1), abs(tr), abs(r2), wrap(q1 - r1), qt - tr, wrap(q2 - r2)


def _image_samples(out: NoiseSamples, frame, T, camera, unit, world_map, config: Config) -> None:
    front = run_front_end(frame.left, frame.right, config)
    pairs = front.kept_pairs
    for pred in predict_planes(camera, T, SEARCH_POSE_COV, world_map, config.planes):
        fit = fit_plane(camera, T, front.disparity.left, pred, config.planes)
        if not fit:
            continue
        plane = pred.plane
        members = np.flatnonzero(plane_members(fit, pairs, front.left_segments, config.planes))
        if len(members):
            P, cov = unit.triangulate(pairs.u_left[members], pairs.u_right[members], T)
            ok = np.all(np.isfinite(P), axis=-1)
            n = plane.normal
            sig = np.sqrt(np.einsum("i,kij,j->k", n, cov[ok], n))
            out.line_z += list(plane.offset(P[ok]) / sig)
        members_u = np.stack([pairs.u_left[members], pairs.u_right[members]], axis=-1) if len(members) \
            else np.zeros((0, 2))
        for edge in plane.free_edges:
            e = pred.edges[edge]
            if not np.all(np.isfinite(e.u)):
                continue
            b = search_boundary(camera, fit, edge, front.disparity.right, members_u, config.landmarks, config.planes,
                                float(config.sad.block_size), border_sigma_px=0.0)
            if b is None:
                continue
            true_u = camera.project_columns(T, plane.edge(edge))
            err = b.u - true_u
            if np.all(np.isfinite(err)) and np.all(np.abs(err) < 3 * config.sad.block_size):
                out.boundary_err[bool(b.snapped)] += list(err)
                out.boundary_model2[bool(b.snapped)] += list(b.sigma_u**2)


def clipped_rms(z, k: float = 4.0, iterations: int = 10) -> float:
    """RMS of ``z`` after iteratively leaving out samples beyond ``k`` times the current RMS (gross outliers
    such as lines of clutter are not noise; the tails within ``k`` σ are, and the RMS keeps them)."""
    z = np.asarray(z, dtype=float)
    z = z[np.isfinite(z)]
    keep = np.ones(len(z), dtype=bool)
    rms = float(np.sqrt(np.mean(z**2)))
    for _ in range(iterations):
        new = np.abs(z) <= k * rms
        rms = float(np.sqrt(np.mean(z[new] ** 2)))
        if np.array_equal(new, keep):
            break
        keep = new
    return rms


def missing_sigma(err, model_var, k: float = 4.0) -> float:
    """The σ ``b`` to add to each sample's modelled variance so that the normalised errors have unit mean
    square: ``mean(err² / (model_var + b²)) = 1`` (0 when they already have less), gross outliers (beyond ``k``
    normalised) left out. Each boundary keeps its own modelled spread; ``b`` is what none of them accounts for
    (block matching's shift of a depth edge, a bias shared by all rows)."""
    err, model_var = np.asarray(err, dtype=float), np.asarray(model_var, dtype=float)

    def msq(b):
        z2 = err**2 / (model_var + b * b)
        z2 = z2[z2 <= k * k * max(1.0, float(np.median(z2)))]
        return float(np.mean(z2)) if len(z2) else 0.0

    if msq(0.0) <= 1.0:
        return 0.0
    lo, hi = 0.0, float(np.sqrt(np.max(err**2))) + 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if msq(mid) > 1.0 else (lo, mid)
    return 0.5 * (lo + hi)


def estimate(samples: NoiseSamples) -> dict:
    """The configuration document ``{noise: {sigma_img, boundary_px}, odometry: {...}}`` the samples give
    (keys whose samples are missing are left out), and ``counts`` of the samples used."""
    doc: dict = {"noise": {}, "odometry": {}}
    z = np.asarray(samples.line_z)
    if len(z) >= 10:
        doc["noise"]["sigma_img"] = round(clipped_rms(z), 4)
    for snapped, key in ((True, "boundary_px"), (False, "free_boundary_px")):
        err = np.asarray(samples.boundary_err[snapped])
        if len(err) >= 4:
            doc["noise"][key] = round(missing_sigma(err, np.asarray(samples.boundary_model2[snapped])), 3)
    o = np.asarray(samples.odometry, dtype=float).reshape(-1, 6)
    r1, tr, r2, e1, et, e2 = o.T
    turn = r1 + r2
    straight = (tr > 1e-3) & (turn < 1e-6)
    on_spot = (tr < 1e-6) & (turn > 1e-3)
    if straight.sum() >= 5:  # driving straight: the per-metre terms alone
        doc["odometry"]["trans_per_m"] = round(math.sqrt(np.sum(et[straight] ** 2) / np.sum(tr[straight])), 5)
        rot = np.sum(e1[straight] ** 2 + e2[straight] ** 2) / np.sum(tr[straight])
        doc["odometry"]["rot_per_m_deg"] = round(math.degrees(math.sqrt(rot)), 4)
    if on_spot.sum() >= 5:  # turning on the spot: the per-radian terms alone
        doc["odometry"]["trans_per_rad"] = round(math.sqrt(np.sum(et[on_spot] ** 2) / np.sum(turn[on_spot])), 5)
        rot = np.sum(e1[on_spot] ** 2 + e2[on_spot] ** 2) / np.sum(turn[on_spot])
        doc["odometry"]["rot_per_rad"] = round(math.sqrt(rot), 5)
    doc = {k: v for k, v in doc.items() if v}
    return doc


@dataclass(frozen=True)
class Consistency:
    """The filter's consistency over some runs: means and 95 % bounds (χ² of the pooled samples)."""

    runs: int
    frames: int
    nees_pose: float
    nees_pose_bounds: tuple[float, float]
    nees_pose_inside: float
    nis: float
    nis_bounds: tuple[float, float]
    nees_landmark: float
    nees_landmark_bounds: tuple[float, float]
    ate: float


def consistency(runs: Sequence) -> Consistency:
    """Pose NEES over all frames of all runs (mean, and the fraction of frames inside the 95 % bounds of one
    frame's NEES, 3 dof), mean NIS and, for runs with ground truth of their landmarks, mean landmark NEES along
    the wall at the end of each run.

    ``runs``: ``(OnlineResult, edges)`` with ``edges`` the true image edges by id (or None)."""
    nees, nis, lm_nees, ates = [], [], [], []
    for result, edges in runs:
        T = result.true_poses
        if T is None:
            raise InputError(f"{result.name}: no ground truth poses: the consistency needs them")
        nees += list(pose_nees(result.poses, result.covs, T))
        nis += [v for r in result.records for v in r.nis]
        ates.append(float(np.sqrt(np.mean(np.sum((result.poses[:, :2] - T[:, :2]) ** 2, axis=1)))))
        for lid, tid in result.truth_of.items():
            if edges is None or tid not in edges or lid not in result.ekf.landmark_ids:
                continue
            lm, e = result.ekf.landmark(lid), edges[tid]
            plane = result.world_map[lm.plane_id]
            lm_nees.append(float(along_wall_nees(lm.position, lm.cov2d, np.array([e.x, e.y]), plane.direction)[0]))
    nees = np.asarray(nees)
    bounds = chi2_bounds(1, 3)
    return Consistency(
        len(runs), len(nees), float(nees.mean()), bounds, fraction_inside(nees, bounds),
        float(np.mean(nis)) if nis else math.nan, chi2_bounds(max(1, len(nis)), 2),
        float(np.mean(lm_nees)) if lm_nees else math.nan, chi2_bounds(max(1, len(lm_nees)), 1),
        float(np.mean(ates)))
