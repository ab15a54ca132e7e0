"""Accuracy of the stereo front end on the simulated lab: `python benchmarks/lab_segment_accuracy.py`.

For frames 0, 10 and 20 of the `lab` run (the paper's first view, 1 m and 2 m), every true vertical edge of
the partition and the whiteboard that is visible is looked up among the extracted segments (same rows, within
2 px), and among the kept segment pairs (both columns within 1 px). Prints how many were found and the
column errors.
"""

import numpy as np

from stablemarks.pipeline import run_front_end
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario


def main() -> None:
    sc = load_scenario("lab")
    run = simulate_run(sc)
    errs, found, total, pairs_ok, pairs_total = [], 0, 0, 0, 0
    for k in (0, 10, 20):
        fr = run.render(k)
        front = run_front_end(fr.left, fr.right)
        for segs, key in ((front.left_segments, "u_l"), (front.right_segments, "u_r")):
            for e in fr.truth.edges:
                visible = e.visible_l if key == "u_l" else e.visible_r
                if not visible or e.wall not in ("partition", "whiteboard"):
                    continue
                total += 1
                v_mid = 0.5 * (max(e.v_top, 0.0) + min(e.v_bottom, sc.camera.height - 1.0))
                overlap = (segs.v_top < e.v_bottom) & (segs.v_bottom > e.v_top)
                d = np.where(overlap, np.abs(segs.u_at(v_mid) - getattr(e, key)), np.inf)
                if len(d) and d.min() < 2.0:
                    found += 1
                    errs.append(float(d.min()))
        p = front.kept_pairs
        for e in fr.truth.edges:
            if e.visible_l and e.visible_r and e.wall in ("partition", "whiteboard"):
                pairs_total += 1
                pairs_ok += bool(((np.abs(p.u_left - e.u_l) < 1.0) & (np.abs(p.u_right - e.u_r) < 1.0)).any())
    errs = np.array(errs)
    print(f"lab frames 0, 10, 20: {found}/{total} true edges of the two planes found as segments; column error "
          f"median {np.median(errs):.3f} px, 95th percentile {np.percentile(errs, 95):.3f} px, "
          f"max {errs.max():.3f} px; "
          f"{pairs_ok}/{pairs_total} true stereo pairs matched and kept (both columns within 1 px)")


if __name__ == "__main__":
    main()
