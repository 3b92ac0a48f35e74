"""`python -m pedsafe_sumo.report DIR`: what it prints, the files it writes, and bad input."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np
import pandas as pd
import pytest
from report_runs import RUN_INFO, standard_episodes, write_run, write_standard_run

from pedsafe_sumo.report.__main__ import main
from pedsafe_sumo.report.figures import DPI

REPO = Path(__file__).resolve().parents[2]
FIGURES = (
    "injury_vs_age.png",
    "injury_vs_speed.png",
    "first_detection_distance.png",
    "case_speed_vs_frame.png",
    "impact_speed.png",
)
TABLES = ("table1.csv", "table1.md", "paired.csv", "paired.md")


def assert_real_png(path: Path, width_in: float | None = None, height_in: float | None = None) -> None:
    assert path.is_file() and path.stat().st_size > 0, path
    image = matplotlib.image.imread(path)
    assert image.ndim == 3 and image.shape[2] in (3, 4)
    if width_in is not None:
        assert image.shape[:2] == (round(height_in * DPI), round(width_in * DPI))
    rgb = image[..., :3]
    assert float(rgb.std()) > 0.01, f"{path.name} is a uniform image"
    # something drawn in each condition's colour: orange-red (SV) and blue (V2I) pixels
    red = (rgb[..., 0] > 0.8) & (rgb[..., 1] < 0.45) & (rgb[..., 2] < 0.2)
    blue = (rgb[..., 2] > 0.6) & (rgb[..., 0] < 0.3)
    assert red.sum() > 20 and blue.sum() > 20, f"{path.name}: SV or V2I colour missing"


def test_report_prints_tables_and_writes_every_file(tmp_path, capsys):
    run = write_standard_run(tmp_path / "run")
    assert main([str(run)]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].startswith(f"run {run}:")
    for text in (
        "10 episodes per scenario and condition (42 rows)",
        "seed 100",
        "wall time 12.3 s",
        "sumo 1.28.0",
    ):
        assert text in lines[0]
    assert any(line.startswith("Table I") for line in lines)
    assert any("crossing" in line and "SV" in line and "0.3000 [0.1078, 0.6032]" in line for line in lines)
    paired_line = next(line for line in lines if line.startswith("jaywalking") and "collision" in line)
    assert paired_line.split()[2:7] == ["10", "1", "5", "0", "4"] and paired_line.split()[-1] == "0.0625"
    assert "first detection, jaywalking V2I: 90% of episodes detect beyond 20.0 m (0 of 10 never)" in out
    assert "case figure: jaywalking episode 3 (seed 103), first perceived SV 5.00 s, V2I 0.50 s" in out
    for name in TABLES:
        assert (run / "tables" / name).stat().st_size > 0
    assert sorted(p.name for p in (run / "figures").iterdir()) == sorted(FIGURES)
    # a panel per scenario with a collision (crossing and jaywalking), side by side
    assert_real_png(run / "figures" / "injury_vs_age.png", 10.4, 4.0)
    assert_real_png(run / "figures" / "injury_vs_speed.png", 10.4, 4.0)
    assert_real_png(run / "figures" / "first_detection_distance.png", 10.4, 4.6)  # two scenario panels
    assert_real_png(run / "figures" / "case_speed_vs_frame.png", 7.0, 4.2)


def test_without_a_collision_the_injury_figures_are_skipped(tmp_path, capsys):
    episodes = standard_episodes()
    crossing = episodes[episodes["scenario"] == "crossing"].assign(collision=False, injury_probability=0.0)
    run = write_run(tmp_path / "run", crossing, run_info=None)
    assert main([str(run)]) == 0
    out = capsys.readouterr().out
    assert "note: no collision (status ok) in this run: injury figures skipped" in out
    assert "note: no case pair" in out and "case figure skipped" in out
    assert not out.startswith("run ")  # no run.json, no header
    assert sorted(p.name for p in (run / "figures").iterdir()) == [
        "first_detection_distance.png",
        "impact_speed.png",
    ]
    assert_real_png(run / "figures" / "first_detection_distance.png", 5.2, 4.6)  # one panel
    # Table I, the paired tests, and the checks of the indexes this run has columns for (the episodes
    # carry every column of EPISODE_COLUMNS, contact_stationary included)
    index_tables = ("agreement.csv", "contacts.csv", "pet.csv", "proximity.csv", "indexes.md")
    # and the audit: the collision witness and the staging diagnostics, always written
    index_tables += ("witness.csv", "witness_disagreements.csv", "staging.csv", "audit.md")
    assert sorted(p.name for p in (run / "tables").iterdir()) == sorted(TABLES + index_tables)


def test_unreadable_run_json_is_a_note_not_an_error(tmp_path, capsys):
    run = write_standard_run(tmp_path / "run")
    (run / "run.json").write_text("{not json")
    assert main([str(run)]) == 0
    assert capsys.readouterr().out.startswith(f"note: {run / 'run.json'} is unreadable")


def test_broken_case_file_skips_only_the_case_figure(tmp_path, capsys):
    run = write_standard_run(tmp_path / "run")
    (run / "cases" / "jaywalking_v2i_103.parquet").write_bytes(b"not parquet")
    assert main([str(run)]) == 0
    out = capsys.readouterr().out
    assert "note: cannot read the case logs of jaywalking seed 103" in out
    assert not (run / "figures" / "case_speed_vs_frame.png").exists()
    assert (run / "figures" / "first_detection_distance.png").exists()


def _bad_parquet(directory: Path) -> Path:
    directory.mkdir()
    (directory / "episodes.parquet").write_bytes(b"PAR1 this is not a parquet file")
    return directory


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda d: d / "nowhere", "does not exist"),
        (lambda d: (d / "empty").mkdir() or d / "empty", "has no episodes.parquet"),
        (
            lambda d: write_run(d / "run", standard_episodes().drop(columns=["collision", "status"])),
            "collision, status",
        ),
        (lambda d: write_run(d / "run", standard_episodes().iloc[:0]), "has no rows"),
        (lambda d: _bad_parquet(d / "run"), "cannot read"),
        (lambda d: (d / "file.txt").write_text("x") and d / "file.txt", "is not a directory"),
    ],
    ids=["missing-dir", "no-parquet", "missing-columns", "no-rows", "broken-parquet", "not-a-dir"],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, make, message):
    directory = make(tmp_path)
    assert main([str(directory)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], captured.err


def test_repeated_episode_numbers_are_bad_input(tmp_path, capsys):
    episodes = standard_episodes()
    run = write_run(tmp_path / "run", pd.concat([episodes, episodes.iloc[:1]]))
    assert main([str(run)]) == 2
    captured = capsys.readouterr()
    err = captured.err.splitlines()
    assert len(err) == 1 and "episode numbers repeat" in err[0]
    assert captured.out == "" and not (run / "tables").exists() and not (run / "figures").exists()


def _cli(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO), "MPLBACKEND": ""}
    env.pop("MPLBACKEND")
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.report", *args],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_cli_subprocess_runs_and_fails_cleanly(tmp_path):
    run = write_standard_run(tmp_path / "run")
    done = _cli(str(run))
    assert done.returncode == 0, done.stderr
    assert "Table I" in done.stdout and "Paired SV vs V2I" in done.stdout
    for name in FIGURES:
        assert_real_png(run / "figures" / name)
    bad = _cli(str(tmp_path / "missing"))
    assert bad.returncode == 2 and bad.stdout == ""
    assert bad.stderr.strip().count("\n") == 0 and "Traceback" not in bad.stderr
    assert np.all([name in done.stdout for name in ("tables/table1.csv", "figures/case_speed_vs_frame.png")])
    assert RUN_INFO["versions"]["pedsafe_sumo"] in done.stdout
