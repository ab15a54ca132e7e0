"""Time the parts of the `planes` and `landmarks` stages of `stablemarks bench` on the lab frame:
`python benchmarks/bench_stages.py [--repeats 50] [--profile planes|landmarks]`.

Single-threaded like the bench; prints the median and the minimum of each part [ms] (the machine may be
shared: the minimum is the steadier figure). `--profile` runs cProfile over the stage and prints the
functions of largest own time.
"""

import argparse
import cProfile
import pstats

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from stablemarks.bench import lab_pair, wall_times
from stablemarks.config import Config
from stablemarks.landmarks import landmarks_on_plane, model_features, search_boundary, select
from stablemarks.maps import visible_parts
from stablemarks.pipeline import run_front_end, valid_columns
from stablemarks.planes import fit_plane, plane_members, predict_planes


def times(fn, repeats: int) -> tuple[float, float]:
    """Median and minimum wall time of ``fn()`` [ms] after two warm-up calls."""
    out = wall_times(fn, repeats, warmup=2)
    return 1000 * float(np.median(out)), 1000 * float(np.min(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument("--profile", choices=("planes", "landmarks"))
    args = ap.parse_args()
    config = Config()
    frame, scenario, run, camera = lab_pair()
    X = run.poses[0].as_array()
    cov_X = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
    world_map = scenario.map  # built once, as the on-line loop holds it
    cv2.setNumThreads(1)
    with threadpool_limits(1):
        front = run_front_end(frame.left, frame.right, config)
        disp, pairs, seg_l = front.disparity, front.kept_pairs, front.left_segments
        preds = predict_planes(camera, X, cov_X, world_map, config.planes)
        fits = [f for f in (fit_plane(camera, X, disp.left, p, config.planes) for p in preds) if f]
        models = [landmarks_on_plane(camera, f, pairs, seg_l, disp.right, config.landmarks, config.planes,
                                     float(config.sad.block_size), valid_columns(disp)) for f in fits]

        def planes():
            return [fit_plane(camera, X, disp.left, p, config.planes)
                    for p in predict_planes(camera, X, cov_X, world_map, config.planes)]

        def landmarks():
            cols = valid_columns(disp)
            return [landmarks_on_plane(camera, f, pairs, seg_l, disp.right, config.landmarks, config.planes,
                                       float(config.sad.block_size), cols) for f in fits]

        members_u = [np.stack([pairs.u_left[m.members], pairs.u_right[m.members]], axis=-1) for m in models]
        parts = {
            "planes (stage)": planes,
            "  predict_planes": lambda: predict_planes(camera, X, cov_X, world_map, config.planes),
            "    visible_parts": lambda: visible_parts(world_map, camera, X, max_range=config.planes.max_range,
                                                   margin_px=-config.planes.view_margin_px,
                                                   planes=world_map.reference_planes),
            "  fit_plane": lambda: [fit_plane(camera, X, disp.left, p, config.planes) for p in preds],
            "landmarks (stage)": landmarks,
            "  valid_columns": lambda: valid_columns(disp),
            "  plane_members": lambda: [plane_members(f, pairs, seg_l, config.planes) for f in fits],
            "  search_boundary": lambda: [search_boundary(camera, f, e, disp.right, mu, config.landmarks,
                                                          config.planes, float(config.sad.block_size))
                                          for f, mu in zip(fits, members_u, strict=True) for e in f.plane.free_edges],
            "  model_features": lambda: [model_features(camera, m.fit, m.boundaries[0], pairs,
                                                        np.flatnonzero(m.members)) for m in models if m.boundaries],
            "  select": lambda: [select(m.candidates, m.boundaries, config.landmarks) for m in models],
        }
        print(f"lab frame 0, {len(preds)} planes, {len(pairs)} pairs, {args.repeats} repeats")
        print(f"{'':22s} {'median':>8s} {'min':>8s}  [ms]")
        for name, fn in parts.items():
            med, low = times(fn, args.repeats)
            print(f"{name:22s} {med:8.2f} {low:8.2f}")
        if args.profile:
            fn = planes if args.profile == "planes" else landmarks
            prof = cProfile.Profile()
            prof.enable()
            for _ in range(args.repeats):
                fn()
            prof.disable()
            pstats.Stats(prof).sort_stats("tottime").print_stats(20)


if __name__ == "__main__":
    main()
