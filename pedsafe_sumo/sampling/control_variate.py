"""The control variate of a `--is-family joint` run: pi_hat, whose nominal mean is known.

The final stage of a joint run draws x from q ∝ p (lambda + (1 - lambda) sqrt(pi_hat) / c) and carries
pi_hat(x), a fitted P(SV collision | x) that can be evaluated at any x without SUMO, with its nominal mean
mu_g = E_p[pi_hat] estimated on 10^6 nominal draws and stored in the proposal (`mean_pi_hat`, with its
standard error `mean_pi_hat_se`). With Y_i = w_i f_i and C_i = w_i g_i - mu_g (g_i = pi_hat(x_i)),
E_q[C] = 0, and the regression estimator (Owen, Monte Carlo theory, methods and examples, 2013, chapter
8, control variates, and chapter 9 on control variates with importance sampling)

    mu_hat = mean(Y) - beta_hat mean(C),      beta_hat = cov(Y, C) / var(C),
    variance = s^2 / n + beta_hat^2 mean_pi_hat_se^2,
    s^2 = sum_i (Y_i - beta_hat C_i - mu_hat)^2 / (n - 2),

is consistent (its bias is O(1/n), from estimating beta) and its variance is never much above that of
mean(Y). s^2 is the regression's residual variance (two fitted coefficients, hence n - 2); the second term
is the known mean's own error, which the estimate carries through beta_hat mu_g.

SV and V2I share the draws and weights of an episode. V2I's control is pi_hat too, except where the
stage's proposal carries the V2I factor (sampling/joint.py): then it is the factor's model of V2I's
collision, pi_hat r, with its own stored nominal mean `mean_pi_v2i` (condition_control).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence

import numpy as np
from scipy import special

from pedsafe_sumo.sampling.importance import Estimate
from pedsafe_sumo.sampling.joint import V2I_CONDITION, JointProposal, is_joint_json

#: The label of Table I's `estimator` column for a row whose indexes use the control variate.
ESTIMATOR_CV = "is+cv"
ESTIMATOR_IS = "is"
#: Below this many final-stage rows the plain estimate stands: the regression's slope, fitted on a handful
#: of draws, extrapolates mean(C) to 0 on noise. Measured on the toy of tests/sampling/test_joint.py (a
#: joint proposal fitted on 2,000 nominal draws, 1,000 replicates per n; docs/sampling.md, "Control
#: variate"): variance over plain IS's, and the 95% interval's coverage (plain's): n = 3
#: 8.2x, 66% (96%); n = 10 1.25x, 80% (91%); n = 30 0.79x, 90% (92%); n = 100 0.77x, 93% (93%); n = 300
#: 0.72x, 95% (94%). 30 is also about where Cochran (Sampling Techniques, 1977, chapter 6) takes the
#: large-sample approximations of ratio estimators to hold.
MIN_ROWS = 30


def control_of(proposal_json: str) -> JointProposal | None:
    """The stage's joint proposal when it can serve as a control variate (joint, with a finite stored
    mean of pi_hat); None for the nominal, a product proposal, or a stored joint one without that mean."""
    if not proposal_json or not is_joint_json(proposal_json):
        return None
    proposal = JointProposal.from_json(proposal_json)
    if not (math.isfinite(proposal.mean_pi_hat) and math.isfinite(proposal.mean_pi_hat_se)):
        return None
    return proposal


def stage_control(proposals: Sequence[str] | None, stage: int) -> JointProposal | None:
    """The control of stage `stage` among a scenario's stored proposals (run.json's sampler_proposals:
    one JSON text per stage), None when there is none (control_of)."""
    if not proposals or not 0 <= stage < len(proposals):
        return None
    return control_of(proposals[stage])


def pi_hat_of_inputs(proposal: JointProposal, sampler_inputs: Sequence[str]) -> np.ndarray:
    """pi_hat at the inputs of each row (episodes.parquet's `sampler_inputs` JSON, key "inputs")."""
    records = [json.loads(text)["inputs"] for text in sampler_inputs]
    missing = sorted({name for name in proposal.names for r in records if name not in r})
    if missing:
        raise ValueError(f"rows of a joint stage lack the proposal's inputs {', '.join(missing)}")
    x = {name: np.array([r[name] for r in records], dtype=float) for name in proposal.names}
    return np.asarray(proposal.pi_hat(x), dtype=float)


def condition_control(
    proposal: JointProposal, sampler_inputs: Sequence[str], condition: str
) -> tuple[np.ndarray, float, float]:
    """The control of `condition`'s rows (their sampler_inputs) under a stage's joint proposal: (g at the
    rows, its nominal mean, that mean's standard error). pi_hat r for V2I where the proposal carries the
    V2I factor with a stored mean, else pi_hat."""
    if (
        condition == V2I_CONDITION
        and proposal.v2i_factor is not None
        and math.isfinite(proposal.mean_pi_v2i)
        and math.isfinite(proposal.mean_pi_v2i_se)
    ):
        records = [json.loads(text)["inputs"] for text in sampler_inputs]
        x = {name: np.array([r[name] for r in records], dtype=float) for name in proposal.names}
        return np.asarray(proposal.pi_v2i_hat(x), dtype=float), proposal.mean_pi_v2i, proposal.mean_pi_v2i_se
    return pi_hat_of_inputs(proposal, sampler_inputs), proposal.mean_pi_hat, proposal.mean_pi_hat_se


def cv_parts(
    values: np.ndarray,
    weights: np.ndarray,
    control: np.ndarray,
    control_mean: float,
    control_mean_se: float,
) -> tuple[float, float] | None:
    """The regression estimate of E_p[f] with the control g (module docstring) and its variance; None
    where the estimator does not apply and the plain estimate stands: fewer than MIN_ROWS rows, no draw
    with w f != 0 (then is_estimate's rule-of-three bound is the interval; the regression would give a
    zero-width one), or var(C) = 0."""
    f = np.asarray(values, dtype=float)
    w = np.asarray(weights, dtype=float)
    g = np.asarray(control, dtype=float)
    if not (f.shape == w.shape == g.shape):
        raise ValueError(f"values, weights and control differ in shape: {f.shape}, {w.shape}, {g.shape}")
    n = len(f)
    y = w * f
    c = w * g - control_mean
    # A constant C (var(C) = 0) is tested on the values: its centred sum of squares need not be exactly 0.
    if n < MIN_ROWS or not np.any(y != 0) or np.all(c == c[0]):
        return None
    c_centred = c - np.mean(c)
    var_c = float(np.sum(c_centred * c_centred))
    if not var_c > 0:
        return None
    beta = float(np.sum((y - np.mean(y)) * c_centred)) / var_c
    mean = float(np.mean(y) - beta * np.mean(c))
    residual = y - beta * c - mean
    variance = float(np.sum(residual * residual)) / (n - 2) / n + beta * beta * control_mean_se**2
    return mean, variance


def cv_estimate(
    values: np.ndarray,
    weights: np.ndarray,
    control: np.ndarray,
    control_mean: float,
    control_mean_se: float,
    confidence: float = 0.95,
) -> Estimate | None:
    """The regression estimate of E_p[f] with the control g (module docstring, cv_parts) and its normal
    interval; `ess` is the weights' (sum w)^2 / sum w^2, as in is_estimate. None where cv_parts is None."""
    parts = cv_parts(values, weights, control, control_mean, control_mean_se)
    if parts is None:
        return None
    mean, variance = parts
    w = np.asarray(weights, dtype=float)
    alpha = 1.0 - confidence
    half = float(special.ndtri(1.0 - alpha / 2)) * math.sqrt(variance)
    ess = float(np.sum(w) ** 2 / np.sum(w**2)) if np.any(w > 0) else 0.0
    return Estimate(mean, mean - half, mean + half, len(w), ess)
