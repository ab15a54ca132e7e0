"""The faults of the health issue on sequences made here: a slip or kidnap, a wrong pan, a pan left out.

For each scenario, simulates its run (`stablemarks simulate`, the scenario's seed or --seed; the head pointed by
the method, or with `--head scenario` by the scenario's rule on dead reckoning, as `simulate --head`), writes the clean
sequence and the edited ones, runs `stablemarks run` on each and prints one line per run: the ATE against dead
reckoning's [mm], the first `warning:` line's frame and condition, the frame of the first one that names the
pan (0 for the warning before the first frame that the recording gives no pans), the final position NEES (2 dof,
99 % bound 9.21), the ATE from three frames after the jump against dead reckoning's, and the number of warning
lines.

Faults: `kidnap` (+0.5 m in the odometry's y after frame 10), `kidnap-x` (+0.5 m in x), `kidnap-neg` (−0.5 m in
y), `kidnap25` (+0.5 m in y after frame 25), `pan` (every recorded pan +0.2 rad), `nopan` (the pan column left
out of frames.csv). The odometry is edited in its own frame: on lab (heading 90°) y is forward and x sideways.

    python benchmarks/fault_runs.py lab room corridor
    python benchmarks/fault_runs.py office --faults clean,kidnap,nopan --seed 7 --keep /tmp/faults
    python benchmarks/fault_runs.py corridor --faults nopan,pan --config my.yaml
"""

import argparse
import contextlib
import csv
import io
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np

from stablemarks.cli import main as cli
from stablemarks.sim.export import write_simulated_sequence
from stablemarks.sim.run import simulate_run
from stablemarks.sim.scenario import load_scenario
from stablemarks.sim.source import steered_by_method

FAULTS = ("clean", "kidnap", "kidnap-x", "kidnap-neg", "kidnap25", "pan", "nopan")


def _rewrite(path: Path, change) -> None:
    with open(path) as f:
        rows = list(csv.DictReader(f))
    rows, fields = change(rows)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def make_fault(clean: Path, fault: str, out: Path) -> tuple[Path | None, int | None]:
    """The sequence folder with ``fault`` applied, and the frame of the jump (None without one); ``(None, None)``
    when the run is too short for the jump."""
    after = 25 if fault == "kidnap25" else 10
    with open(clean / "frames.csv") as f:
        if fault.startswith("kidnap") and sum(1 for _ in f) - 1 <= after + 4:
            return None, None
    shutil.copytree(clean, out)
    if fault.startswith("kidnap"):
        column, amount = ("x", 0.5) if fault == "kidnap-x" else ("y", -0.5 if fault == "kidnap-neg" else 0.5)

        def jump(rows):
            for k, r in enumerate(rows):
                if k > after:
                    r[column] = repr(float(r[column]) + amount)
            return rows, list(rows[0])
        _rewrite(out / "odometry.csv", jump)
        return out, after + 1
    if fault == "pan":
        _rewrite(out / "frames.csv", lambda rows: ([{**r, "pan": repr(float(r["pan"]) + 0.2)} for r in rows],
                                                   list(rows[0])))
    elif fault == "nopan":
        _rewrite(out / "frames.csv", lambda rows: (rows, [k for k in rows[0] if k != "pan"]))
    return out, None


def run_one(seq: Path, out: Path, jump: int | None, config: str | None = None) -> dict:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli(["run", str(seq), "--out", str(out), "--no-figures", *(["--config", config] if config else [])])
    if code != 0:
        raise SystemExit(f"stablemarks run {seq} failed: {err.getvalue()}")
    lines = err.getvalue().splitlines()
    warnings = [line for line in lines if line.startswith("warning:")]
    first = next((line for line in warnings if line.startswith("warning: frame")), None)
    # the pan named: before the first frame (a recording without pans: frame 0) or by a health condition
    upfront = any("no pan recorded" in line for line in warnings)
    pan = next((line for line in warnings if line.startswith("warning: frame") and "pan" in line), None)
    log = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    est, truth, dr = (np.array([r[k] for r in log]) for k in ("pose", "true_pose", "dead_reckoning"))
    e = np.linalg.norm(est[:, :2] - truth[:, :2], axis=1)
    e_dr = np.linalg.norm(dr[:, :2] - truth[:, :2], axis=1)
    r = est[-1, :2] - truth[-1, :2]
    after = slice((jump or 0) + 3, None)
    return {"ate": float(np.sqrt(np.mean(e**2))), "ate_dr": float(np.sqrt(np.mean(e_dr**2))),
            "first": None if first is None else (int(first.split()[2]), first.split(": ")[2]),
            "pan_named": 0 if upfront else None if pan is None else int(pan.split()[2]),
            "nees_position": float(r @ np.linalg.solve(np.array(log[-1]["cov_pose"])[:2, :2], r)),
            "ate_after": float(np.sqrt(np.mean(e[after] ** 2))),
            "ate_dr_after": float(np.sqrt(np.mean(e_dr[after] ** 2))),
            "warnings": len(warnings)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+", help="built-in names or scenario YAML files")
    ap.add_argument("--faults", default=",".join(FAULTS), help=f"comma-separated, of {', '.join(FAULTS)}")
    ap.add_argument("--seed", type=int, help="seed of the runs (default: each scenario's own)")
    ap.add_argument("--keep", help="write the sequences and outputs here (default: a temporary folder)")
    ap.add_argument("--config", help="configuration YAML for every run (default: the defaults)")
    ap.add_argument("--head", choices=("method", "scenario"), default="method",
                    help="who points the head in the clean run (as `stablemarks simulate --head`)")
    args = ap.parse_args()
    faults = args.faults.split(",")
    unknown = [f for f in faults if f not in FAULTS]
    if unknown:
        ap.error(f"--faults: unknown {', '.join(unknown)}; expected some of {', '.join(FAULTS)}")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep or tmp)
        print(f"{'run':24s} {'ATE / DR [mm]':>16s}  {'first warning':26s} {'pan named':>9s} {'NEES pos':>8s}  "
              f"{'after jump / DR [mm]':>20s}  warnings")
        for name in args.scenarios:
            sc = load_scenario(name)
            sim = simulate_run(sc, args.seed)
            if args.head == "method":
                sim = steered_by_method(sim)
            clean = write_simulated_sequence(sim, root / f"{sc.name}-clean")
            for fault in faults:
                seq, jump = (clean, None) if fault == "clean" else make_fault(clean, fault, root / f"{sc.name}-{fault}")
                if seq is None:
                    print(f"{sc.name + ' ' + fault:24s} (the run is too short for the jump)")
                    continue
                m = run_one(seq, root / f"{sc.name}-{fault}-out", jump, args.config)
                first = "none" if m["first"] is None else f"frame {m['first'][0]} {m['first'][1]}"
                after = f"{1000 * m['ate_after']:.1f} / {1000 * m['ate_dr_after']:.1f}" if jump else "-"
                named = "-" if m["pan_named"] is None else f"frame {m['pan_named']}"
                print(f"{sc.name + ' ' + fault:24s} {1000 * m['ate']:7.1f} / {1000 * m['ate_dr']:6.1f}  {first:26s} "
                      f"{named:>9s} {m['nees_position']:8.1f}  {after:>20s}  {m['warnings']}", flush=True)


if __name__ == "__main__":
    main()
