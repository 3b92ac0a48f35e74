"""python -m pedsafe_sumo.sweep --protocol: the protocol's study with one value changed per combination."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys

import pandas as pd
import pytest
import tomllib
from test_sweep import sweep

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.protocol import load_protocol
from pedsafe_sumo.settings import UsageError
from pedsafe_sumo.sweep_protocol import derived_protocol_text, write_derived_protocol

PROTOCOL = REPO_ROOT / "protocols" / "approach-v2.toml"


def test_a_derived_protocol_differs_from_its_source_only_in_the_swept_values_and_its_name():
    source = tomllib.loads(PROTOCOL.read_text())
    text = derived_protocol_text(
        load_protocol(PROTOCOL), {"algorithm.reaction_time_s": "1.5", "occluder_class": "van"}
    )
    derived = tomllib.loads(text)
    assert derived["parameters"]["algorithm"]["reaction_time_s"] == 1.5
    assert all(derived["scenarios"][s]["occluder_class"] == "van" for s in source["protocol"]["scenarios"])
    assert derived["protocol"]["name"] == "approach-v2+algorithm.reaction_time_s=1.5,occluder_class=van"
    # everything else as the source fixes it
    derived["parameters"]["algorithm"]["reaction_time_s"] = source["parameters"]["algorithm"][
        "reaction_time_s"
    ]
    for s in source["protocol"]["scenarios"]:
        derived["scenarios"][s]["occluder_class"] = source["scenarios"][s]["occluder_class"]
    derived["protocol"]["name"] = source["protocol"]["name"]
    assert derived == source
    # its first line names the source and the source's SHA-256
    assert hashlib.sha256(PROTOCOL.read_bytes()).hexdigest() in text.splitlines()[0]


def test_a_value_is_read_as_the_protocols_type():
    text = derived_protocol_text(load_protocol(PROTOCOL), {"queue_vehicles": "6"})
    assert tomllib.loads(text)["scenarios"]["crossing"]["queue_vehicles"] == 6
    with pytest.raises(UsageError, match="not a value of the protocol's type"):
        derived_protocol_text(load_protocol(PROTOCOL), {"queue_vehicles": "six"})


def test_a_derived_file_already_there_and_different_is_refused(tmp_path):
    protocol = load_protocol(PROTOCOL)
    path = tmp_path / "p.toml"
    write_derived_protocol(protocol, {"occluder_class": "van"}, path)
    write_derived_protocol(protocol, {"occluder_class": "van"}, path)  # the same text: kept
    path.write_text(path.read_text().replace('"van"', '"car"', 1))
    with pytest.raises(UsageError, match="changed since this sweep started"):
        write_derived_protocol(protocol, {"occluder_class": "van"}, path)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scenario", "crossing", "--preset", "reaction"], "--protocol fixes --scenario: leave it out"),
        (["--seed", "3", "--preset", "reaction"], "--protocol fixes --seed"),
        (["--vary", "no_such_field=1,2"], "has no scenario field 'no_such_field'"),
        (["--vary", "algorithm.no_such=1,2"], "names no parameter 'algorithm.no_such'"),
        (["--vary", "algorithm.reaction_time_s=0.4,-1"], "reaction_time_s must be >= 0"),
    ],
)
def test_bad_protocol_sweeps_are_one_line_exit_2_and_write_nothing(tmp_path, args, message):
    proc = sweep("--protocol", str(PROTOCOL), "--out", str(tmp_path / "s"), *args)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and message in proc.stderr, proc.stderr
    assert not (tmp_path / "s").exists()


@pytest.mark.slow
def test_each_combination_runs_its_derived_protocol_and_records_it(tmp_path):
    out = tmp_path / "sweep"
    proc = sweep("--protocol", str(PROTOCOL), "--vary", "occluder_class=car,van", "--episodes", "1",
                 "--workers", "1", "--out", str(out))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    source = tomllib.loads(PROTOCOL.read_text())
    for value in ("car", "van"):
        run = json.loads((out / f"occluder_class={value}" / "run.json").read_text())
        derived = out / "protocols" / f"occluder_class={value}.toml"
        assert run["protocol"]["sha256"] == hashlib.sha256(derived.read_bytes()).hexdigest()
        episodes = pd.read_parquet(out / f"occluder_class={value}" / "episodes.parquet")
        assert sorted(set(episodes["scenario"])) == sorted(source["protocol"]["scenarios"])
        assert len(episodes) == 2 * len(source["protocol"]["scenarios"])
        assert set(episodes["seed"]) == set(
            pd.read_parquet(out / "occluder_class=car" / "episodes.parquet")["seed"]
        )  # the same worlds in every combination
    assert len(pd.read_csv(out / "sweep.csv")) == 2 * 2 * len(source["protocol"]["scenarios"])


def _batch(*args, timeout=900):
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", *args],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=timeout,
    )  # fmt: skip


def test_base_run_is_refused_in_one_line_unless_it_is_a_complete_run_of_that_protocol(tmp_path):
    other = tmp_path / "other"
    other.mkdir()
    (other / "run.json").write_text(json.dumps({"protocol": {"sha256": "0" * 64}, "state": "complete"}))
    incomplete = tmp_path / "incomplete"
    incomplete.mkdir()
    own_sha = hashlib.sha256(PROTOCOL.read_bytes()).hexdigest()
    (incomplete / "run.json").write_text(json.dumps({"protocol": {"sha256": own_sha}, "state": "running"}))
    cases = [
        (["--scenario", "crossing", "--vary", "algorithm.reaction_time_s=0.4,1.0", "--base-run", str(other)],
         "--base-run needs --protocol"),
        (["--protocol", str(PROTOCOL), "--preset", "reaction", "--base-run", str(tmp_path / "nothing")],
         "--base-run: no readable run.json"),
        (["--protocol", str(PROTOCOL), "--preset", "reaction", "--base-run", str(other)],
         "is not a run of approach-v2.toml"),
        (["--protocol", str(PROTOCOL), "--preset", "reaction", "--base-run", str(incomplete)],
         "is not complete"),
    ]  # fmt: skip
    for args, message in cases:
        proc = sweep(*args, "--out", str(tmp_path / "s"))
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.count("\n") == 1 and message in proc.stderr, proc.stderr
        assert not (tmp_path / "s").exists()


@pytest.mark.slow
def test_the_protocols_own_combination_takes_the_base_runs_rows_which_a_run_of_it_reproduces(tmp_path):
    base = tmp_path / "base"
    proc = _batch("--protocol", str(PROTOCOL), "--episodes", "2", "--workers", "1", "--out", str(base))
    assert proc.returncode == 0, proc.stderr
    # occluder_class "suv" is the protocol's own value (its [scenarios.*] tables), "car" is not.
    assert tomllib.loads(PROTOCOL.read_text())["scenarios"]["crossing"]["occluder_class"] == "suv"
    taken, ran = tmp_path / "taken", tmp_path / "ran"
    proc = sweep("--protocol", str(PROTOCOL), "--vary", "occluder_class=suv", "--episodes", "1",
                 "--workers", "1", "--base-run", str(base), "--out", str(taken))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "0 combination(s)" in proc.stdout and "(1 more from --base-run)" in proc.stdout
    own = taken / "occluder_class=suv"
    assert not (own / "run.json").exists()  # not run
    assert json.loads((own / "rows_from.json").read_text())["rows_from"] == str(base.resolve())
    # The witness: the same combination run by the batch gives the same rows.
    proc = sweep("--protocol", str(PROTOCOL), "--vary", "occluder_class=suv", "--episodes", "1",
                 "--workers", "1", "--out", str(ran))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    key = ["scenario", "condition", "episode"]
    rows_taken = pd.read_parquet(own / "episodes.parquet").sort_values(key).reset_index(drop=True)
    rows_ran = pd.read_parquet(ran / "occluder_class=suv" / "episodes.parquet")
    rows_ran = rows_ran.sort_values(key).reset_index(drop=True)
    assert len(rows_taken) == 2 * len(tomllib.loads(PROTOCOL.read_text())["protocol"]["scenarios"])
    pd.testing.assert_frame_equal(rows_taken, rows_ran[rows_taken.columns], check_dtype=False)
    assert pd.read_csv(taken / "sweep.csv").equals(pd.read_csv(ran / "sweep.csv"))
