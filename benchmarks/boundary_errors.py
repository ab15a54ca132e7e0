"""How far the boundaries the method uses on-line lie from the true free edges, snapped and free apart.

Runs the full method (the evaluation's start belief and trial seeds, the localizer's own pans) over the first
``--frames`` frames of ``--trials`` trials per scenario; every boundary used in a frame (``log.jsonl``'s
``boundaries`` with ``used`` true) is compared with the simulator's true column of its free edge in the left
image. Printed per scenario, for boundaries moved onto a segment pair (``snapped``) and for the region's own
border (``free``): how many, the median column error and the fractions beyond 3 and 6 px; then the largest
errors (frame, wall, edge, error [px], σ along the wall [m]).

    python benchmarks/boundary_errors.py lab room corridor office hall benchmarks/scenarios/storeroom.yaml
    python benchmarks/boundary_errors.py office --trials 4 --frames 0 --jobs 2
"""

import argparse
from multiprocessing import Pool

import numpy as np

from stablemarks.config import Config, load_config
from stablemarks.evaluation import DEFAULT_COV0, start_belief, trial_seeds
from stablemarks.online import run_online
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def boundary_errors(name: str, trial: int, frames: int | None, config: Config) -> list[tuple]:
    """``(frame, wall, edge, snapped, column error [px], σ along [m])`` of every boundary used in one trial."""
    sc = load_scenario(name)
    run = simulate_run(sc, trial_seeds(sc.seed, trial + 1)[trial])
    out = []

    def observe(frame, est, loc):
        truth = {e.id: e for e in frame.truth.edges}
        for b in est.record.boundaries:
            e = truth.get(f"{b['plane']}-{b['edge']}")
            if b["used"] and e is not None and np.isfinite(e.u_l):
                out.append((est.record.index, b["plane"], b["edge"], b["snapped"], b["u_left"] - e.u_l, b["sigma"]))

    run_online(SimulatedSource(run, frames=frames), observers=[observe], start_pose=start_belief(run, DEFAULT_COV0),
               start_cov=DEFAULT_COV0, config=config, keep="nothing")
    return out


def _task(args):
    name, trial, frames, config = args
    return name, boundary_errors(name, trial, frames, config)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--frames", type=int, default=60, help="first N frames of each run (0: all)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--config", help="a configuration file (default: the defaults)")
    ap.add_argument("--show", type=int, default=5, help="largest errors listed per scenario")
    args = ap.parse_args()
    config = load_config(args.config) if args.config else Config()
    tasks = [(n, t, args.frames or None, config) for n in args.scenarios for t in range(args.trials)]
    found: dict[str, list] = {n: [] for n in args.scenarios}
    with Pool(max(1, args.jobs)) as pool:
        for name, rows in pool.imap_unordered(_task, tasks):
            found[name] += rows
    for name, rows in found.items():
        if not rows:
            print(f"{name}: no boundary used")
            continue
        err = np.array([r[4] for r in rows])
        snapped = np.array([r[3] for r in rows])
        for label, m in (("snapped", snapped), ("free", ~snapped)):
            if m.any():
                a = np.abs(err[m])
                print(f"{name:12s} {label:8s} n={m.sum():4d}  median |du| {np.median(a):5.2f} px  "
                      f"> 3 px {np.mean(a > 3):6.1%}  > 6 px {np.mean(a > 6):6.1%}")
        for r in sorted(rows, key=lambda r: -abs(r[4]))[:args.show]:
            print(f"    frame {r[0]:3d} {r[1]} {r[2]} {'snapped' if r[3] else 'free'}: {r[4]:+.1f} px, σ {r[5]:.3f} m")
