"""Replaying the cases of a batch run with --approach: the commands the HTML report prints for
them work as printed.

A batch with --approach runs the same episode seeds on every approach and names its case logs after the
arm (`crossing_sv_<seed>_S`); run.json records its units as `crossing@S`. A replay command
that named neither would look for `crossing_sv_<seed>` and the settings of `crossing`.
"""

from __future__ import annotations

import html
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from replay_runs import NEVER_BRAKES, run_cli

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.replay.rundir import ReplayError, _approach_unit

HAVE_DISPLAY = bool(os.environ.get("DISPLAY")) or shutil.which("xvfb-run") is not None
#: On Xueqing, crossing is staged on the N (the site's own), S and W approaches (docs/sites.md; on the
#: one-lane W with the occluders parked at the kerb); the replays are checked on N and S.
ARMS = ("N", "S")
HOSTED_ARMS = ("N", "S", "W")


@pytest.fixture(scope="module")
def approach_run(tmp_path_factory) -> Path:
    """crossing on every approach of Xueqing that hosts it, 2 pairs each; the AD stack never brakes, so
    every pair collides and every episode has a case log."""
    out = tmp_path_factory.mktemp("approach") / "run"
    proc = run_cli(
        "pedsafe_sumo.batch",
        *("--scenario", "crossing", "--approach", "all", "--episodes", "2", "--seed", "7"),
        *("--workers", "1", "--algorithm", NEVER_BRAKES, "--out", str(out)),
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert sorted(episodes["approach"].unique()) == list(HOSTED_ARMS)
    return out


def printed_commands(run: Path, arm: str) -> list[str]:
    """The replay commands of the HTML report of `arm`'s episodes (report --approach ARM)."""
    proc = run_cli("pedsafe_sumo.report", str(run), "--approach", arm)
    assert proc.returncode == 0, proc.stderr[-2000:]
    page = (run / f"approach_{arm}" / "report.html").read_text(encoding="utf-8")
    found = re.findall(r"<code>(python -m pedsafe_sumo\.replay [^<]*)</code>", page)
    return [html.unescape(c) for c in found]


def run_printed(command: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    argv = shlex.split(command)
    assert argv[:3] == ["python", "-m", "pedsafe_sumo.replay"]
    # The run's stack lives in the tests package (tests.sim.plugin_agents): importable from the
    # repository root, while the command runs in its own folder so that its outputs land there.
    python_path = os.pathsep.join(filter(None, [str(REPO_ROOT), os.environ.get("PYTHONPATH", "")]))
    env = {**os.environ, "LIBGL_ALWAYS_SOFTWARE": "1", "PYTHONPATH": python_path}
    return subprocess.run(
        [sys.executable, *argv[1:]], capture_output=True, text=True, cwd=cwd, timeout=timeout, env=env
    )


@pytest.mark.slow
@pytest.mark.parametrize("arm", ARMS)
def test_the_reports_export_command_replays_the_case_of_its_approach(approach_run, arm, tmp_path):
    commands = printed_commands(approach_run, arm)
    cases = sorted((approach_run / "cases").glob(f"crossing_*_{arm}.parquet"))
    # 2 pairs x 2 conditions on this approach, each with its case log, each with three commands.
    assert len(cases) == 4 and len(commands) == 3 * len(cases)
    assert all(f"--approach {arm}" in c for c in commands)
    export = next(c for c in commands if "--export-fcd" in c)
    proc = run_printed(export, tmp_path)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    episode, condition = re.search(r"--episode (\d+) --condition (\w+)", export).groups()
    table = pd.read_parquet(approach_run / "episodes.parquet")
    row = table[
        (table["approach"] == arm) & (table["episode"] == int(episode)) & (table["condition"] == condition)
    ].iloc[0]
    stem = f"crossing_{condition}_{int(row['seed'])}_{arm}"
    # Checked against the case log of that approach, every step, and the outcome of its row.
    assert f"checking every step against the case log {approach_run / 'cases' / stem}.parquet" in proc.stdout
    assert "outcome matches episodes.parquet" in proc.stdout
    assert (tmp_path / f"{stem}.fcd.xml").is_file()


@pytest.mark.gui
@pytest.mark.slow
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_the_reports_screenshot_command_renders_beside_the_case_log(approach_run, tmp_path):
    command = next(c for c in printed_commands(approach_run, "S") if "--screenshot" in c)
    picture = Path(re.search(r"--screenshot (\S+)", command).group(1))
    assert picture.parent == approach_run / "cases" and picture.stem.endswith("_S")
    proc = run_printed(command, tmp_path, timeout=400)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert picture.is_file() and picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The report shows it in place of the plot of the logged trajectories.
    printed_commands(approach_run, "S")
    assert "replay screenshot" in (approach_run / "approach_S" / "report.html").read_text(encoding="utf-8")


@pytest.mark.slow
def test_a_run_of_several_approaches_needs_approach_and_refuses_one_it_did_not_run(approach_run):
    proc = run_cli(
        "pedsafe_sumo.replay", str(approach_run), *("--episode", "0", "--condition", "sv"),
        *("--export-fcd", "x.fcd.xml"),
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "ran crossing on approaches N, S, W: say which with --approach" in proc.stderr
    proc = run_cli(
        "pedsafe_sumo.replay", str(approach_run), *("--episode", "0", "--condition", "sv", "--approach", "E"),
        *("--export-fcd", "x.fcd.xml"),
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "did not run crossing on approach E (it has: N, S, W)" in proc.stderr


def test_which_settings_and_rows_an_approach_picks():
    """The logic alone (no SUMO): a unit `crossing@S` of run.json for --approach S, the only approach of a
    one-approach run without --approach, the plain `crossing` of a run made without --approach."""
    rows = pd.DataFrame({"approach": ["N", "S", "N", "S"], "episode": [0, 0, 1, 1]})
    several = {"scenarios": {"crossing@N": {}, "crossing@S": {}}}
    unit, picked = _approach_unit(Path("run"), several, "crossing", rows, "S")
    assert unit == "crossing@S" and list(picked["approach"]) == ["S", "S"]
    with pytest.raises(ReplayError, match="ran crossing on approaches N, S: say which with --approach"):
        _approach_unit(Path("run"), several, "crossing", rows, None)
    one = {"scenarios": {"crossing@S": {}}}
    unit, picked = _approach_unit(Path("run"), one, "crossing", rows[rows["approach"] == "S"], None)
    assert unit == "crossing@S" and len(picked) == 2
    plain = {"scenarios": {"crossing": {}}}
    unit, picked = _approach_unit(Path("run"), plain, "crossing", rows[rows["approach"] == "N"], None)
    assert unit == "crossing" and len(picked) == 2
    unit, _ = _approach_unit(Path("run"), plain, "crossing", rows[rows["approach"] == "N"], "N")
    assert unit == "crossing"
    with pytest.raises(ReplayError, match="ran crossing on approach N, not on approach E"):
        _approach_unit(Path("run"), plain, "crossing", rows[rows["approach"] == "N"], "E")
