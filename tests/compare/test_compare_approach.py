"""compare's replay commands on runs made with batch --approach: the episode lists B's
worse episodes with the command the HTML report prints (report.html.replay_commands), which names the
scenario and the approach, and the command runs as printed.

Before, compare printed `replay RUN_B --episode N --condition C   # scenario`: no --scenario, no
--approach, while such a run names its case logs `<scenario>_<condition>_<seed>_<arm>`.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT

#: A stack that never brakes (tests/sim/plugin_agents.py): under it every crossing pair collides, so B
#: is worse than the reference stack on some episodes and every one of those has a case log.
NEVER_BRAKES = "tests.sim.plugin_agents:NeverBrakes"
#: S: an approach of Xueqing that hosts crossing and is not the site's own (N), so the arm matters.
ARM = "S"


def _run(module: str, *args: str, cwd=REPO_ROOT, timeout: float = 600) -> subprocess.CompletedProcess:
    # The never-braking stack lives in the tests package: importable with the repository on the path.
    python_path = os.pathsep.join(filter(None, [str(REPO_ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
        env={**os.environ, "PYTHONPATH": python_path},
    )


def _approach_batch(out, *extra: str) -> None:
    proc = _run(
        "pedsafe_sumo.batch",
        *("--scenario", "crossing", "--approach", ARM, "--episodes", "2", "--seed", "7", "--workers", "1"),
        *("--out", str(out), *extra),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]


@pytest.mark.slow
def test_compare_prints_replay_commands_that_run_on_an_approach_run(tmp_path):
    run_a, run_b = tmp_path / "a", tmp_path / "b"
    _approach_batch(run_a)
    _approach_batch(run_b, "--algorithm", NEVER_BRAKES)
    rows_b = pd.read_parquet(run_b / "episodes.parquet")
    assert set(rows_b["approach"]) == {ARM} and rows_b["collision"].all()
    proc = _run("pedsafe_sumo.compare", str(run_a), str(run_b), timeout=120)
    assert proc.returncode in (0, 1), proc.stderr
    commands = [line.strip() for line in proc.stdout.splitlines() if "pedsafe_sumo.replay" in line]
    # B collided in every episode; the reference stack (A) avoided at least one of them.
    rows_a = pd.read_parquet(run_a / "episodes.parquet")
    n_worse = int((~rows_a["collision"].astype(bool)).sum())
    assert n_worse > 0 and len(commands) >= n_worse, proc.stdout
    assert all(f"--scenario crossing --approach {ARM}" in c for c in commands), commands
    # The case logs of such a run are named after the arm; the command picks that one.
    assert all(p.stem.endswith(f"_{ARM}") for p in (run_b / "cases").glob("*.parquet"))
    command = commands[0]
    argv = shlex.split(command)
    assert argv[:3] == ["python", "-m", "pedsafe_sumo.replay"]
    # As printed, headless: the FCD export instead of sumo-gui.
    replay = _run(*argv[2:], "--export-fcd", "worse.fcd.xml", cwd=tmp_path, timeout=300)
    assert replay.returncode == 0, replay.stdout[-2000:] + replay.stderr[-2000:]
    episode, condition = re.search(r"--episode (\d+) --condition (\w+)", command).groups()
    row = rows_b[(rows_b["episode"] == int(episode)) & (rows_b["condition"] == condition)].iloc[0]
    stem = f"crossing_{condition}_{int(row['seed'])}_{ARM}"
    assert f"checking every step against the case log {run_b / 'cases' / stem}.parquet" in replay.stdout
    assert "outcome matches episodes.parquet" in replay.stdout
    assert (tmp_path / "worse.fcd.xml").is_file()
