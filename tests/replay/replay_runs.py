"""Helpers of the replay tests: the run's settings, running the CLIs, finding and altering a run's files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd

from pedsafe_sumo import REPO_ROOT

NEVER_BRAKES = "tests.sim.plugin_agents:NeverBrakes"
RUN_SETTINGS = (
    "midblock_distance_min_m=34",
    "midblock_distance_max_m=36",
    "pedestrians.risk_share_unaware=0",
    "pedestrians.risk_share_hasten=1",
    "pedestrians.risk_share_yield=0",
    "pedestrians.hasten_factor=1.2",
)


def run_cli(module: str, *args: str, timeout: float = 300, env: dict | None = None):
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=timeout,
        env=env,
    )


def episode_row(run_dir: Path, episode: int, condition: str) -> dict:
    table = pd.read_parquet(run_dir / "episodes.parquet")
    row = table[(table["episode"] == episode) & (table["condition"] == condition)]
    assert len(row) == 1
    return row.iloc[0].to_dict()


def case_files(run_dir: Path, episode: int, condition: str) -> tuple[Path, Path]:
    row = episode_row(run_dir, episode, condition)
    stem = run_dir / "cases" / f"{row['scenario']}_{condition}_{int(row['seed'])}"
    return stem.with_suffix(".parquet"), stem.with_suffix(".json")


def edit_run_json(run_dir: Path, edit) -> None:
    path = run_dir / "run.json"
    info = json.loads(path.read_text())
    edit(info)
    path.write_text(json.dumps(info, indent=1))
