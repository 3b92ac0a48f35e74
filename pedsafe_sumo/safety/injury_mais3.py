"""Risk of a serious or fatal injury (MAIS 3+ or death) of a pedestrian struck by the front of a vehicle.

The logistic model of Monfort & Mueller (2025), Table 4, MAIS 3+F row: the logit is linear in impact
speed, age, sex and the vehicle's hood leading-edge (HLE) height, each centred on its sample mean, with a
speed x HLE interaction. The episode log knows neither the pedestrian's sex nor the ego's HLE, so both are
held at the sample means, where their terms and the interaction vanish: the curve is that of the study's
average vehicle and sex mix, in impact speed and age alone.

Coefficients as transcribed from the article's Table 4 in the public code of
github.com/balmda/ped_fatality_risk (risk_calc.py, `_MUELLER_COEFS["mais3p"]`); not yet checked against the
article itself (docs/safety_indexes.md, "Injury models").
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


def mais3f_logit(speed_kmh: np.ndarray, age_years: np.ndarray) -> np.ndarray:
    """Logit of P(MAIS 3+ or fatal) at the sample-mean HLE height and sex share (their terms are 0)."""
    return INTERCEPT + PER_KMH * (speed_kmh - MEAN_SPEED_KMH) + PER_YEAR * (age_years - MEAN_AGE_YEARS)
