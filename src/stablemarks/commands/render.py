"""``stablemarks render``: simulate a scenario's run and write its stereo images with ground truth."""

from __future__ import annotations

import argparse
import json
import math
import time

import cv2
import yaml
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from ..errors import ImageError, InputError, expected
from ..io.calibration import save_camera_info_pair
from ..sim import builtin_scenarios, load_scenario, simulate_run
from ..sim.render import renderer_for
from ._common import check_out_dir, out_dir_arg

NAME = "render"
HELP = "render a simulated scenario: stereo PNGs, map, calibration and per-frame ground truth"
DESCRIPTION = (
    "Simulate the robot's run through SCENARIO (a built-in name such as 'lab', or a scenario YAML file) and "
    "write into DIR: frame_NNNNNN_left.png / _right.png for each rendered frame, map.yaml (the robot's map), "
    "calib/left.yaml / calib/right.yaml (ROS camera_info of the rectified pair) and calib/mount.yaml (where the head "
    "sits on the robot), groundtruth.json (per frame: true pose, "
    "pan, noisy odometry, dead reckoning, and every vertical image edge with its true position and "
    "visibility) and map.png (a picture of the scenario and the run). The seed fixes odometry and image noise."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", metavar="SCENARIO",
                        help=f"built-in scenario ({', '.join(builtin_scenarios())}) or a scenario YAML file")
    out_dir_arg(parser)
    parser.add_argument("--seed", type=int, default=None, metavar="N",
                        help="seed of the run (default: the scenario's seed)")
    parser.add_argument("--frames", default="all", metavar="all|I,J,...",
                        help="frames to render: 'all' (default) or comma-separated indices, e.g. 0,10,20")


def parse_frames(text: str, n: int) -> list[int]:
    """``"all"`` → every frame; ``"0,10,20"`` → those indices (each in ``[0, n)``), in the order given."""
    if text.strip() == "all":
        return list(range(n))
    try:
        frames = [int(part) for part in text.split(",")]
    except ValueError:
        raise InputError(expected("'all' or comma-separated frame indices, e.g. 0,10,20", text,
                                  where="--frames")) from None
    bad = [k for k in frames if not 0 <= k < n]
    if bad:
        raise InputError(expected(f"frame indices in [0, {n - 1}]", bad[0], where="--frames"))
    return list(dict.fromkeys(frames))


def run(args: argparse.Namespace) -> int:
    out = check_out_dir(args.out)
    scenario = load_scenario(args.scenario)
    if args.seed is not None and not 0 <= args.seed < 2**63:
        raise InputError(expected("a non-negative seed below 2**63", args.seed, where="--seed"))
    sim = simulate_run(scenario, args.seed)
    frames = parse_frames(args.frames, len(sim))

    console = Console(soft_wrap=True, highlight=False)
    renderer = renderer_for(scenario)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    start = time.perf_counter()
    with Progress(TextColumn("rendering"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  console=console, transient=True) as progress:
        task = progress.add_task("frames", total=len(frames))
        for k in frames:
            frame = sim.render(k, renderer)
            names = {}
            for side, image in (("left", frame.left), ("right", frame.right)):
                name = f"frame_{k:06d}_{side}.png"
                if not cv2.imwrite(str(out / name), image):
                    raise ImageError(f"{out / name}: cannot write image")
                names[side] = name
            records.append({**names, **sim.record(k, frame)})
            progress.advance(task)
    elapsed = time.perf_counter() - start

    from ..viz.scene import save_scene_figure

    scenario.map.save(out / "map.yaml")
    save_camera_info_pair(out / "calib", scenario.camera)
    cam = scenario.camera
    (out / "calib" / "mount.yaml").write_text(yaml.safe_dump({"mount": {
        "x": cam.mount_x, "y": cam.mount_y, "height": cam.mount_height, "pan_deg": math.degrees(cam.pan)}},
        sort_keys=False))
    (out / "groundtruth.json").write_text(json.dumps({**sim.header(), "frames": records}, indent=1, allow_nan=False))
    save_scene_figure(out / "map.png", scenario, sim)

    cam = scenario.camera
    console.print(f"Scenario [bold]{scenario.name}[/bold] ({scenario.source}), seed {sim.seed}: "
                  f"{len(frames)} of {len(sim)} frames rendered in {elapsed:.1f} s "
                  f"({elapsed / max(1, len(frames)):.2f} s per stereo pair)")
    console.print(f"Camera {cam.width}x{cam.height} px, f = {cam.f:g} px, baseline = {cam.baseline:g} m, "
                  f"height = {cam.mount_height:g} m, image noise σ = {scenario.image_noise:g} gray levels")
    last = sim.poses[frames[-1]]
    drift = sim.dead_reckoning[frames[-1]].translation - last.translation
    console.print(f"Frame {frames[-1]}: true pose ({last.x:.3f}, {last.y:.3f}) m, dead-reckoning error "
                  f"{float((drift @ drift) ** 0.5):.3f} m")
    console.print(f"Wrote {out}/: frame_*_left.png, frame_*_right.png, map.yaml, calib/left.yaml, "
                  "calib/right.yaml, calib/mount.yaml, groundtruth.json, map.png")
    return 0
