"""Random draws of the demand model: headways, vehicle speeds, pedestrian attributes.

Every function takes an explicit `numpy.random.Generator`; nothing here touches global random state, so one
seed gives one demand. Distributions follow the paper's eqs. 1-3 and section IV-A (docs/design.md,
'Sources of numbers'); the laws themselves (Lognormal, Exponential, and the walking-speed lognormal of each
age group with its worked arithmetic, lognormal_from_mean_p15) are in pedsafe_sumo/sampling/distributions.py,
which the episode draws share.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pedsafe_sumo.sampling.distributions import Exponential, Lognormal, age_group_speed_distributions


def poisson_departures_s(rng: np.random.Generator, rate_per_s: float, duration_s: float) -> np.ndarray:
    """Departure times in [0, duration_s) of a Poisson process: exponential headways of rate `rate_per_s`.

    Headways are drawn in blocks (expected count plus margin) so one call is a handful of vectorised draws.
    """
    times: list[np.ndarray] = []
    t_s = 0.0
    block = max(16, int(rate_per_s * duration_s * 1.2) + 16)
    while t_s < duration_s:
        arrivals = t_s + np.cumsum(rng.exponential(scale=1.0 / rate_per_s, size=block))
        times.append(arrivals)
        t_s = float(arrivals[-1])
    out = np.concatenate(times)
    return out[out < duration_s]


def traffic_distributions(traffic: dict[str, Any]) -> tuple[Exponential, Lognormal, Lognormal]:
    """(headway, non-intersection speed, intersection speed) distributions from the `[traffic]` section."""
    return (
        Exponential(traffic["headway_rate_per_s"]),
        Lognormal(traffic["speed_nonintersection_log_mu"], traffic["speed_nonintersection_log_sigma"]),
        Lognormal(traffic["speed_intersection_log_mu"], traffic["speed_intersection_log_sigma"]),
    )


@dataclass(frozen=True)
class PedestrianAttributes:
    """What is kept on every generated person (as SUMO <param>s) so results can be joined to it."""

    age_years: int
    age_group: str
    gender: str  # "f" or "m"
    risk: str  # "unaware", "hasten" or "yield"
    speed_mps: float  # free walking speed


def sample_pedestrians(
    rng: np.random.Generator, pedestrians: dict[str, Any], size: int
) -> list[PedestrianAttributes]:
    """`size` pedestrians drawn from the mixture: group by weight, age uniform in the group, gender, risk
    type, then the walking speed from the group's lognormal times the gender factor."""
    groups = list(pedestrians["age_groups"].items())
    weights = np.array([g["weight_share"] for _, g in groups], dtype=float)
    group_index = rng.choice(len(groups), size=size, p=weights / weights.sum())
    risk_types = ("unaware", "hasten", "yield")
    risk_p = np.array([pedestrians[f"risk_share_{r}"] for r in risk_types], dtype=float)
    risk_index = rng.choice(len(risk_types), size=size, p=risk_p / risk_p.sum())
    female = rng.random(size) < pedestrians["gender_female_share"]
    speed_dists = age_group_speed_distributions(pedestrians)
    out = []
    for i in range(size):
        name, group = groups[group_index[i]]
        age_years = int(rng.integers(int(group["age_min_years"]), int(group["age_max_years"]) + 1))
        gender = "f" if female[i] else "m"
        factor = pedestrians["speed_factor_female" if female[i] else "speed_factor_male"]
        speed_mps = float(speed_dists[name].sample(rng, 1)[0]) * factor
        out.append(PedestrianAttributes(age_years, name, gender, risk_types[risk_index[i]], speed_mps))
    return out
