"""Why the true features that count for recall were never modelled: the furthest each one got, per scenario.

Runs the full method as ``stablemarks eval`` does (the same trial seeds, start belief and recall rule: true
on-plane features away from their wall's free edges, in view together with a free edge in some frame,
:func:`stablemarks.evaluation._eligible_features`). For each eligible feature no landmark was modelled from, the
furthest stage it reached in any frame, in this order: its wall not modelled; fitted but no boundary used;
fitted with a boundary but the feature's line not a candidate (its pair dropped by the disparity check or not a
member); a candidate rejected (the selection's reason, digits replaced by ``#``); selected (yet no landmark:
the entry refused it). Printed per scenario: the recall, the count of each outcome, and the features missed in
most trials.

    python benchmarks/recall_misses.py hall office benchmarks/scenarios/storeroom.yaml --trials 3
"""

import argparse
import collections
import re
from multiprocessing import Pool

from stablemarks.config import Config, load_config
from stablemarks.evaluation import (
    DEFAULT_COV0,
    TruthObserver,
    _eligible_features,
    _match_truth,
    _on_plane_features,
    start_belief,
    trial_seeds,
)
from stablemarks.online import run_online
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def misses(name: str, trial: int, config: Config) -> tuple[int, int, dict[str, str]]:
    """``(eligible, found, {missed feature id: the furthest stage it reached})`` of one trial."""
    sc = load_scenario(name)
    run = simulate_run(sc, trial_seeds(sc.seed, trial + 1)[trial])
    truth_observer = TruthObserver()
    furthest: dict[str, tuple[int, str]] = {}

    def observe(frame, est, loc):
        model = est.model
        outcome = {}
        if model is not None:
            for c in model.candidates:
                tid = _match_truth(frame.truth, c)
                if tid is not None:
                    why = "selected" if c.selected else "rejected: " + re.sub(r"[-+]?\d[\d.]*", "#", c.reason or "")
                    outcome[tid] = (4 if c.selected else 3, why)
        planes = {pm.fit.plane.id: pm for pm in model.planes} if model is not None else {}
        for e in frame.truth.edges:
            if e.kind != "feature" or not (e.visible_l and e.visible_r):
                continue
            if e.id in outcome:
                st = outcome[e.id]
            elif e.wall in planes:
                st = (2, "fitted with a boundary, its line not a candidate") if planes[e.wall].boundaries else \
                    (1, "fitted, no boundary used")
            else:
                st = (0, "wall not modelled")
            if e.id not in furthest or st[0] > furthest[e.id][0]:
                furthest[e.id] = st

    result = run_online(SimulatedSource(run), observers=[truth_observer, observe],
                        start_pose=start_belief(run, DEFAULT_COV0), start_cov=DEFAULT_COV0, config=config)
    result = truth_observer.result(result)
    eligible = _eligible_features(result, sc, truth_observer.edges, _on_plane_features(sc, truth_observer.edges))
    found = eligible & set(result.truth_of.values())
    return len(eligible), len(found), {t: furthest.get(t, (-1, "never in view"))[1] for t in eligible - found}


def _task(args):
    name, trial, config = args
    return (name, *misses(name, trial, config))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--config", help="a configuration file (default: the defaults)")
    args = ap.parse_args()
    config = load_config(args.config) if args.config else Config()
    totals = {n: [0, 0, collections.Counter(), collections.Counter()] for n in args.scenarios}
    with Pool(max(1, args.jobs)) as pool:
        for name, n_eligible, n_found, missed in pool.imap_unordered(
                _task, [(n, t, config) for n in args.scenarios for t in range(args.trials)]):
            t = totals[name]
            t[0] += n_eligible
            t[1] += n_found
            t[2].update(missed.values())
            t[3].update(missed.keys())
    for name, (n_eligible, n_found, outcomes, ids) in totals.items():
        print(f"{name}: recall {n_found}/{n_eligible} = {n_found / max(n_eligible, 1):.2f}")
        for why, n in outcomes.most_common():
            print(f"  {n:4d}  {why}")
        print("  missed most often:", ", ".join(f"{tid} ({n})" for tid, n in ids.most_common(8)))
