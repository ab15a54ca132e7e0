"""Along-wall error of modelled features against their range and incidence (the defaults of
``landmarks.max_range`` and ``landmarks.max_incidence_deg``).

Runs the full method on simulated scenarios with the entry limits off, matches every candidate of every frame
to its true feature (as the evaluation does) and prints, per range and incidence bin, the RMS of the
normalised along-wall error ``(s − s_true) / σ_s`` and the RMS error itself.

    python benchmarks/entry_limits.py lab corridor room loop office hall --frames 120
"""

import argparse

import numpy as np

from stablemarks.config import Config
from stablemarks.evaluation import _match_truth, trial_seeds
from stablemarks.localizer import Localizer
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def samples(name: str, frames: int | None, seed: int | None, config: Config) -> list[tuple[float, float, float, float]]:
    sc = load_scenario(name)
    run = simulate_run(sc, seed if seed is not None else trial_seeds(sc.seed, 1)[0])
    source = SimulatedSource(run, frames=frames)
    cfg = config.with_source_defaults(source.config_defaults)
    loc = Localizer(source.world_map, source.camera, start_pose=source.initial_pose, config=cfg)
    source.steer(loc.command_pan)
    out = []
    for frame in source:
        est = loc.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        if est.model is None:
            continue
        edges = {e.id: e for e in frame.truth.edges}
        for c in est.model.candidates:
            tid = _match_truth(frame.truth, c)
            if tid is None or c.reason in ("off the wall", "beyond the wall's height", "outside the plane"):
                continue
            e = edges[tid]
            plane = source.world_map[c.plane_id]
            err = float((c.P - np.array([e.x, e.y])) @ plane.direction)
            out.append((c.range, np.degrees(c.incidence), err, c.sigma_s))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenarios", nargs="+")
    p.add_argument("--frames", type=int, default=None)
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args()
    from stablemarks.commands._common import parse_overrides

    config = Config().with_overrides({"landmarks": {"max_range": 100.0, "max_incidence_deg": 89.9}})
    if args.set:
        config = config.with_overrides(parse_overrides(args.set))
    data = []
    for name in args.scenarios:
        s = samples(name, args.frames, args.seed, config)
        print(f"{name}: {len(s)} candidate observations")
        data += s
    a = np.array(data)
    rng, inc, err, sig = a.T
    z = err / sig
    print(f"all: n={len(a)}  RMS z={np.sqrt(np.mean(z**2)):.2f}  RMS err={1000 * np.sqrt(np.mean(err**2)):.1f} mm")
    def line(label, m):
        if m.any():
            rms_z, rms = np.sqrt(np.mean(z[m] ** 2)), 1000 * np.sqrt(np.mean(err[m] ** 2))
            print(f"{label:<16} {m.sum():>6} {rms_z:>7.2f} {rms:>12.1f} {1000 * np.abs(err[m]).max():>14.1f}")

    print("range [m]            n   RMS z   RMS err [mm]   max |err| [mm]")
    for lo, hi in [(0, 3), (3, 5), (5, 7), (7, 9), (9, 11), (11, 15)]:
        line(f"{lo}-{hi}", (rng >= lo) & (rng < hi))
    print("incidence [deg]      n   RMS z   RMS err [mm]   max |err| [mm]")
    for lo, hi in [(0, 30), (30, 45), (45, 60), (60, 70), (70, 80), (80, 90)]:
        line(f"{lo}-{hi}", (inc >= lo) & (inc < hi))
    print("range, incidence     n   RMS z   RMS err [mm]   max |err| [mm]")
    for lo, hi in [(0, 5), (5, 7), (7, 9), (9, 15)]:
        for a, b in [(0, 60), (60, 90)]:
            line(f"{lo}-{hi} m, {a}-{b}°", (rng >= lo) & (rng < hi) & (inc >= a) & (inc < b))


if __name__ == "__main__":
    main()
