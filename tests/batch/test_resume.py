"""Resumable batches: a batch killed with SIGKILL mid-run and resumed gives the uninterrupted run's
table row for row; a resume repairs what a killed driver leaves; the report refuses or flags the
unfinished run."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest
from batch_cli import SMALL_RUN_ARGS, batch, tree_digest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.io.run_store import Manifest, check_part
from pedsafe_sumo.report.__main__ import main as report_main

#: 12 pairs, one per chunk, 0.15 s slower per episode than the reference stack (about 5 s of work on
#: 2 workers): time to kill the batch with chunks recorded and chunks still to run.
KILL_RUN_ARGS = (
    "--scenario",
    "crossing",
    "--episodes",
    "12",
    "--seed",
    "7",
    "--chunk-size",
    "1",
    "--workers",
    "2",
    "--algorithm",
    "tests.batch.plugin_agents:PausingReference",
)


def recorded_chunks(out) -> int:
    try:
        return len(json.loads((out / "manifest.json").read_text())["chunks"])
    except (FileNotFoundError, json.JSONDecodeError):
        return 0


@pytest.mark.slow
def test_kill_minus_9_then_resume_gives_the_uninterrupted_table(tmp_path, capsys):
    killed = tmp_path / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "pedsafe_sumo.batch", *KILL_RUN_ARGS, "--out", str(killed)],
        cwd=REPO_ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # its own process group: the driver and its workers die together
    )
    deadline = time.monotonic() + 120
    while recorded_chunks(killed) < 1 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL

    # Killed mid-run: chunks recorded, chunks missing, no table; every recorded part intact.
    manifest = Manifest.load(killed / "manifest.json")
    assert 1 <= len(manifest.chunks) < 12, "the batch finished before it could be killed"
    assert json.loads((killed / "run.json").read_text())["state"] == "running"
    assert not (killed / "episodes.parquet").exists()
    assert all(check_part(killed, record) == "" for record in manifest.chunks.values())

    # The report refuses the unfinished run in one line, or reports its finished chunks, flagged.
    assert report_main([str(killed)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unfinished batch run" in err and "--resume" in err
    assert report_main([str(killed), "--partial"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("INCOMPLETE RUN:") and out.rstrip().splitlines()[-1].startswith("INCOMPLETE RUN:")
    assert (killed / "partial" / "tables" / "table1.md").read_text().startswith("**INCOMPLETE RUN:")
    assert not (killed / "tables").exists()

    resumed = batch(*KILL_RUN_ARGS, "--out", str(killed), "--resume")
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    reference = batch(*KILL_RUN_ARGS, "--out", str(tmp_path / "uninterrupted"))
    assert reference.returncode == 0, reference.stderr[-2000:]

    table = pd.read_parquet(killed / "episodes.parquet")
    pd.testing.assert_frame_equal(table, pd.read_parquet(tmp_path / "uninterrupted" / "episodes.parquet"))
    assert not table.duplicated(["scenario", "episode", "condition"]).any() and len(table) == 24
    run = json.loads((killed / "run.json").read_text())
    assert run["state"] == "complete" and len(run["sessions"]) == 2
    assert run["sessions"][1]["chunks_to_run"] == 12 - len(manifest.chunks)
    assert run["wall_time_s"] >= run["sessions"][1]["wall_time_s"]
    # The cases of the resumed run are the uninterrupted run's, byte for byte.
    assert tree_digest(killed / "cases") == tree_digest(tmp_path / "uninterrupted" / "cases")


@pytest.mark.slow
def test_resume_reruns_what_a_killed_driver_left_unrecorded_or_damaged(small_run, tmp_path):
    reference, _ = small_run
    run = tmp_path / "run"
    shutil.copytree(reference, run)
    # The state a driver killed at the worst moments leaves behind:
    info = json.loads((run / "run.json").read_text())
    info.update(state="running", wall_time_s=None, episodes_per_s=None, n_error=None)
    info["sessions"][0]["wall_time_s"] = None
    (run / "run.json").write_text(json.dumps(info))
    (run / "episodes.parquet").unlink()  # killed before assembling the table
    manifest = Manifest.load(run / "manifest.json")
    del manifest.chunks["crossing-000001-000001"]  # part written, killed before recording it
    manifest.save()
    damaged = run / "parts" / "crossing-000002-000002.parquet"
    damaged.write_bytes(damaged.read_bytes()[:100])  # recorded, then damaged on disk
    (run / "parts" / "crossing-000003-000003.parquet.tmp").write_bytes(b"half a part")
    (run / "cases" / "crossing_sv_1.parquet.tmp").write_bytes(b"half a case")

    proc = batch("--resume", "--out", str(run), "--workers", "1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "chunk crossing-000002-000002 runs again: parts/crossing-000002-000002.parquet" in proc.stderr
    assert "removed parts/crossing-000001-000001.parquet (written but never recorded)" in proc.stderr
    assert "removed parts/crossing-000002" not in proc.stderr
    assert "2 chunk(s) to run" in proc.stdout
    pd.testing.assert_frame_equal(
        pd.read_parquet(run / "episodes.parquet"), pd.read_parquet(reference / "episodes.parquet")
    )
    assert not list(run.rglob("*.tmp"))
    assert tree_digest(run / "parts") == tree_digest(reference / "parts")
    assert tree_digest(run / "cases") == tree_digest(reference / "cases")


@pytest.mark.slow
def test_resuming_a_complete_run_changes_nothing(small_run):
    out, _ = small_run
    before = tree_digest(out)
    proc = batch(*SMALL_RUN_ARGS, "--resume", "--out", str(out), timeout=120)
    assert proc.returncode == 0 and "nothing to resume" in proc.stdout
    assert tree_digest(out) == before
