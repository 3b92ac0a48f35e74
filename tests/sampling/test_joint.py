"""The joint proposal (sampling/joint.py, --is-family joint): exact rejection sampling, weights, the toy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special, stats

from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.draws import Draws, draw_lognormal, draw_pedestrian_traits
from pedsafe_sumo.sampling.importance import Beta, Normal, is_estimate
from pedsafe_sumo.sampling.joint import JointProposal, fit_joint, normalised, proposal_of_json
from pedsafe_sumo.sampling.stages import DEFENSIVE_SHARE

PEDESTRIANS = load_params()["pedestrians"]
LOG_MU, LOG_SIGMA = 1.5853, 0.3827  # the intersection speed fit of defaults.toml
OFFSET = Beta(1.0, 1.0, -1.0, 1.5)
NOMINAL = {"ego_speed_log": Normal(LOG_MU, LOG_SIGMA), "conflict_offset_s": OFFSET}
#: The toy collision, a joint condition: the ego faster than 12 m/s AND the offset above 0.5 s. Nominal
#: probability (1 - Phi((ln 12 - mu) / sigma)) x (1.5 - 0.5) / 2.5.
TOY_SPEED_MPS, TOY_OFFSET_S = 12.0, 0.5
TOY_P = (1.0 - stats.norm.cdf((math.log(TOY_SPEED_MPS) - LOG_MU) / LOG_SIGMA)) * (1.5 - TOY_OFFSET_S) / 2.5
#: Features (sorted names: conflict_offset_s, ego_speed_log): 1, z_o, z_o^2, z_e, z_e^2, z_o z_e.
COEFFICIENTS = (-5.0, 1.0, 0.0, 2.0, 0.0, 0.5)


def _episode(rng: np.random.Generator, proposal) -> tuple[dict, float, bool]:
    draws = Draws(rng, proposal, DEFENSIVE_SHARE if proposal else 0.0)
    draw_pedestrian_traits(draws, PEDESTRIANS)
    speed = draw_lognormal(draws, "ego_speed_log", LOG_MU, LOG_SIGMA)
    offset = draws.uniform("conflict_offset_s", -1.0, 1.5)
    return draws.record(), draws.weight, bool(speed > TOY_SPEED_MPS and offset > TOY_OFFSET_S)


def test_rejection_draws_follow_q_and_the_weights_average_to_one():
    """20,000 episodes drawn through Draws under a fixed joint proposal: their mean weight is 1 within 4
    standard errors (E_q[p/q] = 1), and their mean ln speed matches E_q[x] = E_p[x q/p], computed here
    by a 2-D quadrature of the nominal density times q/p (an integral the sampler never sees)."""
    proposal = normalised(NOMINAL, COEFFICIENTS, DEFENSIVE_SHARE)
    rng = np.random.default_rng(5)
    rows = [_episode(rng, proposal) for _ in range(20_000)]
    w = np.array([r[1] for r in rows])
    assert abs(w.mean() - 1.0) < 4 * w.std() / math.sqrt(len(w)), w.mean()
    assert w.max() <= 1 / DEFENSIVE_SHARE + 1e-9
    # The weight recorded is 1 / (q/p) of the recorded inputs.
    rec = rows[0][0]
    x = {name: np.array([rec["inputs"][name]]) for name in NOMINAL}
    assert rows[0][1] == pytest.approx(1.0 / float(proposal.q_over_p(x)[0]))
    # E_q[ln speed] by quadrature over (offset, ln speed).
    e = np.linspace(LOG_MU - 7 * LOG_SIGMA, LOG_MU + 7 * LOG_SIGMA, 1401)
    o = np.linspace(-1.0, 1.5, 501)
    ee, oo = np.meshgrid(e, o)
    density = stats.norm.pdf(ee, LOG_MU, LOG_SIGMA) / 2.5
    ratio = proposal.q_over_p({"ego_speed_log": ee.ravel(), "conflict_offset_s": oo.ravel()}).reshape(
        ee.shape
    )
    mass = np.trapezoid(np.trapezoid(density * ratio, e, axis=1), o)
    mean_q = np.trapezoid(np.trapezoid(density * ratio * ee, e, axis=1), o) / mass
    assert mass == pytest.approx(1.0, abs=5e-3)  # c estimated on 10^6 nominal draws
    logs = np.array([r[0]["inputs"]["ego_speed_log"] for r in rows])
    assert abs(logs.mean() - mean_q) < 4 * logs.std() / math.sqrt(len(logs)), (logs.mean(), mean_q)
    assert mean_q > LOG_MU + 0.1  # the proposal does move the ego faster


def test_json_round_trip_gives_the_same_draws():
    proposal = normalised(NOMINAL, COEFFICIENTS, DEFENSIVE_SHARE)
    again = proposal_of_json(proposal.to_json())
    assert isinstance(again, JointProposal) and again == proposal
    a = [_episode(np.random.default_rng(s), proposal)[0] for s in range(20)]
    b = [_episode(np.random.default_rng(s), again)[0] for s in range(20)]
    assert a == b


def test_a_nominal_law_that_differs_from_the_proposal_is_refused():
    proposal = normalised({"ego_speed_log": Normal(LOG_MU + 0.1, LOG_SIGMA)}, (-3.0, 1.0, 0.0), 0.1)
    draws = Draws(np.random.default_rng(0), proposal)
    with pytest.raises(ValueError, match="nominal law differs"):
        draw_lognormal(draws, "ego_speed_log", LOG_MU, LOG_SIGMA)


@pytest.mark.parametrize("pilot_stages", [1, 2])
def test_pilots_then_joint_final_stage_recover_the_toy_probability(pilot_stages):
    """The joint toy event (P = 0.0038): pilot stages of 1,000 (the first nominal, the next from the
    joint proposal fitted on every pilot row so far), then 2,000 final draws: the interval holds the
    truth, the mean weight is within 4 of its standard errors of 1, and with 2 pilot stages the interval
    is narrower than plain MC's on as many draws, pilots included."""
    rng = np.random.default_rng(2026)
    proposal, pilots = None, []
    for _ in range(pilot_stages):
        pilots += [_episode(rng, proposal) for _ in range(1000)]
        inputs = {n: np.array([r[0]["inputs"][n] for r in pilots]) for n in NOMINAL}
        proposal = fit_joint(inputs, np.array([r[2] for r in pilots], dtype=float), NOMINAL, DEFENSIVE_SHARE)
        assert proposal is not None
    final = [_episode(rng, proposal) for _ in range(2000)]
    w = np.array([r[1] for r in final])
    f = np.array([r[2] for r in final], dtype=float)
    est = is_estimate(f, w)
    assert est.low <= TOY_P <= est.high, (est, TOY_P)
    assert abs(w.mean() - 1.0) < 4 * w.std() / math.sqrt(len(w))
    if pilot_stages == 2:
        n_total = 1000 * pilot_stages + 2000
        assert (est.high - est.low) / 2 < 1.96 * math.sqrt(TOY_P * (1 - TOY_P) / n_total)


