"""A batch stopped by SIGINT or SIGTERM (sent to the driver alone, as `kill` and job schedulers do)
stops within seconds even while a worker is deep in a slow episode, exits with code 130, leaves
run.json "running", and `--resume` then finishes the run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest
from batch_cli import batch
from faulty_stacks import SLEEP_MARKER_ENV

from pedsafe_sumo import REPO_ROOT

#: Longest wait for the stopped batch to exit [s]; its worker sleeps 60 s in the stack otherwise.
STOP_WITHIN_S = 20.0


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_stops_the_batch_within_seconds_and_resume_finishes_it(tmp_path, signum):
    out, marker = tmp_path / "run", tmp_path / "slow"
    marker.touch()
    env = {**os.environ, SLEEP_MARKER_ENV: str(marker)}
    args = ("--scenario", "crossing", "--episodes", "2", "--condition", "sv", "--workers", "1")
    driver = subprocess.Popen(
        [sys.executable, "-m", "pedsafe_sumo.batch", *args, "--chunk-size", "1", "--out", str(out),
         "--algorithm", "tests.batch.faulty_stacks:SleepsWhileMarked"],
        cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,  # the signal reaches the driver alone, not this test's process group
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 300
        while not marker.with_suffix(".asleep").exists():  # a worker is inside the slow run_step
            assert driver.poll() is None and time.monotonic() < deadline, driver.stderr.read()
            time.sleep(0.2)
        sent = time.monotonic()
        driver.send_signal(signum)
        _, stderr = driver.communicate(timeout=STOP_WITHIN_S)
        assert time.monotonic() - sent < STOP_WITHIN_S
    finally:
        if driver.poll() is None:
            driver.kill()
    assert driver.returncode == 130, stderr[-2000:]
    assert "continue with --resume" in stderr
    assert json.loads((out / "run.json").read_text())["state"] == "running"

    marker.unlink()
    resumed = batch("--resume", "--out", str(out), env={SLEEP_MARKER_ENV: str(marker)})
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert json.loads((out / "run.json").read_text())["state"] == "complete"
    table = pd.read_parquet(out / "episodes.parquet")
    assert len(table) == 2 and (table["status"] == "ok").all()
