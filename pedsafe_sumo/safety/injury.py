"""Pedestrian injury models: a registry of named logistic curves in impact speed and age.

Every model takes the impact speed in m/s (the unit of the log) and converts it to km/h itself, the
unit in which the published curves were fitted. A plugin adds a model with `register_injury_model`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pedsafe_sumo.safety.geometry import FloatOrArray
from pedsafe_sumo.safety.injury_mais3 import mais3f_logit
from pedsafe_sumo.safety.logistic import expit

KMH_PER_MPS = 3.6  # [km/h per m/s]


@dataclass(frozen=True)
class InjuryModel:
    name: str
    #: what the probability is of, and where the curve comes from
    description: str
    #: logit of the probability from impact speed (km/h) and age (years)
    logit: Callable[[np.ndarray, np.ndarray], np.ndarray]

    def probability(self, impact_speed_mps: FloatOrArray, age_years: FloatOrArray) -> np.ndarray:
        speed_mps = np.asarray(impact_speed_mps, dtype=float)
        age = np.asarray(age_years, dtype=float)
        if np.any(speed_mps < 0):
            raise ValueError(f"impact speed must not be negative, got {impact_speed_mps} m/s")
        if np.any(age < 0):
            raise ValueError(f"age must not be negative, got {age_years} years")
        return expit(self.logit(speed_mps * KMH_PER_MPS, age))


INJURY_MODELS: dict[str, InjuryModel] = {}


def register_injury_model(model: InjuryModel, *, replace: bool = False) -> InjuryModel:
    """Add a model to the registry under its name (an existing name needs `replace=True`)."""
    if model.name in INJURY_MODELS and not replace:
        raise ValueError(f"injury model '{model.name}' is already registered")
    INJURY_MODELS[model.name] = model
    return model


register_injury_model(
    InjuryModel(
        "saade2020",
        "The paper's eq. 4 after Saade et al. 2020 (IRCOBI, pp. 278-289): "
        "P = sigmoid(-2.9893 + 0.0013 V^2 + 0.0286 A), V impact speed in km/h, A age in years.",
        lambda v_kmh, age: -2.9893 + 0.0013 * v_kmh**2 + 0.0286 * age,
    )
)
register_injury_model(
    InjuryModel(
        "rosen_sander2009",
        "Fatality risk of an adult pedestrian hit by the front of a car, with age, after Rosen & Sander "
        "2009 (Accid. Anal. Prev. 41(3):536-542): P = sigmoid(-9.1 + 0.095 v + 0.040 age), v in km/h "
        "(coefficients as in docs/design.md, 'Sources of numbers').",
        lambda v_kmh, age: -9.1 + 0.095 * v_kmh + 0.040 * age,
    )
)
register_injury_model(
    InjuryModel(
        "monfort_mueller2025_mais3f",
        "Risk of MAIS 3+ or fatal injury of a pedestrian struck by a vehicle's front, after Monfort & "
        "Mueller 2025, Table 4 (MAIS 3+F): P = sigmoid(-0.460 + 0.091 (v - 42.79) + 0.029 (age - 42.42)), "
        "v in km/h, hood leading-edge height and sex at the sample means (safety/injury_mais3.py).",
        mais3f_logit,
    )
)
#: The model of the column `injury_mais3f_probability` (Table I's second injury index).
SEVERE_INJURY_MODEL = "monfort_mueller2025_mais3f"


def get_injury_model(name: str) -> InjuryModel:
    try:
        return INJURY_MODELS[name]
    except KeyError:
        known = ", ".join(sorted(INJURY_MODELS))
        raise ValueError(f"unknown injury model '{name}'; known models: {known}") from None


def injury_probability(
    impact_speed_mps: FloatOrArray, age_years: FloatOrArray, model: str = "saade2020"
) -> FloatOrArray:
    """Probability of injury (as the named model defines it) for a pedestrian hit at the given speed.

    `impact_speed_mps` in m/s (converted to km/h inside), `age_years` in years; arrays broadcast.
    A float for scalar input, an array otherwise. This is the conditional probability given a collision;
    the paper's P_I for an episode is `collided * injury_probability(...)` (see `episode_injury`).
    """
    p = get_injury_model(model).probability(impact_speed_mps, age_years)
    return float(p) if p.ndim == 0 else p


def episode_injury(
    collided: bool, impact_speed_mps: float, age_years: float, model: str = "saade2020"
) -> float:
    """The paper's eq. 4 for one episode: P_I = p_collision * P(speed, age), with p_collision 0 or 1."""
    if not collided:
        get_injury_model(model)  # an unknown name is an error whether or not the episode collided
        return 0.0
    return float(injury_probability(impact_speed_mps, age_years, model))
