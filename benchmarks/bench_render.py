"""Time the stereo simulator on the built-in ``lab`` scenario (640×480, 4 sub-columns per pixel).

Run: ``.venv/bin/python benchmarks/bench_render.py [--repeat N]``. Prints the one-off world build (textures),
the median time of one stereo pair with ground truth and noise, and its parts, against the 1 s budget.
"""

from __future__ import annotations

import argparse
import statistics
import time

from stablemarks.sim import Renderer, frame_truth, load_scenario, simulate_run


def median_time(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=10)
    args = parser.parse_args()
    scenario = load_scenario("lab")
    run = simulate_run(scenario)
    start = time.perf_counter()
    renderer = Renderer(scenario)
    build = time.perf_counter() - start
    k = 10
    X, pan = run.poses[k].as_array(), run.pans[k]
    camera = scenario.camera.with_pan(pan)
    run.render(k, renderer)  # warm-up
    pair = median_time(lambda: run.render(k, renderer), args.repeat)
    clean = median_time(lambda: renderer.render_clean(X, pan), args.repeat)
    truth = median_time(lambda: frame_truth(renderer.world, camera, run.poses[k]), args.repeat)
    cam = scenario.camera
    print(f"lab scenario, {cam.width}x{cam.height} px, {renderer.supersample} sub-columns per pixel, frame {k}, "
          f"median of {args.repeat}")
    print(f"  world build (textures, once per scenario): {build * 1e3:7.1f} ms")
    print(f"  stereo pair with truth and noise:          {pair * 1e3:7.1f} ms   ({pair / 1.0:.2f} of the 1 s budget)")
    print(f"    of which noise-free images:              {clean * 1e3:7.1f} ms")
    print(f"    of which ground truth (16 edges):        {truth * 1e3:7.1f} ms")


if __name__ == "__main__":
    main()
