"""The joint proposal (sampling/joint.py, --is-family joint): exact rejection sampling, weights, the toy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special, stats

from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.distributions import age_group_speed_distributions
from pedsafe_sumo.sampling.draws import Draws, draw_lognormal, draw_pedestrian_traits
from pedsafe_sumo.sampling.importance import Beta, Categorical, Normal, is_estimate
from pedsafe_sumo.sampling.joint import JointProposal, Kinematics, fit_logistic, normalised, proposal_of_json
from pedsafe_sumo.sampling.joint_fit import fit_joint, region_proposal
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


def _final_stage_holds(final: list, truth: float):
    """The final stage's estimate (rows of (record, weight, event, ...)): its interval holds `truth` and
    the weights average to 1 within 4 of their standard errors."""
    w = np.array([r[1] for r in final])
    est = is_estimate(np.array([r[2] for r in final], dtype=float), w)
    assert est.low <= truth <= est.high, (est, truth)
    assert abs(w.mean() - 1.0) < 4 * w.std() / math.sqrt(len(w))
    return est


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
    est = _final_stage_holds([_episode(rng, proposal) for _ in range(2000)], TOY_P)
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


# ---------------------------------------------------------------- kinematic features
GROUP_LAWS = list(age_group_speed_distributions(dict(PEDESTRIANS)).values())
GROUP_SHARES = np.array([g["weight_share"] for g in PEDESTRIANS["age_groups"].values()], dtype=float)
GROUP_SHARES = GROUP_SHARES / GROUP_SHARES.sum()
KIN_NOMINAL = {
    "ped_age_group": Categorical(tuple(float(v) for v in GROUP_SHARES)),
    "ped_walking_speed_z": Normal(0.0, 1.0),
    "ego_speed_log": Normal(LOG_MU, LOG_SIGMA),
    "conflict_offset_s": OFFSET,
}
SPEED_MIN_MPS, SPEED_MAX_MPS, REACTION_S, DECEL_MPS2 = 2.0, 20.0, 0.4, 6.0
KINEMATICS = Kinematics(
    SPEED_MIN_MPS,
    SPEED_MAX_MPS,
    tuple(law.log_mu for law in GROUP_LAWS),
    tuple(law.log_sigma for law in GROUP_LAWS),
    REACTION_S,
    DECEL_MPS2,
)
#: The toy event: no stop possible with a margin to spare, margin_s < -0.3 s.
MARGIN_EVENT_S = -0.3


def _margin_s(offset_s, ego_mps, walk_mps):
    v = np.clip(ego_mps, SPEED_MIN_MPS, SPEED_MAX_MPS)
    return offset_s + 2.3 / walk_mps - REACTION_S - v / (2 * DECEL_MPS2)


def _kinematic_episode(rng: np.random.Generator, proposal) -> tuple[dict, float, bool, tuple]:
    draws = Draws(rng, proposal, DEFENSIVE_SHARE if proposal else 0.0)
    traits = draw_pedestrian_traits(draws, PEDESTRIANS)
    speed = draw_lognormal(draws, "ego_speed_log", LOG_MU, LOG_SIGMA)
    offset = draws.uniform("conflict_offset_s", -1.0, 1.5)
    walk = traits["walking_speed_mps"]  # the sex factors are 1.0 in defaults.toml
    margin = float(_margin_s(offset, speed, walk))
    return (
        draws.record(),
        draws.weight,
        margin < MARGIN_EVENT_S,
        (min(max(speed, 2.0), 20.0), 1 / walk, margin),
    )


def _inputs(rows) -> dict[str, np.ndarray]:
    return {n: np.array([r[0]["inputs"][n] for r in rows]) for n in KIN_NOMINAL}


def test_kinematic_features_are_the_episode_speeds_and_margin():
    """Kinematics.raw of an episode's recorded inputs gives the ego speed, 1 / walking speed and margin the
    episode's own draws give (draw_pedestrian_traits, draw_lognormal), for 200 episodes."""
    rng = np.random.default_rng(11)
    rows = [_kinematic_episode(rng, None) for _ in range(200)]
    raw = KINEMATICS.raw(_inputs(rows))
    for k in range(3):
        assert np.allclose(raw[k], [r[3][k] for r in rows], rtol=1e-12, atol=1e-12)


