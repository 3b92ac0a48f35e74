"""The robustness layers and points (pedsafe_sumo.ncap.robustness) against the calculator's own tables and
compute_robustness_layer_score, and a robustness cell scored by hand."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from euroncap_rating_2026.crash_avoidance import data_model, robustness_layer, test_info

from pedsafe_sumo.ncap.protocol import load_protocol
from pedsafe_sumo.ncap.robustness import layers_passed, robustness_points, run_meets

PROTOCOL = load_protocol()
#: Our test -> the calculator's day load case and its canonical test name in the robustness tables.
LOADCASE = {
    "CPNA": ("CPNA day", "CPNA"),
    "CPFA": ("CPFA day", "CPFA"),
    "CPNCO": ("CPNCO day", "CPNCO"),
    "CPLA": ("CPLA day", "CPLA"),
    "CPTAsame": ("CPTAfs & CPTAns", "CPTA"),
    "CPTAopposite": ("CPTAfo & CPTAno", "CPTA"),
}
#: Our variation -> the calculator's verification condition text (CPTA writes "+ 3 km/h").
CONDITION = {
    "speed+3": ("+3 km/h", "+ 3 km/h"),
    "speed-2": ("-2 km/h",),
    "start-25pct": ("-25% m of distance to impact point",),
    "heading-10": ("-10° (rotation around the impact point)",),
    "heading+20": ("+20° (rotation around the impact point)",),
}
CRITERION = {
    robustness_layer.AssessmentCriteria.NOT_RED: "not_red",
    robustness_layer.AssessmentCriteria.SAME_OR_BETTER_THAN_PREDICTED: "same_or_better",
}
STAGED = ("Speed", "Initial position offset", "Trajectory/Heading")


def _applicable(canonical: str) -> list[str]:
    return [
        layer.value
        for layer, conditions in robustness_layer.ROBUSTNESS_LAYER_TO_VERIFICATION_CONDITION.items()
        if canonical in conditions
    ]


@pytest.mark.parametrize("name", list(LOADCASE))
def test_variations_and_counts_are_the_calculators(name):
    loadcase, canonical = LOADCASE[name]
    assert PROTOCOL.raw["robustness"]["applicable_layers"][name] == len(_applicable(canonical))
    assert PROTOCOL.raw["robustness"]["points"][name] == data_model.TOTAL_SCORES[loadcase]["Robustness"]
    # Every verification condition of a staged layer for this test is one of our variations, with the
    # calculator's assessment criterion; and no variation of ours is outside the calculator's table.
    ours = {v.name: v for v in PROTOCOL.robustness if v.criterion(name) is not None}
    theirs = []
    for layer in STAGED:
        value = robustness_layer.ROBUSTNESS_LAYER_TO_VERIFICATION_CONDITION[layer].get(canonical)
        theirs += [] if value is None else value if isinstance(value, list) else [value]
    assert len(ours) == len(theirs)
    for condition, criterion in theirs:
        variation = next(v for v in ours.values() if condition in CONDITION[v.name])
        assert variation.criterion(name) == CRITERION[criterion]
        assert robustness_layer.RobustnessLayer(variation.layer).value in STAGED
    # Acceleration, the fifth layer of the calculator's test pool, applies to no pedestrian test.
    assert "Acceleration" in test_info.FC_ROBUSTNESS_LAYERS_POOL
    assert "Acceleration" not in _applicable(canonical)


@pytest.mark.parametrize("name", ["CPNA", "CPNCO", "CPTAsame"])
def test_points_are_the_calculators(name):
    loadcase, canonical = LOADCASE[name]
    applicable = _applicable(canonical)
    for passed in range(len(STAGED) + 1):
        claimed = set(STAGED[:passed]) & set(applicable)
        sheet = pd.DataFrame(
            {
                "Robustness layer": applicable,
                canonical: ["YES" if layer in claimed else "NO" for layer in applicable],
            }
        )
        theirs = test_info.compute_robustness_layer_score(sheet, canonical, loadcase).total_score
        total = PROTOCOL.raw["robustness"]["points"][name]
        assert total / len(applicable) * len(claimed) == pytest.approx(theirs)


def _rows(rows):
    columns = ("cell_id", "variation", "colour", "status")
    return pd.DataFrame([dict(zip(columns, r)) for r in rows])


def test_a_robustness_cell_by_hand():
    # CPNA-50 at 40 km/h, nominal orange (impact 5 km/h). The dummy 3 km/h faster: brown (15 km/h), not
    # red: passes "not red". 2 km/h slower and avoided: green passes "same or better than orange", where
    # brown would not.
    nominal = _rows([("CPNA-50_40kmh", "nominal", "orange", "ok")])
    assert run_meets("not_red", "brown", "orange")
    assert run_meets("same_or_better", "green", "orange")
    assert not run_meets("same_or_better", "brown", "orange")
    runs = _rows(
        [
            ("CPNA-50_40kmh_speed+3", "speed+3", "brown", "ok"),
            ("CPNA-50_40kmh_speed-2", "speed-2", "green", "ok"),
            ("CPNA-50_40kmh_start-25pct", "start-25pct", "red", "ok"),
            ("CPNA-50_40kmh_heading-10", "heading-10", "orange", "ok"),
            ("CPNA-50_40kmh_heading+20", "heading+20", "", "error"),
        ]
    )
    # Speed passes (both runs); the nearer start is red: fails; heading: one run errored: fails.
    assert layers_passed(PROTOCOL, "CPNA", runs, nominal) == ["Speed"]
    points = robustness_points(PROTOCOL, "CPNA", runs, nominal)
    # 0.125 robustness points over CPNA's 6 applicable layers, 1 passed.
    assert points == {
        "robustness_layers_passed": 1,
        "robustness_layers_applicable": 6,
        "points_robustness": pytest.approx(0.125 / 6),
    }
    assert not math.isnan(points["points_robustness"])
    assert list(CONDITION) == [v.name for v in PROTOCOL.robustness]
