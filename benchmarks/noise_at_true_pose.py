"""How uncertain the front end's measurements are, against how uncertain the model holds them, at the true pose.

For each simulated scenario, every ``--every``-th frame is processed at the simulator's *true* pose (a small
search covariance, so that gates are narrow but the method is the same): the planes are fitted and the free edges
searched as the localizer does. Printed per scenario:

- boundaries snapped onto a member segment and free ones (the region's own border): the RMS and 99th percentile
  of the column error against the true edge, the median modelled σ of that column, the mean normalised
  squared error (ideal 1), and the error's mean and spread along the outward direction (a shift, not a spread:
  a free boundary lies some pixels inward);
- fitted walls: the mean and median normalised squared error of the offset ``a`` (ideal 1 and 0.455), without
  and with ``planes.disparity_bias_px`` set to ``--bias``, and the RMS of the offset error expressed as a
  disparity shared by the whole wall [px].

    python benchmarks/noise_at_true_pose.py lab room corridor office hall --frames 60 --every 3
"""

import argparse
from dataclasses import replace

import numpy as np

from stablemarks.config import Config
from stablemarks.evaluation import trial_seeds
from stablemarks.landmarks import _inner_columns
from stablemarks.noisefit import SEARCH_POSE_COV
from stablemarks.pipeline import run_front_end, select_landmarks
from stablemarks.planes import fit_plane, predict_planes
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def measure(name: str, frames: int, every: int, bias: float, config: Config) -> None:
    sc = load_scenario(name)
    source = SimulatedSource(simulate_run(sc, trial_seeds(sc.seed, 1)[0]), frames=frames)
    cfg = config.with_source_defaults(source.config_defaults)
    with_bias = replace(cfg.planes, disparity_bias_px=bias)
    bnd = {True: [], False: []}
    z2 = {0: [], 1: []}
    shared = []
    for k, f in enumerate(source):
        if k % every:
            continue
        T = np.asarray(f.true_pose)
        cam = cfg.camera(source.camera).with_pan(f.pan)
        front = run_front_end(f.left, f.right, cfg)
        model = select_landmarks(front, cam, source.world_map, T, SEARCH_POSE_COV, cfg)
        for pm in model.planes:
            for b in pm.boundaries:
                true_u = cam.project_columns(T, pm.fit.plane.edge(b.edge))
                outward = 1.0 if true_u[0] > _inner_columns(cam, T, pm.fit.plane, b.edge)[0] else -1.0
                bnd[bool(b.snapped)].append((b.u[0] - true_u[0], b.sigma_u[0], outward))
        fb = cam.f * cam.baseline
        for pred in predict_planes(cam, T, SEARCH_POSE_COV, source.world_map, cfg.planes):
            fits = [fit_plane(cam, T, front.disparity.left, pred, pc) for pc in (cfg.planes, with_bias)]
            if not fits[0] or not fits[1] or abs(fits[0].a) > 0.1:  # another surface fitted in the band
                continue
            for i, fit in enumerate(fits):
                z2[i].append(fit.a**2 / fit.cov_R[0, 0])
            depth = abs(float(fits[0].plane.offset(cam.camera_pose(T).translation)))
            shared.append(fits[0].a * fb / depth**2)
    n_frames = len(range(0, len(source), every))
    print(f"{name}: {len(z2[0])} wall fits, {len(bnd[True])} snapped and {len(bnd[False])} free boundaries in "
          f"{n_frames} frames")
    for snapped, rows in bnd.items():
        if rows:
            e, s, out = np.array(rows).T
            print(f"  {'snapped' if snapped else 'free   '} boundary: error RMS {np.sqrt(np.mean(e**2)):.2f} px, "
                  f"99 % within {np.percentile(np.abs(e), 99):.2f} px, modelled σ {np.median(s):.2f} px, "
                  f"mean z² {np.mean((e / s) ** 2):.2f}; outward {np.mean(e * out):+.2f} ± {np.std(e * out):.2f} px")
    if z2[0]:
        print(f"  wall offset z²: mean {np.mean(z2[0]):.2f}, median {np.median(z2[0]):.2f} (ideal 1, 0.455); "
              f"with disparity_bias_px {bias:g}: mean {np.mean(z2[1]):.2f}, median {np.median(z2[1]):.2f}; "
              f"as a disparity shared by the wall: RMS {np.sqrt(np.mean(np.square(shared))):.3f} px")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--every", type=int, default=3)
    ap.add_argument("--bias", type=float, default=0.03, help="planes.disparity_bias_px to compare with [px]")
    args = ap.parse_args()
    for name in args.scenarios:
        measure(name, args.frames, args.every, args.bias, Config())


if __name__ == "__main__":
    main()
