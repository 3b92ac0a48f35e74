"""--keep-logs all: every episode's per-step log kept, one Parquet file per chunk, from which every row of
episodes.parquet is recomputed with the safety functions; recorded in the manifest and safe to resume."""

from __future__ import annotations

import json
import math
import shutil

import pandas as pd
import pytest
from batch_cli import batch, tree_digest

from pedsafe_sumo.io.run_store import Manifest, sha256_file
from pedsafe_sumo.io.step_logs import KEY_COLUMNS, episode_logs, read_step_logs
from pedsafe_sumo.safety import INDEX_COLUMNS, episode_indexes
from pedsafe_sumo.safety.proximity import ProximityModel

#: 3 crossing pairs in 2 chunks (2 + 1 pairs), one worker.
KEEP_ALL_ARGS = (
    "--scenario",
    "crossing",
    "--episodes",
    "3",
    "--seed",
    "11",
    "--chunk-size",
    "2",
)


@pytest.fixture(scope="module")
def kept_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("keep") / "all"
    proc = batch(*KEEP_ALL_ARGS, "--workers", "1", "--keep-logs", "all", "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out, proc


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


@pytest.mark.slow
def test_every_row_is_recomputed_from_the_kept_logs(kept_run):
    out, proc = kept_run
    info = json.loads((out / "run.json").read_text())
    assert info["keep_logs"] == "all" and info["arguments"]["keep_logs"] == "all"
    assert "every episode's step log: 2 file(s)" in proc.stdout
    episodes = pd.read_parquet(out / "episodes.parquet")
    steps = read_step_logs(out)
    assert list(steps.columns[: len(KEY_COLUMNS)]) == list(KEY_COLUMNS)
    logs = dict(episode_logs(steps))
    ok = episodes[episodes["status"] == "ok"]
    assert len(ok) == 6 and set(logs) == {(r.scenario, r.condition, r.episode) for r in ok.itertuples()}
    proximity = ProximityModel.from_params(info["parameters"])
    for row in ok.to_dict("records"):
        log = logs[(row["scenario"], row["condition"], row["episode"])]
        # the seed column of the log is the row's seed
        assert (steps.loc[steps["episode"] == row["episode"], "seed"] == row["seed"]).all()
        again = episode_indexes(log, row["ped_age"], proximity_model=proximity)
        different = [c for c in INDEX_COLUMNS if not _same(again[c], row[c])]
        assert not different, (row["episode"], row["condition"], different)


@pytest.mark.slow
def test_step_log_files_are_recorded_in_the_manifest(kept_run):
    out, _ = kept_run
    manifest = Manifest.load(out / "manifest.json")
    files = sorted(record.steplog_file for record in manifest.chunks.values())
    assert files == ["steplogs/crossing-000000-000001.parquet", "steplogs/crossing-000002-000002.parquet"]
    for record in manifest.chunks.values():
        assert sha256_file(out / record.steplog_file) == record.steplog_sha256
    # one file per chunk, holding exactly that chunk's episodes
    first = pd.read_parquet(out / files[0])
    assert sorted(set(first["episode"])) == [0, 1] and set(first["condition"]) == {"sv", "v2i"}


@pytest.mark.slow
def test_default_keeps_no_step_logs(small_run):
    out, _ = small_run
    assert not (out / "steplogs").exists()
    assert json.loads((out / "run.json").read_text())["keep_logs"] == "events"
    assert all(not r.steplog_file for r in Manifest.load(out / "manifest.json").chunks.values())


@pytest.mark.slow
def test_resume_reruns_a_chunk_whose_step_log_is_missing_and_refuses_another_keep_logs(kept_run, tmp_path):
    reference, _ = kept_run
    run = tmp_path / "run"
    shutil.copytree(reference, run)
    # A driver killed after the manifest was written, then a step-log file lost on disk; and a
    # temporary file of a second chunk's log written but never renamed.
    info = json.loads((run / "run.json").read_text())
    info.update(state="running", wall_time_s=None, episodes_per_s=None, n_error=None)
    info["sessions"][0]["wall_time_s"] = None
    (run / "run.json").write_text(json.dumps(info))
    (run / "episodes.parquet").unlink()
    (run / "steplogs" / "crossing-000002-000002.parquet").unlink()
    (run / "steplogs" / "crossing-000000-000001.parquet.tmp").write_bytes(b"half a log")

    refused = batch("--resume", "--keep-logs", "events", "--out", str(run))
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1
    assert "--keep-logs all" in refused.stderr

    proc = batch("--resume", "--out", str(run), "--workers", "1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "chunk crossing-000002-000002 runs again: steplogs/crossing-000002-000002.parquet is missing" in (
        proc.stderr
    )
    assert not list(run.rglob("*.tmp"))
    pd.testing.assert_frame_equal(
        pd.read_parquet(run / "episodes.parquet"), pd.read_parquet(reference / "episodes.parquet")
    )
    # the step logs are the uninterrupted run's (same content; the file re-run is byte for byte too)
    assert tree_digest(run / "steplogs") == tree_digest(reference / "steplogs")


@pytest.mark.slow
def test_dask_keeps_the_same_step_logs(kept_run, tmp_path):
    pool_run, _ = kept_run
    out = tmp_path / "dask"
    proc = batch(*KEEP_ALL_ARGS, "--keep-logs", "all", "--cluster", "local:2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-2000:]
    pd.testing.assert_frame_equal(
        pd.read_parquet(out / "episodes.parquet"), pd.read_parquet(pool_run / "episodes.parquet")
    )
    pd.testing.assert_frame_equal(read_step_logs(out), read_step_logs(pool_run))
    assert sorted(p.name for p in (out / "steplogs").iterdir()) == sorted(
        p.name for p in (pool_run / "steplogs").iterdir()
    )
