"""Joint-EKF update time against the number of landmarks, next to filterpy's dense ``ExtendedKalmanFilter``.

Run: ``python benchmarks/bench_ekf.py [--sizes 10 100 …] [--kind wall|point] [--json FILE]``

For each size n: a robot facing a row of n landmarks (``wall`` landmarks: N = 3 + n state dimensions;
``point``: N = 3 + 2n) with a random dense SPD covariance over the whole state, and one frame of m = 6
observed landmarks (true columns + 0.5 px noise). Both filters start from the same x and P and update with
the same z, H (dense, from :meth:`JointEKF.observation_model`), h(x) and R = σ_img² I:

- ``JointEKF.update``: Joseph form restricted to the touched columns, O(N²·m), including its own
  projection and Jacobians;
- ``filterpy.kalman.ExtendedKalmanFilter.update(z, HJacobian, Hx, R)``: ``K = P Hᵀ S⁻¹`` with ``inv``, then
  the Joseph form ``(I − KH) P (I − KH)ᵀ + K R Kᵀ`` with full N×N matrices, O(N³) (filterpy/kalman/EKF.py).

Single BLAS thread (``threadpool_limits(1)``; DESIGN §4), median over repeated runs; printed: both times
[ms], their ratio, and the largest absolute difference between the two posterior states and covariances.
Goal: ≥ 10× faster at 1000 landmarks, the same results to 1e-9.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from threadpoolctl import threadpool_limits

from stablemarks.estimation import JointEKF, NewLandmark
from stablemarks.geometry import StereoCamera
from stablemarks.maps import ReferencePlane

M_OBS = 6
SIZES = (10, 100, 500, 1000, 2000)
CAMERA = StereoCamera()
POSE = np.array([0.0, 0.0, np.pi / 2])  # facing +y
WALL = ReferencePlane("wall", (-3.0, 5.0), (3.0, 5.0), free_edges=("p1",))


def make_problem(n: int, kind: str = "wall", seed: int = 0):
    """A filter over n landmarks with a random SPD covariance, and m = 6 observations ``[(id, (u_l, u_r))]``."""
    rng = np.random.default_rng(seed)
    s = np.sort(rng.uniform(0.5, 5.5, n))
    if kind == "wall":
        new = [NewLandmark.wall(WALL, v) for v in s]
    else:
        new = [NewLandmark.point(p) for p in WALL.point_at(s) + rng.normal(scale=[0.0, 0.5], size=(n, 2))]
    D = sum(lm.dim for lm in new)
    N = 3 + D
    # Dense SPD covariance: low-rank correlations (every landmark tied to every other and to the pose) + diagonal.
    L = rng.normal(size=(N, 12)) * np.concatenate([[0.05, 0.05, 0.01], np.full(D, 0.03)])[:, None]
    P = L @ L.T + np.diag(np.concatenate([[1e-3, 1e-3, 1e-4], np.full(D, 4e-4)]))
    ekf = JointEKF(CAMERA, POSE, P[:3, :3])
    ids = ekf.add_landmarks(new, P[3:, 3:], cov_pose_new=P[:3, 3:])
    visible = ekf.visible()
    chosen = [int(i) for i in rng.choice(visible, size=min(M_OBS, len(visible)), replace=False)]
    uv = ekf.predict_observation(chosen).uv + rng.normal(scale=CAMERA.sigma_img, size=(len(chosen), 2))
    assert len(ids) == n
    return ekf, list(zip(chosen, uv, strict=True))


def _median_ms(fn, setup, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        arg = setup()
        t0 = time.perf_counter()
        fn(arg)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def _repeats(seconds_per_call: float, budget: float = 3.0, lo: int = 3, hi: int = 51) -> int:
    return int(np.clip(budget / max(seconds_per_call, 1e-6), lo, hi))


def bench_size(n: int, kind: str = "wall") -> dict:
    """Timings [ms] and differences for one size (call under a one-thread BLAS limit)."""
    ekf, obs = make_problem(n, kind)
    ids = [i for i, _ in obs]
    z = np.concatenate([uv for _, uv in obs])
    h, H = ekf.observation_model(ids)
    R = CAMERA.sigma_img**2 * np.eye(len(z))
    x0, P0 = ekf.state, ekf.cov
    N = len(x0)

    ours = ekf.copy()
    t0 = time.perf_counter()
    ours.update(obs)
    t_ours = time.perf_counter() - t0
    ekf_ms = _median_ms(lambda f: f.update(obs), ekf.copy, _repeats(t_ours))

    fp = ExtendedKalmanFilter(dim_x=N, dim_z=len(z))
    hx = h(x0)[:, None]

    def reset(f=fp):
        f.x, f.P = x0[:, None].copy(), P0.copy()
        return f

    def fp_update(f):
        f.update(z[:, None], lambda _x: H, lambda _x: hx, R=R)

    t0 = time.perf_counter()
    fp_update(reset())
    t_fp = time.perf_counter() - t0
    diff_x = float(np.abs(ours.state - fp.x[:, 0]).max())
    diff_P = float(np.abs(ours.cov - fp.P).max())
    fp_ms = _median_ms(fp_update, reset, _repeats(t_fp))
    return {"n_landmarks": n, "kind": kind, "N": N, "m": len(obs), "ekf_ms": ekf_ms, "filterpy_ms": fp_ms,
            "ratio": fp_ms / ekf_ms, "max_abs_diff_x": diff_x, "max_abs_diff_P": diff_P}


def run(sizes=SIZES, kind: str = "wall") -> dict:
    """Benchmark all sizes single-threaded. Keys: ``rows`` (one dict per size), ``ratio_ekf_vs_filterpy_1000``
    (filterpy time / ours at 1000 landmarks, None if 1000 is not among ``sizes``), ``max_abs_diff`` (over all
    sizes, states and covariances)."""
    with threadpool_limits(limits=1):
        rows = [bench_size(int(n), kind) for n in sizes]
    at_1000 = [r["ratio"] for r in rows if r["n_landmarks"] == 1000]
    return {
        "kind": kind,
        "m": M_OBS,
        "rows": rows,
        "ratio_ekf_vs_filterpy_1000": at_1000[0] if at_1000 else None,
        "max_abs_diff": max(max(r["max_abs_diff_x"], r["max_abs_diff_P"]) for r in rows),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="numbers of landmarks")
    parser.add_argument("--kind", choices=("wall", "point"), default="wall", help="landmark kind (state dims 1 or 2)")
    parser.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    args = parser.parse_args(argv)
    res = run(args.sizes, args.kind)
    print(f"EKF update, m = {res['m']} observations, {res['kind']} landmarks, 1 BLAS thread, median")
    print(f"{'landmarks':>9} {'N':>5} {'JointEKF ms':>12} {'filterpy ms':>12} {'ratio':>8} {'|Δx|':>9} {'|ΔP|':>9}")
    for r in res["rows"]:
        print(f"{r['n_landmarks']:>9} {r['N']:>5} {r['ekf_ms']:>12.3f} {r['filterpy_ms']:>12.2f} {r['ratio']:>7.1f}× "
              f"{r['max_abs_diff_x']:>9.1e} {r['max_abs_diff_P']:>9.1e}")
    if res["ratio_ekf_vs_filterpy_1000"] is not None:
        print(f"ratio at 1000 landmarks: {res['ratio_ekf_vs_filterpy_1000']:.1f}× (goal ≥ 10×); "
              f"largest difference {res['max_abs_diff']:.1e} (goal ≤ 1e-9)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
