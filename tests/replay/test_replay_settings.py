"""A replay runs with the run's recorded settings and checks itself against the log.

The session's run was made with a non-default scenario field and non-default parameters (see
conftest.py); none is passed again here. Headless (libsumo): the GUI replay runs the same loop, and
tests/sim/test_gui_equals_headless.py holds sumo-gui to the headless log.
"""

from __future__ import annotations

import dataclasses
import json

import pandas as pd
import pytest
from replay_runs import case_files, edit_run_json, episode_row, run_cli

from pedsafe_sumo.io.cases import read_case
from pedsafe_sumo.replay.rundir import load_logged_episode, scenario_from_record
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim.episode import EpisodeRunner


def export(run_dir, episode, condition, out):
    return run_cli(
        "pedsafe_sumo.replay",
        str(run_dir),
        *("--episode", str(episode), "--condition", condition, "--export-fcd", str(out)),
    )


@pytest.mark.slow
@pytest.mark.parametrize(("episode", "condition"), [(0, "sv"), (1, "v2i")])
def test_the_recorded_settings_reproduce_the_case_log_exactly(replay_run, episode, condition):
    logged = load_logged_episode(replay_run, episode, condition)
    # The run's settings, not today's defaults (the registry has 30 m; the run was made with 34).
    assert get_scenario("jaywalking").midblock_distance_min_m == 30.0
    assert logged.spec.midblock_distance_min_m == 34.0 and logged.spec.midblock_distance_max_m == 36.0
    assert logged.params["pedestrians"]["hasten_factor"] == 1.2
    assert logged.seed == episode_row(replay_run, episode, condition)["seed"]
    case_log, case_meta = read_case(case_files(replay_run, episode, condition)[0])
    runner = EpisodeRunner(logged.site, logged.params, logged.agent_class)
    try:
        setup = runner.draw_setup(logged.spec, logged.seed)
        assert setup == case_meta["setup"]  # the same world, drawn again from the seed
        result = runner.run(logged.spec, condition, logged.seed, setup=setup)
    finally:
        runner.close()
    pd.testing.assert_frame_equal(result.log, case_log)


@pytest.mark.slow
def test_replay_reports_that_it_matched_every_logged_step(replay_run, tmp_path):
    proc = export(replay_run, 2, "sv", tmp_path / "case.fcd.xml")
    assert proc.returncode == 0, proc.stderr
    n_steps = len(pd.read_parquet(case_files(replay_run, 2, "sv")[0]))
    assert f"trajectory matches the log: {n_steps} of {n_steps} steps checked" in proc.stdout
    assert "outcome matches episodes.parquet" in proc.stdout
    assert "differs from the recorded one" not in proc.stdout
    assert "MISMATCH" not in proc.stderr


@pytest.mark.slow
def test_a_log_that_differs_from_the_replay_is_reported_at_its_first_step(run_copy, tmp_path):
    run_dir = run_copy()
    log_path, _ = case_files(run_dir, 1, "sv")
    log = pd.read_parquet(log_path)
    true_x = float(log.loc[20, "ego_x_m"])
    log.loc[20, "ego_x_m"] = true_x + 0.01
    log.to_parquet(log_path, index=False)
    proc = export(run_dir, 1, "sv", tmp_path / "case.fcd.xml")
    assert proc.returncode == 1
    first_line = proc.stderr.strip().splitlines()[0]
    assert first_line == (
        f"MISMATCH at t={log.loc[20, 'time_s']:.2f} s: "
        f"ego_x_m logged {true_x + 0.01:.6f}, replayed {true_x:.6f}"
    )
    assert "trajectory DIFFERS from the log from" in proc.stdout


@pytest.mark.slow
def test_a_changed_run_parameter_changes_the_replay_and_the_difference_is_reported(run_copy, tmp_path):
    # Back to the default hasten factor (1.5): the hastening pedestrian walks faster than logged.
    run_dir = run_copy()
    edit_run_json(run_dir, lambda info: info["parameters"]["pedestrians"].update(hasten_factor=1.5))
    proc = export(run_dir, 1, "sv", tmp_path / "case.fcd.xml")
    assert proc.returncode == 1
    first_line = proc.stderr.strip().splitlines()[0]
    assert first_line.startswith("MISMATCH at t=") and ": ped_" in first_line


@pytest.mark.slow
def test_an_episode_without_case_log_is_replayed_from_the_recorded_scenario(run_copy, tmp_path):
    run_dir = run_copy()
    for condition in ("sv", "v2i"):
        for path in case_files(run_dir, 0, condition):
            path.unlink()
    proc = export(run_dir, 0, "sv", tmp_path / "case.fcd.xml")
    assert proc.returncode == 0, proc.stderr
    assert "nothing recorded to check the trajectory against" in proc.stdout
    assert "outcome matches episodes.parquet" in proc.stdout

    # The same, with run.json's scenario put back to the registry's mid-block distances: another
    # world is drawn from the seed, and the outcome no longer matches the recorded one.
    default = get_scenario("jaywalking")
    edit_run_json(
        run_dir,
        lambda info: info["scenarios"]["jaywalking"].update(
            midblock_distance_min_m=default.midblock_distance_min_m,
            midblock_distance_max_m=default.midblock_distance_max_m,
        ),
    )
    proc = export(run_dir, 0, "sv", tmp_path / "case.fcd.xml")
    assert proc.returncode == 1
    assert "MISMATCH in the outcome" in proc.stderr


@pytest.mark.slow
def test_a_recorded_world_that_differs_from_todays_draw_is_the_one_replayed(run_copy, tmp_path):
    run_dir = run_copy()
    _, meta_path = case_files(run_dir, 2, "sv")
    meta = json.loads(meta_path.read_text())
    # A field the loop does not use: the replay says the worlds differ and still matches the log.
    meta["setup"]["conflict_offset_s"] += 0.1
    meta_path.write_text(json.dumps(meta))
    proc = export(run_dir, 2, "sv", tmp_path / "case.fcd.xml")
    assert proc.returncode == 0, proc.stderr
    assert "differs from the recorded one (conflict_offset_s): replaying the recorded world" in proc.stdout
    # The ego's recorded initial speed: the replay starts from it, so its first step differs from the log.
    logged_speed_mps = meta["setup"]["ego"]["speed_mps"]
    meta["setup"]["ego"]["speed_mps"] = logged_speed_mps + 1.0
    meta_path.write_text(json.dumps(meta))
    proc = export(run_dir, 2, "sv", tmp_path / "case.fcd.xml")
    assert proc.returncode == 1
    first_line = proc.stderr.strip().splitlines()[0]
    assert first_line.startswith("MISMATCH at t=0.05 s: ego_speed_mps logged")
    assert f"replayed {logged_speed_mps + 1.0:.6f}" in first_line


def test_a_run_recorded_before_scenarios_named_their_poles_replays_with_the_one_pole_of_that_time():
    recorded = dataclasses.asdict(get_scenario("background_blending"))
    assert recorded["roadside_units"] == "rsu_camera_0,rsu_camera_1"  # today's default
    del recorded["roadside_units"]
    notes: list[str] = []
    spec = scenario_from_record({"background_blending": recorded}, "background_blending", notes)
    assert spec.roadside_unit_ids == ("rsu_camera_0",)
    assert any("roadside_units" in note for note in notes)
