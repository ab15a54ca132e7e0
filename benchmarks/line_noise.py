"""How the matched lines' columns err, against the simulator's true image edges: how much, how the left and right
columns go together, whether one wall's lines share an error in a frame, and how much stays with an edge.

Every ``--every``-th frame of the first ``--trials`` trials of each scenario goes through the front end (segments,
segment matching, disparity, filter); each kept segment pair is matched to the true feature edge whose left and
right columns it lies nearest to (within ``--match`` px summed over both images; boundaries are left out: their
columns are the boundary search's, not a line's). Printed per scenario:

- the RMS column error in each image and the correlation of the left and right errors (the filter's observation
  noise ``R = σ_img² I`` takes them as independent);
- per frame and wall with three lines or more: the RMS of the lines' mean error (a common shift of a wall's
  lines) against what their scatter alone would give it;
- per true edge seen in four frames or more: the RMS of its mean error over the frames (what stays with a
  landmark: it enters the landmark's position and does not average out) and of the frame-to-frame jitter about
  that mean (what repeated observations average).

    python benchmarks/line_noise.py lab corridor room office hall --trials 2 --frames 40
"""

import argparse
from collections import defaultdict

import numpy as np

from stablemarks.config import load_config
from stablemarks.errors import ConfigError
from stablemarks.evaluation import trial_seeds
from stablemarks.pipeline import run_front_end
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def line_errors(sc, config, trials: int, frames: int, every: int, match_px: float) -> list[tuple]:
    """``(trial, frame, wall, edge id, error u_l, error u_r)`` [px] of every matched line of scenario ``sc``."""
    rows = []
    for trial, seed in enumerate(trial_seeds(sc.seed, trials)):
        source = SimulatedSource(simulate_run(sc, seed), frames=frames)
        cfg = config.with_source_defaults(source.config_defaults)
        for k, frame in enumerate(source):
            if k % every:
                continue
            pairs = run_front_end(frame.left, frame.right, cfg).kept_pairs
            ul, ur = np.asarray(pairs.u_left, dtype=float), np.asarray(pairs.u_right, dtype=float)
            if not len(ul):
                continue
            for e in frame.truth.edges:
                if e.kind != "feature" or not (e.visible_l and e.visible_r) or not np.isfinite(e.u_l):
                    continue
                d = np.abs(ul - e.u_l) + np.abs(ur - e.u_r)
                j = int(np.argmin(d))
                if d[j] < match_px:
                    rows.append((trial, k, e.wall, e.id, ul[j] - e.u_l, ur[j] - e.u_r))
    return rows


def report(name: str, rows: list[tuple]) -> None:
    if len(rows) < 3:
        print(f"{name}: {len(rows)} matched lines, too few to say anything")
        return
    err = np.array([r[4:] for r in rows])
    rms = np.sqrt(np.mean(err**2, axis=0))
    rho = float(np.corrcoef(err.T)[0, 1])
    print(f"{name}: {len(rows)} lines; column error RMS left {rms[0]:.3f} px, right {rms[1]:.3f} px; "
          f"correlation of left and right {rho:.2f}")
    walls, edges = defaultdict(list), defaultdict(list)
    for trial, k, wall, eid, a, b in rows:
        walls[(trial, k, wall)].append((a, b))
        edges[(trial, eid)].append((a, b))
    common, expected = [], []
    for v in walls.values():
        v = np.array(v)
        if len(v) >= 3:
            common.append(v.mean(axis=0))
            expected.append(v.var(axis=0, ddof=1) / len(v))
    if common:
        c, x = np.sqrt(np.mean(np.square(common), axis=0)), np.sqrt(np.mean(expected, axis=0))
        print(f"  a wall's lines in one frame ({len(common)} groups): mean error RMS {c[0]:.3f} / {c[1]:.3f} px, "
              f"{x[0]:.3f} / {x[1]:.3f} px from their scatter alone")
    seen = [np.array(v) for v in edges.values() if len(v) >= 4]
    if seen:
        stay = np.sqrt(np.mean([v.mean(axis=0) ** 2 for v in seen], axis=0))
        jitter = np.sqrt(np.mean(np.concatenate([(v - v.mean(axis=0)) ** 2 for v in seen]), axis=0))
        print(f"  an edge over frames ({len(seen)} edges): persistent RMS {stay[0]:.3f} / {stay[1]:.3f} px, "
              f"frame-to-frame jitter {jitter[0]:.3f} / {jitter[1]:.3f} px")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--every", type=int, default=2)
    ap.add_argument("--match", type=float, default=1.0, help="largest |Δu_l| + |Δu_r| of a match [px] (1)")
    ap.add_argument("--config", help="configuration YAML")
    args = ap.parse_args()
    if args.trials < 1 or args.frames < 1 or args.every < 1 or args.match <= 0:
        ap.error("--trials, --frames and --every must be at least 1 and --match positive")
    try:  # all checked before the first is measured
        config = load_config(args.config)
        scenarios = [(name, load_scenario(name)) for name in args.scenarios]
    except ConfigError as e:
        ap.error(str(e))
    for name, sc in scenarios:
        report(name, line_errors(sc, config, args.trials, args.frames, args.every, args.match))


if __name__ == "__main__":
    main()
