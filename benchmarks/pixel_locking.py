"""Is a wall's shared disparity error pixel locking? The per-pixel disparity error against the true disparity's
fractional part, at the true pose.

Sub-pixel block matching is known to pull disparities towards whole pixels; if that were the wall-shared error
of docs/uncertainty.md, the mean error binned by ``frac(d_true)`` would follow a curve (odd about the integers)
and a wall whose pixels share one fractional disparity (a frontal wall) would carry more of it than a slanted
one, whose fractional disparities spread over [0, 1). For each scenario, every ``--every``-th of the first
``--frames`` frames of the first trial is processed at the simulator's true pose; for every wall fitted there
(its pixels in the fit's region), prints the mean error in ten bins of ``frac(d_true)``, the RMS over walls of
the wall's mean error and of its fitted offset as a disparity, and how the wall's mean error relates to the
coherence ``|mean exp(2πi d_true)|`` of its pixels (1: one fractional disparity, 0: spread).

Each wall's per-pixel error is also regressed on its column, ``e ≈ β + γ x`` with ``x`` from −1 to 1 across the
wall's fitted columns: the RMS over walls of ``β`` and ``γ`` are what ``planes.disparity_bias_px`` and
``planes.disparity_tilt_px`` model, and the fitted offset's and slope's mean normalised squared errors are
printed with the configuration's values and with ``--bias`` and ``--tilt`` (ideal 1).

    python benchmarks/pixel_locking.py lab corridor room
    python benchmarks/pixel_locking.py lab corridor office hall room --trials 2 --frames 30 --bias 0.03 --tilt 0.06
"""

import argparse
from dataclasses import replace

import numpy as np

from stablemarks.config import Config
from stablemarks.evaluation import trial_seeds
from stablemarks.noisefit import SEARCH_POSE_COV
from stablemarks.pipeline import run_front_end
from stablemarks.planes import fit_plane, predict_planes
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def measure(name: str, frames: int, every: int, trials: int = 1, bias: float = 0.03, tilt: float = 0.06) -> None:
    sc = load_scenario(name)
    fracs, errs, walls = [], [], []
    for seed in trial_seeds(sc.seed, trials):
        src = SimulatedSource(simulate_run(sc, seed), frames=frames)
        cfg = Config().with_source_defaults(src.config_defaults)
        _frames(src, cfg, every, bias, tilt, fracs, errs, walls)
    _print(name, fracs, errs, walls, bias, tilt)


def _frames(src, cfg, every, bias, tilt, fracs, errs, walls) -> None:
    other = replace(cfg.planes, disparity_bias_px=bias, disparity_tilt_px=tilt)
    for k, f in enumerate(src):
        if k % every:
            continue
        T = np.asarray(f.true_pose)
        cam = cfg.camera(src.camera).with_pan(f.pan)
        D = run_front_end(f.left, f.right, cfg).disparity.left
        for pred in predict_planes(cam, T, SEARCH_POSE_COV, src.world_map, cfg.planes):
            fit = fit_plane(cam, T, D, pred, cfg.planes)
            if not fit or abs(fit.a) > 0.1:  # another surface fitted in the band
                continue
            vv, uu = np.nonzero(np.asarray(fit.region, dtype=bool))
            d_true, _ = pred.disparity_at(uu)
            e = D[vv, uu] - d_true
            ok = np.isfinite(e) & (np.abs(e) < 1.0)
            fracs.append(d_true[ok] % 1.0)
            errs.append(e[ok])
            depth = abs(float(fit.plane.offset(cam.camera_pose(T).translation)))
            coherence = abs(np.mean(np.exp(2j * np.pi * d_true[ok])))
            u = uu[ok].astype(float)
            x = (u - 0.5 * (u.min() + u.max())) / max(0.5 * (u.max() - u.min()), 1.0)
            beta, gamma = np.linalg.lstsq(np.stack([np.ones_like(x), x], axis=1), e[ok], rcond=None)[0]
            fit2 = fit_plane(cam, T, D, pred, other)
            walls.append((np.mean(e[ok]), fit.a * cam.f * cam.baseline / depth**2, coherence, beta, gamma,
                          fit.a**2 / fit.cov_R[0, 0], fit.b**2 / fit.cov_R[1, 1],
                          fit.a**2 / fit2.cov_R[0, 0], fit.b**2 / fit2.cov_R[1, 1]))


def _print(name, fracs, errs, walls, bias, tilt) -> None:
    fr, e = np.concatenate(fracs), np.concatenate(errs)
    idx = np.minimum((fr * 10).astype(int), 9)
    print(f"{name}: {len(walls)} walls, {len(e)} pixels; mean error [px] by frac(d_true) in tenths: "
          + " ".join(f"{np.mean(e[idx == i]):+.3f}" for i in range(10)))
    w = np.array(walls)
    print(f"  RMS over walls of the wall's mean error {np.sqrt(np.mean(w[:, 0] ** 2)):.3f} px, of its fitted "
          f"offset as a disparity {np.sqrt(np.mean(w[:, 1] ** 2)):.3f} px; correlation of |mean error| with "
          f"coherence {np.corrcoef(np.abs(w[:, 0]), w[:, 2])[0, 1]:+.2f}")
    print(f"  per wall e = β + γ x: β RMS {np.sqrt(np.mean(w[:, 3] ** 2)):.3f} px, γ RMS "
          f"{np.sqrt(np.mean(w[:, 4] ** 2)):.3f} px; fit z² offset, slope: {w[:, 5].mean():.1f}, {w[:, 6].mean():.1f} "
          f"as configured, {w[:, 7].mean():.1f}, {w[:, 8].mean():.1f} with bias {bias:g} and tilt {tilt:g} px")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--frames", type=int, default=45)
    ap.add_argument("--every", type=int, default=3)
    ap.add_argument("--trials", type=int, default=1)
    ap.add_argument("--bias", type=float, default=0.03, help="planes.disparity_bias_px to compare with [px]")
    ap.add_argument("--tilt", type=float, default=0.06, help="planes.disparity_tilt_px to compare with [px]")
    args = ap.parse_args()
    for name in args.scenarios:
        measure(name, args.frames, args.every, args.trials, args.bias, args.tilt)


if __name__ == "__main__":
    main()
