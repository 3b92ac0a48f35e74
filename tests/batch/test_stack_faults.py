"""A misbehaving AD stack is never scored as safe: each fault (an invalid command, an exception at the
first step or in setup or close, sys.exit, a setup that hangs) ends its episode with status "error" (or
"timeout") and a one-line message naming what happened, its traceback is in cases/, SUMO survives (the
second episode of the same worker runs), and the batch finishes with exit code 0."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from batch_cli import batch

STACKS = "tests.batch.faulty_stacks"
ONE_EPISODE = ("--scenario", "crossing", "--episodes", "1", "--workers", "1")

AT_FIRST_STEP = "at t=0.05 s"  # the first step of a crossing episode
# stack, condition(s), extra arguments, status, the row's error ("{stack}": the stack's full name)
CASES = [
    ("ReturnsNaN", "sv", (), "error",
     f"StackError: AD stack {{stack}} returned target_speed_mps=nan {AT_FIRST_STEP}"),
    ("ReturnsInf", "sv", (), "error",
     f"StackError: AD stack {{stack}} returned target_speed_mps=inf {AT_FIRST_STEP}"),
    ("ReturnsNegative", "sv", (), "error",
     f"StackError: AD stack {{stack}} returned target_speed_mps=-1.5 {AT_FIRST_STEP}"),
    ("ReturnsText", "sv", (), "error",
     f"StackError: AD stack {{stack}} returned target_speed_mps='fast' (str, not a number) {AT_FIRST_STEP}"),
    ("ReturnsNone", "sv", (), "error",
     f"StackError: AD stack {{stack}} returned None (NoneType) instead of a Command {AT_FIRST_STEP}"),
    ("ReturnsNumber", "sv", (), "error",
     f"StackError: AD stack {{stack}} returned 8.0 (float) instead of a Command {AT_FIRST_STEP}"),
    # Both conditions in one worker: the second episode runs on the SUMO the first one failed in.
    ("RaisesAtFirstStep", "both", (), "error", "RuntimeError: planner crashed at its first step"),
    ("RaisesInSetup", "sv", (), "error", "ValueError: no map for this site"),
    ("RaisesInClose", "sv", (), "error", "OSError: cannot flush the stack's log"),
    ("ExitsInRunStep", "both", (), "error", "StackError: AD stack {stack} called sys.exit(3)"),
    ("HangsInSetup", "sv", ("--agent-timeout", "0.5"), "timeout",
     "AgentTimeoutError: the AD stack's setup did not return within 0.5 s (--agent-timeout)"),
]  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize(("stack", "condition", "extra", "status", "error"), CASES, ids=[c[0] for c in CASES])
def test_a_misbehaving_stack_gives_error_rows_and_a_finished_batch(
    tmp_path, stack, condition, extra, status, error
):
    message = error.format(stack=f"{STACKS}:{stack}")
    out = tmp_path / "run"
    proc = batch(
        *ONE_EPISODE,
        "--condition",
        condition,
        "--algorithm",
        f"{STACKS}:{stack}",
        *extra,
        "--out",
        str(out),
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    table = pd.read_parquet(out / "episodes.parquet")
    assert len(table) == (2 if condition == "both" else 1)
    assert (table["status"] == status).all(), table[["status", "error"]]
    assert (table["error"] == message).all(), table["error"].tolist()
    assert not table["collision"].any()  # a failed episode is never counted as a safe one: it is no episode
    run = json.loads((out / "run.json").read_text())
    assert run["state"] == "complete" and run["n_error"] == len(table)
    assert run["sessions"][0]["worker_deaths"] == 0  # SUMO did not crash
    traces = sorted((out / "cases").glob("*.error.txt"))
    assert len(traces) == len(table)
    for trace in traces:
        text = trace.read_text(encoding="utf-8")
        assert text.startswith(message + "\n") and "Traceback (most recent call last)" in text


@pytest.mark.slow
def test_a_stack_that_ends_its_process_is_an_error_row_not_retried_for_ever(tmp_path):
    out = tmp_path / "run"
    proc = batch(
        *ONE_EPISODE, "--condition", "sv", "--algorithm", f"{STACKS}:KillsItsProcess", "--out", str(out)
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    table = pd.read_parquet(out / "episodes.parquet")
    assert table["status"].tolist() == ["error"]
    assert table["error"].iloc[0].startswith("worker process died each time this episode pair ran")
