"""The MAIS 3+F risk of Monfort & Mueller 2025 (Table 4), worked by hand, and its column in a row."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from scipy.special import expit

from pedsafe_sumo.safety import episode_indexes
from pedsafe_sumo.safety.injury import SEVERE_INJURY_MODEL, injury_probability
from pedsafe_sumo.safety.injury_mais3 import mais3f_logit_full
from pedsafe_sumo.safety.stats import table_one

MODEL = "monfort_mueller2025_mais3f"


# logit = -0.460 + 0.091 (v - 42.79) + 0.029 (A - 42.42), v in km/h; P = 1 / (1 + e^-logit).
# Age 30: the age term is 0.029 * (-12.42) = -0.36018.
#   30 km/h: -0.460 + 0.091 * (-12.79) - 0.36018 = -0.460 - 1.16389 - 0.36018 = -1.98407;
#            e^1.98407 = e^2 * e^-0.01593 = 7.389056 * 0.984196 = 7.27228; P = 1 / 8.27228 = 0.120886
#   40 km/h: -0.460 + 0.091 * (-2.79) - 0.36018 = -0.460 - 0.25389 - 0.36018 = -1.07407;
#            e^1.07407 = e * e^0.07407 = 2.718282 * 1.076882 = 2.92727; P = 1 / 3.92727 = 0.254630
#   50 km/h: -0.460 + 0.091 * 7.21 - 0.36018 = -0.460 + 0.65611 - 0.36018 = -0.16407;
#            e^0.16407 = 1.178300; P = 1 / 2.178300 = 0.459073
# Age 70: the age term is 0.029 * 27.58 = 0.79982.
#   30 km/h: -0.460 - 1.16389 + 0.79982 = -0.82407; e^0.82407 = 2.279762; P = 1 / 3.279762 = 0.304900
#   40 km/h: -0.460 - 0.25389 + 0.79982 = 0.08593; e^-0.08593 = 0.917658; P = 1 / 1.917658 = 0.521469
#   50 km/h: -0.460 + 0.65611 + 0.79982 = 0.99593; e^-0.99593 = 0.369385; P = 1 / 1.369385 = 0.730256
@pytest.mark.parametrize(
    ("age", "speed_kmh", "expected"),
    [
        (30, 30, 0.120886),
        (30, 40, 0.254630),
        (30, 50, 0.459073),
        (70, 30, 0.304900),
        (70, 40, 0.521469),
        (70, 50, 0.730256),
    ],
)
def test_hand_worked_risk(age, speed_kmh, expected):
    assert injury_probability(speed_kmh / 3.6, age, model=MODEL) == pytest.approx(expected, abs=2e-6)


def test_at_zero_speed_far_below_eq4():
    # 0 km/h, age 30: -0.460 - 0.091 * 42.79 - 0.36018 = -0.460 - 3.89389 - 0.36018 = -4.71407;
    # e^4.71407 = e^4.7 * e^0.01407 = 109.9472 * 1.014169 = 111.5050; P = 1 / 112.5050 = 0.008888.
    # eq. 4 at 0 km/h, age 30: sigmoid(-2.9893 + 0.858) = sigmoid(-2.1313) = 1 / (1 + 8.425813) = 0.106092
    assert injury_probability(0.0, 30.0, model=MODEL) == pytest.approx(0.008888, abs=1e-6)
    assert injury_probability(0.0, 30.0) == pytest.approx(0.106092, abs=1e-6)


def test_eq4_intercept_at_zero_speed_ages_13_and_85():
    # eq. 4 at V = 0: age 13: -2.9893 + 0.3718 = -2.6175, e^2.6175 = 13.701427, P = 1 / 14.701427 = 0.068021;
    # age 85: -2.9893 + 2.431 = -0.5583, e^0.5583 = 1.747699, P = 1 / 2.747699 = 0.363941
    assert injury_probability(0.0, 13.0) == pytest.approx(0.068021, abs=1e-6)
    assert injury_probability(0.0, 85.0) == pytest.approx(0.363941, abs=2e-6)


def test_the_row_has_both_injury_columns(collision_log):
    # contact at 10 m/s = 36 km/h, age 30: logit = -0.460 + 0.091 * (-6.79) - 0.36018
    # = -0.460 - 0.61789 - 0.36018 = -1.43807; e^1.43807 = 4.212558; P = 1 / 5.212558 = 0.191844
    row = episode_indexes(collision_log, ped_age_years=30.0)
    assert SEVERE_INJURY_MODEL == MODEL
    assert row["injury_probability"] == pytest.approx(0.390193, abs=1e-6)
    assert row["injury_mais3f_probability"] == pytest.approx(0.191844, abs=1e-6)
    # another registered model by name
    other = episode_indexes(collision_log, ped_age_years=30.0, severe_injury_model="rosen_sander2009")
    assert other["injury_mais3f_probability"] == pytest.approx(0.011206, abs=1e-6)


def test_no_collision_no_risk(near_miss_log):
    assert episode_indexes(near_miss_log, ped_age_years=80.0)["injury_mais3f_probability"] == 0.0


def _episodes(mais3f):
    rows = {
        "scenario": ["crossing"] * 4 + ["jaywalking"] * 2,
        "condition": ["sv"] * 6,
        "collision": [True, True, False, False, False, True],
        "injury_probability": [0.3, 0.5, 0.0, 0.0, 0.0, 0.2],
        "conflict": [False] * 6,
        "status": ["ok"] * 6,
    }
    if mais3f is not None:
        rows["injury_mais3f_probability"] = mais3f
    return pd.DataFrame(rows)


def test_table_one_has_the_mais3f_mean_beside_p_i():
    # crossing: (0.2 + 0.4 + 0 + 0) / 4 = 0.15; the interval is the two-part one of P_I: the same
    # function of the same kind of values, so the MAIS 3+F values put into the P_I column give it again
    table = table_one(_episodes([0.2, 0.4, 0.0, 0.0, 0.0, 0.1]))
    crossing = table.iloc[0]
    assert crossing["mais3f_mean"] == pytest.approx(0.15)
    swapped = table_one(_episodes(None).assign(injury_probability=[0.2, 0.4, 0.0, 0.0, 0.0, 0.1])).iloc[0]
    assert (crossing["mais3f_low"], crossing["mais3f_high"]) == pytest.approx(
        (swapped["injury_low"], swapped["injury_high"])
    )
    # two positives: the t interval of their mean reaches 0 (t = 12.71 at 1 degree of freedom)
    assert crossing["mais3f_low"] == 0.0 and 0.15 < crossing["mais3f_high"] < 1.0
    assert table.iloc[1]["mais3f_mean"] == pytest.approx(0.05)


def test_table_one_without_the_column_or_with_gaps():
    assert "mais3f_mean" not in table_one(_episodes(None)).columns
    assert "mais3f_mean" not in table_one(_episodes([math.nan] * 6)).columns  # a run written before it
    # a scenario whose rows lack values gets NaN, not a mean over the rows that have them
    table = table_one(_episodes([0.2, math.nan, 0.0, 0.0, 0.0, 0.1]))
    assert math.isnan(table.iloc[0]["mais3f_mean"]) and table.iloc[1]["mais3f_mean"] == pytest.approx(0.05)


MPH_TO_KMH = 1.609344


def full_risk(speed_kmh, hle_cm, age=42.42, male=0.59):
    return float(expit(mais3f_logit_full(speed_kmh, age, hle_cm, male)))


def test_the_full_row_at_the_sample_means_is_the_column():
    # HLE 85.25 cm and a male share of 0.59: the HLE, sex and interaction terms are 0.
    assert full_risk(40.0, 85.25, age=30.0) == pytest.approx(0.254630, abs=2e-6)


def test_the_full_row_reproduces_the_published_serious_injury_risks():
    # IIHS news release, 10 December 2024: "18% chance of a serious injury" at 20 mph (32.19 km/h);
    # at 27 mph (43.45 km/h) 30% for a median-height car, 62% for a median-height pickup whose front end
    # is 13 in (33.0 cm) higher. The release rounds to whole per cent and does not give the car's HLE:
    # 75 cm assumed, so the pickup is at 108 cm; age and sex at the sample means.
    # By hand, 20 mph: -0.460 + 0.091 * (32.18688 - 42.79) = -1.424884; P = 1 / (1 + e^1.424884) = 0.193897.
    # 27 mph, car: dv = 0.662288, dh = -10.25:
    #   -0.460 + 0.060268 - 0.39975 - 0.013577 = -0.813059; P = 0.307239.
    # 27 mph, pickup: dh = 22.77: -0.460 + 0.060268 + 0.88803 + 0.030161 = 0.518459; P = 0.626787.
    assert full_risk(20 * MPH_TO_KMH, 85.25) == pytest.approx(0.193897, abs=1e-6)
    assert full_risk(27 * MPH_TO_KMH, 75.0) == pytest.approx(0.307239, abs=1e-6)
    assert full_risk(27 * MPH_TO_KMH, 75.0 + 33.02) == pytest.approx(0.626787, abs=1e-5)
    for speed_mph, hle_cm, published in ((20, 85.25, 0.18), (27, 75.0, 0.30), (27, 108.02, 0.62)):
        assert full_risk(speed_mph * MPH_TO_KMH, hle_cm) == pytest.approx(published, abs=0.015)
