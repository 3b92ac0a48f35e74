"""Pooling the stages of an adaptive importance-sampling run (sampling/pooling.py, Table I's
`--is-pool-from`): the formula worked by hand, one stage giving exactly the one-stage estimators, and, on a
Gaussian tail with each proposal adapted from the stages before it, a pooled estimate that is unbiased and
whose 95% interval covers the known probability."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from pedsafe_sumo.sampling.control_variate import cv_estimate
from pedsafe_sumo.sampling.importance import is_estimate
from pedsafe_sumo.sampling.pooling import (
    StageRows,
    first_estimated_stage,
    pooled_estimate,
    pooled_from_stage,
    stage_max_weight,
)

Z95 = 1.959963984540054


def test_two_stages_worked_by_hand():
    # stage a: products w f = [0.5, 0, 0, 0]: mean 1/8, sample variance 0.0625, its mean's 0.0625 / 4
    # stage b: products [0.2, 0.4, 0]: mean 0.2, sample variance 0.04, variance of the mean 0.04 / 3
    # shares 4/7 and 3/7: mean (4 x 0.125 + 3 x 0.2) / 7 = 1.1 / 7; variance (16 x 0.015625 + 9 x 0.04 / 3)
    # / 49 = 0.37 / 49
    a = StageRows(np.array([1.0, 0, 0, 0]), np.array([0.5, 1, 1, 1]))
    b = StageRows(np.array([1.0, 1, 0]), np.array([0.2, 0.4, 1]))
    pooled = pooled_estimate([a, b]).estimate
    assert pooled.mean == pytest.approx(1.1 / 7)
    assert pooled.high - pooled.mean == pytest.approx(Z95 * math.sqrt(0.37 / 49))
    assert pooled.mean - pooled.low == pytest.approx(Z95 * math.sqrt(0.37 / 49))
    assert pooled.n == 7
    # ESS of the seven weights: (sum w)^2 / sum w^2 = 5.1^2 / (0.25 + 3 + 0.04 + 0.16 + 1)
    assert pooled.ess == pytest.approx(5.1**2 / 4.45)


def test_a_stage_without_an_event_adds_its_episodes_and_no_variance():
    events = StageRows(np.array([1.0, 0, 1, 0]), np.array([0.5, 1, 0.5, 1]))
    none = StageRows(np.zeros(4), np.ones(4))
    pooled = pooled_estimate([events, none]).estimate
    # products [0.5, 0, 0.5, 0]: mean 0.25, sample variance 1/12; shares 1/2 each
    assert pooled.mean == pytest.approx(0.125)
    assert pooled.high - pooled.mean == pytest.approx(Z95 * math.sqrt(0.25 * (1 / 12) / 4))


def test_no_event_in_any_stage_gives_the_rule_of_three_bound_on_all_the_weights():
    stages = [StageRows(np.zeros(50), np.full(50, 0.5)), StageRows(np.zeros(30), np.full(30, 2.0))]
    pooled = pooled_estimate(stages).estimate
    weights = np.r_[np.full(50, 0.5), np.full(30, 2.0)]
    ess = weights.sum() ** 2 / np.sum(weights**2)
    assert pooled.mean == 0.0 and pooled.low == 0.0
    assert pooled.high == pytest.approx(-math.log(0.025) / ess)


def test_one_stage_is_the_one_stage_estimators():
    rng = np.random.default_rng(5)
    f = (rng.random(400) < 0.2).astype(float)
    w = rng.lognormal(0.0, 0.5, 400)
    g = np.clip(0.2 + 0.1 * rng.normal(size=400), 0, 1)
    plain = pooled_estimate([StageRows(f, w)]).estimate
    assert plain == is_estimate(f, w)
    controlled = pooled_estimate([StageRows(f, w, g, 0.21, 0.001)])
    assert controlled.stages_with_control == 1
    expected = cv_estimate(f, w, g, 0.21, 0.001)
    assert expected is not None
    assert controlled.estimate.mean == pytest.approx(expected.mean, rel=1e-12)
    assert controlled.estimate.high == pytest.approx(expected.high, rel=1e-12)
    assert controlled.estimate.low == pytest.approx(expected.low, rel=1e-12)


#: The toy: P(X > 3) for X ~ N(0, 1), whose value is known. Stage 0 draws from the nominal; each later stage
#: from N(mu, 1), mu the weighted mean of the previous stage's elite (the cross-entropy update of a normal's
#: mean: its top 10%, or the events once they are that many), so every proposal depends on the stages
#: before it, as in a batch run. The control is g(x) = Phi(2 (x - 3)), with E_p[g] = Phi(-6 / sqrt(5))
#: exactly (E[Phi(a X + b)] = Phi(b / sqrt(1 + a^2)) for X ~ N(0, 1)).
TAIL = 3.0
TRUTH = float(stats.norm.sf(TAIL))
CONTROL_MEAN = float(stats.norm.cdf(-2 * TAIL / math.sqrt(5)))


def adaptive_run(rng: np.random.Generator, n_stages: int, n_per_stage: int, control: bool) -> list[StageRows]:
    mu, stages = 0.0, []
    for _ in range(n_stages):
        x = rng.normal(mu, 1.0, n_per_stage)
        weights = np.exp(-mu * x + mu * mu / 2)  # N(0, 1) / N(mu, 1)
        values = (x > TAIL).astype(float)
        g = stats.norm.cdf(2 * (x - TAIL)) if control and mu != 0.0 else None
        stages.append(StageRows(values, weights, g, CONTROL_MEAN, 0.0))
        level = min(TAIL, float(np.quantile(x, 0.9)))
        elite = x >= level
        mu = float(np.sum(weights[elite] * x[elite]) / np.sum(weights[elite]))
    return stages


@pytest.mark.parametrize(("first", "control"), [(1, False), (2, False), (2, True), (3, True)])
def test_pooled_stages_of_an_adaptive_run_are_unbiased_and_cover(first, control):
    rng = np.random.default_rng(20261123 + first + 10 * control)
    replicates = 2000
    means, covered, final_var, pooled_var = [], 0, [], []
    for _ in range(replicates):
        stages = adaptive_run(rng, n_stages=5, n_per_stage=200, control=control)
        pooled = pooled_estimate(stages[first:]).estimate
        final = pooled_estimate(stages[-1:]).estimate
        means.append(pooled.mean)
        covered += pooled.low <= TRUTH <= pooled.high
        pooled_var.append(((pooled.high - pooled.mean) / Z95) ** 2)
        final_var.append(((final.high - final.mean) / Z95) ** 2)
    means = np.asarray(means)
    se = means.std(ddof=1) / math.sqrt(replicates)
    assert abs(means.mean() - TRUTH) < 3.5 * se, (means.mean(), TRUTH, se)
    # 95% nominal; 2,000 replicates give a binomial sd of 0.005, so 0.93-0.97 is a 4-sd band
    assert 0.93 <= covered / replicates <= 0.97, covered / replicates
    # and the pooled stages are worth more than the final stage alone (their variance is smaller)
    assert np.mean(pooled_var) < np.mean(final_var)


def test_the_first_stage_pooled_is_recorded_and_capped_at_the_final_stage():
    assert pooled_from_stage(2, 3) == 2
    assert pooled_from_stage(2, 1) == 1
    assert pooled_from_stage(None, 3) == 3
    assert first_estimated_stage({"sampler": {"kind": "is", "estimate_from_stage": 2}}) == 2
    assert first_estimated_stage({"sampler": {"kind": "is"}}) is None
    assert first_estimated_stage({"sampler": None}) is None
    assert first_estimated_stage(None) is None


def test_no_event_with_known_weight_bounds_gives_the_bound_on_equivalent_nominal_draws():
    # a nominal stage of 50 (bound 1) and a joint stage of 30 with defensive share 0.1 (bound 10):
    # -ln(0.025) / (50 + 3); the ESS stays that of all the weights.
    stages = [
        StageRows(np.zeros(50), np.ones(50), max_weight=1.0),
        StageRows(np.zeros(30), np.full(30, 2.0), max_weight=10.0),
    ]
    pooled = pooled_estimate(stages).estimate
    weights = np.r_[np.ones(50), np.full(30, 2.0)]
    assert pooled.mean == 0.0 and pooled.low == 0.0
    assert pooled.high == pytest.approx(-math.log(0.025) / 53)
    assert pooled.ess == pytest.approx(weights.sum() ** 2 / np.sum(weights**2))
    # one stage: is_estimate with its bound, -ln(0.025) x 10 / 30
    one = pooled_estimate([stages[1]]).estimate
    assert one.high == pytest.approx(-math.log(0.025) * 10 / 30)


def test_stage_max_weight_from_the_stored_proposals():
    from pedsafe_sumo.sampling.importance import Normal
    from pedsafe_sumo.sampling.joint import JointProposal

    joint = JointProposal({"x": Normal(0.0, 1.0)}, (0.0, 0.0, 0.0), 0.5, 0.25).to_json()
    proposals = ["", joint, '{"x": {"family": "normal", "mean": 1.0, "sd": 1.0}}']
    assert stage_max_weight(proposals, 0) == 1.0
    assert stage_max_weight(proposals, 1) == 4.0
    assert math.isnan(stage_max_weight(proposals, 2))  # a product proposal: its share is not stored in it
    assert math.isnan(stage_max_weight(None, 0))
    assert math.isnan(stage_max_weight(proposals, 3))
