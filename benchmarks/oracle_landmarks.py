"""Is the pose filter itself consistent? The method run with every landmark replaced, when it enters, by its true
position along its wall.

A diagnosis, not a method: it reads the simulator's truth. Each frame runs the full method (front end, model,
selection, association, update) on a simulated trial (the evaluation's start belief and trial seeds); right after
the frame, every wall landmark it entered is moved to the true along-wall position of the feature it was modelled
from (the evaluation's matching, :func:`stablemarks.evaluation._match_truth`; a landmark without one is removed)
and given a variance of its own, uncorrelated with the rest of the state: ``--sigma-px`` pixels at the view it was
entered from (the along-wall length of that many pixels at its range and incidence) or ``--sigma-mm``
millimetres. Printed per scenario: the mean pose NEES over all frames and trials (3 dof), each trial's mean, and
the per-frame average of the first 25 frames.

If the pose NEES is about 3 here while the method's own landmarks give less, the filter's prediction, observation
model and update are consistent, and what makes the pose cautious is the landmark map (the landmarks' entry
covariance against their actual errors).

    python benchmarks/oracle_landmarks.py lab corridor room --trials 6 --sigma-px 0.05
    python benchmarks/oracle_landmarks.py lab --sigma-mm 1 --config my.yaml
"""

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from stablemarks.config import load_config
from stablemarks.errors import ConfigError
from stablemarks.evaluation import DEFAULT_COV0, _match_truth, start_belief, trial_seeds
from stablemarks.localizer import Localizer
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import SimulatedSource


def _true_landmarks(ekf, est, truth, pose, f: float, sigma_px: float | None, sigma_m: float | None) -> None:
    """Move the frame's entered wall landmarks onto their true features (diagnosis only: private state)."""
    if not est.entered.ids:
        return
    edges = {e.id: e for e in truth.edges}
    for c, i in zip(est.entered.candidates, est.entered.ids, strict=True):
        if i not in ekf.landmark_ids:
            continue
        tid = _match_truth(truth, c) if c is not None else None
        if tid is None:
            ekf.remove_landmark(i)
            continue
        r = int(ekf._rows([i], "oracle")[0])
        j = int(ekf._idx2[r, 0])
        J = ekf._J_p_l[r][:, 0]
        p = np.array([edges[tid].x, edges[tid].y])
        ekf._x[j] = float((p - ekf._start[r]) @ J / (J @ J))
        if sigma_m is None:
            view = p - pose[:2]
            rng = float(np.hypot(*view))
            normal = np.array([-J[1], J[0]]) / np.hypot(*J)
            cos_inc = max(abs(float(view @ normal)) / rng, 0.2)
            sigma = sigma_px * rng / (f * cos_inc)
        else:
            sigma = sigma_m
        ekf._P[j, :] = 0.0
        ekf._P[:, j] = 0.0
        ekf._P[j, j] = sigma**2


def run_trial(task) -> tuple[str, np.ndarray]:
    name, sc, trial, config, sigma_px, sigma_m = task
    run = simulate_run(sc, trial_seeds(sc.seed, trial + 1)[trial])
    source = SimulatedSource(run)
    config = config.with_source_defaults(source.config_defaults)
    loc = Localizer(source.world_map, source.camera, start_pose=start_belief(run, DEFAULT_COV0),
                    start_cov=DEFAULT_COV0, config=config)
    source.steer(loc.command_pan)
    nees = []
    for k, frame in enumerate(source):
        est = loc.step(frame.stamp, frame.left, frame.right, odometry=frame.odometry, pan=frame.pan)
        truth_pose = run.poses[k].as_array()
        _true_landmarks(loc.ekf, est, frame.truth, truth_pose, float(source.camera.f), sigma_px, sigma_m)
        e = loc.ekf.pose - truth_pose
        e[2] = (e[2] + np.pi) % (2 * np.pi) - np.pi
        nees.append(float(e @ np.linalg.solve(loc.ekf.cov_pose, e)))
    return name, np.array(nees)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--trials", type=int, default=6)
    ap.add_argument("--config", help="configuration YAML")
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--sigma-px", type=float, default=0.05, help="landmark σ in pixels at its entry view (0.05)")
    group.add_argument("--sigma-mm", type=float, help="landmark σ in millimetres instead")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    if args.trials < 1 or args.jobs < 1:
        ap.error("--trials and --jobs must be at least 1")
    try:  # loaded once here, handed to the workers
        config = load_config(args.config)
        scenarios = [(name, load_scenario(name)) for name in args.scenarios]
    except ConfigError as e:
        ap.error(str(e))
    sigma_m = None if args.sigma_mm is None else args.sigma_mm / 1000.0
    if (sigma_m if sigma_m is not None else args.sigma_px) <= 0:
        ap.error("the landmark σ must be positive")
    tasks = [(name, sc, t, config, args.sigma_px, sigma_m) for name, sc in scenarios for t in range(args.trials)]
    results: dict[str, list[np.ndarray]] = {}
    with ProcessPoolExecutor(args.jobs) as ex:
        for scenario, nees in ex.map(run_trial, tasks):
            results.setdefault(scenario, []).append(nees)
    what = f"{args.sigma_mm:g} mm" if sigma_m is not None else f"{args.sigma_px:g} px at the entry view"
    print(f"true landmarks, σ {what}; pose NEES (3 dof: 3 when consistent)")
    for scenario, runs in results.items():
        n = min(len(r) for r in runs)
        per_frame = np.mean([r[:n] for r in runs], axis=0)
        print(f"{scenario}: {np.mean(np.concatenate(runs)):.2f}   per trial "
              + " ".join(f"{r.mean():.2f}" for r in runs))
        print("   per frame: " + " ".join(f"{v:.1f}" for v in per_frame[:25]))


if __name__ == "__main__":
    main()
