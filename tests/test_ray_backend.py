"""eval on an existing Ray cluster: a local head node started with ``ray start``, reached by its address.

Ray runs in subprocesses (the cluster and the evaluation both): its import sets up logging, signal handlers and
warnings that have no place in the test process."""

import json
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("ray")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_two_trials_through_a_ray_cluster_address(tmp_path):
    ray_cli = Path(sys.executable).with_name("ray")
    if not ray_cli.exists():
        ray_cli = shutil.which("ray")
    assert ray_cli, "ray is importable but its command-line tool is not on this interpreter's path"
    port = _free_port()
    head = [str(ray_cli), "start", "--head", "--port", str(port), "--num-cpus", "2", "--include-dashboard=false",
            "--disable-usage-stats"]
    subprocess.run(head, check=True, capture_output=True, timeout=180)
    out = tmp_path / "ev"
    try:
        code = ("import sys; from stablemarks.cli import main; sys.exit(main(sys.argv[1:]))")
        run = subprocess.run([sys.executable, "-c", code, "eval", "lab", "--trials", "2", "--frames", "2",
                              "--methods", "dead_reckoning", "--backend", "ray", "--address", f"127.0.0.1:{port}",
                              "--out", str(out), "--no-figures"], capture_output=True, text=True, timeout=300)
    finally:
        subprocess.run([str(ray_cli), "stop", "--force"], capture_output=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    # it joined the cluster at that address instead of starting one of its own
    assert "Connecting to existing Ray cluster at address: " in run.stderr + run.stdout
    lines = [json.loads(x) for x in (out / "trials.jsonl").read_text().splitlines()]
    assert sorted((r["trial"], r["method"]) for r in lines) == [(0, "dead_reckoning"), (1, "dead_reckoning")]
    assert all("error" not in r for r in lines)
    assert "ray" in run.stdout  # the summary names the backend it ran on
