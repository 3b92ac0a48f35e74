"""The batch runner: a small paired batch on two workers writes every column with the right types,
1 and 2 workers give identical tables, failing episodes are errors not crashes, bad input is refused."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.batch.runner import episode_seed
from pedsafe_sumo.io.episodes import EPISODE_COLUMNS

MUST_EXIST = [
    "scenario",
    "condition",
    "episode",
    "seed",
    "ped_age",
    "ped_gender",
    "ped_risk",
    "ped_speed_mps",
    "ego_initial_speed_mps",
    "collision",
    "injury_probability",
    "conflict",
    "sumo_collision",
    "status",
]


def batch(*args, timeout=600):
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", *args],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=timeout,
    )


@pytest.fixture(scope="module")
def two_worker_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("batch") / "run2"
    proc = batch(
        "--scenario", "crossing", "--episodes", "4", "--workers", "2", "--seed", "5", "--out", str(out)
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out, proc


@pytest.mark.slow
def test_small_paired_batch_writes_every_column_with_the_right_types(two_worker_run):
    out, proc = two_worker_run
    table = pd.read_parquet(out / "episodes.parquet")
    assert list(table.columns) == list(EPISODE_COLUMNS)
    assert len(table) == 8 and sorted(table["condition"].unique()) == ["sv", "v2i"]
    assert table[MUST_EXIST].notna().all().all()
    assert (table["status"] == "ok").all() and (table["error"] == "").all()
    for column in ("collision", "conflict", "sumo_collision"):
        assert table[column].dtype == bool
    for column in ("episode", "seed"):
        assert table[column].dtype == np.int64
    # Paired: episode i has the same seed and the same pedestrian and ego under both conditions.
    pairs = table.pivot(
        index="episode", columns="condition", values=["seed", "ped_age", "ego_initial_speed_mps"]
    )
    for value in ("seed", "ped_age", "ego_initial_speed_mps"):
        assert (pairs[(value, "sv")] == pairs[(value, "v2i")]).all()
    assert list(table.loc[table.condition == "sv", "seed"]) == [episode_seed(5, i) for i in range(4)]
    # Injury probability is 0 exactly where there is no collision.
    assert (table.loc[~table["collision"], "injury_probability"] == 0).all()
    run = json.loads((out / "run.json").read_text())
    assert run["run_seed"] == 5 and run["episodes_per_scenario"] == 4 and run["workers"] == 2
    assert run["versions"]["sumo"].startswith("v1.28") and run["wall_time_s"] > 0
    assert "perception" in run["parameters"] and "crossing" in run["scenarios"]
    # Cases come in pairs, for the episodes with a collision or a conflict.
    kept = table[table["collision"] | table["conflict"]]["episode"].unique()
    assert len(list((out / "cases").glob("*.parquet"))) == 2 * len(kept)
    assert "Table I" in proc.stdout


@pytest.mark.slow
def test_one_and_two_workers_give_identical_tables(two_worker_run, tmp_path):
    out2, _ = two_worker_run
    proc = batch(
        "--scenario",
        "crossing",
        "--episodes",
        "4",
        "--workers",
        "1",
        "--seed",
        "5",
        "--out",
        str(tmp_path / "run1"),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    pd.testing.assert_frame_equal(
        pd.read_parquet(tmp_path / "run1" / "episodes.parquet"), pd.read_parquet(out2 / "episodes.parquet")
    )


@pytest.mark.slow
def test_failing_episodes_are_recorded_as_errors_and_the_batch_goes_on(tmp_path):
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
    assert (table.loc[odd, "status"] == "error").all() and (table.loc[~odd, "status"] == "ok").all()
    assert table.loc[odd, "error"].str.contains("planner crashed").all()
    assert json.loads((out / "run.json").read_text())["n_error"] == int(odd.sum())


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scenario", "parking"], "unknown scenario 'parking'"),
        (["--scenario", "crossing", "--condition", "v3i"], "unknown condition 'v3i'"),
        (["--scenario", "crossing", "--episodes", "0"], "--episodes must be at least 1"),
        (
            ["--scenario", "crossing", "--set", "perception.v2i.packet_loss_probability=1.5"],
            "packet_loss_probability",
        ),
        (["--scenario", "crossing", "--set", "ego_speed_min_mps=-2"], "ego_speed_min_mps"),
        (["--scenario", "crossing", "--algorithm", "nowhere:Agent"], "cannot import module 'nowhere'"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, args, message):
    out = tmp_path / "out"
    proc = batch(*args, "--out", str(out), timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and message in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()


def test_an_existing_run_is_never_overwritten(two_worker_run):
    out, _ = two_worker_run
    before = (out / "episodes.parquet").read_bytes()
    proc = batch("--scenario", "crossing", "--episodes", "1", "--out", str(out), timeout=120)
    assert proc.returncode == 2 and "already holds a run" in proc.stderr
    assert (out / "episodes.parquet").read_bytes() == before
