"""How well the fitted wall's covariance covers its error, with each of ``planes.fit_covariance``'s estimators.

At the true pose of the first frames of a few trials of each scenario, every reference wall in view is fitted
(Sec 2.3.4) and its line ``o = a + b (s − s0)`` compared with the map's wall (``a = b = 0`` at the true pose):
the normalised squared errors ``a² / var_a`` and ``b² / var_b`` should average 1. Prints, per scenario and
estimator, their mean and median (a χ²₁ median is 0.45) over all fits whose offset is within 10 cm (the wall
itself, not clutter fitted in its band).

    python benchmarks/fit_covariance.py lab room corridor office hall [--trials 2] [--frames 8]
"""

import argparse
from dataclasses import replace

import numpy as np

from stablemarks.config import Config
from stablemarks.evaluation import trial_seeds
from stablemarks.pipeline import run_front_end
from stablemarks.planes import FIT_COVARIANCES, fit_plane, predict_planes
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--frames", type=int, default=8, help="first N frames of each trial (8)")
    args = ap.parse_args()
    print(f"{'scenario':12s} {'estimator':12s} {'fits':>5s}  mean a²/var  mean b²/var  median a²/var  median b²/var")
    for name in args.scenarios:
        sc = load_scenario(name)
        z2 = {k: [] for k in FIT_COVARIANCES}
        for seed in trial_seeds(sc.seed, args.trials):
            source = SimulatedSource(simulate_run(sc, seed), frames=args.frames)
            config = Config().with_source_defaults(source.config_defaults)
            for frame in source:
                T = np.asarray(frame.true_pose)
                camera = config.camera(source.camera).with_pan(frame.pan)
                disparity = run_front_end(frame.left, frame.right, config).disparity.left
                for pred in predict_planes(camera, T, np.diag([0.02, 0.02, np.radians(0.5)]) ** 2,
                                           source.world_map, config.planes):
                    for kind in FIT_COVARIANCES:
                        fit = fit_plane(camera, T, disparity, pred, replace(config.planes, fit_covariance=kind))
                        if fit and abs(fit.a) < 0.1:
                            z2[kind].append((fit.a**2 / fit.cov_R[0, 0], fit.b**2 / fit.cov_R[1, 1]))
        for kind, values in z2.items():
            v = np.array(values).reshape(-1, 2)
            if not len(v):
                print(f"{name:12s} {kind:12s}     0")
                continue
            mean, med = v.mean(axis=0), np.median(v, axis=0)
            print(f"{name:12s} {kind:12s} {len(v):5d}  {mean[0]:11.2f}  {mean[1]:11.2f}  "
                  f"{med[0]:13.2f}  {med[1]:13.2f}")


if __name__ == "__main__":
    main()
