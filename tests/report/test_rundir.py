"""Reading the run directory: the header line from the batch's run.json."""

from __future__ import annotations

import json

from report_runs import standard_episodes, write_run

from pedsafe_sumo.report.rundir import load_run, run_header


def test_header_reads_the_batch_keys(tmp_path):
    info = {
        "episodes_per_scenario": 500,
        "wall_time_s": 61.04,
        "run_seed": 7,
        "versions": {"sumo": "1.28.0", "python": "3.12.1", "packages": {"numpy": "2.4"}},
    }
    run = load_run(write_run(tmp_path / "run", standard_episodes(), info))
    assert run_header(run) == (
        f"run {tmp_path / 'run'}: 500 episodes per scenario and condition (42 rows); seed 7; "
        "wall time 61.0 s; versions: sumo 1.28.0, python 3.12.1"
    )


def test_header_with_few_keys_or_no_run_json(tmp_path):
    run = load_run(write_run(tmp_path / "a", standard_episodes(), {"command": "batch"}))
    assert run_header(run) == f"run {tmp_path / 'a'}: 42 episode rows"
    run = load_run(write_run(tmp_path / "b", standard_episodes(), None))
    assert run.run_info is None and run_header(run).endswith("42 episode rows (no run.json)")


def test_run_json_that_is_not_an_object_is_noted(tmp_path):
    directory = write_run(tmp_path / "run", standard_episodes(), None)
    (directory / "run.json").write_text(json.dumps([1, 2]))
    run = load_run(directory)
    assert run.run_info is None and "is not a JSON object" in run.run_info_problem
