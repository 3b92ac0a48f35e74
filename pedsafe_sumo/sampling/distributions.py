"""The nominal laws of the model's random inputs, shared by the demand generator and the episode draws.

Headways are exponential, speeds lognormal (paper eqs. 1-3 and section IV-A); each age group's walking
speed is the lognormal of its mean and 15th percentile. The demand generator (pedsafe_sumo.demand) draws
whole populations from them, the episode draws (sampling/draws.py) one pedestrian at a time.
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


def age_group_speed_distributions(pedestrians: dict[str, Any]) -> dict[str, Lognormal]:
    """Walking-speed lognormal of every age group of the `[pedestrians]` section."""
    return {
        name: lognormal_from_mean_p15(group["speed_mean_mps"], group["speed_p15_mps"])
        for name, group in pedestrians["age_groups"].items()
    }
