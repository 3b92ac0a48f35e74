"""The partial-grid summary (pedsafe_sumo.ncap.coverage) and the partial label of the points, on a
hand-made ncap.csv table."""

from __future__ import annotations

import math

import pandas as pd

from pedsafe_sumo.ncap.coverage import grid_summary, missing_cells
from pedsafe_sumo.ncap.protocol import load_protocol
from pedsafe_sumo.ncap.suite import CELL_COLUMNS, score_tests

PROTOCOL = load_protocol()


def table_of(cells: list[tuple[str, str, float, float, str, str]]) -> pd.DataFrame:
    """Rows (test, lighting, speed, pct, condition, status), green standard cells."""
    rows = []
    for test, lighting, speed, pct, condition, status in cells:
        row = dict.fromkeys(CELL_COLUMNS, math.nan)
        row.update(
            test=test, lighting=lighting, ego_speed_kmh=speed, impact_point_pct=pct, condition=condition,
            status=status, variation="nominal", turn="", colour="green", cell_score=1.0,
            test_range=PROTOCOL.tests[test].test_range(pct),
        )  # fmt: skip
        rows.append(row)
    return pd.DataFrame(rows, columns=list(CELL_COLUMNS))


def test_whole_cpnco_day_grid_under_both_conditions_but_one_error():
    test = PROTOCOL.tests["CPNCO"]
    cells = [
        ("CPNCO", "day", speed, pct, condition, "ok")
        for _, speed in test.rows
        for pct in test.impact_points_pct
        for condition in ("sv", "v2i")
    ]
    # One V2I run errored: that cell is missing (a cell counts when it ran under every condition).
    cells[-1] = (*cells[-1][:5], "error")
    table = table_of(cells)
    missing = missing_cells(PROTOCOL, table)
    # 18 cells in CPNCO's grid (6 speeds x 3 columns), 17 ran under both conditions.
    assert missing[:3] == [
        "CPNA day (30 of 30 cells)",
        "CPNA night (30 of 30 cells)",
        "CPFA day (30 of 30 cells)",
    ]
    assert "CPNCO day (1 of 18 cells)" in missing
    assert "CPNCO night (18 of 18 cells)" in missing
    assert "CPTAopposite day (25 of 25 cells)" in missing
    line = grid_summary(PROTOCOL, table)
    assert "\n" not in line
    assert line.startswith("ncap: PARTIAL grid, points are partial")
    for part in ("CPNCO day (1 of 18 cells)", "robustness layers (not run", "Driver input pre-crash (refused",
                 "CPMRCm, CPMRCs (refused", "CPMFC (refused"):  # fmt: skip
        assert part in line
    scores = score_tests(PROTOCOL, table)
    sv = scores[(scores["test"] == "CPNCO") & (scores["condition"] == "sv")].iloc[0]
    v2i = scores[(scores["test"] == "CPNCO") & (scores["condition"] == "v2i")].iloc[0]
    # SV ran the whole grid green: 1.0 + 0.125, a rating of the test; V2I misses a cell: partial.
    assert (sv["points"], sv["points_kind"], v2i["points_kind"]) == (1.125, "rating", "partial")
    # The overall row is partial: the other tests and CPNCO night were not run.
    assert (scores.loc[scores["test"] == "overall", "points_kind"] == "partial").all()
