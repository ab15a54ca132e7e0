"""``log.jsonl`` names every candidate the frame modelled and every boundary it found, with the reason when one
is not used (issue 14: rejections in the log as in ``landmarks.csv``)."""

from __future__ import annotations

import json

from stablemarks import landmarks
from stablemarks.cli import main
from stablemarks.io.results import log_line
from stablemarks.localizer import REASON_BOUNDARY_RECHECK

from .test_sources import N_FRAMES, write_lab_sequence

REASONS = {v for k, v in vars(landmarks).items() if k.startswith("REASON_")} | {REASON_BOUNDARY_RECHECK}
CLUTTER = {landmarks.REASON_OFF_WALL, landmarks.REASON_HEIGHT, landmarks.REASON_BESIDE_NEARER}


def check_line(d: dict, planes: set[str]) -> None:
    for c in d["candidates"]:
        assert set(c) == {"plane", "index", "pair", "u_left", "u_right", "edge", "s", "selected", "reason"}, c
        assert c["plane"] in planes and c["edge"] in ("p1", "p2")
        assert isinstance(c["s"], float) and isinstance(c["u_left"], float)
        assert (c["reason"] is None) == c["selected"], c
        assert c["reason"] is None or c["reason"] in REASONS, c
    for b in d["boundaries"]:
        assert b["plane"] in planes and b["edge"] in ("p1", "p2")
        assert (b["reason"] is None) == b["used"], b
        assert b["reason"] is None or b["reason"].startswith("plane "), b


def test_run_logs_every_candidate_with_its_decision(tmp_path, capsys):
    folder = write_lab_sequence(tmp_path / "lab")
    out = tmp_path / "out"
    assert main(["run", str(folder), "--out", str(out), "--no-figures"]) == 0
    lines = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    assert len(lines) == N_FRAMES
    from stablemarks.sim.scenario import load_scenario

    planes = {p.id for p in load_scenario("lab").map.planes}
    for d in lines:
        check_line(d, planes)
    cands = [c for d in lines for c in d["candidates"]]
    assert any(c["selected"] for c in cands) and any(not c["selected"] for c in cands)
    assert any(b["used"] for d in lines for b in d["boundaries"])
    # the paper's own rejection (Table 1: partition 2 near its boundary) is in the first frame's line
    assert landmarks.REASON_NEAR_BOUNDARY in {c["reason"] for c in lines[0]["candidates"]}


def test_clutter_in_front_of_a_wall_is_rejected_with_its_reason_in_the_log():
    from stablemarks.online import run_online
    from stablemarks.sim.run import simulate_run
    from stablemarks.sim.scenario import load_scenario
    from stablemarks.sim.source import SimulatedSource

    scenario = load_scenario("office")
    result = run_online(SimulatedSource(simulate_run(scenario), frames=2))
    lines = [json.loads(log_line(r)) for r in result.records]
    planes = {p.id for p in scenario.map.planes}
    for d in lines:
        check_line(d, planes)
    reasons = {c["reason"] for d in lines for c in d["candidates"]}
    # the office's clutter: a line of something standing in front of a wall, and the whiteboard's end hidden by it
    assert reasons & CLUTTER, reasons
    unused = [b for d in lines for b in d["boundaries"] if not b["used"]]
    assert unused and all("not used" in b["reason"] for b in unused), unused
