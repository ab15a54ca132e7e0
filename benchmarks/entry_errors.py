"""Where the landmarks' initial uncertainty is wrong: the part their boundary shares, or the part between them.

Landmarks modelled from one boundary in one frame enter the filter together, with a joint covariance
(Eq 17 and the shared terms of :func:`stablemarks.landmarks.relative_error_model`). Their along-wall errors at
entry split into

- the *shared* part, the group's mean error: mostly the boundary's column error (``noise.boundary_px``), which
  moves every landmark of the group alike;
- the *relative* part, the errors about that mean: the lines' own column noise (``noise.sigma_img``) and the
  fitted wall's errors (``planes.disparity_bias_px``, ``planes.correlation_px``), which stretch the group
  along the wall (a wall seen at a slant turns a small error of its fitted line into a scale error).

For each part this prints the mean normalised squared error against the joint covariance the filter was given
(1 when the model is right; below 1 too cautious, above 1 overconfident) and the RMS error itself [mm]. The
filter's pose inherits both: the shared part moves it along the wall, the relative part turns it.

Runs the full method on simulated scenarios (the evaluation's start belief and trial seeds); each entered
landmark is matched to the nearest true feature edge of its wall (within ``--match``, 5 cm as the evaluation's
precision at least allows; the others are left out: this measures the model's noise, not false landmarks, which a
wider match would count as large errors).

    python benchmarks/entry_errors.py lab room corridor --trials 6 --frames 40
    python benchmarks/entry_errors.py corridor --trials 6 --frames 40 --set noise.boundary_px=0.5
    python benchmarks/entry_errors.py office hall --trials 4 --frames 0 --preset narrow
"""

import argparse

import numpy as np
import yaml

from stablemarks.commands._common import preset_arg
from stablemarks.config import Config
from stablemarks.evaluation import DEFAULT_COV0, start_belief, trial_seeds
from stablemarks.localizer import Localizer
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def entry_groups(name: str, trials: int, frames: int | None, config: Config, match: float = 0.05
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(errors (n,), joint covariance (n, n))`` of every group of wall landmarks entered together."""
    sc = load_scenario(name)
    out = []
    for seed in trial_seeds(sc.seed, trials):
        run = simulate_run(sc, seed)
        source = SimulatedSource(run, frames=frames)
        cfg = config.with_source_defaults(source.config_defaults)
        loc = Localizer(source.world_map, source.camera, start_pose=start_belief(run, DEFAULT_COV0),
                        start_cov=DEFAULT_COV0, config=cfg)
        source.steer(loc.command_pan)
        for frame in source:
            est = loc.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
            for ids, _values, cov in est.record.landmark_priors:
                cov = np.asarray(cov, dtype=float)
                if cov.shape != (len(ids), len(ids)):
                    continue  # point landmarks (two dimensions each)
                errors = []
                for lid in ids:
                    plane = loc.ekf.landmark_plane(lid)
                    if plane is None:
                        break
                    true_s = [plane.along(np.array([e.x, e.y])) for e in frame.truth.edges
                              if e.wall == plane.id and e.kind == "feature"]
                    position = plane.along(loc.ekf.landmark_position(lid))
                    best = min(true_s, key=lambda t: abs(t - position), default=None)
                    if best is None or abs(best - position) > match:
                        break
                    errors.append(position - best)
                if len(errors) == len(ids):
                    out.append((np.array(errors), cov))
    return out


def split(groups) -> dict:
    """Normalised squared errors and RMS errors [m] of the shared and the relative parts."""
    shared_z2, shared_e2, rel_z2, rel_dof, rel_e2, rel_n = [], [], 0.0, 0, 0.0, 0
    for e, C in groups:
        n = len(e)
        mean = np.full(n, 1.0 / n)
        shared_z2.append(float(mean @ e) ** 2 / float(mean @ C @ mean))
        shared_e2.append(float(mean @ e) ** 2)
        if n >= 2:
            centre = np.eye(n) - 1.0 / n
            w, V = np.linalg.eigh(centre @ C @ centre)
            keep = w > w.max() * 1e-9
            rel_z2 += float(np.sum((V[:, keep].T @ (centre @ e)) ** 2 / w[keep]))
            rel_dof += int(keep.sum())
            rel_e2 += float(np.sum((centre @ e) ** 2))
            rel_n += n - 1
    return {"groups": len(groups), "landmarks": sum(len(e) for e, _ in groups),
            "shared_z2": float(np.mean(shared_z2)) if shared_z2 else float("nan"),
            "shared_rms_mm": 1e3 * float(np.sqrt(np.mean(shared_e2))) if shared_e2 else float("nan"),
            "relative_z2": rel_z2 / rel_dof if rel_dof else float("nan"),
            "relative_rms_mm": 1e3 * float(np.sqrt(rel_e2 / rel_n)) if rel_n else float("nan")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--trials", type=int, default=6)
    ap.add_argument("--frames", type=int, default=40, help="first N frames of each run (0: all)")
    ap.add_argument("--match", type=float, default=0.05, help="largest distance to a true feature [m] (0.05)")
    preset_arg(ap)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="configuration override")
    args = ap.parse_args()
    config = Config.preset(args.preset) if args.preset else Config()
    for item in args.set:
        key, _, value = item.partition("=")
        section, _, field = key.partition(".")
        config = config.with_overrides({section: {field: yaml.safe_load(value)}})
    print(f"{'scenario':10s} {'groups':>6s} {'lms':>5s} {'shared z²':>10s} {'shared RMS':>11s} "
          f"{'relative z²':>12s} {'relative RMS':>13s}")
    for name in args.scenarios:
        r = split(entry_groups(name, args.trials, args.frames or None, config, args.match))
        print(f"{name:10s} {r['groups']:6d} {r['landmarks']:5d} {r['shared_z2']:10.2f} {r['shared_rms_mm']:8.1f} mm "
              f"{r['relative_z2']:12.2f} {r['relative_rms_mm']:10.1f} mm")


if __name__ == "__main__":
    main()
