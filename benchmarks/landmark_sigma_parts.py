"""What a new landmark's σ along its wall is made of, at the true pose.

Every ``--every``-th frame of a simulated scenario's first trial is processed at the simulator's *true* pose (the
search covariance of ``calibrate-noise``, so that the gates are narrow but the method is the same). For every
selected candidate with a joint error model, its σ of ``s`` (the distance along the wall from the boundary it was
modelled from) is split into the parts the filter enters it with (``methods.enter_wall_landmarks``): the fitted
wall's line ``(a, b)``, the boundary's columns (``noise.boundary_px`` or ``noise.free_boundary_px`` beyond the line
noise) and the feature's own columns (``noise.sigma_img``). Printed: the medians [mm] and the median range [m].
The filter's floor (``ekf.landmark_sigma_floor``) comes on top after an update.

    python benchmarks/landmark_sigma_parts.py lab office hall
    python benchmarks/landmark_sigma_parts.py lab --config my.yaml --frames 30 --every 3
"""

import argparse

import numpy as np

from stablemarks.config import load_config
from stablemarks.errors import ConfigError
from stablemarks.evaluation import trial_seeds
from stablemarks.noisefit import SEARCH_POSE_COV
from stablemarks.pipeline import run_front_end, select_landmarks
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def parts(name: str, config, frames: int, every: int) -> np.ndarray:
    """(n, 5): σ from the fitted line, the boundary, the feature's own columns and in all [m], and the range [m]."""
    sc = load_scenario(name)
    source = SimulatedSource(simulate_run(sc, trial_seeds(sc.seed, 1)[0]), frames=frames)
    cfg = config.with_source_defaults(source.config_defaults)
    rows = []
    for k, f in enumerate(source):
        if k % every:
            continue
        T = np.asarray(f.true_pose)
        cam = cfg.camera(source.camera).with_pan(f.pan)
        model = select_landmarks(run_front_end(f.left, f.right, cfg), cam, source.world_map, T, SEARCH_POSE_COV, cfg)
        for c in model.selected:
            if c.shared_jacobian is None:
                continue
            J, C = c.shared_jacobian, c.shared_cov
            line = float(J[:2] @ C[:2, :2] @ J[:2])
            boundary = float(J[2:] @ C[2:, 2:] @ J[2:])
            total = float(J @ C @ J) + c.sigma_own**2
            rows.append((np.sqrt(line), np.sqrt(boundary), c.sigma_own, np.sqrt(total), c.range))
    return np.array(rows).reshape(-1, 5)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--config", help="configuration YAML")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--every", type=int, default=3)
    args = ap.parse_args()
    try:
        config = load_config(args.config)
    except ConfigError as e:
        ap.error(str(e))
    for name in args.scenarios:
        r = parts(name, config, args.frames, args.every)
        if not len(r):
            print(f"{name}: no selected candidate with an error model")
            continue
        m = np.median(r, axis=0)
        print(f"{name}: {len(r)} selected candidates; median σ of s [mm]: fitted line {1e3 * m[0]:.2f}, boundary "
              f"{1e3 * m[1]:.2f}, own columns {1e3 * m[2]:.2f}, in all {1e3 * m[3]:.2f}; median range {m[4]:.1f} m")


if __name__ == "__main__":
    main()
