"""The report's collision witness table (report/witness_check.py) on hand-built episodes and logs."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from report_runs import episode_row

from pedsafe_sumo.report.witness_check import witness_agreement

STEP_S = 0.05
DETECTION_FLAGS = ("detected_onboard_camera", "detected_onboard_lidar", "detected_roadside", "perceived")


def hit_log(ped_x_m: float) -> pd.DataFrame:
    """The ego (4 m long, 2 m wide) from centre x = 0 along +x at 10 m/s, steps of 0.05 s from t = 0; a
    pedestrian (radius 0.3 m) standing at (ped_x_m, 0). The front (10 t + 2) first reaches the circle
    (ped_x_m - 0.3) at t = (ped_x_m - 2.3) / 10: for ped_x_m = 12.28, t = 0.998 s, so the first step in
    contact is t = 1.0 s (step 20), 2 cm deep; at 0.95 s the front is 48 cm short."""
    t = np.arange(60) * STEP_S
    n = len(t)
    return pd.DataFrame(
        {
            "time_s": t,
            "ego_x_m": 10.0 * t,
            "ego_y_m": np.zeros(n),
            "ego_yaw_rad": np.zeros(n),
            "ego_speed_mps": np.full(n, 10.0),
            "ego_length_m": np.full(n, 4.0),
            "ego_width_m": np.full(n, 2.0),
            "ped_x_m": np.full(n, ped_x_m),
            "ped_y_m": np.zeros(n),
            "ped_vx_mps": np.zeros(n),
            "ped_vy_mps": np.zeros(n),
            "ped_radius_m": np.full(n, 0.3),
            **{flag: np.zeros(n, dtype=bool) for flag in DETECTION_FLAGS},
        }
    )


def row(episode: int, collision: bool, witness, witness_time_s=math.nan, condition="sv", **values):
    r = episode_row("crossing", condition, episode, collision=collision, **values)
    r.update(witness_collision=witness, witness_collision_time_s=witness_time_s)
    return r


def lookup(logs: dict[int, pd.DataFrame]):
    return lambda scenario, condition, episode, seed: logs.get(episode)


def test_agreement_counts_and_the_disagreements_listed():
    # The loop's first contact in hit_log(12.28) is at 1.0 s (worked out in hit_log).
    rows = [
        row(0, False, False),  # both none: agree
        row(1, True, True, 1.05),  # one step later than the loop's 1.0 s: agree
        row(2, True, True, 1.10),  # two steps later: disagree
        row(3, True, False),  # only the loop
        row(4, False, True, 2.0),  # only the witness
        row(5, True, True, 7.0),  # no log: the verdicts agree, the time is unchecked
        row(6, False, None),  # no column value, no log: not recorded
        row(7, False, None),  # no column value, a log without contact: computed, agree
        row(8, True, None),  # no column value, a log with contact at 1.0 s: computed, agree
        row(9, True, True, 1.0, status="error"),  # errored: not counted
    ]
    logs = {1: hit_log(12.28), 2: hit_log(12.28), 3: hit_log(12.28), 7: hit_log(100.0), 8: hit_log(12.28)}
    table, disagreements = witness_agreement(pd.DataFrame(rows), lookup(logs))
    crossing = table.iloc[0]
    assert crossing["n"] == 9 and crossing["loop_collisions"] == 5
    assert crossing["not_recorded"] == 1 and crossing["compared"] == 8
    assert crossing["witness_collisions"] == 5  # episodes 1, 2, 4, 5, 8
    assert crossing["agree"] == 5 and crossing["disagreements"] == 3  # agree: 0, 1, 5, 7, 8
    assert crossing["agreement"] == pytest.approx(5 / 8)
    assert crossing["times_unchecked"] == 1
    assert disagreements["episode"].tolist() == [2, 3, 4]
    late = disagreements.iloc[0]
    assert late["loop_time_s"] == pytest.approx(1.0) and late["witness_time_s"] == pytest.approx(1.1)
    assert "0.100 s apart" in late["why"]
    assert disagreements.iloc[1]["why"] == "only the loop saw a collision"
    assert disagreements.iloc[2]["why"] == "only the witness saw a collision"
    assert table.iloc[-1]["scenario"] == "all" and table.iloc[-1]["compared"] == 8


def test_sumo_is_counted_where_it_sees():
    rows = [
        row(0, True, True, 1.0, sumo_collision=True),
        row(1, True, True, 1.0, sumo_collision=None),
        row(2, False, False, sumo_collision=True),
        row(3, False, False, sumo_collision=False, condition="v2i"),
    ]
    table, _ = witness_agreement(pd.DataFrame(rows))
    sv, v2i = table.iloc[0], table.iloc[1]
    assert (sv["sumo_seen"], sv["sumo_collisions"], sv["sumo_agrees_with_loop"]) == (2, 2, 1)
    assert (v2i["sumo_seen"], v2i["sumo_collisions"], v2i["sumo_agrees_with_loop"]) == (1, 0, 1)


def test_a_run_without_the_witness_columns_and_logs_is_not_recorded():
    episodes = pd.DataFrame([episode_row("crossing", "sv", e, collision=e == 0) for e in range(3)])
    table, disagreements = witness_agreement(episodes, lookup({}))
    assert table.iloc[0]["not_recorded"] == 3 and table.iloc[0]["compared"] == 0
    assert math.isnan(table.iloc[0]["agreement"]) and disagreements.empty
    # With the logs kept, the witness is judged from them: episode 0's log collides, the others do not.
    table, disagreements = witness_agreement(
        episodes, lookup({0: hit_log(12.28), 1: hit_log(100.0), 2: hit_log(100.0)})
    )
    assert table.iloc[0]["compared"] == 3 and table.iloc[0]["agree"] == 3 and disagreements.empty


def test_a_broken_log_costs_its_episode_only():
    def broken(scenario, condition, episode, seed):
        raise OSError("not parquet")

    episodes = pd.DataFrame([row(0, True, None), row(1, False, False)])
    table, _ = witness_agreement(episodes, broken)
    assert table.iloc[0]["not_recorded"] == 1 and table.iloc[0]["agree"] == 1
