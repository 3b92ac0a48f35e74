"""Table I of an importance-sampling run (report/tables.py): weighted estimates of the final stage with
their central-limit intervals, the effective sample size, and every episode run counted; numbers by hand."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from pedsafe_sumo.report.tables import is_weighted, table_one_of_run, table_one_rows
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
    # The Markdown/text rows carry ESS and the episodes run.
    header, rows = table_one_rows(table)
    assert header[-2:] == ["ESS", "episodes run (pilots included)"] and rows[0][-1] == "8"


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
