"""Which landmarks count against the selection's precision, and what they were made from.

Runs the full method on simulated scenarios (the evaluation's start belief and trial seeds) and, for every
landmark it enters that the evaluation does not match to a true on-plane feature
(:func:`stablemarks.evaluation._match_truth`, the rule of ``selection_precision``), prints the frame, the wall,
its image columns, its modelled position and σ along the wall, its heights, range, incidence and offset from the
fitted wall, its score against the fitted wall (:func:`stablemarks.landmarks.nearer_than_fit`, the test of
``landmarks.nearer_fit_sigma``), and the true image edges nearest its columns in that frame: their kind
(``feature`` / ``boundary``), wall, world distance from the landmark [mm] and column offsets [px]. A ``boundary``
edge there means a plane's end was taken for a feature; an edge of another wall means something off the wall
entered; a feature of the same wall a few cm away means the landmark was placed too far off to be matched
(unmapped clutter has no true edges: its lines show as features of their wall far away, or as nothing).

At the end, per scenario, the scores of the entered landmarks that *are* true features. With the test on, no
entered line scores above it; to see what the test would reject, run it off:

    python benchmarks/false_landmarks.py office benchmarks/scenarios/storeroom.yaml --trials 2
    python benchmarks/false_landmarks.py lab room corridor --trials 2 --set landmarks.nearer_fit_sigma=null
"""

import argparse
from collections import Counter

import numpy as np

from stablemarks.commands._common import parse_overrides
from stablemarks.config import Config
from stablemarks.errors import InputError
from stablemarks.evaluation import DEFAULT_COV0, _match_truth, start_belief, trial_seeds
from stablemarks.landmarks import nearer_than_fit
from stablemarks.online import run_online
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def nearest_edges(truth, c, n: int = 3) -> list[tuple]:
    """The ``n`` true edges visible in both images nearest candidate ``c``'s columns (sum of both images):
    ``(edge, Δu_left, Δu_right [px], distance from the candidate's position [mm])``."""
    rows = sorted(((abs(e.u_l - c.u_left) + abs(e.u_r - c.u_right), e) for e in truth.edges
                   if e.visible_l and e.visible_r), key=lambda r: r[0])
    return [(e, e.u_l - c.u_left, e.u_r - c.u_right, 1e3 * float(np.hypot(e.x - c.P[0], e.y - c.P[1])))
            for _, e in rows[:n]]


def fit_score(localizer, frame, est, c) -> float:
    """Candidate ``c``'s score against its wall as fitted in this frame, as the landmark stage computes it."""
    fit = next((m.fit for m in est.model.planes if m.fit.plane.id == c.plane_id), None)
    if fit is None:
        return float("nan")
    camera = localizer.camera.with_pan(frame.pan)
    front = est.front
    slope = float(front.left_segments.slope[front.kept_pairs.left_index][c.pair])
    config = localizer.config
    return float(nearer_than_fit(camera, fit, front.disparity.left, [c.u_left], [c.v_top], [c.v_bottom], [slope],
                                 config.sad.block_size, config.planes.sigma_nu(camera))[0])


def false_entries(name: str, trials: int, frames: int | None, config: Config):
    """Print every false entry of ``trials`` runs of scenario ``name``; ``(entered, Counter of kinds, the true
    features' scores)``."""
    sc = load_scenario(name)
    refs = {p.id for p in sc.map.planes if p.reference}
    kinds: Counter = Counter()
    totals = [0]
    true_z: list[float] = []
    for t, seed in enumerate(trial_seeds(sc.seed, trials)):
        run = simulate_run(sc, seed)
        k_frame = [0]

        def observe(frame, est, localizer, t=t, k_frame=k_frame):
            k = k_frame[0]
            k_frame[0] += 1
            for c in est.entered.candidates:
                if c is None:  # a point landmark
                    continue
                totals[0] += 1
                z = fit_score(localizer, frame, est, c)
                tid = _match_truth(frame.truth, c)
                edge = next((e for e in frame.truth.edges if e.id == tid), None)
                if edge is not None and edge.kind == "feature" and edge.wall in refs:
                    true_z.append(z)
                    continue
                near = nearest_edges(frame.truth, c)
                e0 = near[0][0] if near else None
                kind = ("nothing" if e0 is None else "other wall" if e0.wall != c.plane_id and e0.wall in refs
                        else "unmapped" if e0.wall != c.plane_id else "feature too far" if e0.kind == "feature"
                        else e0.kind)
                kinds[kind] += 1
                print(f"{sc.name} trial {t} frame {k:3d} {c.plane_id:>12s} {c.edge} s={c.s:6.3f} "
                      f"σs={1e3 * c.sigma_s:5.1f}mm u=({c.u_left:6.1f},{c.u_right:6.1f}) "
                      f"z=[{c.z_low:4.2f},{c.z_high:4.2f}] range={c.range:4.1f} inc={np.degrees(c.incidence):4.0f}° "
                      f"off={1e3 * c.wall_offset:5.1f}±{1e3 * c.sigma_wall_offset:4.1f}mm score {z:+5.1f}  -> {kind}")
                for e, dl, dr, dist in near:
                    print(f"      {e.kind:8s} {e.wall:>12s} {e.feature:>14s} z=[{e.z[0]:4.2f},{e.z[1]:4.2f}] "
                          f"du=({dl:+6.1f},{dr:+6.1f}) px  {dist:7.1f} mm")

        run_online(SimulatedSource(run, frames=frames), observers=[observe], start_pose=start_belief(run, DEFAULT_COV0),
                   start_cov=DEFAULT_COV0, config=config, keep="nothing")
    return totals[0], kinds, np.array(true_z)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--frames", type=int, default=0, help="first N frames of each run (0: all)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="configuration override")
    args = ap.parse_args()
    try:
        config = Config().with_overrides(parse_overrides(args.set))
    except InputError as exc:
        ap.error(str(exc))
    for name in args.scenarios:
        total, kinds, true_z = false_entries(name, args.trials, args.frames or None, config)
        bad = sum(kinds.values())
        if np.isfinite(true_z).any():
            q = np.nanpercentile(true_z, [50, 90, 99, 100])
            print(f"   true features' scores against the fitted wall: median {q[0]:.1f}, 90 % {q[1]:.1f}, "
                  f"99 % {q[2]:.1f}, max {q[3]:.1f} (n = {len(true_z)}); above 3: {int(np.sum(true_z > 3))}, "
                  f"above 5: {int(np.sum(true_z > 5))}")
        print(f"== {name}: {bad} of {total} entered landmarks not on a true feature "
              f"(precision {1 - bad / max(total, 1):.2f}): {dict(kinds)}")


if __name__ == "__main__":
    main()
