"""How well the modelled uncertainty matches the actual error on the simulated lab:
`python benchmarks/lab_model_calibration.py`.

For 12 seeds, frames 0 and 10: every boundary found (error of P_b along the wall against the true free
edge) and every candidate feature (error of s against the nearest true edge), with the modelled σ;
`rms z` is the RMS of error/σ (1.0 = calibrated, below 1 = conservative).
"""

import numpy as np

from stablemarks.pipeline import process_frame
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario


def main(seeds: int = 12) -> None:
    sc = load_scenario("lab")
    cov0 = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
    rows = []
    for seed in range(seeds):
        run = simulate_run(sc, 200 + seed)
        for k in (0, 10):
            fr = run.render(k)
            cam = sc.camera.with_pan(run.pans[k])
            res = process_frame(fr.left, fr.right, cam, sc.map, run.poses[k].as_array(), cov0)
            truth = [e for e in fr.truth.edges if e.visible_l]
            for m in res.planes:
                for b in m.boundaries:
                    err = float((b.P - m.fit.plane.edge(b.edge)) @ b.inward)
                    rows.append(("boundary", m.fit.plane.id, b.edge, err, b.sigma_along))
            for c in res.candidates:
                plane = sc.map[c.plane_id]
                s_true = np.array([float(plane.along(np.array([e.x, e.y]), c.edge)) for e in truth
                                   if e.wall == c.plane_id])
                err = c.s - s_true[int(np.argmin(np.abs(s_true - c.s)))]
                rows.append(("feature", c.plane_id, c.edge, err, c.sigma_s))
    print(f"{'':9s} {'plane':10s} edge     n  mean err  rms err  mean σ  rms z   (mm)")
    for kind in ("boundary", "feature"):
        for pid in ("partition", "whiteboard"):
            for edge in ("p1", "p2"):
                z = np.array([(r[3], r[4]) for r in rows if r[:3] == (kind, pid, edge)])
                if not len(z):
                    continue
                err, sig = 1000 * z[:, 0], 1000 * z[:, 1]
                print(f"{kind:9s} {pid:10s} {edge:4s} {len(z):5d} {err.mean():9.1f} {np.sqrt((err**2).mean()):8.1f} "
                      f"{sig.mean():7.1f} {np.sqrt(((err / sig) ** 2).mean()):6.2f}")


if __name__ == "__main__":
    main()
