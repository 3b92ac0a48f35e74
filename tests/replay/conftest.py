"""A small batch run to replay, made once per session through the batch CLI.

Jaywalking, 3 paired episodes, an AD stack that never brakes (every pair collides, so every episode
has a case log), and settings that differ from today's defaults on purpose: a narrower mid-block
distance (a scenario field), every pedestrian hastening and a smaller hasten factor (parameters). A
replay that fell back on any default would draw another world or move the pedestrian differently.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from replay_runs import NEVER_BRAKES, RUN_SETTINGS, run_cli


@pytest.fixture(scope="session")
def replay_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("replay") / "run"
    settings = [arg for pair in RUN_SETTINGS for arg in ("--set", pair)]
    proc = run_cli(
        "pedsafe_sumo.batch",
        *("--scenario", "jaywalking", "--episodes", "3", "--seed", "7", "--workers", "1"),
        *("--algorithm", NEVER_BRAKES, "--out", str(out), *settings),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out


@pytest.fixture
def run_copy(replay_run, tmp_path):
    """A private copy of the run, to alter."""

    def make(name: str = "copy") -> Path:
        target = tmp_path / name
        shutil.copytree(replay_run, target)
        return target

    return make
