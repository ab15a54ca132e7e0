"""Which directions of the pose the filter is too cautious or too sure about, frame by frame.

Runs the full method on one trial of a simulated scenario (the evaluation's start belief and trial seed) and
prints, for every frame, the pose NEES and, along each principal axis of the pose covariance (smallest σ
first), its σ (× 1000: mm, or mrad where the axis is the heading) and the normalised squared error z² of
the estimate along it (ideal 1 on average; below 1 too cautious, above 1 overconfident). Walls seen head-on
observe the bearing and the range well and the along-wall position against the heading poorly, so a filter
can be right about the weak direction and wrong about the strong ones, which the NEES alone does not show.

    python benchmarks/pose_directions.py lab --trial 0
    python benchmarks/pose_directions.py corridor --trial 2 --config my.yaml --frames 30
"""

import argparse

import numpy as np

from stablemarks.config import load_config
from stablemarks.errors import ConfigError
from stablemarks.evaluation import DEFAULT_COV0, start_belief, trial_seeds
from stablemarks.localizer import Localizer
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--trial", type=int, default=0, help="trial index, as in `stablemarks eval` (0)")
    ap.add_argument("--config", help="configuration YAML")
    ap.add_argument("--frames", type=int, help="first N frames only")
    args = ap.parse_args()
    try:
        config = load_config(args.config)
    except ConfigError as e:
        ap.error(str(e))
    sc = load_scenario(args.scenario)
    run = simulate_run(sc, trial_seeds(sc.seed, args.trial + 1)[args.trial])
    source = SimulatedSource(run, frames=args.frames)
    config = config.with_source_defaults(source.config_defaults)
    loc = Localizer(source.world_map, source.camera, start_pose=start_belief(run, DEFAULT_COV0),
                    start_cov=DEFAULT_COV0, config=config)
    source.steer(loc.command_pan)
    print("frame   NEES | per principal axis of P, smallest first: σ × 1000 (mm or mrad), z²")
    for k, frame in enumerate(source):
        est = loc.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        e = est.pose - run.poses[k].as_array()
        e[2] = (e[2] + np.pi) % (2 * np.pi) - np.pi
        w, V = np.linalg.eigh(est.cov)
        z2 = (V.T @ e) ** 2 / w
        nees = float(e @ np.linalg.solve(est.cov, e))
        axes = "  ".join(f"{1e3 * np.sqrt(wi):7.2f} {zi:5.2f}" for wi, zi in zip(w, z2, strict=True))
        print(f"{k:5d} {nees:6.2f} | {axes}")


if __name__ == "__main__":
    main()
