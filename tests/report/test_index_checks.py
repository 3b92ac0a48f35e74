"""The report's checks of the indexes on hand-made tables with known counts."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from report_runs import episode_row, write_standard_run

from pedsafe_sumo.report import indexes as idx
from pedsafe_sumo.report.__main__ import main as report_main


def _table(rows: list[dict]) -> pd.DataFrame:
    return pd.DataFrame(rows)


def test_stationary_contacts_are_counted_apart_from_collisions():
    rows = [
        episode_row("crossing", "sv", 0, collision=True),
        episode_row("crossing", "sv", 1) | {"contact_stationary": True},
        episode_row("crossing", "sv", 2) | {"contact_stationary": True},
        episode_row("crossing", "sv", 3, status="error") | {"contact_stationary": True},  # left out
        episode_row("crossing", "v2i", 0),
    ]
    for row in rows:
        row.setdefault("contact_stationary", False)
    table = idx.stationary_contacts(_table(rows))
    assert table.to_dict("records") == [
        {"scenario": "crossing", "condition": "sv", "n": 3, "contact_stationary": 2, "collision": 1},
        {"scenario": "crossing", "condition": "v2i", "n": 1, "contact_stationary": 0, "collision": 0},
    ]
    assert idx.stationary_contacts(_table([episode_row("crossing", "sv", 0)])) is None


def test_agreement_with_sumo_leaves_out_where_sumo_cannot_see():
    # crossing sv: ours/SUMO (T, T), (T, F), (F, T), (F, F), (F, F); jaywalking sv: two mid-block rows
    # where SUMO cannot see (null) and one (F, F)
    pairs = [(True, True), (True, False), (False, True), (False, False), (False, False)]
    rows = [episode_row("crossing", "sv", i, collision=c, sumo_collision=s) for i, (c, s) in enumerate(pairs)]
    rows += [
        episode_row("jaywalking", "sv", 0, collision=True, sumo_collision=pd.NA),
        episode_row("jaywalking", "sv", 1, collision=False, sumo_collision=pd.NA),
        episode_row("jaywalking", "sv", 2, collision=False, sumo_collision=False),
    ]
    episodes = _table(rows)
    episodes["sumo_collision"] = episodes["sumo_collision"].astype("boolean")
    table = idx.collision_agreement(episodes).set_index("scenario")
    crossing = table.loc["crossing"]
    assert (crossing["compared"], crossing["sumo_null"], crossing["both"]) == (5, 0, 1)
    assert (crossing["ours_only"], crossing["sumo_only"], crossing["neither"]) == (1, 1, 2)
    assert crossing["agreement"] == pytest.approx(3 / 5)
    jay = table.loc["jaywalking"]
    assert (jay["n"], jay["sumo_null"], jay["compared"], jay["neither"], jay["agreement"]) == (
        3,
        2,
        1,
        1,
        1.0,
    )
    overall = table.loc["all"]
    assert (overall["n"], overall["compared"], overall["agreement"]) == (8, 6, pytest.approx(4 / 6))
    assert idx.sumo_collision_is_nullable(episodes)
    plain = _table([episode_row("crossing", "sv", 0)])
    assert not idx.sumo_collision_is_nullable(plain)


def _log(ego_speed_end: float, ped_speed_end: float) -> pd.DataFrame:
    """Ego along +x on y = 0 from x = -20 m, pedestrian walking +y at x = 0 from y = -6 m; 11 steps of
    0.1 s: the ego's centre reaches x = -11 m at most, the pedestrian y = -4.5 m: their paths never cross.
    The last step's speeds are set as given (who stood when the log ended)."""
    t = np.arange(11) * 0.1
    ego_speed = np.full(11, 9.0)
    ego_speed[-1] = ego_speed_end
    ped_vy = np.full(11, 1.5)
    ped_vy[-1] = ped_speed_end
    return pd.DataFrame(
        {
            "time_s": t,
            "ego_x_m": -20.0 + 9.0 * t,
            "ego_y_m": 0.0,
            "ego_yaw_rad": 0.0,
            "ego_speed_mps": ego_speed,
            "ego_length_m": 4.0,
            "ego_width_m": 2.0,
            "ped_x_m": 0.0,
            "ped_y_m": -6.0 + 1.5 * t,
            "ped_vx_mps": 0.0,
            "ped_vy_mps": ped_vy,
            "ped_radius_m": 0.3,
            "detected_onboard_camera": False,
            "detected_onboard_lidar": False,
            "detected_roadside": False,
            "perceived": False,
        }
    )


