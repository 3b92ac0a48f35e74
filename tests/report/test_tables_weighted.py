"""Table I of an importance-sampling run (report/tables.py): weighted estimates of the final stage with
their central-limit intervals, the effective sample size, and every episode run counted; numbers by hand."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo.report.tables import is_weighted, table_one_of_run, table_one_rows, weight_check
from pedsafe_sumo.safety.stats import table_one


def _episodes() -> pd.DataFrame:
    """crossing: 4 pilot pairs (stage 0, weight 1) and 4 final pairs (stage 1) with weights 0.5, 0.5, 2, 1;
    under SV the final episodes with weight 0.5 and 2 collide (injury 0.4 and 0.1), the last has a
    conflict; one pilot v2i row errored."""
    rows = []
    final = [
        (0.5, True, 0.4, False),
        (0.5, False, 0.0, False),
        (2.0, True, 0.1, False),
        (1.0, False, 0.0, True),
    ]
    for episode in range(8):
        stage = 0 if episode < 4 else 1
        weight, collision, injury, conflict = (1.0, False, 0.0, False) if stage == 0 else final[episode - 4]
        for condition in ("sv", "v2i"):
            hit = collision and condition == "sv"
            status = "error" if (episode == 1 and condition == "v2i") else "ok"
            rows.append(
                {
                    "scenario": "crossing",
                    "condition": condition,
                    "episode": episode,
                    "collision": hit,
                    "injury_probability": injury if hit else 0.0,
                    "conflict": conflict,
                    "status": status,
                    "weight": weight,
                    "sampler_stage": stage,
                }
            )
    return pd.DataFrame(rows)


def test_weighted_table_one_by_hand():
    episodes = _episodes()
    assert is_weighted(episodes)
    table = table_one_of_run(episodes)
    sv = table[table.condition == "sv"].iloc[0]
    # (1/n) sum w f over the 4 final episodes: collisions (0.5 + 2) / 4, injury (0.5*0.4 + 2*0.1) / 4,
    # conflicts (1 * 1) / 4.
    assert sv["collision_rate"] == pytest.approx(0.625)
    assert sv["injury_mean"] == pytest.approx(0.1)
    assert sv["conflict_rate"] == pytest.approx(0.25)
    # Interval: mean -+ 1.959964 sd(w f) / sqrt(4); w f = (0.5, 0, 2, 0): sd = 0.9464847 (ddof 1).
    half = 1.959964 * 0.9464847 / 2
    assert sv["collision_high"] == pytest.approx(0.625 + half, rel=1e-6)
    assert sv["collision_low"] == 0.0  # 0.625 - 0.9275 < 0: a rate's interval stops at 0
    # ESS = (sum w)^2 / sum w^2 = 16 / 5.5; n_run: all 8 episodes (pilots included); n: the final 4.
    assert sv["ess"] == pytest.approx(16 / 5.5)
    assert (sv["n_run"], sv["n"], sv["n_error"]) == (8, 4, 0)
    v2i = table[table.condition == "v2i"].iloc[0]
    assert v2i["collision_rate"] == 0.0 and v2i["n_run"] == 8
    # The weights' check: mean of the final SV weights (0.5 + 0.5 + 2 + 1) / 4 = 1; the largest share
    # of sum w f (0.5 + 2) is 2 / 2.5 = 80% > 25%: flagged.
    assert sv["mean_weight"] == pytest.approx(1.0)
    assert sv["max_share"] == pytest.approx(0.8)
    assert sv["weight_note"] == "one episode carries 80% of the collision estimate"
    # The Markdown/text rows carry ESS, the episodes run, the mean weight and the check.
    header, rows = table_one_rows(table)
    assert header[-4:] == ["ESS", "episodes run (pilots included)", "mean weight", "check"]
    assert rows[0][-3:-1] == ["8", "1.000"]


def test_plain_monte_carlo_table_is_unchanged():
    """Every row at stage 0 with weight 1: the Wilson table of safety.stats, nothing added."""
    episodes = _episodes()
    episodes["sampler_stage"] = 0
    episodes["weight"] = 1.0
    assert not is_weighted(episodes)
    table = table_one_of_run(episodes)
    assert "ess" not in table.columns
    pd.testing.assert_frame_equal(table, table_one(episodes).reset_index(drop=True))
    assert math.isfinite(table["collision_high"].iloc[0])


def test_weight_check_flags_a_mean_weight_far_from_one():
    """Weights 0.5 +- a little (mean 0.5, SE 0.0097): 0.5 lies 51 SE from 1, flagged; weights with mean 1
    and collisions spread over 40 episodes pass (no share above 1/40)."""
    weights = np.array([0.45, 0.55] * 20)
    se = np.std(weights, ddof=1) / math.sqrt(40)
    assert (1 - 0.5) / se > 3
    check = weight_check(weights, np.ones(40))
    assert check["mean_weight"] == pytest.approx(0.5)
    assert check["weight_note"].startswith("mean weight 0.500 is more than 3 SE from 1")
    good = weight_check(np.array([0.8, 1.2] * 20), np.ones(40))
    assert good["weight_note"] == "" and good["max_share"] == pytest.approx(1.2 / 40)
    # No collision: no share, and the mean weight alone decides.
    assert math.isnan(weight_check(np.array([0.8, 1.2] * 20), np.zeros(40))["max_share"])
