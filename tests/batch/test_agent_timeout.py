"""An AD stack whose run_step never returns: its episodes end with status "timeout" after
--agent-timeout, the batch finishes on the process pool and on Dask, every other episode is the
reference run's, and Table I counts the timeouts apart from every rate."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from batch_cli import SMALL_RUN_ARGS, batch

from pedsafe_sumo.batch.chunks import episode_seed
from pedsafe_sumo.safety.stats import table_one

HUNG_EPISODE = 1  # of the small run (seed 5)
LIMIT_S = "0.5"


@pytest.mark.slow
@pytest.mark.parametrize("executor", [("--workers", "2"), ("--cluster", "local:2")], ids=["pool", "dask"])
def test_a_stack_that_sleeps_forever_gives_timeout_rows_and_a_finished_batch(small_run, tmp_path, executor):
    reference, _ = small_run
    out = tmp_path / "run"
    proc = batch(
        *SMALL_RUN_ARGS,
        *executor,
        "--algorithm",
        "tests.batch.plugin_agents:SleepsForever",
        "--agent-timeout",
        LIMIT_S,
        "--out",
        str(out),
        env={"PEDSAFE_TEST_SLEEP_SEED": str(episode_seed(5, HUNG_EPISODE))},
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    table = pd.read_parquet(out / "episodes.parquet")
    hung = table["episode"] == HUNG_EPISODE
    assert hung.sum() == 2 and (table.loc[hung, "status"] == "timeout").all()
    # SleepsForever falls asleep at t = 1.0 s (plugin_agents.SLEEP_AT_S).
    assert (
        table.loc[hung, "error"]
        == "AgentTimeoutError: the AD stack's run_step did not return within 0.5 s (--agent-timeout) "
        "at t=1.00 s"
    ).all()
    expected = pd.read_parquet(reference / "episodes.parquet")
    pd.testing.assert_frame_equal(
        table[~hung].reset_index(drop=True),
        expected[expected["episode"] != HUNG_EPISODE].reset_index(drop=True),
    )
    run = json.loads((out / "run.json").read_text())
    assert run["state"] == "complete" and run["n_timeout"] == 2 and run["n_error"] == 2
    assert run["arguments"]["agent_timeout"] == float(LIMIT_S)
    summary = table_one(table).set_index("condition")
    ran = expected[expected["episode"] != HUNG_EPISODE]
    for condition, group in ran.groupby("condition"):
        assert summary.loc[condition, "n"] == len(group) and summary.loc[condition, "n_error"] == 1
        assert summary.loc[condition, "collision_rate"] == pytest.approx(group["collision"].mean())
