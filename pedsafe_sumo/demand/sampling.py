"""Random draws of the demand model: headways, vehicle speeds, pedestrian attributes.

Every function takes an explicit `numpy.random.Generator`; nothing here touches global random state, so one
seed gives one demand. Distributions follow the paper's eqs. 1-3 and section IV-A (docs/design.md,
'Sources of numbers').
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

#: Standard-normal quantile of the 85th percentile: the 15th percentile lies z_085 sigmas below the median.
Z_085 = float(stats.norm.ppf(0.85))  # 1.03643...


@dataclass(frozen=True)
class Lognormal:
    """ln(X) ~ Normal(log_mu, log_sigma); X in the unit of the caller (m/s for speeds)."""

    log_mu: float
    log_sigma: float

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        return rng.lognormal(mean=self.log_mu, sigma=self.log_sigma, size=size)

    def cdf(self, x: np.ndarray | float) -> np.ndarray:
        return stats.lognorm.cdf(x, s=self.log_sigma, scale=math.exp(self.log_mu))

    @property
    def median(self) -> float:
        return math.exp(self.log_mu)

    @property
    def mean(self) -> float:
        return math.exp(self.log_mu + self.log_sigma**2 / 2)


@dataclass(frozen=True)
class Exponential:
    """X ~ Exponential(rate); rate in 1/s for headways."""

    rate_per_s: float

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        return rng.exponential(scale=1.0 / self.rate_per_s, size=size)

    def cdf(self, x: np.ndarray | float) -> np.ndarray:
        return stats.expon.cdf(x, scale=1.0 / self.rate_per_s)


def lognormal_from_mean_p15(mean_mps: float, p15_mps: float) -> Lognormal:
    """The lognormal whose mean is `mean_mps` and whose 15th percentile is `p15_mps` (both m/s).

    Two conditions, two unknowns:
        mean:  mu + sigma^2 / 2 = ln(mean)
        p15:   mu - z sigma     = ln(p15),   z = Phi^-1(0.85) = 1.0364
    Subtracting: sigma^2 / 2 + z sigma - ln(mean / p15) = 0, whose positive root is
        sigma = -z + sqrt(z^2 + 2 ln(mean / p15)),   mu = ln(mean) - sigma^2 / 2.
    Worked values (Fitzpatrick et al. 2006 15th percentiles, paper means):
        19-30: mean 1.46, p15 1.15: ln(1.2696) = 0.2387, sigma = -1.0364 + sqrt(1.0742 + 0.4773) = 0.2092,
               mu = 0.3784 - 0.0219 = 0.3566 (median 1.428 m/s)
        31-60: mean 1.45, p15 1.15: sigma = 0.2036, mu = 0.3508
        > 60:  mean 1.03, p15 0.92: ln(1.1196) = 0.1129, sigma = -1.0364 + sqrt(1.0742 + 0.2259) = 0.1038,
               mu = 0.0296 - 0.0054 = 0.0242 (median 1.024 m/s)
    A lognormal rather than a normal (sigma = (mean - p15) / z = 0.299 m/s for 19-30) keeps every speed
    positive without truncation, and matches the right skew of observed walking speeds.
    """
    if not 0 < p15_mps < mean_mps:
        raise ValueError(f"need 0 < p15 < mean, got p15={p15_mps}, mean={mean_mps}")
    log_ratio = math.log(mean_mps / p15_mps)
    sigma = -Z_085 + math.sqrt(Z_085**2 + 2.0 * log_ratio)
    return Lognormal(log_mu=math.log(mean_mps) - sigma**2 / 2.0, log_sigma=sigma)


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


def age_group_speed_distributions(pedestrians: dict[str, Any]) -> dict[str, Lognormal]:
    """Walking-speed lognormal of every age group of the `[pedestrians]` section."""
    return {
        name: lognormal_from_mean_p15(group["speed_mean_mps"], group["speed_p15_mps"])
        for name, group in pedestrians["age_groups"].items()
    }


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