def test_pet_coverage_and_why_it_is_undefined():
    # crossing sv: PET defined in 0 and 1; undefined in 2 (ego stood), 3 (pedestrian stood), 4 (both
    # still moving), 5 (no log kept); crossing v2i: episode 0 defined.
    rows = [
        episode_row("crossing", "sv", 0, pet_s=1.5),
        episode_row("crossing", "sv", 1, pet_s=0.0, collision=True),
        *(episode_row("crossing", "sv", i, pet_s=math.nan) for i in (2, 3, 4, 5)),
        episode_row("crossing", "v2i", 0, pet_s=0.7),
    ]
    logs = {2: _log(0.0, 1.5), 3: _log(9.0, 0.0), 4: _log(9.0, 1.5)}
    seen = []

    def find_log(scenario, condition, episode, seed):
        seen.append((scenario, condition, episode, seed))
        return logs.get(episode)

    table = idx.pet_coverage(_table(rows), find_log).set_index("condition")
    sv = table.loc["sv"]
    assert (sv["n"], sv["pet_defined"], sv["share"]) == (6, 2, pytest.approx(2 / 6))
    assert sv[idx.REASON_EGO_STOPPED] == 1 and sv[idx.REASON_PED_STOPPED] == 1
    assert sv[idx.REASON_ENDED] == 1 and sv[idx.REASON_NO_LOG] == 1 and sv[idx.REASON_NOT_REACHED] == 0
    assert table.loc["v2i", "share"] == 1.0
    # only the undefined episodes' logs are looked up, with their seeds (seed = 100 + episode)
    assert seen == [("crossing", "sv", i, 100 + i) for i in (2, 3, 4, 5)]
    # without any log every undefined episode says so
    assert idx.pet_coverage(_table(rows)).set_index("condition").loc["sv", idx.REASON_NO_LOG] == 4


def test_proximity_summary_counts_close_passes_without_collision():
    base = {"min_clearance_m": 2.0, "ego_speed_at_min_clearance_mps": 6.0, "drac_mps2": math.nan}
    rows = [
        # a collision with a close pass before it: not counted as a close pass
        episode_row("crossing", "sv", 0, collision=True, conflict=True)
        | {**base, "close_pass": True, "min_clearance_m": -0.2, "drac_mps2": 40.0},
        # close pass of a standing pedestrian: no Amini conflict, no DRAC
        episode_row("crossing", "sv", 1) | {**base, "close_pass": True, "min_clearance_m": 0.3},
        # close pass that is also an Amini conflict, DRAC 5 m/s2 (over 3.4)
        episode_row("crossing", "sv", 2, conflict=True)
        | {**base, "close_pass": True, "min_clearance_m": 0.9, "drac_mps2": 5.0},
        # a wide pass with DRAC 2 m/s2 (under 3.4)
        episode_row("crossing", "sv", 3)
        | {**base, "close_pass": False, "min_clearance_m": 4.0, "drac_mps2": 2.0},
    ]
    table = idx.proximity_summary(_table(rows), drac_threshold_mps2=3.4)
    r = table.iloc[0]
    assert (r["n"], r["close_pass"], r["close_pass_not_conflict"]) == (4, 2, 1)
    # over the 3 episodes with an interaction (clearance defined) and no collision
    assert r["n_interaction"] == 3 and r["close_pass_rate"] == 2 / 3
    # medians over the 3 episodes without a collision: clearances 0.3, 0.9, 4.0 -> 0.9; speeds all 6
    assert (
        r["min_clearance_median_m"] == pytest.approx(0.9)
        and r["ego_speed_at_min_clearance_median_mps"] == 6.0
    )
    # DRAC defined in episodes 2 and 3 (the collision's is left out), one over 3.4; median (5 + 2) / 2
    assert (r["drac_defined"], r["drac_over_threshold"], r["drac_median_mps2"]) == (2, 1, 3.5)
    # an episode without an interaction step (NaN clearance) is left out of the close-pass rate
    rows[3] = rows[3] | {"min_clearance_m": math.nan, "ego_speed_at_min_clearance_mps": math.nan}
    r = idx.proximity_summary(_table(rows), drac_threshold_mps2=3.4).iloc[0]
    assert (r["n"], r["n_interaction"], r["close_pass"], r["close_pass_rate"]) == (4, 2, 2, 1.0)
    assert r["min_clearance_median_m"] == pytest.approx(0.6)  # (0.3 + 0.9) / 2
    assert idx.proximity_summary(_table([episode_row("crossing", "sv", 0)]).drop(columns=[]), 3.4) is None


def test_an_older_run_still_reports_and_says_what_is_missing(tmp_path, capsys):
    run = write_standard_run(tmp_path / "run")
    episodes = pd.read_parquet(run / "episodes.parquet")
    old = [c for c in (*idx.PROXIMITY_COLUMNS, "contact_stationary") if c in episodes.columns]
    episodes.drop(columns=old).to_parquet(run / "episodes.parquet", index=False)
    assert report_main([str(run)]) == 0
    out = capsys.readouterr().out
    assert "note: no contact_stationary in this run" in out
    assert "note: no min_clearance_m, ego_speed_at_min_clearance_mps, drac_mps2, close_pass" in out
    assert "plain boolean" in out  # a boolean sumo_collision: compared everywhere, and it says so
    assert (run / "tables" / "agreement.csv").is_file() and (run / "tables" / "pet.csv").is_file()
    assert not (run / "tables" / "proximity.csv").exists()
    assert "Post-encroachment time" in (run / "tables" / "indexes.md").read_text()
