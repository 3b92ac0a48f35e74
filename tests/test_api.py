"""pedsafe_sumo.api: the same rows as the command line, the same one-line refusals, the report's numbers.

One small run through the API and the same run through `python -m pedsafe_sumo.batch` (2 crossing pairs,
one worker, every step log kept): their rows must be equal, column for column; Table I from the API must
hold the counts of the rows (counted here) and the numbers of the report's tables/table1.csv.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from pedsafe_sumo import REPO_ROOT, api
from pedsafe_sumo.batch.__main__ import main as batch_main
from pedsafe_sumo.episode import main as episode_main
from pedsafe_sumo.report.__main__ import main as report_main

#: Options of the small run, as the API takes them and as the command line spells them.
OPTIONS = {"scenario": "crossing", "episodes": 2, "seed": 5, "workers": 1, "keep_logs": "all"}
CLI_OPTIONS = [
    "--scenario",
    "crossing",
    "--episodes",
    "2",
    "--seed",
    "5",
    "--workers",
    "1",
    "--keep-logs",
    "all",
]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The small run made by the API (quietly) and by the command line."""
    base = tmp_path_factory.mktemp("api")
    run = api.run_batch(base / "api", progress=False, **OPTIONS)
    done = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", *CLI_OPTIONS, "--out", str(base / "cli")],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr
    return run, base / "cli"


@pytest.mark.slow
def test_run_batch_gives_the_rows_of_the_command_line(runs):
    run, cli_dir = runs
    cli_rows = pd.read_parquet(cli_dir / "episodes.parquet")
    # episodes.parquet has no timing or provenance column (docs/columns.md): every column is compared.
    assert len(run.episodes) == 4
    pd.testing.assert_frame_equal(run.episodes, cli_rows, check_exact=True)
    cli_config = json.loads((cli_dir / "run.json").read_text())
    for key in ("arguments", "run_seed", "scenarios", "conditions", "parameters", "algorithm"):
        assert run.config[key] == cli_config[key], key
    assert run.config["state"] == "complete"


@pytest.mark.slow
def test_table_one_holds_the_counts_of_the_rows_and_the_reports_numbers(runs, capsys):
    run, _ = runs
    table = api.table_one(run)
    rows = run.episodes
    for condition in ("sv", "v2i"):
        mine = rows[(rows["condition"] == condition) & (rows["status"] == "ok")]
        line = table[(table["scenario"] == "crossing") & (table["condition"] == condition)].iloc[0]
        assert line["n"] == len(mine) == 2
        assert line["collision_rate"] * line["n"] == pytest.approx(int(mine["collision"].sum()))
        # Table I's conflict is a conflict in an episode without a collision.
        conflicts = int((mine["conflict"] & ~mine["collision"]).sum())
        assert line["conflict_rate"] * line["n"] == pytest.approx(conflicts)
        assert line["injury_mean"] == pytest.approx(mine["injury_probability"].fillna(0).mean())
    # The report of the same directory writes Table I and the paired table as CSV.
    assert report_main([str(run.path)]) == 0
    capsys.readouterr()
    written = pd.read_csv(run.path / "tables" / "table1.csv")
    assert list(written.columns) == list(table.columns)
    for column in table.columns:
        if pd.api.types.is_numeric_dtype(table[column]):
            assert np.allclose(written[column], table[column], rtol=1e-12, equal_nan=True), column
        else:
            assert list(written[column]) == list(table[column]), column
    paired = api.paired_comparison(run)
    written_paired = pd.read_csv(run.path / "tables" / "paired.csv")
    assert list(written_paired.columns) == list(paired.columns)
    assert list(paired["n_pairs"]) == [2] * len(paired)
    sv = rows[rows["condition"] == "sv"].set_index("episode")
    v2i = rows[rows["condition"] == "v2i"].set_index("episode")
    collision = paired[paired["outcome"] == "collision"].iloc[0]
    both = int((sv["collision"] & v2i["collision"]).sum())
    assert collision["both"] == both


@pytest.mark.slow
def test_figures_are_matplotlib_figures(runs):
    run, _ = runs
    drawn = api.figure(run, "impact_speed")
    assert isinstance(drawn, Figure) and drawn.axes
    assert "Impact speeds" in drawn.axes[0].get_title()
    # The injury figures have a panel per scenario with a collision: without one they cannot be drawn,
    # and the error says why.
    collided = run.episodes["collision"].astype("boolean").fillna(False)
    if collided.any():
        assert len(api.figure(run, "injury_vs_age").axes) >= 1
    else:
        with pytest.raises(api.ReportError, match="no collision"):
            api.figure(run, "injury_vs_age")
    with pytest.raises(api.ReportError, match="unknown figure 'speed'"):
        api.figure(run, "speed")


