"""research/experiments/is_within_episode.py: the ceiling and the share of variance left, from repeat outcomes
whose pi(x) is known, and the collision-stratum identity against a direct integral (no SUMO)."""

from __future__ import annotations

import importlib.util
import json
import math
import sys

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT

_spec = importlib.util.spec_from_file_location(
    "is_within_episode", REPO_ROOT / "research" / "experiments" / "is_within_episode.py"
)
tool = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = tool  # its dataclass looks its module up there
_spec.loader.exec_module(tool)


def _outcomes(per_episode: dict[tuple[int, int], list[int]], mode: str = "fresh") -> pd.DataFrame:
    """(stratum, episode) -> the collisions of its repeats, as the tool's CSV rows."""
    rows = [
        {"episode": e, "stratum": s, "mode": mode, "repeat": r, "collision": c}
        for (s, e), outcomes in per_episode.items()
        for r, c in enumerate(outcomes)
    ]
    return pd.DataFrame(rows)


def test_a_collision_decided_by_the_inputs_leaves_no_variance_and_no_ceiling() -> None:
    outcomes = _outcomes({(1, 1): [1] * 10, (1, 2): [1] * 10, (0, 3): [0] * 10, (0, 4): [0] * 10})
    row = tool.summarise(outcomes, 0.03).iloc[0]
    assert row["ceiling"] == math.inf  # pi in {0, 1}: the zero-variance proposal exists
    assert row["share of Var(Y) left"] == 0.0
    assert row["collision episodes with pi < 1"] == "0/2"


def test_half_chance_collisions_by_hand() -> None:
    # Both collision episodes collide in 5 of 10 repeats: pi taken as (5 + 1) / (10 + 1), E[pi^(-1/2) | Y=1]
    # = sqrt(11/6); ceiling (1 - P) / (P (11/6 - 1)); share left (1 - 1/2) / (1 - P).
    rate = 0.05
    outcomes = _outcomes({(1, 1): [1, 0] * 5, (1, 2): [0, 1] * 5, (0, 3): [0] * 10})
    row = tool.summarise(outcomes, rate).iloc[0]
    assert math.isclose(row["ceiling"], (1 - rate) / (rate * 5 / 6))
    assert math.isclose(row["share of Var(Y) left"], 0.5 / (1 - rate))
    assert math.isclose(row["E[pi | Y=1]"], 0.5)


def test_the_ceiling_from_the_collision_stratum_equals_the_one_over_the_nominal() -> None:
    # x ~ U(0, 1), pi(x) = x^2: P = 1/3, E_p[sqrt(pi)] = E[x] = 1/2, so the ceiling over x is
    # P (1 - P) / (1/4 - P^2) = 1.6. The tool sees only collision episodes (x given Y = 1) and 1/sqrt(pi).
    rng = np.random.default_rng(3)
    x = rng.random(400_000)
    hit = x[rng.random(x.size) < x * x]
    assert math.isclose(tool.ceiling(1 / 3, 1 / hit), 1.6, rel_tol=0.02)


def test_episodes_drawn_from_a_proposal_give_the_nominal_ceiling_through_their_weights() -> None:
    # The same x ~ U(0, 1), pi(x) = x^2 (ceiling 1.6), but the episodes drawn from q(x) = 2x, each with
    # its weight p/q = 1 / (2x): unweighted, x given Y = 1 follows x^3 instead of x^2 and the mean of
    # 1/sqrt(pi) falls from 3/2 to 4/3 (ceiling 2/3 (1/(16/9 - 1)) / (1/3) = 2.57 instead of 1.6).
    rng = np.random.default_rng(5)
    x = np.sqrt(rng.random(400_000))  # inverse CDF of q(x) = 2x
    hit = x[rng.random(x.size) < x * x]
    assert math.isclose(tool.ceiling(1 / 3, 1 / hit, 1 / (2 * hit)), 1.6, rel_tol=0.03)
    assert math.isclose(tool.ceiling(1 / 3, 1 / hit), (2 / 3) / (16 / 9 - 1) / (1 / 3), rel_tol=0.03)


def test_weighted_strata_by_hand() -> None:
    # Collision episode 1 (weight 3) collides in all 4 repeats, episode 2 (weight 1) in 2 of 4:
    # E[pi | Y=1] = (3 * 1 + 1 * 0.5) / 4; the other stratum's episodes (weights 1 and 3, pi 1/4 and 0)
    # give (1 * 0.25 + 3 * 0) / 4.
    outcomes = _outcomes({(1, 1): [1] * 4, (1, 2): [1, 0, 1, 0], (0, 3): [1, 0, 0, 0], (0, 4): [0] * 4})
    outcomes["weight"] = outcomes["episode"].map({1: 3.0, 2: 1.0, 3: 1.0, 4: 3.0})
    row = tool.summarise(outcomes, 0.1).iloc[0]
    assert math.isclose(row["E[pi | Y=1]"], 3.5 / 4)
    assert row["E[pi | Y=0] (implied)"].startswith(f"{0.25 / 4:.4f} ")
    # pi taken as (k + 1) / (m + 1): episode 1 1, episode 2 3/5; E[pi^(-1/2)] weighted 3:1.
    mean_inverse_root = (3 * 1 + math.sqrt(5 / 3)) / 4
    assert math.isclose(row["ceiling"], 0.9 / (0.1 * (mean_inverse_root**2 - 1)))


