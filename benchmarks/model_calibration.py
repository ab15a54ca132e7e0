"""How well the modelled uncertainty matches the actual error on a simulated scenario:
`python benchmarks/model_calibration.py [--scenario lab] [--seeds 12] [--frames 0 10] [--set landmarks.X=V ...]`.

For each seed and frame: every boundary found (error of P_b along the wall against the true wall end) and
every candidate feature (error of s against the nearest true edge of its wall), with the modelled σ;
`rms z` is the RMS of error/σ (1.0 = calibrated, below 1 = conservative, above 1 = overconfident).
"""

import argparse

import numpy as np

from stablemarks.config import Config
from stablemarks.pipeline import process_frame
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario


def _overrides(items) -> dict:
    out: dict = {}
    for item in items:
        key, value = item.split("=", 1)
        section, name = key.split(".", 1)
        out.setdefault(section, {})[name] = None if value.lower() == "none" else float(value)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="lab")
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--frames", type=int, nargs="+", default=[0, 10])
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    config = Config().with_overrides(_overrides(args.set), "--set")
    cov0 = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
    rows = []
    for seed in range(args.seeds):
        run = simulate_run(sc, 200 + seed)
        for k in args.frames:
            if k >= len(run):
                continue
            fr = run.render(k)
            cam = sc.camera.with_pan(run.pans[k])
            res = process_frame(fr.left, fr.right, cam, sc.map, run.poses[k].as_array(), cov0, config)
            truth = [e for e in fr.truth.edges if e.visible_l]
            for m in res.planes:
                for b in m.boundaries:
                    err = float((b.P - m.fit.plane.edge(b.edge)) @ b.inward)
                    rows.append(("boundary", m.fit.plane.id, b.edge, err, b.sigma_along))
            for c in res.candidates:
                plane = sc.map[c.plane_id]
                s_true = np.array([float(plane.along(np.array([e.x, e.y]), c.edge)) for e in truth
                                   if e.wall == c.plane_id])
                if len(s_true):
                    err = c.s - s_true[int(np.argmin(np.abs(s_true - c.s)))]
                    rows.append(("feature", c.plane_id, c.edge, err, c.sigma_s))
    print(f"{args.scenario}, {args.seeds} seeds, frames {args.frames}")
    print(f"{'':9s} {'plane':12s} edge     n  mean err  rms err  mean σ  rms z   (mm)")
    for kind in ("boundary", "feature"):
        for pid, edge in sorted({(r[1], r[2]) for r in rows if r[0] == kind}):
            z = np.array([(r[3], r[4]) for r in rows if r[:3] == (kind, pid, edge)])
            err, sig = 1000 * z[:, 0], 1000 * z[:, 1]
            print(f"{kind:9s} {pid:12s} {edge:4s} {len(z):5d} {err.mean():9.1f} {np.sqrt((err**2).mean()):8.1f} "
                  f"{sig.mean():7.1f} {np.sqrt(((err / sig) ** 2).mean()):6.2f}")


if __name__ == "__main__":
    main()