@pytest.mark.slow
def test_steps_of_a_kept_episode(runs):
    run, _ = runs
    row = run.episodes.iloc[1]
    steps = run.steps(row)
    assert len(steps) > 0
    assert set(steps["condition"]) == {row["condition"]} and set(steps["episode"]) == {row["episode"]}
    pd.testing.assert_frame_equal(steps, run.steps(int(row["episode"]), condition=str(row["condition"])))
    with pytest.raises(api.ReportError, match="no episode 7 of crossing under sv"):
        run.steps(7, "sv")


def refused_by_cli(capsys, main, argv: list[str]) -> str:
    """The line (without "error: ") a command prints when it refuses `argv` with exit code 2."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1, err
    return err.removeprefix("error: ").removesuffix("\n").removesuffix(" (see --help)")


@pytest.mark.parametrize(
    ("options", "argv", "message"),
    [
        ({"workers": 0}, ["--workers", "0"], "--workers must be at least 1, got 0"),
        ({"keep_logs": "some"}, ["--keep-logs", "some"], "invalid choice: 'some'"),
        ({"episodes": "many"}, ["--episodes", "many"], "invalid int value: 'many'"),
        ({"conditions": "v3i"}, ["--condition", "v3i"], "unknown condition 'v3i'"),
        (
            {"overrides": {"lane_count": 3}},
            ["--set", "lane_count=3"],
            "unknown scenario parameter 'lane_count'",
        ),
        ({"seed": -1}, ["--seed", "-1"], "--seed must not be negative"),
    ],
)
def test_run_batch_refuses_bad_input_with_the_command_lines_message(tmp_path, capsys, options, argv, message):
    out = tmp_path / "run"
    with pytest.raises(api.UsageError) as refused:
        api.run_batch(out, **{"scenario": "crossing", "episodes": 2, **options})
    assert message in str(refused.value) and "\n" not in str(refused.value)
    # The flag given last wins, as it does in the API's options.
    cli_line = refused_by_cli(
        capsys, batch_main, ["--scenario", "crossing", "--episodes", "2", *argv, "--out", str(out)]
    )
    assert str(refused.value) == cli_line
    assert not out.exists()


def test_run_batch_refuses_a_flag_a_protocol_fixes(tmp_path, capsys):
    with pytest.raises(api.UsageError) as refused:
        api.run_batch(tmp_path / "run", protocol="paper-v7", seed=3)
    cli_line = refused_by_cli(
        capsys, batch_main, ["--protocol", "paper-v7", "--seed", "3", "--out", str(tmp_path / "run")]
    )
    assert str(refused.value) == cli_line
    assert cli_line.startswith("--protocol fixes every value: --seed cannot be given with it")


@pytest.mark.parametrize(
    ("options", "argv", "message"),
    [
        ({"seed": -1}, ["--seed", "-1"], "--seed must not be negative"),
        ({"conditions": ["sv", "v3i"]}, ["--condition", "sv,v3i"], "unknown condition 'sv,v3i'"),
        ({"approach": "up"}, ["--approach", "up"], "up"),
    ],
)
def test_run_episode_refuses_bad_input_with_the_command_lines_message(capsys, options, argv, message):
    with pytest.raises(api.UsageError) as refused:
        api.run_episode("crossing", **options)
    assert message in str(refused.value)
    assert str(refused.value) == refused_by_cli(capsys, episode_main, ["--scenario", "crossing", *argv])


def test_run_episode_refuses_an_unknown_scenario(capsys):
    with pytest.raises(api.UsageError) as refused:
        api.run_episode("parking")
    assert str(refused.value) == refused_by_cli(capsys, episode_main, ["--scenario", "parking"])
    assert "parking" in str(refused.value)


@pytest.mark.slow
def test_run_episode_tells_what_the_command_prints(capsys):
    episode = api.run_episode("crossing", conditions="sv", seed=7)
    assert capsys.readouterr().out == ""  # quiet unless progress=True
    assert episode_main(["--scenario", "crossing", "--condition", "sv", "--seed", "7"]) == 0
    assert episode.describe() + "\n" == capsys.readouterr().out
    outcome = episode.outcomes.iloc[0]
    assert outcome["condition"] == "sv" and outcome["seed"] == 7
    steps = episode.steps()
    assert np.allclose(np.diff(steps["time_s"]), 0.05)


def test_load_run_of_a_missing_directory_is_one_line(tmp_path):
    with pytest.raises(api.ReportError) as refused:
        api.load_run(tmp_path / "nowhere")
    assert str(refused.value) == f"run directory {tmp_path / 'nowhere'} does not exist"


def test_load_run_of_a_directory_without_rows(tmp_path):
    with pytest.raises(api.ReportError, match="has no episodes.parquet: not a batch run directory"):
        api.load_run(tmp_path)


def test_importing_the_package_does_not_import_the_api():
    code = "import sys, pedsafe_sumo; print('pedsafe_sumo.api' in sys.modules, 'pandas' in sys.modules)"
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO_ROOT, check=True
    )
    assert done.stdout.split() == ["False", "False"]
