"""Which landmarks count against the selection's precision, and what they were made from.

Runs the full method on simulated scenarios (the evaluation's start belief and trial seeds) and, for every
landmark it enters that the evaluation does not match to a true on-plane feature
(:func:`stablemarks.evaluation._match_truth`, the rule of ``selection_precision``), prints the frame, the wall,
its image columns, its modelled position and σ along the wall, and the true image edges nearest its columns in
that frame: their kind (``feature`` / ``boundary``), wall, world distance from the landmark [mm] and column
offsets [px]. A ``boundary`` edge there means a plane's end was taken for a feature; an edge of another wall,
or of an unmapped object (``clutter``, a wall that is no reference plane), means something off the wall
entered; a feature of the same wall a few cm away means the landmark was placed too far off to be matched.

    python benchmarks/false_landmarks.py office benchmarks/scenarios/storeroom.yaml --trials 3
"""

import argparse
from collections import Counter

import numpy as np

from stablemarks.config import Config
from stablemarks.evaluation import DEFAULT_COV0, _match_truth, start_belief, trial_seeds
from stablemarks.landmarks import nearer_than_fit
from stablemarks.localizer import Localizer
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def nearest_edges(truth, c, n: int = 3) -> list[tuple]:
    """The ``n`` true edges visible in both images nearest candidate ``c``'s columns (sum of both images)."""
    rows = []
    for e in truth.edges:
        if not (e.visible_l and e.visible_r):
            continue
        du = abs(e.u_l - c.u_left) + abs(e.u_r - c.u_right)
        rows.append((du, e))
    rows.sort(key=lambda r: r[0])
    return [(e, e.u_l - c.u_left, e.u_r - c.u_right, 1e3 * float(np.hypot(e.x - c.P[0], e.y - c.P[1])))
            for _, e in rows[:n]]


