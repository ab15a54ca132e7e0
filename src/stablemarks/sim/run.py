"""A simulated run: the robot drives a scenario's path, reads noisy odometry and pans its head.

Randomness comes from one seed through independent streams (``numpy.random.SeedSequence`` spawn keys):
``(0,)`` draws the odometry of the whole run, ``(1, k)`` the exposure and sensor noise of frame ``k`` — so
rendering any subset of frames gives the same images as rendering all of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import SE2
from ..motion import increments, integrate, look_at_free_edges, plan_path
from .render import Renderer, SimFrame, renderer_for
from .scenario import Scenario


@dataclass(frozen=True)
class Run:
    """Per-frame true poses, noisy odometry, dead reckoning and pans of a run (all of length ``n``).

    ``odometry[k]`` is the noisy increment from frame ``k - 1`` to frame ``k`` in the robot frame of frame
    ``k - 1`` (``odometry[0]`` is the identity); ``dead_reckoning`` integrates it from the true start.
    ``pans[k]`` follows the scenario's pan policy from the *dead-reckoning* pose (what the robot believes).
    """

    scenario: Scenario
    seed: int
    poses: tuple[SE2, ...]
    odometry: tuple[SE2, ...]
    dead_reckoning: tuple[SE2, ...]
    pans: tuple[float, ...]

    def __len__(self) -> int:
        return len(self.poses)

    def frame_rng(self, k: int) -> np.random.Generator:
        """The random stream of frame ``k``'s exposure and sensor noise."""
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(1, k)))

    def render(self, k: int, renderer: Renderer | None = None) -> SimFrame:
        """Render frame ``k`` (its images depend only on the seed and ``k``)."""
        renderer = renderer or renderer_for(self.scenario)
        return renderer.render(self.poses[k].as_array(), self.pans[k], self.frame_rng(k))

    def record(self, k: int, frame: SimFrame) -> dict:
        """JSON-ready ground truth of frame ``k``: truth of the frame plus odometry and dead reckoning."""
        true_delta = self.poses[k - 1].between(self.poses[k]) if k else SE2()
        noise = self.scenario.robot.odometry
        return {
            "index": k,
            **frame.truth.to_dict(),
            "odometry": self.odometry[k].as_array().tolist(),
            "odometry_true": true_delta.as_array().tolist(),
            "cov_odometry": noise.covariance(self.odometry[k]).tolist(),
            "dead_reckoning": self.dead_reckoning[k].as_array().tolist(),
        }

    def header(self) -> dict:
        """JSON-ready description of the run (scenario, seed, camera, noise figures)."""
        sc = self.scenario
        cam = sc.camera
        return {
            "scenario": sc.name,
            "seed": self.seed,
            "n_frames": len(self),
            "camera": {
                "width": cam.width, "height": cam.height, "f": cam.f, "cu": cam.cu, "cv": cam.cv,
                "baseline": cam.baseline, "mount_x": cam.mount_x, "mount_y": cam.mount_y,
                "mount_height": cam.mount_height, "image_noise": sc.image_noise,
                "pan_limits": list(sc.pan_limits),
            },
            "odometry_noise": {
                "trans_per_m": sc.robot.odometry.trans_per_m, "rot_per_m_deg": sc.robot.odometry.rot_per_m_deg,
                "rot_per_rad": sc.robot.odometry.rot_per_rad, "trans_per_rad": sc.robot.odometry.trans_per_rad,
            },
            "units": "metres, radians, pixels; poses (x, y, theta) in the world; odometry in the previous robot frame",
        }


def simulate_run(scenario: Scenario, seed: int | None = None) -> Run:
    """Plan the scenario's path, draw its odometry and choose the pan of every frame (no rendering).

    ``seed`` defaults to the scenario's ``seed``.
    """
    seed = scenario.seed if seed is None else int(seed)
    plan = scenario.robot
    poses = plan_path(plan.start, plan.path, plan.frame_spacing, plan.frame_turn)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))
    odometry = [SE2()] + [plan.odometry.sample(d, rng) for d in increments(poses)]
    believed = integrate(plan.start, odometry[1:])
    pans: list[float] = []
    world_map = scenario.map
    for X in believed:
        if plan.pan.policy == "fixed":
            pans.append(float(np.clip(plan.pan.angle, *scenario.pan_limits)))
        else:
            default = pans[-1] if pans else plan.pan.angle
            pans.append(look_at_free_edges(world_map, scenario.camera, X.as_array(), limits=scenario.pan_limits,
                                           default=default, view_fraction=None))
    return Run(scenario, seed, tuple(poses), tuple(odometry), tuple(believed), tuple(pans))
