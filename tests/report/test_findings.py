"""The paper's qualitative findings on hand-built episode tables (counts chosen so each finding's
verdict is known by hand)."""

from __future__ import annotations

import math

import pandas as pd

from pedsafe_sumo.report.findings import findings_figure, paper_findings


def _episodes(collisions: dict[tuple[str, str], int], n: int = 10, v2i_distance_m: float = 20.0):
    rows = []
    for (scenario, condition), hits in collisions.items():
        for i in range(n):
            rows.append(
                {
                    "scenario": scenario,
                    "condition": condition,
                    "collision": i < hits,
                    "conflict": False,
                    "status": "ok",
                    "first_detection_distance_m": v2i_distance_m,
                }
            )
    return pd.DataFrame(rows)


def test_all_four_findings_hold():
    table = _episodes(
        {
            ("crossing", "sv"): 3, ("crossing", "v2i"): 1,
            ("jaywalking", "sv"): 5, ("jaywalking", "v2i"): 2,
            ("background_blending", "sv"): 1, ("background_blending", "v2i"): 0,
        }
    )  # fmt: skip
    assert paper_findings(table) == dict.fromkeys(paper_findings(table), 1.0)


def test_each_finding_fails_on_its_counterexample():
    table = _episodes(
        {
            ("crossing", "sv"): 6, ("crossing", "v2i"): 7,  # V2I worse in crossing
            ("jaywalking", "sv"): 5, ("jaywalking", "v2i"): 2,  # jaywalking below crossing
            ("background_blending", "sv"): 5, ("background_blending", "v2i"): 0,  # ties jaywalking, lowest
        },
        v2i_distance_m=12.0,  # never beyond 13 m
    )  # fmt: skip
    found = paper_findings(table)
    assert found["v2i_safer_everywhere"] == 0.0
    assert found["jaywalking_most_dangerous"] == 0.0
    assert found["blending_safest"] == 1.0  # a tie for lowest holds
    assert found["v2i_beyond_13m_in_90pct"] == 0.0


def test_missing_scenarios_are_not_evaluated_and_the_figure_draws(tmp_path):
    table = _episodes({("crossing", "sv"): 1, ("crossing", "v2i"): 0})
    found = paper_findings(table)
    assert found["v2i_safer_everywhere"] == 1.0
    assert math.isnan(found["jaywalking_most_dangerous"]) and math.isnan(found["blending_safest"])
    frame = pd.DataFrame([{"run": "a=1", **found}, {"run": "a=2", **found}])
    path = findings_figure(frame, tmp_path / "f.png")
    assert path.stat().st_size > 1000
