"""Robustness points of the day load cases, as the Euro NCAP Rating Calculator 2026 gives them.

The calculator ([CALC] test_info.compute_robustness_layer_score): a test's Robustness points R are
shared among the layers applicable to it (N, protocol.toml `[robustness.applicable_layers]`); a maker
claims some, one claimed layer is verified by a test, and the test scores R / N per claimed layer (the
verified one plus the others), 0 when none is claimed. Here every variation is simulated, so a layer is
claimed when each of its runs on each cell run meets its assessment criterion against the nominal cell
(robustness_layer.AssessmentCriteria: "Not red", or "Same or better than predicted", the prediction being
the nominal cell's measured colour), and the points are R / N x the layers passed. Layers not staged (the
refused driver input, the environment layers outside the calculator's test pool) are not claimed.
tests/ncap/test_robustness.py checks the points against compute_robustness_layer_score.
"""

from __future__ import annotations

import pandas as pd

from pedsafe_sumo.ncap.protocol import COLOURS, Protocol

ROBUSTNESS_COLUMNS = ("robustness_layers_passed", "robustness_layers_applicable", "points_robustness")


def run_meets(criterion: str, colour: str, nominal_colour: str) -> bool:
    """Whether a variation run's colour meets its criterion against its nominal cell's colour."""
    if colour not in COLOURS or nominal_colour not in COLOURS:
        return False  # a run (or its nominal cell) that errored has no colour
    if criterion == "not_red":
        return colour != "red"
    return COLOURS.index(colour) <= COLOURS.index(nominal_colour)


def layers_passed(protocol: Protocol, test: str, runs: pd.DataFrame, nominal: pd.DataFrame) -> list[str]:
    """The layers of `test` whose every variation run (of one condition) meets its criterion; a layer
    with no run is not passed."""
    variations = {v.name: v for v in protocol.robustness}
    nominal_colour = dict(zip(nominal["cell_id"], nominal["colour"]))
    verdicts: dict[str, bool] = {}
    for _, run in runs.iterrows():
        variation = variations[run["variation"]]
        criterion = variation.criterion(test)
        if criterion is None:
            continue
        base_id = run["cell_id"].removesuffix(f"_{variation.name}")
        ok = run["status"] == "ok" and run_meets(criterion, run["colour"], nominal_colour.get(base_id, ""))
        verdicts[variation.layer] = verdicts.get(variation.layer, True) and ok
    return [layer for layer, ok in verdicts.items() if ok]


def robustness_points(protocol: Protocol, test: str, runs: pd.DataFrame, nominal: pd.DataFrame) -> dict:
    """ROBUSTNESS_COLUMNS of one test and condition."""
    applicable = int(protocol.raw["robustness"]["applicable_layers"][test])
    total = float(protocol.raw["robustness"]["points"][test])
    passed = layers_passed(protocol, test, runs, nominal)
    return {
        "robustness_layers_passed": len(passed),
        "robustness_layers_applicable": applicable,
        "points_robustness": total / applicable * len(passed),
    }