def side_z(camera, fit, disparity_left, c, window: int, sigma_nu: float) -> tuple[float, float]:
    """Per side of ``c``'s left line (left, right): how much nearer than the *fitted* wall the disparity just beyond
    the line is, as a z-score: the median over the line's rows of each row's median ``d − d_fit`` over offsets of
    half a window to a window, over the standard error of that median (rows correlated over one window; the
    larger of the model's ``σ_ν`` and the rows' own spread)."""
    X = np.asarray(fit.X, dtype=float)
    cam = camera.camera_pose(X)
    fwd = np.array([np.cos(cam.theta), np.sin(cam.theta)])
    right = np.array([np.sin(cam.theta), -np.cos(cam.theta)])
    plane = fit.plane
    c_s, c_o = float(plane.along(cam.translation)), float(plane.offset(cam.translation))
    fb = camera.f * camera.baseline
    H, W = disparity_left.shape
    v0, v1 = max(0, int(np.ceil(c.v_top))), min(H - 1, int(np.floor(c.v_bottom)))
    out = []
    for side in (-1, 1):
        rows = []
        for v in range(v0, v1 + 1):
            vals = []
            for off in range(window // 2 + 1, window + 2):
                col = int(round(c.u_left + side * off))
                if not 0 <= col < W:
                    continue
                d = float(disparity_left[v, col])
                if not np.isfinite(d):
                    continue
                r = fwd + (col - camera.cu) / camera.f * right
                r_s, r_o = float(r @ plane.direction), float(r @ plane.normal)
                Z = (fit.a + fit.b * (c_s - fit.s0) - c_o) / (r_o - fit.b * r_s)
                if Z <= 0:
                    continue
                vals.append(d - fb / Z)
            if vals:
                rows.append(float(np.median(vals)))
        if len(rows) < 5:
            out.append(float("nan"))
            continue
        rows = np.array(rows)
        m = float(np.median(rows))
        spread = max(sigma_nu, 1.4826 * float(np.median(np.abs(rows - m))))
        n_eff = max(1.0, len(rows) / window)
        out.append(m / (1.2533 * spread / np.sqrt(n_eff)))
    return out[0], out[1]


def false_entries(name: str, trials: int, frames: int | None, config: Config):
    sc = load_scenario(name)
    refs = {p.id for p in sc.map.planes if p.reference}
    kinds: Counter = Counter()
    total = 0
    true_z = []
    for t, seed in enumerate(trial_seeds(sc.seed, trials)):
        run = simulate_run(sc, seed)
        source = SimulatedSource(run, frames=frames)
        cfg = config.with_source_defaults(source.config_defaults)
        loc = Localizer(source.world_map, source.camera, start_pose=start_belief(run, DEFAULT_COV0),
                        start_cov=DEFAULT_COV0, config=cfg)
        source.steer(loc.command_pan)
        for k, frame in enumerate(source):
            est = loc.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
            for c in est.entered.candidates:
                if c is None:
                    continue
                total += 1
                tid = _match_truth(frame.truth, c)
                edge = next((e for e in frame.truth.edges if e.id == tid), None)
                fit = next((m.fit for m in est.model.planes if m.fit.plane.id == c.plane_id), None)
                z = side_z(source.camera.with_pan(frame.pan), fit, est.front.disparity.left, c, cfg.sad.block_size,
                           cfg.planes.sigma_nu(source.camera)) if fit is not None else (np.nan, np.nan)
                if fit is not None:
                    slope = float(est.front.left_segments.slope[est.front.kept_pairs.left_index][c.pair])
                    lib = float(nearer_than_fit(source.camera.with_pan(frame.pan), fit, est.front.disparity.left,
                                                [c.u_left], [c.v_top], [c.v_bottom], [slope], cfg.sad.block_size,
                                                cfg.planes.sigma_nu(source.camera))[0])
                else:
                    lib = float("nan")
                if edge is not None and edge.kind == "feature" and edge.wall in refs:
                    true_z.append(max(z))
                    if max(z) > 3:
                        print(f"{sc.name} trial {t} frame {k:3d} {c.plane_id:>12s} true feature {edge.feature} "
                              f"u=({c.u_left:6.1f},{c.u_right:6.1f}) z=[{c.z_low:4.2f},{c.z_high:4.2f}] "
                              f"range={c.range:4.1f} side z=({z[0]:+5.1f},{z[1]:+5.1f})")
                    continue
                near = nearest_edges(frame.truth, c)
                e0 = near[0][0] if near else None
                kind = ("nothing" if e0 is None else e0.kind if e0.wall == c.plane_id
                        else "other wall" if e0.wall in refs else "unmapped")
                if e0 is not None and e0.wall == c.plane_id and e0.kind == "feature":
                    kind = "feature too far"
                kinds[kind] += 1
                print(f"{sc.name} trial {t} frame {k:3d} {c.plane_id:>12s} {c.edge} s={c.s:6.3f} "
                      f"σs={1e3 * c.sigma_s:5.1f}mm u=({c.u_left:6.1f},{c.u_right:6.1f}) "
                      f"z=[{c.z_low:4.2f},{c.z_high:4.2f}] range={c.range:4.1f} inc={np.degrees(c.incidence):4.0f}° "
                      f"off={1e3 * c.wall_offset:5.1f}±{1e3 * c.sigma_wall_offset:4.1f}mm  "
                      f"side z=({z[0]:+5.1f},{z[1]:+5.1f}) nearer_than_fit {lib:+5.1f}  -> {kind}")
                for e, dl, dr, dist in near:
                    print(f"      {e.kind:8s} {e.wall:>12s} {e.feature:>14s} z=[{e.z[0]:4.2f},{e.z[1]:4.2f}] "
                          f"du=({dl:+6.1f},{dr:+6.1f}) px  {dist:7.1f} mm")
    return total, kinds, np.array(true_z)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--frames", type=int, default=0, help="first N frames of each run (0: all)")
    args = ap.parse_args()
    for name in args.scenarios:
        total, kinds, true_z = false_entries(name, args.trials, args.frames or None, Config())
        bad = sum(kinds.values())
        if len(true_z):
            q = np.nanpercentile(true_z, [50, 90, 99, 100])
            print(f"   true features' larger side z: median {q[0]:.1f}, 90 % {q[1]:.1f}, 99 % {q[2]:.1f}, "
                  f"max {q[3]:.1f} (n = {len(true_z)}); above 3: {int(np.sum(true_z > 3))}, "
                  f"above 4: {int(np.sum(true_z > 4))}")
        print(f"== {name}: {bad} of {total} entered landmarks not on a true feature "
              f"(precision {1 - bad / max(total, 1):.2f}): {dict(kinds)}")


if __name__ == "__main__":
    main()
