"""The batch runner: a small paired batch writes every column with the right types, in chunks recorded
atomically in a manifest; 1 and 2 workers give identical tables."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from batch_cli import SMALL_RUN_ARGS, batch

from pedsafe_sumo.batch.chunks import auto_chunk_size, episode_seed, plan_chunks
from pedsafe_sumo.io.episodes import EPISODE_COLUMNS
from pedsafe_sumo.io.run_store import LOCK_FILE, Manifest, sha256_file

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
    "contact_stationary",
    "end_reason",
    "status",
]


@pytest.mark.slow
def test_small_paired_batch_writes_every_column_with_the_right_types(small_run):
    out, proc = small_run
    table = pd.read_parquet(out / "episodes.parquet")
    assert list(table.columns) == list(EPISODE_COLUMNS)
    assert len(table) == 8 and sorted(table["condition"].unique()) == ["sv", "v2i"]
    assert table[MUST_EXIST].notna().all().all()
    assert (table["status"] == "ok").all() and (table["error"] == "").all()
    for column in ("collision", "conflict", "contact_stationary"):
        assert table[column].dtype == bool
    # Null where SUMO does not check person-vehicle contact (a pedestrian off crossings/walking areas).
    assert table["sumo_collision"].dtype == "boolean"
    assert table.loc[table.scenario == "crossing", "sumo_collision"].notna().all()
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
    assert run["state"] == "complete" and run["run_seed"] == 5 and run["episodes_per_scenario"] == 4
    assert run["workers"] == 2 and run["n_error"] == 0
    assert run["versions"]["sumo"].startswith("v1.28") and run["wall_time_s"] > 0
    assert "perception" in run["parameters"] and "crossing" in run["scenarios"]
    assert set(run["site_files_sha256"]) == {
        "xueqing.net.xml",
        "xueqing.poly.xml",
        "xueqing.rsu.add.xml",
        "xueqing.site.json",
    }
    # Cases come in pairs, for the episodes with a collision or a conflict.
    kept = table[table["collision"] | table["conflict"]]["episode"].unique()
    assert len(list((out / "cases").glob("*.parquet"))) == 2 * len(kept)
    assert "Table I" in proc.stdout


@pytest.mark.slow
def test_every_chunk_is_a_part_file_recorded_with_its_checksum(small_run):
    out, _ = small_run
    manifest = Manifest.load(out / "manifest.json")
    assert sorted(manifest.chunks) == [f"crossing-{i:06d}-{i:06d}" for i in range(4)]
    parts = []
    for record in manifest.chunks.values():
        assert sha256_file(out / record.file) == record.sha256
        part = pd.read_parquet(out / record.file)
        assert len(part) == record.rows == 2 and set(part["episode"]) == {record.first_episode}
        parts.append(part)
    whole = pd.concat(parts).sort_values(["episode", "condition"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(whole, pd.read_parquet(out / "episodes.parquet"))
    # No temporary file, no stray part, and the lock is gone with the driver.
    assert not list(out.rglob("*.tmp")) and len(list((out / "parts").iterdir())) == 4
    assert not (out / LOCK_FILE).exists()
    run = json.loads((out / "run.json").read_text())
    assert run["chunks_total"] == 4 and run["chunk_size_pairs"] == 1 and len(run["sessions"]) == 1


@pytest.mark.slow
def test_one_and_two_workers_give_identical_tables(small_run, tmp_path):
    out2, _ = small_run
    proc = batch(*SMALL_RUN_ARGS, "--workers", "1", "--out", str(tmp_path / "run1"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    pd.testing.assert_frame_equal(
        pd.read_parquet(tmp_path / "run1" / "episodes.parquet"), pd.read_parquet(out2 / "episodes.parquet")
    )


def test_chunks_cover_every_episode_once_in_order():
    chunks = plan_chunks(["crossing", "jaywalking"], ["sv", "v2i"], 10, 3, 4)
    assert [(c.scenario, c.first_episode, c.last_episode) for c in chunks] == [
        ("crossing", 0, 3),
        ("crossing", 4, 7),
        ("crossing", 8, 9),
        ("jaywalking", 0, 3),
        ("jaywalking", 4, 7),
        ("jaywalking", 8, 9),
    ]
    episodes = [(t.scenario, t.episode) for c in chunks for t in c.tasks]
    assert len(episodes) == len(set(episodes)) == 20
    assert all(t.seed == episode_seed(3, t.episode) for c in chunks for t in c.tasks)
    assert chunks[2].key == "crossing-000008-000009" and chunks[2].n_rows == 4


def test_automatic_chunk_size_gives_each_worker_several_chunks_of_at_most_25_pairs():
    assert auto_chunk_size(4, 2) == 1
    assert auto_chunk_size(100, 2) == 7  # 15 chunks: about 8 per worker
    assert auto_chunk_size(10_000, 2) == 25
    assert auto_chunk_size(10_000, 64) == 20


@pytest.mark.slow
def test_approach_staging_gives_identical_tables_on_one_and_two_workers(tmp_path):
    # The approach staging draws more (start distance, walk-in) and adds the pedestrian to SUMO mid-episode:
    # still a function of the seed alone, whatever worker runs the pair.
    args = (
        "--scenario", "crossing,jaywalking", "--set", "staging=approach", "--episodes", "3",
        "--seed", "5", "--chunk-size", "1",
    )  # fmt: skip
    tables = []
    for workers in ("1", "2"):
        out = tmp_path / f"run{workers}"
        proc = batch(*args, "--workers", workers, "--out", str(out))
        assert proc.returncode == 0, proc.stderr[-2000:]
        tables.append(pd.read_parquet(out / "episodes.parquet"))
    pd.testing.assert_frame_equal(tables[0], tables[1])
    # The staging's own columns are drawn, not defaults: every pedestrian appears after the start.
    assert (tables[0]["ped_appear_time_s"] > 0).any() and tables[0]["ego_start_distance_m"].min() >= 100.0
