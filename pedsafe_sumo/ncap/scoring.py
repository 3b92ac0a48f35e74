"""Euro NCAP scoring of pedestrian AEB cells: colour band, cell score, points per test.

The rules are those of the official Euro NCAP Rating Calculator 2026 (PyPI euroncap-rating-2026, see
protocol.toml for the exact functions), reimplemented here because its interface is an Excel workbook of
OEM predictions; tests/ncap/test_scoring.py checks these functions against the calculator's own on the
same inputs.

- Colour: the relative impact speed v (km/h) in the bands of the cell's VUT speed (50 km/h and above use
  the 50 km/h bands): green is v = 0 (avoided), the other bands are half-open [lower, upper). The
  turning tests are scored on avoidance: green if avoided, red otherwise.
- Cell score: standard-range cells by colour (green 1, yellow 0.75, orange 0.5, brown 0.25, red 0);
  extended-range cells 1 unless red.
- Points of a test: points_standard x the mean standard cell score, plus points_extended x the mean
  extended cell score snapped down to 0, 50 %, 75 % or 100 % of points_extended.
Every cell is simulated, so each cell's "prediction" is its own measurement and the calculator's
verification discount is 1: the points are what the calculator gives for a prediction sheet equal to the
measured colours.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from pedsafe_sumo.ncap.protocol import NcapError, Protocol

#: Score comparisons at 6 decimals, as the calculator's round_half_up(., 6) does on band edges.
_EDGE_DECIMALS = 6


def bands_for(protocol: Protocol, vut_kmh: float) -> tuple[tuple[str, float], ...]:
    """The colour bands above green for a VUT speed: ((colour, upper edge km/h), ...), red last."""
    key = min(float(vut_kmh), max(protocol.bands))
    if key not in protocol.bands:
        raise NcapError(f"no colour bands for a {vut_kmh:g} km/h test (known: {sorted(protocol.bands)})")
    return protocol.bands[key]


def band_colour(
    protocol: Protocol, vut_kmh: float, impact_speed_kmh: float, criterion: str = "mitigation_or_avoidance"
) -> str:
    """The true colour of a cell: its relative impact speed in the bands, no tolerance (green: avoided).
    Under the "avoidance" criterion (the turning tests) any impact is red."""
    if not math.isfinite(impact_speed_kmh) or impact_speed_kmh <= 0.0:
        return "green"
    if criterion == "avoidance":
        return "red"
    lower = 0.0
    for colour, upper in bands_for(protocol, vut_kmh):
        if lower <= impact_speed_kmh < upper:
            return colour
        lower = upper
    return "red"


def applied_colour(
    protocol: Protocol, vut_kmh: float, impact_speed_kmh: float, predicted: str
) -> tuple[str, str]:
    """(result, colour) of a measured cell checked against a predicted colour with the 2 km/h tolerance.

    result is "correct" (measured in the predicted band), "in_tolerance" (in the predicted band widened
    by the tolerance: the predicted colour is applied) or "incorrect" (the measured colour is applied).
    The widened window: green v < t; a middle band [lower - t, upper + t) with its lower edge kept
    strictly above 0; red [lower, inf), not widened downwards.
    """
    measured = band_colour(protocol, vut_kmh, impact_speed_kmh)
    if measured == predicted:
        return "correct", measured
    tolerance = protocol.tolerance_kmh
    edges = (("green", 0.0), *bands_for(protocol, vut_kmh))
    index = next((i for i, (c, _) in enumerate(edges) if c == predicted), None)
    if index is None:
        return "incorrect", measured
    upper = edges[index][1]
    v = impact_speed_kmh
    upper_ok = v < upper + tolerance
    if index == 0:
        lower_ok = True
    else:
        raw_lower = edges[index - 1][1]
        lower = raw_lower if index == len(edges) - 1 else raw_lower - tolerance
        lower_ok = v > 0.0 if lower <= 0.0 else v >= lower
    if lower_ok and upper_ok:
        return "in_tolerance", predicted
    return "incorrect", measured


def cell_score(protocol: Protocol, colour: str, test_range: str) -> float:
    """The score of one cell: by colour in the standard range, 1 unless red in the extended range."""
    if test_range == "standard":
        return protocol.cell_scores[colour]
    if test_range == "extended":
        return 0.0 if colour == "red" else 1.0
    raise NcapError(f"unknown test range '{test_range}'")


def snap_extended(points: float, total: float) -> float:
    """The calculator's extended-range bands: below 50 % of the total 0, then 50 %, 75 %, 100 %."""
    score = round(points, _EDGE_DECIMALS)
    if score < round(0.5 * total, _EDGE_DECIMALS):
        return 0.0
    if score < round(0.75 * total, _EDGE_DECIMALS):
        return 0.5 * total
    if score < round(total, _EDGE_DECIMALS):
        return 0.75 * total
    return total


def points_of_test(
    points_standard: float,
    points_extended: float,
    cells: Iterable[tuple[str, float]],
) -> dict[str, float]:
    """Points of one test from its cells' (test_range, cell_score): standard, extended and their sum."""
    standard: list[float] = []
    extended: list[float] = []
    for test_range, score in cells:
        (standard if test_range == "standard" else extended).append(score)
    standard_points = sum(standard) / len(standard) * points_standard if standard else 0.0
    extended_points = (
        snap_extended(sum(extended) / len(extended) * points_extended, points_extended) if extended else 0.0
    )
    return {
        "points_standard": standard_points,
        "points_extended": extended_points,
        "points": standard_points + extended_points,
    }
