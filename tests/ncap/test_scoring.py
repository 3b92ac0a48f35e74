"""pedsafe_sumo.ncap's grid and scoring against the official Euro NCAP Rating Calculator 2026.

The calculator (PyPI euroncap-rating-2026) is the reference: its packaged template gives the grids, its
ComputedTestPoint the colours (with and without the 2 km/h tolerance), its TestPoint the cell scores and
its compute_predicted_score the points of a test, all on the same hand-made inputs as ours.
"""

from __future__ import annotations

import itertools
from importlib import resources

import openpyxl
import pytest
from euroncap_rating_2026 import common
from euroncap_rating_2026.crash_avoidance import data_model, matrix_processing, test_info

from pedsafe_sumo.ncap.protocol import load_protocol, select_cells
from pedsafe_sumo.ncap.scoring import applied_colour, band_colour, cell_score, points_of_test

PROTOCOL = load_protocol()
#: Our test -> the calculator's day load case (the night ones: test_night.py).
LOADCASE = {
    "CPNA": "CPNA day",
    "CPFA": "CPFA day",
    "CPNCO": "CPNCO day",
    "CPLA": "CPLA day",
    "CPTAsame": "CPTAfs & CPTAns",
    "CPTAopposite": "CPTAfo & CPTAno",
}
COLOUR = {c.value.lower(): c for c in common.PredictionColor if c.value.lower() in PROTOCOL.cell_scores}
IMPACT_SPEEDS_KMH = (0.0, 0.5, 1.99, 2.0, 9.99, 10.0, 11.99, 12.0, 19.99, 20.0, 28.0, 30.0, 31.9, 32.0, 45.0)


def _template_grid(loadcase: str) -> tuple[list[tuple[str, float]], list[float], str]:
    """(rows as (turn, VUT speed), impact locations in %, target direction) of a load case's rows in the
    calculator's template (turn and direction empty where the sheet has none)."""
    path = resources.files("euroncap_rating_2026").joinpath("../data/ca_template.xlsx")
    sheet = openpyxl.load_workbook(str(path))["FC - Ped & Cyc pred."]
    first = next(r for r in range(1, sheet.max_row + 1) if sheet.cell(r, 1).value == loadcase)
    start_col = data_model.MATRIX_INDICES[loadcase]["start_col"] + 1  # 0-based in the calculator
    n_cols = data_model.MATRIX_INDICES[loadcase]["n_cols"]
    locations = [round(100 * sheet.cell(first + 1, c).value) for c in range(start_col, start_col + n_cols)]
    turning = sheet.cell(first, 2).value == "Turn"
    rows, direction = [], ""
    row = first + 2
    while sheet.cell(row, 1).value:
        if loadcase.startswith("CPLA") and sheet.cell(row, 3).value != "AEB":
            break  # the FCW/AEB choice band, not staged (protocol.toml)
        turn = sheet.cell(row, 2).value.lower() if turning else ""
        direction = sheet.cell(row, 3).value.lower() if turning else ""
        rows.append((turn, float(sheet.cell(row, 1).value.split()[0])))
        row += 1
    return rows, locations, direction


@pytest.mark.parametrize("name", list(LOADCASE))
def test_grids_are_the_calculators(name):
    test = PROTOCOL.tests[name]
    rows, locations, direction = _template_grid(LOADCASE[name])
    assert list(test.rows) == rows
    assert test.direction == direction
    assert sorted(test.impact_points_pct) == sorted(locations)
    # Standard vs extended range: the calculator's static map, cell by cell.
    for (row, (turn, speed)), (col, pct) in itertools.product(enumerate(rows), enumerate(locations)):
        theirs = matrix_processing.check_extended_range(row, col, LOADCASE[name])
        assert test.test_range(pct, turn, speed) == theirs.value.lower(), (name, turn, speed, pct)
    assert test.points_standard == data_model.TOTAL_SCORES[LOADCASE[name]]["Standard"]
    assert test.points_extended == data_model.TOTAL_SCORES[LOADCASE[name]]["Extended"]
    # The criterion: the turning tests are scored on avoidance, the others on mitigation or avoidance.
    criteria = {"avoidance": data_model.NcapTestCriteria.AVOIDANCE}
    expected = criteria.get(test.criterion, data_model.NcapTestCriteria.MITIGATION_OR_AVOIDANCE)
    assert data_model.get_criteria_for_test(LOADCASE[name]) == expected


def _calculator_point(loadcase, vut_kmh, impact_kmh, predicted, test_range="Standard"):
    point = matrix_processing.TestPoint(
        row=0,
        col=0,
        color=COLOUR[predicted],
        test_range=matrix_processing.TestRange(test_range),
        attributes={"VUT speed": f"{vut_kmh:g} km/h"},
    )
    return matrix_processing.ComputedTestPoint(point, test_name=loadcase, value=impact_kmh)


@pytest.mark.parametrize("vut_kmh", [10.0, 15.0, 20.0, 25.0])
def test_turning_colours_equal_the_calculators(vut_kmh):
    for impact_kmh, predicted in itertools.product(IMPACT_SPEEDS_KMH, COLOUR):
        theirs = _calculator_point("CPTAfs & CPTAns", vut_kmh, impact_kmh, predicted)
        colour = band_colour(PROTOCOL, vut_kmh, impact_kmh, PROTOCOL.tests["CPTAsame"].criterion)
        assert colour == theirs.measured_color.value.lower(), (impact_kmh, predicted)


