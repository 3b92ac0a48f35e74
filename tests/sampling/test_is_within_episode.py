"""tools/experiments/is_within_episode.py: the ceiling and the share of variance left, from repeat outcomes
whose pi(x) is known (no SUMO)."""

from __future__ import annotations

import importlib.util
import math
import sys

import pandas as pd

from pedsafe_sumo import REPO_ROOT

_spec = importlib.util.spec_from_file_location(
    "is_within_episode", REPO_ROOT / "tools" / "experiments" / "is_within_episode.py"
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
    rate = 0.03
    outcomes = _outcomes({(1, 1): [1] * 10, (1, 2): [1] * 10, (0, 3): [0] * 10, (0, 4): [0] * 10})
    row = tool.summarise(outcomes, rate).iloc[0]
    assert math.isclose(row["E_p[sqrt(pi)]"], rate)  # pi in {0, 1}: E sqrt(pi) = E pi = P
    assert row["ceiling (efficiency per episode)"] == math.inf  # the zero-variance proposal exists
    assert math.isclose(row["share of Var(Y) left"], 0.0, abs_tol=1e-12)


def test_a_collision_the_inputs_do_not_touch_gives_plain_monte_carlo() -> None:
    # pi(x) = 1/2 for every x, 5 of 10 repeats: E_p[sqrt(pi)] = sqrt(1/2); with P = 1/2 the ceiling is
    # P (1 - P) / (1/2 - P^2) = 1, and the unbiased E[pi^2] = 5 * 4 / (10 * 9) = 2/9 leaves
    # (1/2 - 2/9) / (1/4) = 10/9 of Var(Y) (the estimator's own noise: 1 in expectation).
    outcomes = _outcomes({(1, 1): [1, 0] * 5, (0, 2): [0, 1] * 5})
    row = tool.summarise(outcomes, 0.5).iloc[0]
    assert math.isclose(row["E_p[sqrt(pi)]"], math.sqrt(0.5))
    assert math.isclose(row["ceiling (efficiency per episode)"], 1.0)
    assert math.isclose(row["share of Var(Y) left"], 10 / 9)


def test_the_strata_are_recombined_with_the_run_rate() -> None:
    # Collision stratum pi = 0.8 (8 of 10), other stratum pi = 0.1 (1 of 10), P = 0.2:
    # E_p[sqrt(pi)] = 0.2 sqrt(0.8) + 0.8 sqrt(0.1).
    outcomes = _outcomes({(1, 1): [1] * 8 + [0] * 2, (0, 2): [1] + [0] * 9})
    row = tool.summarise(outcomes, 0.2).iloc[0]
    root = 0.2 * math.sqrt(0.8) + 0.8 * math.sqrt(0.1)
    assert math.isclose(row["E_p[sqrt(pi)]"], root)
    assert math.isclose(row["ceiling (efficiency per episode)"], 0.2 * 0.8 / (root * root - 0.04))
    assert math.isclose(row["E_p[pi] (check: P)"], 0.2 * 0.8 + 0.8 * 0.1)
