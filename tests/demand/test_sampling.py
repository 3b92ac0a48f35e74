"""Samplers: draws follow the fitted distributions (KS at a fixed seed) and refit within their intervals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from pedsafe_sumo.demand.fit import fit_exponential, fit_lognormal
from pedsafe_sumo.demand.sampling import poisson_departures_s, sample_pedestrians, traffic_distributions
from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.distributions import Exponential, Lognormal, lognormal_from_mean_p15

SEED = 20240607
#: Intervals for the refit checks: 99.9% so that five checks at one seed fail by chance with ~0.5%
#: probability, while a bias of a few standard errors still fails.
CHECK_CONFIDENCE = 0.999


def test_speed_samples_pass_ks_and_refit_within_intervals():
    _, nonint, inter = traffic_distributions(load_params()["traffic"])
    rng = np.random.default_rng(SEED)
    for dist in (nonint, inter):
        x = dist.sample(rng, 5000)
        assert stats.kstest(x, dist.cdf).pvalue > 0.01
        fit = fit_lognormal(x, "mu", "sigma", "speed", confidence=CHECK_CONFIDENCE)
        mu, sigma = fit.estimates
        assert mu.ci_low <= dist.log_mu <= mu.ci_high
        assert sigma.ci_low <= dist.log_sigma <= sigma.ci_high


def test_poisson_departures_have_exponential_headways_at_the_rate():
    rng = np.random.default_rng(SEED)
    departs = poisson_departures_s(rng, 0.1742, 20000.0)
    assert departs.min() >= 0 and departs.max() < 20000.0 and np.all(np.diff(departs) > 0)
    headways = np.diff(departs)
    assert stats.kstest(headways, Exponential(0.1742).cdf).pvalue > 0.01
    (rate,) = fit_exponential(headways, confidence=CHECK_CONFIDENCE).estimates
    assert rate.ci_low <= 0.1742 <= rate.ci_high


def test_lognormal_from_mean_and_15th_percentile_matches_both():
    # 19-30: mean 1.46 m/s (paper), 15th percentile 1.15 m/s (Fitzpatrick et al. 2006).
    dist = lognormal_from_mean_p15(1.46, 1.15)
    assert dist.mean == pytest.approx(1.46, abs=1e-12)
    assert stats.lognorm.ppf(0.15, s=dist.log_sigma, scale=math.exp(dist.log_mu)) == pytest.approx(1.15)
    assert dist.log_sigma == pytest.approx(0.2092, abs=1e-4)  # the worked value in the docstring
    older = lognormal_from_mean_p15(1.03, 0.92)
    assert older.log_sigma == pytest.approx(0.1038, abs=1e-4)
    with pytest.raises(ValueError):
        lognormal_from_mean_p15(1.0, 1.2)


def test_pedestrian_mixture_follows_group_weights_and_speeds():
    peds = load_params()["pedestrians"]
    people = sample_pedestrians(np.random.default_rng(SEED), peds, 20000)
    groups = peds["age_groups"]
    for name, group in groups.items():
        members = [p for p in people if p.age_group == name]
        share = len(members) / len(people)
        assert share == pytest.approx(group["weight_share"], abs=0.015)
        ages = np.array([p.age_years for p in members])
        assert ages.min() >= group["age_min_years"] and ages.max() <= group["age_max_years"]
        speeds = np.array([p.speed_mps for p in members])
        assert speeds.mean() == pytest.approx(group["speed_mean_mps"], rel=0.02)
        assert np.quantile(speeds, 0.15) == pytest.approx(group["speed_p15_mps"], rel=0.03)
    assert {p.gender for p in people} == {"f", "m"}
    risk_share = {r: sum(p.risk == r for p in people) / len(people) for r in ("unaware", "hasten", "yield")}
    for risk, share in risk_share.items():
        assert share == pytest.approx(peds[f"risk_share_{risk}"], abs=0.015)


def test_same_generator_state_same_draws():
    a = Lognormal(1.8304, 0.4857).sample(np.random.default_rng(7), 10)
    b = Lognormal(1.8304, 0.4857).sample(np.random.default_rng(7), 10)
    c = Lognormal(1.8304, 0.4857).sample(np.random.default_rng(8), 10)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