def test_mean_pi_hat_is_the_nominal_mean_of_the_fitted_probability():
    """E_p[pi_hat] stored with the proposal (the control variate's known mean) against a 2-D quadrature of
    the nominal density times expit(features . coefficients), features written out here by hand."""
    proposal = normalised(NOMINAL, COEFFICIENTS, DEFENSIVE_SHARE)
    e = np.linspace(LOG_MU - 8 * LOG_SIGMA, LOG_MU + 8 * LOG_SIGMA, 1601)
    o = np.linspace(-1.0, 1.5, 501)
    ee, oo = np.meshgrid(e, o)
    z_e = (ee - LOG_MU) / LOG_SIGMA
    z_o = (oo - 0.25) / (2.5 / math.sqrt(12.0))  # the uniform's mean and sd
    b = COEFFICIENTS
    pi = special.expit(b[0] + b[1] * z_o + b[2] * z_o**2 + b[3] * z_e + b[4] * z_e**2 + b[5] * z_o * z_e)
    density = stats.norm.pdf(ee, LOG_MU, LOG_SIGMA) / 2.5
    expected = np.trapezoid(np.trapezoid(density * pi, e, axis=1), o)
    assert 0 < proposal.mean_pi_hat_se < 1e-2 * expected  # 10^6 draws
    assert abs(proposal.mean_pi_hat - expected) < 4 * proposal.mean_pi_hat_se, (
        proposal.mean_pi_hat,
        expected,
    )
    again = proposal_of_json(proposal.to_json())
    assert again.mean_pi_hat == proposal.mean_pi_hat and again.mean_pi_hat_se == proposal.mean_pi_hat_se
