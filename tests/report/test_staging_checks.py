"""The staging diagnostics (report/staging_checks.py) and Table I's collisions by type, on hand-built tables
whose answers follow from their construction."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from report_runs import episode_row

from pedsafe_sumo.report.staging_checks import collision_type_columns, staging_diagnostics, staging_rows
from pedsafe_sumo.report.tables import table_one_of_run, table_one_rows


def episodes(n: int, condition: str = "sv", **columns) -> pd.DataFrame:
    """n crossing episodes; each keyword a sequence of n values (or one value for all)."""
    rows = [episode_row("crossing", condition, e) for e in range(n)]
    table = pd.DataFrame(rows)
    table["ego_start_distance_m"] = np.linspace(20.0, 80.0, n)
    table["min_clearance_m"] = 1.0 + 0.1 * np.arange(n)  # all different
    table["collision_type"] = "none"
    for name, values in columns.items():
        table[name] = values
    return table


def test_detection_at_a_fixed_share_of_the_start_distance_correlates_fully_and_misses_the_target():
    table = episodes(20)
    table["first_detection_distance_m"] = 0.98 * table["ego_start_distance_m"]
    row = staging_diagnostics(table).iloc[0]
    assert row["correlation_n"] == 20
    assert row["pearson_r"] == pytest.approx(1.0) and row["spearman_r"] == pytest.approx(1.0)
    assert row["correlation_target_met"] is not None and not row["correlation_target_met"]
    assert staging_rows(staging_diagnostics(table))[1][0][4] == "MISSED"


def test_uncorrelated_detection_meets_the_target():
    # A detection distance symmetric about the middle of the start distances: Pearson r is exactly 0.
    table = episodes(11)
    start = table["ego_start_distance_m"].to_numpy()
    table["first_detection_distance_m"] = 5.0 + (start - 50.0) ** 2 / 100.0
    row = staging_diagnostics(table).iloc[0]
    assert abs(row["pearson_r"]) < 1e-12 and bool(row["correlation_target_met"])


def test_a_constant_start_distance_or_too_few_episodes_give_no_correlation():
    constant = episodes(12, ego_start_distance_m=50.0)
    row = staging_diagnostics(constant).iloc[0]
    assert math.isnan(row["pearson_r"]) and row["correlation_note"].startswith("n/a")
    assert "constant" in row["correlation_note"] and row["correlation_target_met"] is None
    few = episodes(12)
    few.loc[3:, "first_detection_distance_m"] = np.nan  # 3 episodes with both finite
    row = staging_diagnostics(few).iloc[0]
    assert row["correlation_n"] == 3 and "fewer than 10" in row["correlation_note"]
    assert staging_rows(staging_diagnostics(few))[1][0][4] == "n/a"
    fixed = episodes(12, ego_start_distance_m=np.nan)  # the fixed staging records no start distance
    assert "no episode records" in staging_diagnostics(fixed).iloc[0]["correlation_note"]
    assert (
        "no ego_start_distance_m"
        in staging_diagnostics(episodes(12).drop(columns="ego_start_distance_m")).iloc[0]["correlation_note"]
    )


@pytest.mark.parametrize("early, share, met", [(1, 0.025, True), (2, 0.05, False), (4, 0.1, False)])
def test_the_first_second_share(early, share, met):
    # 40 episodes: `early` of them detect at 0.5 s or exactly 1.0 s (inside the first second), one never
    # (NaN: not in the first second), the rest at 2.5 s.
    times = np.full(40, 2.5)
    times[:early] = 0.5
    times[0] = 1.0
    times[-1] = np.nan
    row = staging_diagnostics(episodes(40, first_detection_time_s=times)).iloc[0]
    assert row["first_second_share"] == pytest.approx(share) and bool(row["first_second_target_met"]) is met


@pytest.mark.parametrize("same, met", [(3, False), (2, True)])
def test_the_most_common_clearance(same, met):
    # 40 episodes without a collision, `same` of them at 0.50 m once rounded to 1 cm (0.501, 0.499,
    # 0.5004), the others 10 cm apart; a 41st with a collision at 0.50 m is not counted.
    table = episodes(41)
    table.loc[: same - 1, "min_clearance_m"] = [0.501, 0.499, 0.5004][:same]
    table.loc[40, ["collision", "min_clearance_m"]] = [True, 0.5]
    row = staging_diagnostics(table).iloc[0]
    assert row["no_collision_n"] == 40 and row["modal_clearance_m"] == pytest.approx(0.5)
    assert row["modal_clearance_share"] == pytest.approx(same / 40)  # 7.5% or 5%
    assert bool(row["clearance_target_met"]) is met
    cells = staging_rows(staging_diagnostics(table))[1][0]
    assert cells[7] == f"0.50 m in {100 * same / 40:.1f}% of 40" and cells[8] == ("met" if met else "MISSED")


def test_only_ok_rows_and_each_condition_apart():
    sv, v2i = episodes(10, first_detection_time_s=3.0), episodes(10, "v2i", first_detection_time_s=0.2)
    table = pd.concat([sv, v2i], ignore_index=True)
    table.loc[0, "status"] = "error"
    result = staging_diagnostics(table)
    assert result["condition"].tolist() == ["sv", "v2i"] and result["n"].tolist() == [9, 10]
    assert result["first_second_share"].tolist() == [0.0, 1.0]


def test_collision_types_beside_table_one_leave_its_numbers_alone():
    table = episodes(10)
    kinds = ["ego_strikes_pedestrian"] * 3 + ["pedestrian_strikes_side"] * 2 + ["none"] * 5
    table["collision_type"] = kinds
    table["collision"] = [k != "none" for k in kinds]
    table["injury_probability"] = [0.5] * 5 + [0.0] * 5
    plain = table_one_of_run(table)
    with_types = collision_type_columns(plain, table)
    pd.testing.assert_frame_equal(with_types[plain.columns], plain)
    row = with_types.iloc[0]
    assert (row["ego_strikes_pedestrian"], row["pedestrian_strikes_side"]) == (3, 2)
    assert row["ego_strikes_pedestrian_rate"] == pytest.approx(0.3)
    assert row["pedestrian_strikes_side_rate"] == pytest.approx(0.2)
    # Wilson 95% interval of 2 in 10, from its formula.
    z, p, n = 1.959963984540054, 0.2, 10
    centre, half = (
        (p + z * z / (2 * n)) / (1 + z * z / n),
        z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)),
    )
    assert row["pedestrian_strikes_side_low"] == pytest.approx(centre - half / (1 + z * z / n))
    header, rows = table_one_rows(with_types)
    assert header[-2:] == [
        "ego strikes pedestrian rate [95% CI]",
        "pedestrian strikes side rate [95% CI]",
    ]
    assert rows[0][-1].startswith("0.2000 [")
    assert table_one_rows(plain)[1][0] == rows[0][: len(table_one_rows(plain)[0])]
    # A run without the column: Table I as it was.
    assert collision_type_columns(plain, table.drop(columns="collision_type")) is plain
