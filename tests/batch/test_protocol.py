"""Protocols: protocols/paper-v1.toml names every value with its reason, the batch
runs it with --protocol (only --episodes and --workers may override it), and run.json records exactly
the protocol's values and the file's hash. The expected values are read from the file with tomllib
here, not through pedsafe_sumo.protocol."""

from __future__ import annotations

import copy
import hashlib
import json

import pandas as pd
import pytest
import tomllib
from batch_cli import batch

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.params import load_params
from pedsafe_sumo.protocol import VALUES_BEFORE, parameter_reasons
from pedsafe_sumo.scenarios.specs import get_scenario

#: The newest protocol: the one that runs on this code (older ones lack parameters the code has, and are
#: refused, as a protocol must name every value).
PROTOCOL = REPO_ROOT / "protocols" / "paper-v7.toml"


def _leaves(tree, prefix=""):
    out = {}
    for key, value in tree.items():
        dotted = f"{prefix}.{key}" if prefix else key
        out.update(_leaves(value, dotted) if isinstance(value, dict) else {dotted: value})
    return out


def test_the_newest_protocol_names_every_value():
    data = tomllib.loads(PROTOCOL.read_text(encoding="utf-8"))
    # Every parameter of the parameter file and every field of each scenario it runs.
    # (but the values it was written before, VALUES_BEFORE, which it then names none of).
    named = set(_leaves(data["parameters"]))
    assert named | set(VALUES_BEFORE["parameters"]) == set(_leaves(load_params()))
    for name in data["protocol"]["scenarios"]:
        fields = {f for f in get_scenario(name).__dataclass_fields__ if f not in ("name", "description")}
        assert set(data["scenarios"][name]) | set(VALUES_BEFORE["scenarios"]) == fields
        assert not set(data["scenarios"][name]) & set(VALUES_BEFORE["scenarios"])


@pytest.mark.parametrize("path", sorted((REPO_ROOT / "protocols").glob("*.toml")), ids=lambda p: p.stem)
def test_every_protocol_gives_each_value_a_reason(path):
    # Each value line of the scenario and parameter tables has a comment (source or reason) above it.
    lines = path.read_text(encoding="utf-8").splitlines()
    in_values = False
    for previous, line in zip(lines, lines[1:]):
        if line.startswith("["):
            in_values = not line.startswith("[protocol]")
            continue
        if in_values and "=" in line and not line.startswith("#"):
            assert previous.startswith("#") and len(previous) > 3, f"no reason above: {line}"


@pytest.mark.parametrize(
    "extra", [("--seed", "3"), ("--scenario", "crossing"), ("--set", "time_limit_s=5"), ("--chunk-size", "2")]
)
def test_protocol_refuses_other_flags_in_one_line(tmp_path, extra):
    out = tmp_path / "run"
    proc = batch("--protocol", str(PROTOCOL), "--out", str(out), *extra)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "--protocol fixes every value" in proc.stderr
    assert not out.exists()


def test_protocol_that_leaves_out_a_parameter_is_refused(tmp_path):
    text = PROTOCOL.read_text(encoding="utf-8").replace("headway_rate_per_s = 0.1742\n", "")
    partial = tmp_path / "partial.toml"
    partial.write_text(text, encoding="utf-8")
    proc = batch("--protocol", str(partial), "--out", str(tmp_path / "run"))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "traffic.headway_rate_per_s" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.slow
def test_run_json_records_the_protocols_values(tmp_path):
    out = tmp_path / "run"
    proc = batch("--protocol", str(PROTOCOL), "--out", str(out), "--episodes", "1", "--workers", "1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    data = tomllib.loads(PROTOCOL.read_text(encoding="utf-8"))
    run = json.loads((out / "run.json").read_text(encoding="utf-8"))
    assert run["protocol"]["sha256"] == hashlib.sha256(PROTOCOL.read_bytes()).hexdigest()
    # The parameters it was written before are recorded as the behaviour it ran with.
    expected_parameters = copy.deepcopy(data["parameters"])
    for dotted, value in VALUES_BEFORE["parameters"].items():
        *tables, key = dotted.split(".")
        target = expected_parameters
        for table in tables:
            target = target.setdefault(table, {})
        target[key] = value
    assert run["parameters"] == expected_parameters
    header = data["protocol"]
    assert list(run["scenarios"]) == header["scenarios"]
    for name, fields in data["scenarios"].items():
        recorded = {k: v for k, v in run["scenarios"][name].items() if k not in ("name", "description")}
        # run.json keeps the spec's numbers as floats (with_overrides parses them so).
        expected = {k: float(v) if type(v) is int else v for k, v in fields.items()}
        # The values it was written before are recorded as the behaviour it ran with.
        assert recorded == {**expected, **VALUES_BEFORE["scenarios"]}
    assert run["run_seed"] == header["seed"] and run["episodes_per_scenario"] == 1
    assert run["algorithm"] == header["algorithm"] and run["site"] == header["site"]
    table = pd.read_parquet(out / "episodes.parquet")
    assert sorted(table["scenario"].unique()) == sorted(header["scenarios"])
    assert set(table["condition"]) == {"sv", "v2i"} and (table["status"] == "ok").all()
    assert set(table["ego_signal"]) == {"green"}


def test_each_parameter_gets_the_comment_above_it_not_those_of_the_keys_before():
    text = (
        "[walk]\n"
        "# Arrivals (assumption).\n"
        "rate = 1.0\n"
        "# Shares of the types (assumption).\n"
        "share_a = 0.5\n"
        "share_b = 0.5\n"
        "# Reaction (assumption).\n"
        "reaction_s = 1.0\n"
        "speed = 1.4                # inline reason\n"
        "\n"
        "# About the next table.\n"
        "[next]\n"
        "x = 1\n"
    )
    assert parameter_reasons(text) == {
        "walk.rate": "Arrivals (assumption).",
        "walk.share_a": "Shares of the types (assumption).",
        "walk.share_b": "Shares of the types (assumption).",
        "walk.reaction_s": "Reaction (assumption).",
        "walk.speed": "inline reason",
        "next.x": "About the next table.",
    }
