"""Faults in workers: a worker process killed by SIGKILL has its chunk run again (on the process pool
and on Dask) without losing or repeating an episode; a pair that kills its worker every time becomes
error rows and the batch goes on; an exception in the AD stack is an error row."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from batch_cli import SMALL_RUN_ARGS, batch

from pedsafe_sumo.batch.chunks import episode_seed
from pedsafe_sumo.report.__main__ import main as report_main
from pedsafe_sumo.safety.stats import table_one

KILLED_EPISODE = 2  # of the small run (seed 5)


def kill_env(tmp_path) -> dict[str, str]:
    return {
        "PEDSAFE_TEST_KILL_SEED": str(episode_seed(5, KILLED_EPISODE)),
        "PEDSAFE_TEST_KILL_MARKER": str(tmp_path / "killed-once"),
    }


@pytest.mark.slow
@pytest.mark.parametrize("executor", [("--workers", "2"), ("--cluster", "local:2")], ids=["pool", "dask"])
def test_a_killed_worker_is_retried_and_no_episode_is_counted_twice(small_run, tmp_path, executor):
    reference, _ = small_run
    out = tmp_path / "run"
    proc = batch(
        *SMALL_RUN_ARGS,
        *executor,
        "--algorithm",
        "tests.batch.plugin_agents:KillsWorkerOnce",
        "--out",
        str(out),
        env=kill_env(tmp_path),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "killed-once").read_text().startswith("killed pid")  # the kill did happen
    table = pd.read_parquet(out / "episodes.parquet")
    assert not table.duplicated(["scenario", "episode", "condition"]).any()
    pd.testing.assert_frame_equal(table, pd.read_parquet(reference / "episodes.parquet"))
    if executor[0] == "--workers":  # Dask reruns the task itself, unseen by the batch
        assert json.loads((out / "run.json").read_text())["sessions"][0]["worker_deaths"] >= 1


@pytest.mark.slow
@pytest.mark.parametrize("executor", [("--workers", "2"), ("--cluster", "local:2")], ids=["pool", "dask"])
def test_a_pair_that_always_kills_its_worker_becomes_error_rows(small_run, tmp_path, executor):
    reference, _ = small_run
    out = tmp_path / "run"
    proc = batch(
        *SMALL_RUN_ARGS[:-1],
        "2",  # two pairs per chunk: the killing chunk is split and its other pair still runs
        *executor,
        "--algorithm",
        "tests.batch.plugin_agents:KillsWorkerAlways",
        "--out",
        str(out),
        env=kill_env(tmp_path),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    table = pd.read_parquet(out / "episodes.parquet")
    killed = table["episode"] == KILLED_EPISODE
    assert (table.loc[killed, "status"] == "error").all() and killed.sum() == 2
    assert (
        table.loc[killed, "error"].str.startswith("worker process died each time this episode pair ran").all()
    )
    expected = pd.read_parquet(reference / "episodes.parquet")
    pd.testing.assert_frame_equal(
        table[~killed].reset_index(drop=True),
        expected[expected["episode"] != KILLED_EPISODE].reset_index(drop=True),
    )
    assert json.loads((out / "run.json").read_text())["n_error"] == 2


@pytest.mark.slow
def test_failing_episodes_are_errors_counted_apart_from_every_rate(tmp_path):
    out = tmp_path / "run"
    proc = batch(
        "--scenario",
        "jaywalking",
        "--episodes",
        "4",
        "--workers",
        "1",
        "--out",
        str(out),
        "--algorithm",
        "tests.sim.plugin_agents:FailsOnOddSeeds",
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    table = pd.read_parquet(out / "episodes.parquet")
    odd = table["seed"] % 2 == 1
    assert odd.any() and (~odd).any(), "the seeds of this run should be mixed"
    assert (table.loc[odd, "status"] == "error").all() and (table.loc[~odd, "status"] == "ok").all()
    assert table.loc[odd, "error"].str.contains("planner crashed").all()
    assert json.loads((out / "run.json").read_text())["n_error"] == int(odd.sum())

    # Table I counts the errors apart and computes every rate over the episodes that ran.
    summary = table_one(table).set_index("condition")
    for condition, group in table.groupby("condition"):
        ran = group[group["status"] == "ok"]
        row = summary.loc[condition]
        assert row["n"] == len(ran) and row["n_error"] == len(group) - len(ran)
        assert row["collision_rate"] == pytest.approx(ran["collision"].mean())
        assert row["injury_mean"] == pytest.approx(ran["injury_probability"].mean())
        assert row["conflict_rate"] == pytest.approx((ran["conflict"] & ~ran["collision"]).mean())
        # The batch's own summary prints the same counts.
        assert f"n={len(ran):5d} (errors {len(group) - len(ran)})" in proc.stdout

    # So does the report: its table1.csv, and the paired test drops the pairs with an error.
    assert report_main([str(out)]) == 0
    report_table = pd.read_csv(out / "tables" / "table1.csv").set_index("condition")
    pd.testing.assert_series_equal(report_table["n_error"], summary["n_error"], check_names=False)
    for column in ("n", "collision_rate", "injury_mean", "conflict_rate"):
        assert report_table[column].to_numpy() == pytest.approx(summary[column].to_numpy(), nan_ok=True)
    paired = pd.read_csv(out / "tables" / "paired.csv")
    assert (paired["n_pairs"] == int((~odd).sum() // 2)).all()
