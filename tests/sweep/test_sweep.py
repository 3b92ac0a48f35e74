"""python -m pedsafe_sumo.sweep: one batch per combination, same worlds, Table I across them."""

from __future__ import annotations

import math
import subprocess
import sys

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT


def sweep(*args, timeout=600):
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.sweep", *args],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=timeout,
    )


@pytest.mark.slow
def test_sweep_runs_every_combination_on_the_same_worlds_and_tabulates_them(tmp_path):
    out = tmp_path / "sweep"
    args = ["--scenario", "crossing", "--episodes", "3", "--workers", "1", "--out", str(out), "--seed", "5",
            "--vary", "algorithm.reaction_time_s=0.4,1.5",
            "--vary", "algorithm.max_decel_mps2=6"]  # fmt: skip
    proc = sweep(*args)
    assert proc.returncode == 0, proc.stderr
    labels = ["algorithm.reaction_time_s=0.4,algorithm.max_decel_mps2=6",
              "algorithm.reaction_time_s=1.5,algorithm.max_decel_mps2=6"]  # fmt: skip
    runs = {label: pd.read_parquet(out / label / "episodes.parquet") for label in labels}
    # Same seed: the same pedestrians and ego speeds in every combination.
    first, second = runs.values()
    for column in ("seed", "ped_age", "ped_speed_mps", "ego_initial_speed_mps"):
        assert first[column].tolist() == second[column].tolist()
    table = pd.read_csv(out / "sweep.csv")
    assert len(table) == 4  # 2 combinations x 2 conditions
    for label, episodes in runs.items():
        reaction = float(label.split(",")[0].split("=")[1])
        for condition, group in episodes.groupby("condition"):
            row = table[(table["algorithm.reaction_time_s"] == reaction) & (table["condition"] == condition)]
            assert len(row) == 1
            assert row["n"].iloc[0] == len(group)
            assert row["collision_rate"].iloc[0] == pytest.approx(group["collision"].mean())
    assert (out / "sweep.md").read_text().count("\n") == 2 + 4
    assert (out / "sweep.png").stat().st_size > 10_000
    # A second call finds every run done and only tabulates again.
    again = sweep(*args)
    assert again.returncode == 0 and again.stdout.count("done before, kept") == 2


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vary", "algorithm.reaction_time_s"], "--vary needs KEY=V1,V2"),
        (["--vary", "algorithm.reaction_time_s=0.4,-1"], "algorithm.reaction_time_s must be >= 0"),
        (["--vary", "no_such_field=1,2"], "unknown scenario parameter 'no_such_field'"),
        (["--vary", "occluder_class=suv", "--vary", "occluder_class=van"], "each --vary key may appear once"),
    ],
)
def test_bad_sweep_input_is_one_line_exit_2_and_writes_nothing(tmp_path, args, message):
    proc = sweep("--scenario", "crossing", "--out", str(tmp_path / "s"), *args)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and message in proc.stderr
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([], "give --vary KEY=V1,V2,... or --preset NAME"),
        (["--preset", "no_such_sweep"], "unknown preset 'no_such_sweep' (known: reaction, deceleration"),
    ],
)
def test_a_sweep_needs_a_vary_or_a_known_preset(tmp_path, args, message):
    proc = sweep("--scenario", "crossing", "--out", str(tmp_path / "s"), *args)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and message in proc.stderr
    assert not (tmp_path / "s").exists()


def test_each_preset_is_one_key_over_a_range_that_holds_its_default():
    """The sensitivity sweeps: every preset varies one key, validated like --vary, and its values
    include the default of that key (defaults.toml or the scenario registry)."""
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sweep import PRESETS, parse_args, validate

    params = load_params()
    assert set(PRESETS) >= {"reaction", "deceleration", "blend_gap", "occluder_class", "queue_length",
                            "v2i_latency", "gap_acceptance"}  # fmt: skip
    for name, vary in PRESETS.items():
        args = parse_args(["--scenario", "crossing", "--out", "unused", "--preset", name])
        combos = validate(args)
        key, values = vary.split("=")
        assert [list(c) for c in combos] == [[key]] * len(values.split(","))
        if "." in key:
            section, *path = key.split(".")
            default = params[section]
            for part in path:
                default = default[part]
        else:
            default = getattr(get_scenario("crossing"), key)
        as_typed = [type(default)(v) if not isinstance(default, str) else v for v in values.split(",")]
        assert default in as_typed, f"{name}: {values} lacks the default {default}"


def _findings_csv(directory, key, values, holds):
    directory.mkdir(parents=True)
    rows = ["run,v2i_safer_everywhere,jaywalking_most_dangerous,blending_safest,v2i_beyond_13m_in_90pct"]
    rows += [f'"{key}={v}",{",".join(h)}' for v, h in zip(values, holds)]
    (directory / "findings.csv").write_text("\n".join(rows) + "\n")


def test_combine_puts_the_findings_of_one_key_sweeps_side_by_side(tmp_path):
    _findings_csv(
        tmp_path / "a",
        "queue_vehicles",
        ["1", "3"],
        [("1.0", "0.0", "1.0", ""), ("1.0", "0.0", "0.0", "1.0")],
    )
    _findings_csv(tmp_path / "b", "algorithm.max_decel_mps2", ["6", "3"], [("1.0",) * 4, ("0.0",) * 4])
    proc = sweep("--combine", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(tmp_path / "out" / "findings_across_sweeps.csv")
    assert table["sweep"].tolist() == ["queue_vehicles"] * 2 + ["algorithm.max_decel_mps2"] * 2
    assert table["value"].astype(str).tolist() == ["1", "3", "6", "3"]
    assert table["blending_safest"].tolist() == [1.0, 0.0, 1.0, 0.0]
    assert math.isnan(table["v2i_beyond_13m_in_90pct"].iloc[0])
    assert (tmp_path / "out" / "findings_across_sweeps.png").stat().st_size > 5_000
    # A directory without findings, or a sweep of two keys: one line, exit 2.
    (tmp_path / "c").mkdir()
    bad = sweep("--combine", str(tmp_path / "c"), "--out", str(tmp_path / "out2"))
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "no findings.csv" in bad.stderr
    _findings_csv(tmp_path / "d", "queue_vehicles", ["1,occluder_class=van"], [("1.0",) * 4])
    bad = sweep("--combine", str(tmp_path / "d"), "--out", str(tmp_path / "out3"))
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "not a sweep of one key" in bad.stderr
