"""The stereo simulator: scenario files, a 2.5D ray-casting renderer, simulated runs and ground truth.

>>> from stablemarks.sim import load_scenario, simulate_run
>>> run = simulate_run(load_scenario("lab"))
>>> len(run)
21
"""

from .render import Renderer, SimFrame, render_stereo
from .run import Run, simulate_run
from .scenario import Scenario, builtin_scenarios, load_scenario, parse_scenario
from .source import SimulatedSource, steered_by_method
from .truth import EdgeTruth, FrameTruth, frame_truth

__all__ = [
    "EdgeTruth",
    "FrameTruth",
    "Renderer",
    "Run",
    "Scenario",
    "SimFrame",
    "SimulatedSource",
    "builtin_scenarios",
    "frame_truth",
    "load_scenario",
    "parse_scenario",
    "render_stereo",
    "simulate_run",
    "steered_by_method",
]
