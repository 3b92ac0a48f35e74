"""Fixtures of the batch tests: one small finished reference run, shared by the test modules."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from batch_cli import SMALL_RUN_ARGS, batch


@pytest.fixture(scope="session")
def small_run(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """A finished reference run (SMALL_RUN_ARGS on 2 pool workers); tests only read it."""
    out = tmp_path_factory.mktemp("batch") / "small"
    proc = batch(*SMALL_RUN_ARGS, "--workers", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out, proc
