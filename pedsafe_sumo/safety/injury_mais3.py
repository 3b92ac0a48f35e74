"""Risk of a serious or fatal injury (MAIS 3+ or death) of a pedestrian struck by the front of a vehicle.

The logistic model of Monfort & Mueller (2025), Table 4, MAIS 3+F row: the logit is linear in impact
speed, age, sex and the vehicle's hood leading-edge (HLE) height, each centred on its sample mean, with a
speed x HLE interaction. The episode log knows neither the pedestrian's sex nor the ego's HLE, so both are
held at the sample means, where their terms and the interaction vanish: the curve is that of the study's
average vehicle and sex mix, in impact speed and age alone.

Coefficients as transcribed from the article's Table 4 in the public code of
github.com/balmda/ped_fatality_risk (risk_calc.py, `_MUELLER_COEFS["mais3p"]`); not checked against the
article itself. With the hood-height and sex terms (`mais3f_logit_full`) they reproduce, within 1.5
points, the serious-injury risks of the Insurance Institute for Highway Safety's news release of 10
December 2024 on the study (18 % at 20 mph; 30 % for a median-height car and 62 % for a median-height
pickup at 27 mph): docs/safety_indexes.md, "Injury models".
"""

from __future__ import annotations

import numpy as np

#: Sample means the predictors are centred on (Monfort & Mueller 2025, Table 4).
MEAN_SPEED_KMH = 42.79
MEAN_AGE_YEARS = 42.42
#: MAIS 3+F coefficients (Table 4): intercept at the sample means, per km/h of impact speed, per year of age.
INTERCEPT = -0.460
PER_KMH = 0.091
PER_YEAR = 0.029
#: The terms the column holds at the sample means (Table 4): mean hood leading-edge height [cm] and
#: share of male pedestrians, and the coefficients per cm of HLE, for a male pedestrian, and per km/h x cm.
MEAN_HLE_CM = 85.25
MEAN_MALE_SHARE = 0.59
PER_HLE_CM = 0.039
MALE = -0.119
PER_KMH_PER_HLE_CM = 0.002


def mais3f_logit(speed_kmh: np.ndarray, age_years: np.ndarray) -> np.ndarray:
    """Logit of P(MAIS 3+ or fatal) at the sample-mean HLE height and sex share (their terms are 0)."""
    return INTERCEPT + PER_KMH * (speed_kmh - MEAN_SPEED_KMH) + PER_YEAR * (age_years - MEAN_AGE_YEARS)


def mais3f_logit_full(
    speed_kmh: np.ndarray, age_years: np.ndarray, hle_cm: np.ndarray, male: np.ndarray
) -> np.ndarray:
    """The whole MAIS 3+F row of Table 4: logit with the hood leading-edge height (cm) and sex (1 male,
    0 female; the sample's share 0.59 gives the mix). At hle_cm = MEAN_HLE_CM and male = MEAN_MALE_SHARE
    it is mais3f_logit. The column does not use it (the log has neither); it lets the transcription be
    checked against published risks for named vehicles."""
    dv = np.asarray(speed_kmh, dtype=float) - MEAN_SPEED_KMH
    dh = np.asarray(hle_cm, dtype=float) - MEAN_HLE_CM
    return (
        mais3f_logit(np.asarray(speed_kmh, dtype=float), np.asarray(age_years, dtype=float))
        + PER_HLE_CM * dh
        + MALE * (np.asarray(male, dtype=float) - MEAN_MALE_SHARE)
        + PER_KMH_PER_HLE_CM * dv * dh
    )
