"""python -m pedsafe_sumo.sweep: one batch per combination, same worlds, Table I across them."""

from __future__ import annotations

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
