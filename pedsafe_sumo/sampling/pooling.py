"""One estimate from several stages of an importance-sampling run (Table I's `--is-pool-from`).

Stage t of a run draws n_t episodes from a proposal q_t that was fixed from the stages before it, so its
own estimate m_t (the weighted mean (1/n_t) sum w_i f_i, or the control-variate estimate with its own
pi_hat) is unbiased given stages 0..t-1 (O(1/n_t) bias for the control variate, as for one stage). With
the stages' shares lambda_t = n_t / N fixed by the run's layout before any episode ran (pilot stages of
`--is-pilot-episodes` pairs, the final stage of `--episodes`),

    mu_hat = sum_t lambda_t m_t,        variance = sum_t lambda_t^2 v_t,

is unbiased by the tower rule, and the stage errors m_t - mu are martingale differences, uncorrelated, so
the variance adds (v_t the variance of m_t: s_t^2 / n_t for the weighted mean, the regression's for the
control variate). The interval is the normal one on that variance (the martingale central limit theorem,
Hall & Heyde, Martingale limit theory and its application, 1980), as for any fixed-weight combination of
adaptive importance-sampling stages.

Weights chosen from the stages' own estimated variances (inverse-variance weighting) are not used: under
importance sampling a stage's estimate and its estimated variance are positively correlated (both come
from the few heavy weights that hit the event), so such weights favour the stages that came out low, a
downward bias. Only the run's layout sets the shares.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import special

from pedsafe_sumo.sampling.control_variate import cv_estimate, cv_parts
from pedsafe_sumo.sampling.importance import Estimate, is_estimate, no_event_bound
from pedsafe_sumo.sampling.joint import is_joint_json

#: run.json's sampler key of the first stage Table I pools (absent: the final stage alone).
POOL_FROM_KEY = "estimate_from_stage"


def pooled_from_stage(pool_from: int | None, pilot_stages: int) -> int:
    """The first stage Table I pools: `pool_from` (--is-pool-from) capped at the final stage
    (`pilot_stages`); None (no --is-pool-from recorded) is the final stage alone."""
    return pilot_stages if pool_from is None else min(int(pool_from), int(pilot_stages))


def first_estimated_stage(run_info: dict[str, Any] | None) -> int | None:
    """The first stage Table I pools for the run whose run.json is `run_info`; None for the final stage
    alone (a run made before --is-pool-from, or with it at the final stage)."""
    sampler = (run_info or {}).get("sampler")
    if not isinstance(sampler, dict) or sampler.get(POOL_FROM_KEY) is None:
        return None
    return int(sampler[POOL_FROM_KEY])


def stage_max_weight(proposals: Sequence[str] | None, stage: int) -> float:
    """The bound on stage `stage`'s weights p/q from a scenario's stored proposals (run.json's
    sampler_proposals, one JSON text per stage): 1 for the nominal (an empty text), 1/lambda for a joint
    proposal of defensive share lambda (sampling/joint.py: p/q = 1 / (lambda + (1 - lambda) h / c)); NaN
    where it is not known (no proposals; a product proposal, whose share only run.json's sampler holds)."""
    if proposals is None or not 0 <= stage < len(proposals):
        return math.nan
    text = proposals[stage]
    if not text:
        return 1.0
    if not is_joint_json(text):
        return math.nan
    share = float(json.loads(text)["defensive_share"])
    return 1.0 / share if share > 0 else math.nan


@dataclass(frozen=True)
class StageRows:
    """One stage's rows of one index: values f, weights w, and where the stage drew from a joint
    proposal with a known E_p[pi_hat], pi_hat at each row's inputs (`control`) with that mean and its
    standard error; `control` None for a stage without one (the nominal, a product proposal)."""

    values: np.ndarray
    weights: np.ndarray
    control: np.ndarray | None = None
    control_mean: float = math.nan
    control_mean_se: float = math.nan
    #: A known bound on the stage's weights p/q (1 for the nominal, 1/lambda for a defensive mixture of
    #: share lambda): the bound with no event (importance.no_event_bound); NaN where unknown.
    max_weight: float = math.nan


@dataclass(frozen=True)
class PooledEstimate:
    """The pooled estimate, and how many of the stages used their control variate."""

    estimate: Estimate
    stages_with_control: int


def stage_mean_variance(stage: StageRows) -> tuple[float, float, bool]:
    """(m_t, v_t, whether the control variate was used) of one stage: the control-variate estimate where
    it applies (control_variate.cv_parts), else the weighted mean with s^2 / n (0 for a stage where no
    row has w f != 0: it adds nothing to the variance, and the pooled interval then rests on the others)."""
    f = np.asarray(stage.values, dtype=float)
    w = np.asarray(stage.weights, dtype=float)
    if stage.control is not None:
        g = np.asarray(stage.control, dtype=float)
        parts = cv_parts(f, w, g, stage.control_mean, stage.control_mean_se)
        if parts is not None:
            return parts[0], parts[1], True
    products = w * f
    variance = float(np.var(products, ddof=1)) / len(products) if np.any(products != 0) else 0.0
    return float(np.mean(products)), variance, False


def pooled_estimate(stages: Sequence[StageRows], confidence: float = 0.95) -> PooledEstimate:
    """sum_t lambda_t m_t with lambda_t = n_t / N over the stages given (module docstring), its normal
    interval, and the ESS of all their weights, (sum w)^2 / sum w^2.

    Stages with fewer than 2 rows are left out (no variance can be estimated from them; a stage is never
    planned that small, so only errors can make one). Where no row of any stage has w f != 0, the
    estimate is 0 and the upper end importance.no_event_bound over the stages, where each stage's weights
    have a known bound (`max_weight`); else is_estimate's on all the rows (the rule of three on their ESS).
    """
    used = [s for s in stages if len(np.asarray(s.values)) >= 2]
    values, weights = _joined(used or stages)
    if not used or not np.any(values * weights != 0):
        estimate = is_estimate(values, weights, confidence)
        samples = [(len(np.asarray(s.values)), s.max_weight) for s in used or stages]
        bound = no_event_bound(samples, confidence)
        if not np.any(values * weights != 0) and len(values) > 1 and math.isfinite(bound):
            estimate = dataclasses.replace(estimate, high=bound)
        return PooledEstimate(estimate, 0)
    if len(used) == 1:  # one stage: the one-stage estimators themselves, to the last bit
        return _one_stage(used[0], confidence)
    n_total = len(values)
    mean = variance = 0.0
    with_control = 0
    for stage in used:
        m, v, controlled = stage_mean_variance(stage)
        share = len(np.asarray(stage.values)) / n_total
        mean += share * m
        variance += share * share * v
        with_control += int(controlled)
    half = float(special.ndtri(0.5 + confidence / 2)) * math.sqrt(variance)
    ess = float(np.sum(weights) ** 2 / np.sum(weights**2)) if np.any(weights > 0) else 0.0
    return PooledEstimate(Estimate(mean, mean - half, mean + half, n_total, ess), with_control)


def _one_stage(stage: StageRows, confidence: float) -> PooledEstimate:
    """cv_estimate where the stage's control applies, else is_estimate."""
    if stage.control is not None:
        cv = cv_estimate(
            stage.values, stage.weights, stage.control, stage.control_mean, stage.control_mean_se, confidence
        )
        if cv is not None:
            return PooledEstimate(cv, 1)
    return PooledEstimate(is_estimate(stage.values, stage.weights, confidence, stage.max_weight), 0)


def _joined(stages: Sequence[StageRows]) -> tuple[np.ndarray, np.ndarray]:
    """All the stages' values and weights, each as one array."""
    if not stages:
        return np.array([]), np.array([])
    values = np.concatenate([np.asarray(s.values, dtype=float) for s in stages])
    weights = np.concatenate([np.asarray(s.weights, dtype=float) for s in stages])
    return values, weights
