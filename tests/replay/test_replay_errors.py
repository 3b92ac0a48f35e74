"""Bad input to the replay ends in one line on stderr and exit status 2, never a traceback."""

from __future__ import annotations

import pandas as pd
import pytest
from replay_runs import case_files, edit_run_json, run_cli

from pedsafe_sumo.replay.__main__ import main
from pedsafe_sumo.replay.rundir import load_logged_episode


def one_error_line(capsys, argv) -> str:
    status = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2, err
    assert len(err) == 1 and err[0].startswith("error: ")
    return err[0]


def test_missing_run_directory(capsys, tmp_path):
    line = one_error_line(capsys, [str(tmp_path / "nowhere"), "--episode", "0", "--condition", "sv"])
    assert "does not exist" in line


@pytest.mark.parametrize("present", ["nothing", "run.json only", "episodes.parquet only"])
def test_directory_that_is_not_a_run(capsys, tmp_path, present):
    if present == "run.json only":
        (tmp_path / "run.json").write_text("{}")
    if present == "episodes.parquet only":
        pd.DataFrame({"scenario": ["crossing"]}).to_parquet(tmp_path / "episodes.parquet")
    line = one_error_line(capsys, [str(tmp_path), "--episode", "0", "--condition", "sv"])
    assert "not a batch run directory" in line


@pytest.mark.slow
def test_unreadable_run_json(capsys, run_copy):
    run_dir = run_copy()
    (run_dir / "run.json").write_text("{ not json")
    assert "cannot read" in one_error_line(capsys, [str(run_dir), "--episode", "0", "--condition", "sv"])


@pytest.mark.slow
@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--episode", "7", "--condition", "sv"], "episode 7 is not in run"),
        (["--episode", "-1", "--condition", "sv"], "episode -1 is not in run"),
        (["--episode", "0", "--condition", "lidar"], "unknown condition 'lidar'"),
        (
            ["--episode", "0", "--condition", "sv", "--scenario", "crossing"],
            "scenario 'crossing' is not in run",
        ),
        (["--episode", "0", "--condition", "sv", "--at", "3"], "--at chooses the moment of --screenshot"),
        (["--episode", "0", "--condition", "sv", "--delay", "-5"], "--delay must be"),
        (["--episode", "0", "--condition", "sv", "--screenshot", "x.jpg"], "PNG"),
        (
            ["--episode", "0", "--condition", "sv", "--screenshot", "x.png", "--export-fcd", "x.xml"],
            "separate runs",
        ),
    ],
    ids=[
        "unknown-episode",
        "negative-episode",
        "unknown-condition",
        "scenario-not-in-run",
        "at-without-screenshot",
        "negative-delay",
        "not-png",
        "screenshot-and-fcd",
    ],
)
def test_bad_arguments(capsys, replay_run, extra, expected):
    assert expected in one_error_line(capsys, [str(replay_run), *extra])


@pytest.mark.slow
def test_condition_the_run_did_not_run(capsys, run_copy):
    run_dir = run_copy()
    table = pd.read_parquet(run_dir / "episodes.parquet")
    table[table["condition"] == "sv"].to_parquet(run_dir / "episodes.parquet", index=False)
    line = one_error_line(capsys, [str(run_dir), "--episode", "0", "--condition", "v2i"])
    assert "condition 'v2i' was not run" in line


@pytest.mark.slow
def test_several_scenarios_need_scenario(capsys, run_copy):
    # The same episodes listed under a second scenario: the episode number alone no longer says which.
    run_dir = run_copy()
    table = pd.read_parquet(run_dir / "episodes.parquet")
    pd.concat([table, table.assign(scenario="crossing")]).to_parquet(
        run_dir / "episodes.parquet", index=False
    )
    line = one_error_line(capsys, [str(run_dir), "--episode", "0", "--condition", "sv"])
    assert "several scenarios (crossing, jaywalking)" in line and "--scenario" in line
    assert load_logged_episode(run_dir, 0, "sv", scenario="jaywalking").scenario == "jaywalking"


@pytest.mark.slow
def test_unloadable_algorithm(capsys, run_copy):
    run_dir = run_copy()
    edit_run_json(run_dir, lambda info: info.update(algorithm="nosuch.stack:Planner"))
    line = one_error_line(capsys, [str(run_dir), "--episode", "0", "--condition", "sv"])
    assert "the run's algorithm cannot be loaded" in line and "nosuch.stack" in line


@pytest.mark.slow
def test_run_json_without_the_parameters(capsys, run_copy):
    run_dir = run_copy()
    edit_run_json(run_dir, lambda info: info.pop("parameters"))
    line = one_error_line(capsys, [str(run_dir), "--episode", "0", "--condition", "sv"])
    assert "lacks parameters" in line


@pytest.mark.slow
def test_scenario_field_this_version_does_not_know(capsys, run_copy):
    run_dir = run_copy()
    edit_run_json(run_dir, lambda info: info["scenarios"]["jaywalking"].update(rain_intensity=0.5))
    line = one_error_line(capsys, [str(run_dir), "--episode", "0", "--condition", "sv"])
    assert "rain_intensity" in line


@pytest.mark.slow
@pytest.mark.parametrize(
    ("moment", "expected"),
    [
        ("99", "the episode runs from t=0 to"),
        ("-1", "the episode runs from t=0 to"),
        ("soon", "--at must be"),
    ],
)
def test_screenshot_moment_outside_the_episode(capsys, monkeypatch, replay_run, tmp_path, moment, expected):
    monkeypatch.setenv("DISPLAY", ":pedsafe-test")  # refused before sumo-gui would ever start
    argv = [str(replay_run), "--episode", "0", "--condition", "sv", "--screenshot", str(tmp_path / "x.png")]
    assert expected in one_error_line(capsys, [*argv, "--at", moment])
    assert not (tmp_path / "x.png").exists()


@pytest.mark.slow
def test_screenshot_of_a_collision_that_never_happened(capsys, monkeypatch, run_copy, tmp_path):
    # Without its case log and with a pedestrian who reacts at once and runs (x2, up to 3 m/s), the
    # pedestrian of episode 0 escapes: the replay (a headless run gives its course in advance) has no
    # collision to show. (At x1.5 they do not: they react only once they see the ego,
    # which the queue hides until they step out.)
    run_dir = run_copy()
    for condition in ("sv", "v2i"):
        for path in case_files(run_dir, 0, condition):
            path.unlink()
    escapes = {"hasten_factor": 2.0, "hasten_max_speed_mps": 3.0, "reaction_time_s": 0.0}
    edit_run_json(run_dir, lambda info: info["parameters"]["pedestrians"].update(escapes))
    monkeypatch.setenv("DISPLAY", ":pedsafe-test")
    argv = [str(run_dir), "--episode", "0", "--condition", "sv", "--screenshot", str(tmp_path / "x.png")]
    assert "there is no collision in jaywalking episode 0" in one_error_line(
        capsys, [*argv, "--at", "collision"]
    )


@pytest.mark.slow
def test_command_line_error_has_no_traceback(replay_run):
    proc = run_cli("pedsafe_sumo.replay", str(replay_run), "--episode", "12", "--condition", "sv")
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"error: episode 12 is not in run {replay_run} (jaywalking has episodes 0-2)"
    ]
