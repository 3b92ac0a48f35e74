"""The per-episode draws object (sampling/draws.py): nominal draws equal the bare Generator's calls;
under a proposal the weight is p/q and averages to 1 over the proposal."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from pedsafe_sumo.demand.sampling import sample_pedestrians, traffic_distributions
from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.draws import (
    Draws,
    draw_lognormal,
    draw_pedestrian_traits,
    product_from_json,
    product_to_json,
)
from pedsafe_sumo.sampling.importance import Beta, Categorical, Normal, Product

PARAMS = load_params()


def test_nominal_draws_repeat_the_demand_samplers_call_for_call():
    """No proposal: the pedestrian and the ego speed are those of sample_pedestrians and the lognormal fit
    drawn from the same Generator, and the Generator ends in the same state (the later draws match)."""
    _, _, intersection = traffic_distributions(PARAMS["traffic"])
    for seed in range(200):
        before = np.random.default_rng(seed)
        person = sample_pedestrians(before, PARAMS["pedestrians"], 1)[0]
        ego_before = float(intersection.sample(before, 1)[0])
        offset_before = float(before.uniform(-1.0, 1.5))

        draws = Draws(np.random.default_rng(seed))
        traits = draw_pedestrian_traits(draws, PARAMS["pedestrians"])
        ego = draw_lognormal(draws, "ego_speed_log", intersection.log_mu, intersection.log_sigma)
        offset = draws.uniform("conflict_offset_s", -1.0, 1.5)

        assert traits == {
            "age_years": person.age_years,
            "gender": person.gender,
            "risk": person.risk,
            "walking_speed_mps": person.speed_mps,
        }
        assert (ego, offset) == (ego_before, offset_before)
        assert draws.weight == 1.0
        # Recorded on the nominal families' scales.
        assert draws.inputs["ego_speed_log"] == pytest.approx(math.log(ego))
        assert draws.inputs["conflict_offset_s"] == offset
        assert 0 <= draws.inputs["ped_age_group"] < len(PARAMS["pedestrians"]["age_groups"])


def test_a_proposed_input_is_weighted_by_its_density_ratio():
    """Weight of one proposed draw = p(x)/q(x), by scipy's own densities; unproposed inputs weigh 1."""
    q = Normal(2.3, 0.2)
    draws = Draws(
        np.random.default_rng(5), {"ego_speed_log": q, "conflict_offset_s": Beta(3.0, 1.5, -1.0, 1.5)}
    )
    speed = draw_lognormal(draws, "ego_speed_log", 1.5853, 0.3827)
    offset = draws.uniform("conflict_offset_s", -1.0, 1.5)
    draws.index("clothing", 8)  # nominal: no factor
    x = math.log(speed)
    u = (offset + 1.0) / 2.5
    expected = (stats.norm.pdf(x, 1.5853, 0.3827) / stats.norm.pdf(x, 2.3, 0.2)) * (
        (1 / 2.5) / (stats.beta.pdf(u, 3.0, 1.5) / 2.5)
    )
    assert draws.weight == pytest.approx(expected, rel=1e-9)


def test_drawing_one_input_twice_is_refused():
    draws = Draws(np.random.default_rng(0))
    draws.uniform("gap_m", 0.0, 1.0)
    with pytest.raises(ValueError, match="drawn twice"):
        draws.uniform("gap_m", 0.0, 1.0)


PROPOSAL = {
    "ego_speed_log": Normal(1.9, 0.35),
    "ped_walking_speed_z": Normal(-0.5, 1.0),
    "ped_age_group": Categorical((0.1, 0.3, 0.3, 0.3)),
    "ped_risk": Categorical((0.6, 0.2, 0.2)),
    "conflict_offset_s": Beta(1.5, 2.0, -1.0, 1.5),
    "occluder_0.class": Categorical((0.3, 0.3, 0.4)),
}


def _episode_inputs(draws: Draws) -> float:
    """The draws of one crossing-like episode; returns its ego speed."""
    draw_pedestrian_traits(draws, PARAMS["pedestrians"])
    speed = draw_lognormal(draws, "ego_speed_log", 1.5853, 0.3827)
    draws.uniform("conflict_offset_s", -1.0, 1.5)
    draws.choice("occluder_0.class", np.array([0.55, 0.35, 0.10]))
    draws.index("clothing", 8)
    return speed


def test_weights_average_to_one_over_the_proposal():
    """E_q[p/q] = 1: the mean weight of 5,000 episodes drawn under a proposal that moves six inputs is 1
    within 4 standard errors, and the weighted share of ego speeds above 8 m/s recovers the nominal
    probability 1 - Phi((ln 8 - mu) / sigma) (a rare-ish event the proposal favours) within its interval."""
    rng = np.random.default_rng(17)
    n = 5_000
    weights, fast = np.empty(n), np.empty(n)
    for i in range(n):
        draws = Draws(rng, PROPOSAL)
        fast[i] = _episode_inputs(draws) > 8.0
        weights[i] = draws.weight
    se = weights.std(ddof=1) / math.sqrt(n)
    assert abs(weights.mean() - 1.0) < 4 * se, (weights.mean(), se)
    assert se < 0.05  # the test could fail: the proposal is not so far off that nothing can be said
    p_nominal = 1.0 - stats.norm.cdf((math.log(8.0) - 1.5853) / 0.3827)
    products = weights * fast
    half = 4 * products.std(ddof=1) / math.sqrt(n)
    assert abs(products.mean() - p_nominal) < half, (products.mean(), p_nominal, half)


def test_proposals_survive_json():
    product = Product(PROPOSAL)
    again = product_from_json(product_to_json(product))
    assert again.families == product.families
    assert product_from_json("").families == {}
