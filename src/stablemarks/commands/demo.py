"""``stablemarks demo``: the paper's experiment on the built-in ``lab`` scenario.

Renders the lab's first view, models and selects landmarks on the partition and the whiteboard, prints
our table beside the paper's Table 1 row by row, writes ``landmarks.csv`` / ``landmarks.json`` and the
figures; then drives the 1 m and 2 m motion with the joint EKF and prints its final error and
uncertainty beside dead reckoning.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from ._common import check_image_settings, check_out_dir, make_console, out_dir_arg, parse_sigmas

NAME = "demo"
HELP = "run the paper's lab experiment on the built-in scenario (Table 1, then the 1 m / 2 m motion)"

TABLE1_PLANES = {"partition": "partition", "whiteboard": "whiteboard"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    out_dir_arg(p, default="results/demo")
    p.add_argument("--scenario", default="lab", help="built-in scenario name or YAML path (default: lab)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    p.add_argument("--pose-sigma", default="0.05,0.05,1deg", metavar="SX,SY,STHETA",
                   help="standard deviations of the initial pose belief (default 0.05,0.05,1deg)")
    p.add_argument("--config", metavar="FILE", help="thresholds (YAML, see README)")
    p.add_argument("--no-motion", action="store_true", help="only the first view (Table 1)")


def run(args) -> int:
    from ..config import Config, parse_config
    from ..io.results import write_landmarks
    from ..maps import read_yaml
    from ..pipeline import process_frame
    from ..sim.run import simulate_run
    from ..sim.scenario import load_scenario
    from ..viz.scene import save_scene_figure
    from ._tables import landmark_table, match_table1, summary_counts, table1_comparison
    from .select import frame_figure_names, write_frame_figures

    console = make_console()
    out = check_out_dir(args.out)
    # the paper's noise values reproduce its Table 1; --config adds to them
    config = Config.preset("paper") if args.config is None else parse_config(
        read_yaml(args.config, "configuration file"), str(args.config), base=Config.preset("paper"))
    scenario = load_scenario(args.scenario)
    sigma = parse_sigmas(args.pose_sigma, "--pose-sigma")
    if args.seed is not None and not 0 <= args.seed < 2**63:
        from ..errors import InputError, expected

        raise InputError(expected("a non-negative seed below 2**63", args.seed, where="--seed"))
    check_image_settings(config, scenario.camera.width, scenario.camera.height, f"scenario {args.scenario}'s camera")
    out.mkdir(parents=True, exist_ok=True)
    sim = simulate_run(scenario, args.seed)
    frame = sim.render(0)
    import cv2

    cv2.imwrite(str(out / "frame_000000_left.png"), frame.left)
    cv2.imwrite(str(out / "frame_000000_right.png"), frame.right)
    save_scene_figure(out / "map.png", scenario, sim)
    X0 = sim.poses[0].as_array()
    cov0 = np.diag(sigma**2)
    camera = scenario.camera.with_pan(sim.pans[0])
    console.rule(f"[bold]{scenario.name}[/]: first view, landmark modeling and selection (paper Sec 6, Table 1)")
    result = process_frame(frame.left, frame.right, camera, scenario.map, X0, cov0, config, dense=True)  # Fig 6
    for w in result.warnings:
        console.print(f"[yellow]warning:[/] {w}")
    console.print(landmark_table(result.candidates, mm=True, title="stablemarks, first view"))
    summary = {}
    matches = None
    if scenario.name == "lab":
        matches, extra = match_table1(result.candidates, TABLE1_PLANES)
        console.print(table1_comparison(matches))
        counts = summary_counts(matches)
        summary["table1"] = counts
        console.print(
            f"Table 1: {counts['found']}/{counts['rows']} features found, selection decisions agree on "
            f"{counts['decisions_agree']}/{counts['found']}; largest σy {1000 * counts['sigma_y_max']:.2f} mm; "
            f"{len(extra)} further candidate(s) not in the paper's table "
            f"({', '.join(f'{c.plane_id} x={1000 * c.P[0]:.0f} mm: ' + (c.reason or 'selected') for c in extra)})."
        )
    truth = {"points": [[e.x, e.y] for e in frame.truth.edges if e.kind == "feature" and e.visible_l]}
    write_landmarks(out, result.candidates, extra={"pose": X0.tolist(), "cov_pose": cov0.tolist()})
    write_frame_figures(out, frame.left, frame.right, result, scenario.map, camera, truth, matches)
    console.print(f"wrote {out}/landmarks.csv, " + ", ".join(
        ["landmarks.json", "frame_000000_left.png", "frame_000000_right.png", *frame_figure_names(result), "map.png"]))
    if not args.no_motion:
        summary["motion"] = _motion(console, scenario, sim, out, cov0, config)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    console.print(f"wrote {out}/summary.json")
    return 0


def _motion(console, scenario, sim, out, cov0, config):
    """The 1 m and 2 m motion with the on-line loop: every frame predicted, observed, updated, and new
    landmarks selected; Figure 10 and the run's files in ``out``."""
    from ..evaluation import TruthObserver
    from ..io.results import write_run
    from ..online import run_online
    from ..sim.source import SimulatedSource
    from ..viz.trajectory import figure10
    from ._report import frame_progress, print_motion_summary

    console.rule("[bold]motion[/]: on-line selection and localization with the joint EKF (paper Sec 5, Figs 8-10)")
    source = SimulatedSource(sim)
    truth = TruthObserver()
    config = config.with_source_defaults(source.config_defaults)
    with frame_progress(console, "driving", len(sim)) as progress:
        result = truth.result(run_online(source, start_cov=cov0, config=config, observers=[truth], progress=progress))
    write_run(out, result, config)
    figure10(out / "fig10_motion.png", result)
    summary = print_motion_summary(console, result, config.odometry)
    console.print(f"wrote {out}/trajectory.tum, dead_reckoning.tum, groundtruth.tum, landmarks.yaml, log.jsonl, "
                  "fig10_motion.png")
    return summary