@pytest.mark.parametrize("vut_kmh", [10.0, 20.0, 30.0, 40.0, 50.0, 60.0])
def test_colours_and_tolerance_equal_the_calculators(vut_kmh):
    for impact_kmh, predicted in itertools.product(IMPACT_SPEEDS_KMH, COLOUR):
        theirs = _calculator_point("CPNA day", vut_kmh, impact_kmh, predicted)
        assert band_colour(PROTOCOL, vut_kmh, impact_kmh) == theirs.measured_color.value.lower()
        result, colour = applied_colour(PROTOCOL, vut_kmh, impact_kmh, predicted)
        assert colour == theirs.computed_color.value.lower(), (impact_kmh, predicted)
        assert result == theirs.prediction_result.value.lower().replace(" ", "_"), (impact_kmh, predicted)


def test_colour_bands_by_hand():
    # FC sec 5.2 as the calculator encodes it: green only when avoided; a boundary belongs to the band above.
    assert band_colour(PROTOCOL, 20, 0.0) == "green"
    assert band_colour(PROTOCOL, 20, 0.1) == "red"
    assert band_colour(PROTOCOL, 30, 9.9) == "brown"
    assert band_colour(PROTOCOL, 30, 10.0) == "red"
    assert band_colour(PROTOCOL, 40, 10.0) == "brown"
    assert band_colour(PROTOCOL, 60, 5.0) == "yellow"
    assert band_colour(PROTOCOL, 60, 29.9) == "brown"
    assert band_colour(PROTOCOL, 60, 30.0) == "red"
    # Within 2 km/h of a predicted yellow the prediction is applied; a measured red never turns green.
    assert applied_colour(PROTOCOL, 50, 11.5, "yellow") == ("in_tolerance", "yellow")
    assert applied_colour(PROTOCOL, 50, 12.0, "yellow") == ("incorrect", "orange")
    assert applied_colour(PROTOCOL, 50, 1.0, "green") == ("in_tolerance", "green")


@pytest.mark.parametrize("colour", list(COLOUR))
@pytest.mark.parametrize("test_range", ["standard", "extended"])
def test_cell_scores_equal_the_calculators(colour, test_range):
    point = matrix_processing.TestPoint(
        row=0, col=0, color=COLOUR[colour], test_range=matrix_processing.TestRange(test_range.capitalize())
    )
    assert cell_score(PROTOCOL, colour, test_range) == point.predicted_score


# Hand-made result sheets: one colour per cell, cycling through the colours so every band occurs.
SHEETS = {
    "all_green": lambda i: "green",
    "all_red": lambda i: "red",
    "cycle": lambda i: ("green", "yellow", "orange", "brown", "red")[i % 5],
    "extended_red_every_third": lambda i: "red" if i % 3 == 0 else "green",
    "mostly_brown": lambda i: "brown" if i % 4 else "orange",
}


@pytest.mark.parametrize("sheet", list(SHEETS))
@pytest.mark.parametrize("name", list(LOADCASE))
def test_points_equal_the_calculators(name, sheet):
    test = PROTOCOL.tests[name]
    cells = select_cells(PROTOCOL, name)
    colours = [SHEETS[sheet](i) for i in range(len(cells))]
    ours = points_of_test(
        test.points_standard,
        test.points_extended,
        [(c.test_range, cell_score(PROTOCOL, colour, c.test_range)) for c, colour in zip(cells, colours)],
    )
    points = [
        matrix_processing.TestPoint(
            row=0,
            col=0,
            color=COLOUR[colour],
            test_range=matrix_processing.TestRange(c.test_range.capitalize()),
        )
        for c, colour in zip(cells, colours)
    ]
    standard, extended = test_info.compute_predicted_score(LOADCASE[name], points)
    assert ours["points_standard"] == pytest.approx(standard, abs=1e-12)
    assert ours["points_extended"] == pytest.approx(extended, abs=1e-12)


def test_points_by_hand():
    # CPNA: 18 standard cells (3 columns x 6 speeds), 12 extended. 9 standard green + 9 standard brown:
    # (9 x 1 + 9 x 0.25) / 18 x 0.5 = 0.3125. Extended: 9 of 12 not red = 75 % -> snapped to 75 % of 0.0625.
    test = PROTOCOL.tests["CPNA"]
    standard = [("standard", 1.0)] * 9 + [("standard", 0.25)] * 9
    cells = standard + [("extended", 1.0)] * 9 + [("extended", 0.0)] * 3
    points = points_of_test(test.points_standard, test.points_extended, cells)
    assert points["points_standard"] == pytest.approx(0.3125)
    assert points["points_extended"] == pytest.approx(0.75 * 0.0625)
    # 8 of 12 (66.7 %) snaps down to 50 %; 5 of 12 to 0.
    cells8 = cells[:18] + [("extended", 1.0)] * 8 + [("extended", 0.0)] * 4
    assert points_of_test(0.5, 0.0625, cells8)["points_extended"] == pytest.approx(0.5 * 0.0625)
    cells5 = cells[:18] + [("extended", 1.0)] * 5 + [("extended", 0.0)] * 7
    assert points_of_test(0.5, 0.0625, cells5)["points_extended"] == 0.0