def test_joint_proposal_with_kinematics_recovers_a_margin_event():
    """The toy event margin_s < -0.3 s, whose probability is computed here by 2 million vectorised nominal
    draws: one nominal pilot of 1,000, a joint proposal fitted with the kinematic features, 2,000 final
    draws through Draws: the interval holds the truth, the weights average to 1, the proposal round-trips
    through JSON, and the interval is narrower than plain MC's on as many draws, pilots included."""
    big = np.random.default_rng(99)
    n = 2_000_000
    group = big.choice(len(GROUP_LAWS), size=n, p=GROUP_SHARES)
    mu = np.array([law.log_mu for law in GROUP_LAWS])[group]
    sigma = np.array([law.log_sigma for law in GROUP_LAWS])[group]
    walk = np.exp(mu + sigma * big.standard_normal(n))
    ego = np.exp(LOG_MU + LOG_SIGMA * big.standard_normal(n))
    offset = big.uniform(-1.0, 1.5, n)
    truth = float(np.mean(_margin_s(offset, ego, walk) < MARGIN_EVENT_S))
    assert 0.005 < truth < 0.05  # a rare event, not a degenerate one

    rng = np.random.default_rng(2026)
    pilot = [_kinematic_episode(rng, None) for _ in range(1000)]
    y = np.array([r[2] for r in pilot], dtype=float)
    proposal = fit_joint(_inputs(pilot), y, KIN_NOMINAL, DEFENSIVE_SHARE, kinematics=KINEMATICS)
    assert proposal is not None and proposal.kinematics is not None and proposal.kinematics.moments
    assert proposal_of_json(proposal.to_json()) == proposal
    est = _final_stage_holds([_kinematic_episode(rng, proposal) for _ in range(2000)], truth)
    assert (est.high - est.low) / 2 < 1.96 * math.sqrt(truth * (1 - truth) / 3000)


def test_a_scenario_without_the_kinematic_inputs_fits_on_its_inputs_alone():
    y = np.zeros(50)
    y[:5] = 1
    rng = np.random.default_rng(3)
    inputs = {name: family.sample(rng, 50) for name, family in NOMINAL.items()}
    proposal = fit_joint(inputs, y, NOMINAL, DEFENSIVE_SHARE, kinematics=KINEMATICS)
    assert proposal is not None and proposal.kinematics is None


def test_the_guard_draws_where_the_braking_margin_is_negative():
    """region_proposal: pi_hat is a step at margin_s = 0 (margins by hand, _margin_s), and episodes drawn
    from it through Draws have margin_s < 0 in the share lambda P(margin < 0) + (1 - lambda), P by 10^6
    vectorised nominal draws; their weights average to 1."""
    proposal = region_proposal(KIN_NOMINAL, KINEMATICS, DEFENSIVE_SHARE)
    assert proposal is not None and proposal_of_json(proposal.to_json()) == proposal
    rng = np.random.default_rng(4)
    rows = [_kinematic_episode(rng, None) for _ in range(400)]
    margin = np.array([r[3][2] for r in rows])
    pi = proposal.pi_hat(_inputs(rows))
    assert np.all(pi[margin < -0.1] > 0.99) and np.all(pi[margin > 0.1] < 0.01)
    big = np.random.default_rng(5)
    n = 1_000_000
    group = big.choice(len(GROUP_LAWS), size=n, p=GROUP_SHARES)
    walk = np.exp(
        np.array([law.log_mu for law in GROUP_LAWS])[group]
        + np.array([law.log_sigma for law in GROUP_LAWS])[group] * big.standard_normal(n)
    )
    ego = np.exp(LOG_MU + LOG_SIGMA * big.standard_normal(n))
    p_negative = float(np.mean(_margin_s(big.uniform(-1.0, 1.5, n), ego, walk) < 0))
    drawn = [_kinematic_episode(rng, proposal) for _ in range(2000)]
    share = np.mean([r[3][2] < 0 for r in drawn])
    expected = DEFENSIVE_SHARE * p_negative + (1 - DEFENSIVE_SHARE)
    assert abs(share - expected) < 4 * math.sqrt(expected * (1 - expected) / 2000) + 0.01, (share, expected)
    w = np.array([r[1] for r in drawn])
    assert abs(w.mean() - 1.0) < 4 * w.std() / math.sqrt(len(w))
    assert region_proposal(NOMINAL, KINEMATICS, DEFENSIVE_SHARE) is None  # no kinematic inputs


def test_a_row_weight_of_k_fits_as_k_copies_of_the_row():
    """fit_logistic's row weights scale each row's log-likelihood: integer weights give the fit of the
    rows repeated that many times (an independent fit), and weights of 1 give the unweighted fit."""
    rng = np.random.default_rng(17)
    x = np.column_stack([np.ones(300), rng.normal(size=(300, 2))])
    y = (rng.random(300) < special.expit(x @ np.array([-1.0, 1.5, -0.5]))).astype(float)
    counts = rng.integers(1, 4, size=300)
    weighted = fit_logistic(x, y, 1.0, counts.astype(float))
    repeated = fit_logistic(np.repeat(x, counts, axis=0), np.repeat(y, counts), 1.0)
    np.testing.assert_allclose(weighted, repeated, atol=1e-4)
    np.testing.assert_array_equal(fit_logistic(x, y, 1.0, np.ones(300)), fit_logistic(x, y, 1.0))
    assert not np.allclose(weighted, fit_logistic(x, y, 1.0), atol=1e-3)
