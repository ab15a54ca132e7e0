"""eval on an existing Dask cluster: a local scheduler with workers, reached by its address."""

import json

import pytest

from stablemarks.cli import main

distributed = pytest.importorskip("distributed")


@pytest.mark.slow
def test_two_trials_through_a_dask_scheduler_address(tmp_path):
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        out = tmp_path / "ev"
        assert main(["eval", "lab", "--trials", "2", "--frames", "2", "--methods", "dead_reckoning",
                     "--backend", "dask", "--address", cluster.scheduler_address, "--out", str(out),
                     "--no-figures"]) == 0
        with distributed.Client(cluster.scheduler_address) as client:
            assert len(client.scheduler_info()["workers"]) == 2
    lines = [json.loads(x) for x in (out / "trials.jsonl").read_text().splitlines()]
    assert [(r["trial"], r["method"]) for r in lines] == [(0, "dead_reckoning"), (1, "dead_reckoning")]
    assert all("error" not in r for r in lines)
