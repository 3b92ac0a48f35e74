"""python -m pedsafe_sumo.ncap: bad input is one line and exit 2 and damages nothing; a small grid writes
its result files; any cell replays and exports FCD with the existing replay tool."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.ncap.__main__ import main

TESTS_DIR = Path(__file__).parent
sys.path.insert(0, str(TESTS_DIR))  # agents:Class for --algorithm in-process
ISSUE_COLUMNS = [
    "test", "ego_speed_kmh", "impact_point_pct", "condition", "avoided", "impact_speed_kmh", "colour",
    "cell_score",
]  # fmt: skip


def ncap(*args: str, module: str = "pedsafe_sumo.ncap") -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), str(TESTS_DIR)])}
    return subprocess.run(
        [sys.executable, "-m", module, *args], capture_output=True, text=True, env=env, timeout=300
    )


@pytest.mark.parametrize(
    "args, says",
    [
        (["--tests", "CPXX"], "unknown test 'CPXX'"),
        (["--tests", "CPNA-30"], "CPNA has no 30 % column"),
        (["--speeds", "25"], "has no 25 km/h row"),
        (["--speeds", "-10"], "not a positive speed"),
        (["--speeds", "fast"], "'fast' is not a number"),
        (["--site", "atlantis"], "unknown site 'atlantis'"),
        (["--algorithm", "nosuchpkg.mod:Stack"], "cannot import module 'nosuchpkg.mod'"),
        (["--condition", "v3i"], "--condition must be sv, v2i or both"),
        (["--seed", "-1"], "--seed must not be negative"),
        (["--lighting", "dusk"], "--lighting must be day, night or both"),
        (["--tests", "CPTAsame", "--lighting", "night"], "has no night load case"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, says):
    out = tmp_path / "out"
    assert main(["--out", str(out), *args]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], lines
    assert not out.exists()


def test_a_bad_argument_from_the_shell_is_one_line_and_exit_2(tmp_path):
    done = ncap("--out", str(tmp_path / "out"), "--robustness", "yes")
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr


def test_results_already_written_are_refused_and_kept(tmp_path, capsys):
    (tmp_path / "ncap.csv").write_text("earlier results\n")
    assert main(["--out", str(tmp_path), "--tests", "CPNA-50", "--speeds", "20"]) == 2
    assert "already holds results" in capsys.readouterr().err
    assert (tmp_path / "ncap.csv").read_text() == "earlier results\n"


@pytest.mark.slow
def test_a_small_grid_writes_the_issues_files_and_any_cell_replays(tmp_path):
    out = tmp_path / "run"
    done = ncap(
        "--out",
        str(out),
        "--tests",
        "CPNA-25,CPTAsame-50",
        "--speeds",
        "10",
        "--algorithm",
        "agents:NeverBrakes",
    )
    assert done.returncode == 0, done.stderr
    table = pd.read_csv(out / "ncap.csv")
    assert list(table.columns[: len(ISSUE_COLUMNS)]) == ISSUE_COLUMNS
    # CPNA-25 at 10 km/h, CPTAsame-50 farside and nearside at 10 km/h; each under SV and V2I.
    assert len(table) == 6 and set(table["condition"]) == {"sv", "v2i"}
    assert not table["avoided"].any() and (table["colour"] == "red").all()
    assert (table["impact_speed_kmh"] - 10).abs().max() < 1.0
    scores = pd.read_csv(out / "ncap_scores.csv")
    assert set(scores["test"]) == {"CPNA", "CPTAsame", "overall"} and (scores["points"] == 0).all()
    assert (out / "figures" / "ncap_grid.png").stat().st_size > 0
    assert len(list((out / "cases").glob("*.parquet"))) == 6
    # The metrics: never braking, no brake onset, no speed taken off, no warning output.
    assert table["brake_onset_ttc_s"].isna().all() and table["warning_time_s"].isna().all()
    assert (table["speed_reduction_kmh"].abs() < 1e-9).all()
    # The last line says the grid is partial and what is missing.
    last = done.stdout.strip().splitlines()[-1]
    assert last.startswith("ncap: PARTIAL grid") and "CPNA day (29 of 30 cells)" in last
    assert (scores["points_kind"] == "partial").all()

    # A turning cell replays too (the engine holding the ego's movement green, as the suite ran it).
    fcd = tmp_path / "cell.fcd.xml"
    cell = "CPTAsame-50_nearside10kmh"
    replay = ncap(
        str(out), "--scenario", cell, "--episode", "0", "--condition", "v2i", "--export-fcd", str(fcd),
        module="pedsafe_sumo.replay",
    )  # fmt: skip
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "trajectory matches the log" in replay.stdout and "differs" not in replay.stdout
    text = fcd.read_text()
    assert "<fcd-export" in text and 'id="ego"' in text and 'id="ped"' in text


@pytest.mark.slow
def test_a_night_only_run_replays_its_cells_with_the_night_camera(tmp_path):
    out = tmp_path / "night"
    done = ncap("--out", str(out), "--tests", "CPNCO-25", "--speeds", "50", "--lighting", "night")
    assert done.returncode == 0, done.stderr
    table = pd.read_csv(out / "ncap.csv")
    assert list(table["cell_id"]) == ["CPNCO-25_50kmh_night"] * 2 and (table["lighting"] == "night").all()
    replay = ncap(
        str(out), "--scenario", "CPNCO-25_50kmh_night", "--episode", "0", "--condition", "sv",
        "--export-fcd", str(tmp_path / "night.fcd.xml"), module="pedsafe_sumo.replay",
    )  # fmt: skip
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "trajectory matches the log" in replay.stdout and "differs" not in replay.stdout


@pytest.mark.slow
def test_a_stack_that_raises_is_recorded_as_an_error_and_the_suite_goes_on(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        ["--out", str(out), "--tests", "CPNA-50", "--speeds", "10,20", "--algorithm", "agents:RaisesAt20Kmh"]
    )
    assert code == 0
    table = pd.read_csv(out / "ncap.csv").set_index(["cell_id", "condition"])
    assert (table.loc["CPNA-50_20kmh", "status"] == "error").all()
    assert table.loc["CPNA-50_20kmh", "error"].str.contains("ZeroDivisionError: the stack's bug").all()
    assert (table.loc["CPNA-50_10kmh", "status"] == "ok").all()
    assert not table.loc["CPNA-50_10kmh", "avoided"].any()  # it holds its speed: hit
    episodes = pd.read_parquet(out / "episodes.parquet")
    errors = episodes[episodes["status"] == "error"]
    assert len(errors) == 2 and not errors["collision"].any()
    scores = pd.read_csv(out / "ncap_scores.csv")
    assert not scores["complete"].any() and (scores["cells"] == 1).all()
    assert "2 error(s)" in capsys.readouterr().out
