"""Worker recycling (--recycle-chunks): the process pool replaces its worker processes
after every N chunks per worker, so libsumo's per-`load` memory cannot pile up over a long run; the rows
are those of a run without recycling, because an episode's rows depend on its seed, not on its process."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from batch_cli import SMALL_RUN_ARGS, batch
from test_worker_faults import kill_env

from pedsafe_sumo.batch.__main__ import main
from pedsafe_sumo.io.run_store import Manifest


def chunk_workers(out) -> list[str]:
    """The worker process ("host:pid") of each chunk, in episode order."""
    records = sorted(Manifest.load(out / "manifest.json").chunks.values(), key=lambda r: r.first_episode)
    return [record.worker for record in records]


@pytest.mark.slow
def test_recycled_workers_give_the_table_of_unrecycled_ones(small_run, tmp_path):
    reference, _ = small_run  # 4 one-pair chunks on 2 workers, never recycled (4 < 100 chunks)
    every_chunk = tmp_path / "every_chunk"
    proc = batch(*SMALL_RUN_ARGS, "--workers", "1", "--recycle-chunks", "1", "--out", str(every_chunk))
    assert proc.returncode == 0, proc.stderr[-2000:]
    # One worker, replaced after each chunk: four chunks, four processes.
    workers = chunk_workers(every_chunk)
    assert len(workers) == 4 and len(set(workers)) == 4, workers
    every_two = tmp_path / "every_two"
    proc = batch(*SMALL_RUN_ARGS, "--workers", "1", "--recycle-chunks", "2", "--out", str(every_two))
    assert proc.returncode == 0, proc.stderr[-2000:]
    workers = chunk_workers(every_two)
    assert workers[0] == workers[1] != workers[2] == workers[3], workers
    table = pd.read_parquet(reference / "episodes.parquet")
    pd.testing.assert_frame_equal(pd.read_parquet(every_chunk / "episodes.parquet"), table)
    pd.testing.assert_frame_equal(pd.read_parquet(every_two / "episodes.parquet"), table)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--recycle-chunks", "-1"], "--recycle-chunks must be between 0 (never) and 1,000,000, got -1"),
        (["--recycle-chunks", str(10**12)], "--recycle-chunks must be between 0 (never) and 1,000,000"),
        (["--recycle-chunks", "5", "--cluster", "local:1"], "--recycle-chunks applies to the process pool"),
    ],
)
def test_recycle_chunks_out_of_range_is_refused_in_one_line(capsys, tmp_path, extra, message):
    out = tmp_path / "run"
    code = main(["--scenario", "crossing", "--episodes", "2", "--out", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err
    assert not out.exists()


@pytest.mark.slow
def test_a_worker_killed_between_recycled_generations_loses_and_repeats_nothing(small_run, tmp_path):
    """Episode 2 kills its worker once (tests/batch/plugin_agents.py); with a fresh pool every chunk per
    worker, the broken generation's chunk reruns alone and the generations after it still run."""
    reference, _ = small_run
    out = tmp_path / "run"
    proc = batch(
        *SMALL_RUN_ARGS,
        "--workers",
        "2",
        "--recycle-chunks",
        "1",
        "--algorithm",
        "tests.batch.plugin_agents:KillsWorkerOnce",
        "--out",
        str(out),
        env=kill_env(tmp_path),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "killed-once").read_text().startswith("killed pid")
    table = pd.read_parquet(out / "episodes.parquet")
    pd.testing.assert_frame_equal(table, pd.read_parquet(reference / "episodes.parquet"))
    assert json.loads((out / "run.json").read_text())["sessions"][0]["worker_deaths"] >= 1
