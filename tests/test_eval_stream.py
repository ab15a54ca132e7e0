"""eval speaks when its output is a file, keeps every finished task in trials.jsonl, resumes, and compares pan
policies side by side."""

import json

from stablemarks.cli import main


def test_lines_per_task_and_resume(tmp_path, capsys):
    out = tmp_path / "ev"
    argv = ["eval", "lab", "--frames", "3", "--methods", "stablemarks,dead_reckoning", "--out", str(out),
            "--no-figures"]
    assert main(argv + ["--trials", "2"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("lab ")]
    assert len(lines) == 4 and all("ATE" in line and line.rstrip().endswith("/4)") for line in lines)
    first = [json.loads(x) for x in (out / "trials.jsonl").read_text().splitlines()]
    # each line's seconds are its task's own: its frames' time, whatever else ran meanwhile
    for line, r in zip(lines, first, strict=True):
        seconds = f"{r['time_per_frame'] * r['frames']:.1f} s"
        assert f"trial {r['trial']}:" in line and line.split(", ")[-1].startswith(seconds)
    # an interruption after the first task: only its line is kept, and --resume runs the other three
    (out / "trials.jsonl").write_text(json.dumps(first[0]) + "\n" + '{"torn')
    assert main(argv + ["--trials", "2", "--resume"]) == 0
    ran = [line for line in capsys.readouterr().out.splitlines() if line.startswith("lab ")]
    assert len(ran) == 3
    again = [json.loads(x) for x in (out / "trials.jsonl").read_text().splitlines()]
    assert len(again) == 4 and again[0] == first[0]
    assert {(r["trial"], r["method"]) for r in again} == {(r["trial"], r["method"]) for r in first}


def test_pan_policies_side_by_side(tmp_path, capsys):
    out = tmp_path / "ev"
    assert main(["eval", "lab", "--trials", "1", "--frames", "3", "--methods", "stablemarks", "--pan-policy",
                 "fixed,information", "--out", str(out), "--no-figures"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["lab"]) == {"stablemarks@fixed", "stablemarks@information"}
    report = (out / "report.md").read_text()
    assert "stablemarks@fixed" in report and "stablemarks@information" in report
    assert main(["eval", "lab", "--trials", "1", "--pan-policy", "wander", "--out", str(out)]) == 1
    assert "--pan-policy: expected one of fixed, free_edges, information" in capsys.readouterr().err
