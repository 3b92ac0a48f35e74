"""The impact-speed figure and the line on eq. 4's share at 0 km/h, on a hand-built table."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from pedsafe_sumo.report.impact import eq4_at_rest, impact_speed_histogram, intercept_note, intercept_share


def sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


def episodes() -> pd.DataFrame:
    # two collisions: age 30 at 36 km/h (10 m/s), age 80 at 0.9 km/h (0.25 m/s); one episode without
    rows = [
        ("sv", True, 10.0, 30.0),
        ("sv", True, 0.25, 80.0),
        ("v2i", False, float("nan"), 50.0),
    ]
    table = pd.DataFrame(rows, columns=["condition", "collision", "impact_speed_mps", "ped_age"])
    table["injury_probability"] = [
        sigmoid(-2.9893 + 0.0013 * 36.0**2 + 0.0286 * 30),  # 0.390193
        sigmoid(-2.9893 + 0.0013 * 0.9**2 + 0.0286 * 80),  # -0.700247 -> 0.331757
        0.0,
    ]
    return table


def test_eq4_at_rest_is_0068_to_0364():
    # age 13: sigmoid(-2.9893 + 0.3718) = 0.068021; age 85: sigmoid(-2.9893 + 2.431) = 0.363941
    assert eq4_at_rest() == pytest.approx((0.068021, 0.363941), abs=2e-6)


def test_intercept_share_by_hand():
    # at 0 km/h: age 30 sigmoid(-2.1313) = 0.106092; age 80 sigmoid(-0.7013) = 0.331524
    # summed P_I: 0.390193 + 0.331757 = 0.721951; share 0.437616 / 0.721951 = 0.606157
    share = intercept_share(episodes())
    assert share.n_collisions == 2
    assert share.eq4_sum == pytest.approx(0.721951, abs=2e-6)
    assert share.eq4_at_rest_sum == pytest.approx(0.437616, abs=2e-6)
    assert share.share == pytest.approx(0.606157, abs=5e-6)
    note = intercept_note(episodes())
    assert "0.068 at age 13 to 0.364 at age 85" in note and "61% of the summed P_I" in note


def test_figure_is_written(tmp_path):
    path = tmp_path / "impact_speed.png"
    figure = impact_speed_histogram(episodes(), path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert figure.axes[0].get_xlabel() == "impact speed [km/h]"
    empty = episodes().assign(collision=False)
    impact_speed_histogram(empty, tmp_path / "none.png")
    assert (tmp_path / "none.png").stat().st_size > 0
    assert intercept_note(empty).endswith("no collision in this run")
