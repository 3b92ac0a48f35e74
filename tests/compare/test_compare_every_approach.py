"""compare on runs made with `batch --approach all`: each arm is compared on its own (before, compare
refused such runs in one line: the report reads one approach at a time).

A fast test on hand-made runs whose collisions per arm are counted by hand, and a slow one on two real
batches of every approach that hosts crossing.
"""

from __future__ import annotations

import pandas as pd
import pytest

from pedsafe_sumo.compare import main
from tests.compare.test_compare_approach import NEVER_BRAKES, _run
from tests.report.report_runs import episode_row, write_run


def _two_arm_run(directory, collided: dict[str, set[int]]):
    """Crossing, SV and V2I, episodes 0-9 on arms N and E; SV collides in the episodes `collided[arm]`."""
    rows = []
    for arm in ("N", "E"):
        for episode in range(10):
            for condition in ("sv", "v2i"):
                hit = condition == "sv" and episode in collided[arm]
                row = episode_row("crossing", condition, episode, collision=hit)
                rows.append({**row, "approach": arm})
    return write_run(directory, pd.DataFrame(rows))


def test_every_approach_is_compared_on_its_own_with_its_own_counts(tmp_path, capsys):
    run_a = _two_arm_run(tmp_path / "a", {"N": {0}, "E": set()})
    # B collides in 3 more SV episodes on E only: N equal, E worse.
    run_b = _two_arm_run(tmp_path / "b", {"N": {0}, "E": {1, 2, 3}})
    status = main([str(run_a), str(run_b), "--out", str(tmp_path / "out")])
    out = capsys.readouterr().out
    table = pd.read_csv(tmp_path / "out" / "compare.csv", keep_default_na=False)
    sv_collision = table[(table["condition"] == "sv") & (table["index"] == "collision")].set_index("approach")
    assert sorted(sv_collision.index) == ["E", "N"]
    assert (sv_collision["n_pairs"] == 10).all()
    # Rates counted by hand from the rows written above.
    assert sv_collision.loc["N", "a"] == pytest.approx(0.1)
    assert sv_collision.loc["N", "b"] == pytest.approx(0.1)
    assert sv_collision.loc["E", "a"] == 0.0 and sv_collision.loc["E", "b"] == pytest.approx(0.3)
    assert sv_collision.loc["N", "difference"] == 0.0
    assert sv_collision.loc["E", "difference"] == pytest.approx(0.3)
    worse = pd.read_csv(tmp_path / "out" / "worse_episodes.csv")
    assert sorted(zip(worse["approach"], worse["episode"], strict=True)) == [("E", 1), ("E", 2), ("E", 3)]
    assert "crossing E" in out and "crossing N" in out
    # 3 discordant pairs in 10 do not rule out a 0.01 margin: FAIL, exit 1.
    assert status == 1


def test_one_approach_is_picked_with_approach(tmp_path, capsys):
    run_a = _two_arm_run(tmp_path / "a", {"N": {0}, "E": set()})
    run_b = _two_arm_run(tmp_path / "b", {"N": {0}, "E": {1, 2, 3}})
    # 10 pairs rule out no margin: FAIL (1) either way; what matters is which rows were compared.
    assert main([str(run_a), str(run_b), "--approach", "N", "--out", str(tmp_path / "out")]) == 1
    table = pd.read_csv(tmp_path / "out" / "compare.csv", keep_default_na=False)
    assert set(table["approach"]) == {"N"}


def test_runs_on_different_approaches_are_refused_in_one_line(tmp_path, capsys):
    run_a = _two_arm_run(tmp_path / "a", {"N": set(), "E": set()})
    rows = pd.read_parquet(run_a / "episodes.parquet")
    run_b = write_run(tmp_path / "b", rows.assign(approach=rows["approach"].replace({"E": "S"})))
    assert main([str(run_a), str(run_b)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "different approaches" in err, err


@pytest.mark.slow
def test_two_real_runs_of_every_approach_compare_arm_by_arm(tmp_path):
    runs = {}
    for name, extra in (("a", ()), ("b", ("--algorithm", NEVER_BRAKES))):
        out = tmp_path / name
        proc = _run(
            "pedsafe_sumo.batch",
            *("--scenario", "crossing", "--approach", "all", "--episodes", "1", "--seed", "7"),
            *("--workers", "1", "--out", str(out), *extra),
        )
        assert proc.returncode == 0, proc.stderr[-2000:]
        runs[name] = pd.read_parquet(out / "episodes.parquet")
    arms = sorted(set(runs["b"]["approach"]))
    assert len(arms) > 1, arms
    run_a, run_b, out = (str(tmp_path / name) for name in ("a", "b", "c"))
    proc = _run("pedsafe_sumo.compare", run_a, run_b, "--out", out)
    assert proc.returncode in (0, 1), proc.stderr
    table = pd.read_csv(tmp_path / "c" / "compare.csv", keep_default_na=False)
    collision = table[table["index"] == "collision"]
    for arm in arms:
        for condition in ("sv", "v2i"):
            row = collision[(collision["approach"] == arm) & (collision["condition"] == condition)].iloc[0]
            for name, column in (("a", "a"), ("b", "b")):
                rows = runs[name]
                mine = rows[(rows["approach"] == arm) & (rows["condition"] == condition)]
                assert row[column] == pytest.approx(mine["collision"].astype(float).mean()), (arm, condition)
    # Every replay command of a worse episode names its own arm.
    commands = [line.strip() for line in proc.stdout.splitlines() if "pedsafe_sumo.replay" in line]
    worse = pd.read_csv(tmp_path / "c" / "worse_episodes.csv", keep_default_na=False)
    assert len(commands) == len(worse)
    for command, arm in zip(commands, worse["approach"], strict=True):
        assert f"--approach {arm}" in command, command
