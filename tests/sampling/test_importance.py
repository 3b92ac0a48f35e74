"""Importance sampling and the cross-entropy method on problems whose rare-event probability is known."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from pedsafe_sumo.sampling.importance import (
    Beta,
    Categorical,
    Normal,
    Product,
    cross_entropy,
    is_estimate,
    likelihood_ratio,
    no_event_bound,
)

GAMMA = 4.0
#: P(X > 4) for X ~ N(0, 1), from the normal survival function (not from the code under test).
TAIL = float(stats.norm.sf(GAMMA))
NOMINAL = Product({"x": Normal(0.0, 1.0)})


def _tail_event(inputs):
    return inputs["x"]


def _fixed_proposal_estimate(seed: int, n: int = 2000):
    proposal = Product({"x": Normal(GAMMA, 1.0)})
    rng = np.random.default_rng(seed)
    inputs = proposal.sample(rng, n)
    weights = likelihood_ratio(NOMINAL, proposal, inputs)
    return is_estimate((inputs["x"] > GAMMA).astype(float), weights), weights


def test_weight_of_a_hand_worked_draw():
    # p(4)/q(4) for p = N(0,1), q = N(4,1): exp(-8) / exp(0) = exp(-8).
    proposal = Product({"x": Normal(GAMMA, 1.0)})
    w = likelihood_ratio(NOMINAL, proposal, {"x": np.array([4.0, 0.0])})
    assert w[0] == pytest.approx(math.exp(-8.0))
    assert w[1] == pytest.approx(math.exp(8.0))


def test_fixed_proposal_recovers_the_gaussian_tail_within_its_interval():
    estimate, _ = _fixed_proposal_estimate(seed=11)
    assert estimate.low <= TAIL <= estimate.high
    # Plain Monte Carlo with 2000 draws would almost surely see no event at all (P = 0.94).
    assert estimate.high - estimate.low < TAIL


def test_interval_covers_the_tail_in_about_95_percent_of_replications():
    covered = [
        (lambda e: e.low <= TAIL <= e.high)(_fixed_proposal_estimate(seed, n=1000)[0]) for seed in range(300)
    ]
    # Binomial(300, 0.95) lies within [0.91, 0.98] with probability > 0.99.
    assert 0.91 <= np.mean(covered) <= 0.98


def test_weights_average_to_one_over_the_proposal():
    _, weights = _fixed_proposal_estimate(seed=5, n=200_000)
    # E_q[p/q] = 1; the standard error of the mean weight here is sqrt(e^16 - 1)/sqrt(n) ~ 6.7: use a
    # proposal with bounded weights instead for a tight check.
    wide = Product({"x": Normal(1.0, 1.5)})
    rng = np.random.default_rng(3)
    inputs = wide.sample(rng, 200_000)
    w = likelihood_ratio(NOMINAL, wide, inputs)
    assert np.mean(w) == pytest.approx(1.0, abs=0.01)
    assert np.isfinite(weights).all()


def test_cross_entropy_adapts_towards_the_tail_and_recovers_it():
    rng = np.random.default_rng(2026)
    adapted = cross_entropy(NOMINAL, _tail_event, GAMMA, rng, draws_per_stage=1000, elite_fraction=0.1)
    assert adapted.stages[-1].level == GAMMA
    assert 2 <= len(adapted.stages) <= 10
    # The optimal proposal is the nominal conditioned on X > 4, mean phi(4)/sf(4) = 4.2256.
    optimal_mean = stats.norm.pdf(GAMMA) / TAIL
    assert adapted.proposal.families["x"].mean == pytest.approx(optimal_mean, abs=0.15)
    inputs = adapted.proposal.sample(rng, 2000)
    weights = likelihood_ratio(NOMINAL, adapted.proposal, inputs)
    estimate = is_estimate((inputs["x"] > GAMMA).astype(float), weights)
    assert estimate.low <= TAIL <= estimate.high
    # Plain Monte Carlo would need about 4/(0.15^2 TAIL) = 5.6 million draws for this half-width.
    assert (estimate.high - estimate.low) / 2 < 0.15 * TAIL
    # The pilots are counted: the cost of the estimate is every draw made.
    assert adapted.pilot_draws == 1000 * len(adapted.stages)


def test_cross_entropy_over_mixed_families():
    # Event: X + 3 C >= 5 and U >= 0.5, X ~ N(0,1), C ~ Cat(0.9, 0.1), U ~ Uniform(0,1) = Beta(1,1).
    nominal = Product({"x": Normal(0.0, 1.0), "c": Categorical((0.9, 0.1)), "u": Beta(1.0, 1.0, 0.0, 1.0)})
    truth = 0.5 * (0.9 * stats.norm.sf(5.0) + 0.1 * stats.norm.sf(2.0))

    def score(inputs):
        return np.minimum(inputs["x"] + 3 * inputs["c"] - 5.0, 10.0 * (inputs["u"] - 0.5))

    rng = np.random.default_rng(7)
    adapted = cross_entropy(nominal, score, 0.0, rng, draws_per_stage=2000)
    assert adapted.proposal.families["c"].probabilities[1] > 0.5
    inputs = adapted.proposal.sample(rng, 4000)
    weights = likelihood_ratio(nominal, adapted.proposal, inputs)
    estimate = is_estimate((score(inputs) >= 0.0).astype(float), weights)
    assert estimate.low <= truth <= estimate.high
    assert estimate.ess < 4000


def test_plain_monte_carlo_with_no_event_gives_the_rule_of_three_bound():
    estimate = is_estimate(np.zeros(300))
    assert estimate.mean == 0.0 and estimate.low == 0.0
    assert estimate.high == pytest.approx(-math.log(0.025) / 300)
    assert estimate.ess == 300


def test_plain_monte_carlo_interval_is_the_normal_one():
    values = np.array([1.0] * 30 + [0.0] * 70)
    estimate = is_estimate(values)
    half = 1.959964 * math.sqrt(0.3 * 0.7 * 100 / 99) / 10
    assert estimate.mean == pytest.approx(0.3)
    assert estimate.low == pytest.approx(0.3 - half, rel=1e-5)
    assert estimate.high == pytest.approx(0.3 + half, rel=1e-5)


def test_no_event_with_a_known_weight_bound_worked_by_hand():
    # 2,000 draws whose weights never exceed 10 (a defensive share of 0.1): -ln(0.025) x 10 / 2,000.
    weights = np.r_[np.full(1000, 0.05), np.full(1000, 1.9)]
    estimate = is_estimate(np.zeros(2000), weights, max_weight=10.0)
    assert estimate.mean == 0.0 and estimate.low == 0.0
    assert estimate.high == pytest.approx(-math.log(0.025) * 10.0 / 2000)
    # stages of 200 nominal draws (bound 1) and 2,000 from a defensive mixture (bound 10): 200 + 200
    # equivalent nominal draws.
    assert no_event_bound([(200, 1.0), (2000, 10.0)]) == pytest.approx(-math.log(0.025) / 400)
    assert math.isnan(no_event_bound([(200, 1.0), (2000, math.nan)]))


def test_the_no_event_bound_covers_where_the_rule_of_three_on_the_ess_does_not():
    """An event that lies where the proposal has q/p at its defensive floor. p = U(0, 1); q/p = 0.1 on
    [0, 0.3) and (1 - 0.03) / 0.7 on [0.3, 1); the event is [0, 0.008), P = 0.008, and q draws it with
    probability 0.0008. E_p[p/q] = 3 + 0.7^2 / 0.97, so the ESS of 2,000 draws is about 570 and the
    rule of three on it, 3.69 / 570 = 0.0065, lies below P; no event in 2,000 draws happens with
    probability (1 - 0.0008)^2000 = 0.20, so that bound fails in about 20% of runs, not 2.5%. The bound
    on the weights (W = 10: 3.69 x 10 / 2,000 = 0.018) never does."""
    rng = np.random.default_rng(21)
    share, low_mass, rate, n, runs = 0.1, 0.3, 0.008, 2000, 2000
    high_ratio = (1 - share * low_mass) / (1 - low_mass)
    fails = {"ess": 0, "bound": 0}
    empty = 0
    for _ in range(runs):
        in_low = rng.random(n) < share * low_mass  # q's mass on [0, 0.3) is 0.03
        u = np.where(in_low, rng.random(n) * low_mass, low_mass + rng.random(n) * (1 - low_mass))
        weights = np.where(in_low, 1 / share, 1 / high_ratio)
        f = (u < rate).astype(float)
        if f.any():
            continue
        empty += 1
        ess = weights.sum() ** 2 / np.sum(weights**2)
        fails["ess"] += int(-math.log(0.025) / ess < rate)
        fails["bound"] += int(is_estimate(f, weights, max_weight=1 / share).high < rate)
    assert 0.15 < empty / runs < 0.25  # (1 - 0.0008)^2000 = 0.202
    assert fails["ess"] == empty  # every empty run's ESS bound lies below the truth
    assert fails["bound"] == 0
