"""--cluster: a Dask LocalCluster gives the process pool's table; without Dask, or without a scheduler
to reach, the batch says so in one line and writes nothing."""

from __future__ import annotations

import json
import socket

import pandas as pd
import pytest
from batch_cli import SMALL_RUN_ARGS, batch

from pedsafe_sumo.batch.executors import parse_cluster_address
from pedsafe_sumo.settings import UsageError


@pytest.mark.slow
def test_local_cluster_gives_the_process_pool_table(small_run, tmp_path):
    pool_run, _ = small_run
    out = tmp_path / "dask"
    proc = batch(*SMALL_RUN_ARGS, "--cluster", "local:2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-2000:]
    pd.testing.assert_frame_equal(
        pd.read_parquet(out / "episodes.parquet"), pd.read_parquet(pool_run / "episodes.parquet")
    )
    run = json.loads((out / "run.json").read_text())
    assert run["executor"] == "Dask cluster local:2, 2 worker(s)" and run["workers"] == 2


def test_cluster_without_dask_names_the_extra(tmp_path):
    # A `dask` that cannot be imported, as on an install without the cluster extra.
    fake = tmp_path / "no_dask" / "dask"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ModuleNotFoundError(\"No module named 'dask'\", name='dask')\n")
    out = tmp_path / "out"
    proc = batch(
        *SMALL_RUN_ARGS,
        "--cluster",
        "local:2",
        "--out",
        str(out),
        env={"PYTHONPATH": str(fake.parent)},
        timeout=120,
    )
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "pip install 'pedsafe_sumo[cluster]'" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()


def test_an_unreachable_scheduler_is_one_line_and_writes_nothing(tmp_path):
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    out = tmp_path / "out"
    proc = batch(
        *SMALL_RUN_ARGS,
        "--cluster",
        f"tcp://127.0.0.1:{port}",
        "--out",
        str(out),
        env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "1s"},
        timeout=120,
    )
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert f"cannot reach the Dask scheduler at tcp://127.0.0.1:{port}" in proc.stderr
    assert not out.exists()


def test_cluster_addresses():
    assert parse_cluster_address("local:3") == ("local", 3)
    assert parse_cluster_address("tcp://10.0.0.5:8786") == ("tcp://10.0.0.5:8786", 0)
    for bad in ("local:0", "local:x", "10.0.0.5:8786", "tcp://"):
        with pytest.raises(UsageError):
            parse_cluster_address(bad)