@pytest.mark.slow
def test_on_sumo_an_episode_reproduces_and_fresh_draws_keep_only_its_inputs(tmp_path):
    """A real 3-pair MC run of jaywalking (SV): re-run with all its own draws, each episode gives its
    recorded row; with fresh draws its proposable inputs stay (setup_for checks each against the row)
    while the unproposed ones change (the signal point, here)."""
    from pedsafe_sumo.batch.__main__ import main as batch_main
    from pedsafe_sumo.batch.runner import scenario_spec
    from pedsafe_sumo.control.agent import load_agent_class
    from pedsafe_sumo.network.sites import get_site
    from pedsafe_sumo.settings import configure
    from pedsafe_sumo.sim.episode import EpisodeRunner

    run = tmp_path / "mc"
    argv = [
        "--scenario",
        "jaywalking",
        "--condition",
        "sv",
        "--episodes",
        "3",
        "--seed",
        "3",
        "--workers",
        "1",
    ]
    assert batch_main([*argv, "--out", str(run)]) == 0
    rows = pd.read_parquet(run / "episodes.parquet").sort_values("episode")
    info = json.loads((run / "run.json").read_text())
    _, params = configure(["jaywalking"], None, [])
    spec = scenario_spec("jaywalking", {})
    runner = EpisodeRunner(get_site(info["site"]), params, load_agent_class(info["algorithm"]))
    try:
        for _, row in rows.iterrows():
            own = tool.setup_for(runner, spec, row, "reproduce", 0)
            outcome = runner.run(spec, "sv", int(row["seed"]), setup=own).outcome
            assert outcome["collision"] == row["collision"]
            assert outcome["min_ttc_s"] == pytest.approx(row["min_ttc_s"], rel=0, abs=0, nan_ok=True)
            fresh = tool.setup_for(runner, spec, row, "fresh", tool.fresh_seed(1, int(row["episode"]), 0))
            assert fresh.pedestrian.walking_speed_mps == own.pedestrian.walking_speed_mps
            assert fresh.signals.cycle_start_s != own.signals.cycle_start_s
    finally:
        runner.close()


@pytest.mark.slow
def test_on_sumo_the_final_stage_of_an_is_run_reproduces_under_v2i(tmp_path):
    """A real IS run of jaywalking (one nominal pilot stage of 20 pairs, then 3 final pairs drawn from the
    fitted proposal, or the nominal when the pilot saw no collision): the final stage's V2I rows come back
    through the stage's proposal (rows_and_runner), and each reproduces its recorded V2I outcome, the link
    drawn from its own seed; a fresh world keeps its proposable inputs."""
    from pedsafe_sumo.batch.__main__ import main as batch_main

    run = tmp_path / "is"
    argv = ["--scenario", "jaywalking", "--episodes", "3", "--seed", "4", "--workers", "1"]
    argv += ["--sampler", "is", "--is-pilot-stages", "1", "--is-pilot-episodes", "20"]
    assert batch_main([*argv, "--out", str(run)]) == 0
    rows, spec, runner, proposal = tool.rows_and_runner(run, "jaywalking", [], "v2i")
    try:
        assert len(rows) == 3 and set(rows["condition"]) == {"v2i"} and set(rows["sampler_stage"]) == {1}
        stored = json.loads((run / "run.json").read_text())["sampler_proposals"]["jaywalking"][1]
        assert proposal and proposal == stored  # the guard's region proposal or the fit: never the nominal
        for _, row in rows.iterrows():
            own = tool.setup_for(runner, spec, row, "reproduce", 0, proposal)
            outcome = runner.run(spec, "v2i", int(row["seed"]), setup=own).outcome
            assert outcome["collision"] == row["collision"]
            assert outcome["min_ttc_s"] == pytest.approx(row["min_ttc_s"], rel=0, abs=0, nan_ok=True)
            fresh = tool.setup_for(
                runner, spec, row, "fresh", tool.fresh_seed(1, int(row["episode"]), 0), proposal
            )
            assert fresh.pedestrian.walking_speed_mps == own.pedestrian.walking_speed_mps
    finally:
        runner.close()


def test_modes_joined_by_plus_keep_every_source_named() -> None:
    assert tool.kept_by("fresh") == ((), False, False)
    assert tool.kept_by("keep_link") == ((), False, True)
    assert tool.kept_by("keep_vehicles") == (("colours", "vehicles"), False, False)
    assert tool.kept_by("keep_clothing+colours+link") == (("clothing", "colours"), False, True)
    assert tool.kept_by("keep_traffic+ped_traits") == (("ped_traits",), True, False)
    with pytest.raises(ValueError, match="unknown mode"):
        tool.kept_by("keep_clothing+weather")
    # The vehicles' colours form their own group; their classes and gaps stay "vehicles".
    assert [tool.group_of(n) for n in ("queued_2.colour", "queued_2.gap_m", "clothing", "ped_female")] == [
        "colours",
        "vehicles",
        "clothing",
        "ped_traits",
    ]
