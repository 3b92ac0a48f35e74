"""The interval of the mean injury P_I (mostly zeros): worked by hand, and its coverage by simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from pedsafe_sumo.safety.stats import zero_inflated_mean_interval

Z = 1.959964  # two-sided 95 % normal quantile


def closed_form_wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson 1927 by its closed form (not scipy), to check the implementation against."""
    p, denom = k / n, 1 + Z * Z / n
    centre = (p + Z * Z / (2 * n)) / denom
    half = Z * math.sqrt(p * (1 - p) / n + Z * Z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def test_all_zero_episodes_do_not_give_a_certain_zero():
    # 150 episodes, no injury: mean 0, interval (0, z^2 / (n + z^2)) = 3.841459 / 153.841459 = 0.0249702,
    # where a Student t interval gives [0, 0].
    mean, low, high = zero_inflated_mean_interval(np.zeros(150))
    assert (mean, low) == (0.0, 0.0)
    assert high == pytest.approx(3.841459 / 153.841459, abs=1e-6)


def test_one_injury_gives_the_wilson_bound_of_the_share():
    # k = 1 of 40: the spread of the positives is unknown, so (0, Wilson upper of 1/40) with m <= 1.
    values = np.zeros(40)
    values[7] = 0.35
    mean, low, high = zero_inflated_mean_interval(values)
    assert mean == pytest.approx(0.35 / 40)
    assert low == 0.0 and high == pytest.approx(closed_form_wilson(1, 40)[1], abs=1e-6)


def test_two_part_interval_by_hand():
    # n = 20, positives 0.2, 0.4, 0.6, 0.4: q = 0.2, m = 0.4, mean = 0.08.
    # Wilson(4, 20): 1 + z^2/20 = 1.192073; centre = (0.2 + 0.096036) / 1.192073 = 0.248338;
    #   half = z sqrt(0.008 + 0.002401) / 1.192073 = 1.959964 * 0.101985 / 1.192073 = 0.167680
    #   -> (0.080658, 0.416017)
    # t interval of the positives: sd = sqrt(0.08 / 3) = 0.163299, t(0.975, 3) = 3.182446,
    #   half = 3.182446 * 0.163299 / 2 = 0.259845 -> (0.140155, 0.659845)
    # MOVER on logs: down = hypot(ln(0.2/0.080658), ln(0.4/0.140155)) = hypot(0.908104, 1.048720) = 1.387251
    #   up = hypot(ln(0.416017/0.2), ln(0.659845/0.4)) = hypot(0.732410, 0.500541) = 0.887111
    #   low = 0.08 exp(-1.387251) = 0.019981, high = 0.08 exp(0.887111) = 0.194248
    values = np.zeros(20)
    values[[1, 5, 11, 19]] = [0.2, 0.4, 0.6, 0.4]
    mean, low, high = zero_inflated_mean_interval(values)
    assert mean == pytest.approx(0.08)
    assert closed_form_wilson(4, 20) == pytest.approx((0.080658, 0.416017), abs=2e-6)
    assert (low, high) == pytest.approx((0.019981, 0.194248), abs=2e-6)


def test_bad_values_are_refused():
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        zero_inflated_mean_interval([0.0, 1.2])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        zero_inflated_mean_interval([0.0, math.nan])
    assert all(math.isnan(v) for v in zero_inflated_mean_interval([]))


def student_t_interval(values: np.ndarray) -> tuple[float, float, float]:
    """The interval Table I used before (Student t, clipped at 0): the reference that under-covers."""
    n, mean = len(values), float(np.mean(values))
    half = stats.t.ppf(0.975, n - 1) * float(np.std(values, ddof=1)) / math.sqrt(n)
    return mean, max(0.0, mean - half), mean + half


def coverage(interval, n: int, share: float, seed: int, replications: int = 600) -> float:
    """Share of replications whose interval holds the true mean. Each replication: n episodes, each an
    injury with probability `share`, its P_I ~ Beta(2, 5) (mean 2/7, skewed like P_I at impact); so the
    true mean is share * 2/7 exactly."""
    rng = np.random.default_rng(seed)
    true_mean = share * 2.0 / 7.0
    hits = 0
    for _ in range(replications):
        values = np.where(rng.random(n) < share, rng.beta(2.0, 5.0, n), 0.0)
        _, low, high = interval(values)
        hits += low <= true_mean <= high
    return hits / replications


# 600 replications: the standard error of a coverage near 0.95 is 0.009; the tolerance is 3 of them.
TOLERANCE = 0.03


def test_coverage_with_few_injuries():
    # n = 2000 episodes, injury in 0.3 % of them: about 6 positive values, 99.8 % zeros.
    got = coverage(zero_inflated_mean_interval, 2000, 0.003, seed=12)
    assert abs(got - 0.95) <= TOLERANCE, got
    # The same simulation fails the Student t interval: it can tell a bad interval from a good one.
    student_t = coverage(student_t_interval, 2000, 0.003, seed=12)
    assert student_t < 0.95 - TOLERANCE, student_t


def test_coverage_with_many_injuries():
    # n = 1000, 15 % injured: about 150 positive values, where every method should be near 95 %.
    got = coverage(zero_inflated_mean_interval, 1000, 0.15, seed=13)
    assert abs(got - 0.95) <= TOLERANCE, got
