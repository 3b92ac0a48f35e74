"""Importance sampling in a batch (`--sampler is`): the stages, the score, the cross-entropy update.

Per scenario the batch runs `pilot_stages` pilot stages of `pilot_episodes` pairs, then the final stage of
`--episodes` pairs, numbered on: stage s (0-based) holds episodes first_s .. first_s + n_s - 1, with
first_s = s * pilot_episodes, and the final stage is stage `pilot_stages`. Episode seeds follow the run's
seed rule on these numbers, so a stage's episodes are a function of (run seed, episode, proposal).

Stage 0 draws from the nominal (it is plain Monte Carlo, weight 1). After each pilot stage the proposal
for the next is refitted by the multilevel cross-entropy method (sampling.importance; Rubinstein &
Kroese 2004, algorithm 3.4.1) on the SV condition's rows of that stage: the elite are the episodes whose
score reaches the stage's level gamma_t = min(threshold, the (1 - ELITE_FRACTION) quantile of the
scores), and every proposed input's family is refitted by weighted maximum likelihood on the elite, with
the weights p/q of the stage. The final proposal is fixed and stored in run.json; resuming, any number
of workers and Dask then give the same rows. SV and V2I of an episode share its draw and its weight.

The score is continuous so that the levels can climb while collisions are still rare: a collision scores
COLLISION_SCORE + impact speed [m/s], any other episode minus its closest clearance between the ego's
body and the pedestrian's (-min_clearance_m, at most 0), and an episode without a clearance (they never
came near) scores NO_APPROACH_SCORE. The rare event is {score >= COLLISION_SCORE}: a collision.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from pedsafe_sumo.sampling.draws import family_from_json
from pedsafe_sumo.sampling.importance import (
    MIN_SPREAD_OF_NOMINAL,
    SMOOTHING_ALPHA,
    Beta,
    Categorical,
    Family,
    Normal,
    Product,
)

#: The score of a collision is this plus the impact speed; any miss scores at most 0 (module docstring).
COLLISION_SCORE = 1.0
#: Score of an episode whose clearance was never measured (the two never came near).
NO_APPROACH_SCORE = -1.0e3
#: Share of a stage's episodes kept as its elite (rho; de Boer et al. 2005 advise 0.01-0.1; 0.1 keeps
#: 20 elite episodes out of the default 200 pilot pairs, enough to refit about ten families).
ELITE_FRACTION = 0.1
#: Share of the nominal in the defensive mixture every proposed stage draws from (sampling/draws.py):
#: weights stay at most 1 / 0.1 = 10 whatever the fit; Hesterberg (1995) and Owen (2013, sec. 9.11)
#: suggest 0.1-0.2. Chosen before any batch ran, from the toy's infinite-variance weights, not tuned.
DEFENSIVE_SHARE = 0.1
#: Bounds of --is-defensive-share: below 0.01 the weights may reach 100; at 0.9 and above the proposal
#: barely matters.
MIN_DEFENSIVE_SHARE = 0.01
MAX_DEFENSIVE_SHARE = 0.9
#: Input screen (--is-inputs screened): an input enters the proposal once the elite of a pilot stage,
#: weighted by p/q, differs from its nominal law at this significance (Pearson's chi-square on the
#: elite's effective size, screen_inputs). 0.01 per input keeps the chance that one of the eleven
#: inputs that do not matter enters by chance at a stage near 10%; chosen before any batch ran.
SCREEN_P_VALUE = 0.01
#: Values of --is-inputs: "screened" proposes only the inputs the screen selects, "all" every input of
#: sampling.draws.PROPOSED_INPUTS the scenario draws (the cross-entropy method without a screen).
INPUTS_SCREENED = "screened"
INPUTS_ALL = "all"
INPUT_MODES = (INPUTS_SCREENED, INPUTS_ALL)
#: Values of --is-score, how a pilot episode without a collision is ranked: "clearance" by minus its closest
#: clearance [m], "ttc" by minus its smallest time to collision [s] (Hayward
#: 1972's surrogate). On the paper-v5 MC run's 10,000 SV crossing episodes the top 10% by clearance are 93%
#: yielding pedestrians with a slower ego (4.3 m/s; all: 5.2), who stop about 1 m from the car, while the
#: collisions are 63% unaware pedestrians and a fast ego (10.3 m/s): the clearance drives the proposal away
#: from collisions. The top 10% by TTC: ego 7.0 m/s, 53% unaware (docs/decisions/2026-11-23-is-score-ttc.md).
SCORE_CLEARANCE = "clearance"
SCORE_TTC = "ttc"
SCORES = (SCORE_CLEARANCE, SCORE_TTC)
#: Lower bound of --is-min-spread: a proposal 20 times narrower than the nominal gives weights up to the
#: defensive bound on nearly every draw.
MIN_SPREAD_FLAG = 0.05
#: Condition whose outcome the proposal is adapted to (the paired V2I episodes share the draws).
ADAPT_CONDITION = "sv"
#: Pilot settings: defaults and bounds of --is-pilot-stages and --is-pilot-episodes. Three stages of 200
#: pairs cost 600 pairs per scenario; at least 20 pairs so the elite (10%) holds 2 episodes.
DEFAULT_PILOT_STAGES = 3
MAX_PILOT_STAGES = 10
DEFAULT_PILOT_EPISODES = 200
MIN_PILOT_EPISODES = 20
MAX_PILOT_EPISODES = 100_000
#: Default of --is-pool-from: Table I pools the episodes of stages 2..final, each stage with its own
#: estimate (sampling/pooling.py). A stage's episodes add precision when its efficiency is above about half
#: the final stage's (the pooled variance sum n_t s_t^2 / N^2 is then below the final stage's alone).
#: Stage 0 is plain Monte Carlo and stage 1's proposal is fitted on one stage of 200 pairs; on ten-stage
#: runs of jaywalking and blending stage 1 is worth 1.7-6.1 per episode against the final's 4.8-12.3
#: with the control variate, and stage 2 5.7-10.3 (docs/decisions/2026-11-23-is-pooling-and-pilot-stages.md).
#: So from stage 2, fixed before any run that pools; a run of fewer pilot stages pools from its final stage.
DEFAULT_POOL_FROM_STAGE = 2


@dataclass(frozen=True)
class StageRange:
    stage: int
    first_episode: int
    n_episodes: int


def stage_layout(pilot_stages: int, pilot_episodes: int, final_episodes: int) -> list[StageRange]:
    """The episode ranges of the stages of one scenario (module docstring)."""
    stages = [StageRange(s, s * pilot_episodes, pilot_episodes) for s in range(pilot_stages)]
    return [*stages, StageRange(pilot_stages, pilot_stages * pilot_episodes, final_episodes)]


def episode_scores(rows: pd.DataFrame, score: str = SCORE_CLEARANCE) -> np.ndarray:
    """The cross-entropy score of each row (module docstring); `score` "ttc" scores a miss by minus its
    smallest time to collision (min_ttc_s) instead of its closest clearance (SCORES)."""
    if score not in SCORES:
        raise ValueError(f"score must be one of {SCORES}, got {score!r}")
    collision = rows["collision"].astype("boolean").fillna(False).to_numpy(dtype=bool)
    impact = rows["impact_speed_mps"].to_numpy(dtype=float)
    closeness = rows["min_clearance_m" if score == SCORE_CLEARANCE else "min_ttc_s"].to_numpy(dtype=float)
    miss = np.where(np.isfinite(closeness), -np.maximum(closeness, 0.0), NO_APPROACH_SCORE)
    hit = COLLISION_SCORE + np.where(np.isfinite(impact), np.maximum(impact, 0.0), 0.0)
    return np.where(collision, hit, miss)


def _inputs_and_nominal(rows: pd.DataFrame) -> tuple[dict[str, np.ndarray], Product]:
    """The proposed inputs of `rows` (name -> values) and their nominal families."""
    records = [json.loads(text) for text in rows["sampler_inputs"]]
    nominal_json: dict[str, Any] = {}
    for record in records:
        for name, family in record["nominal"].items():
            nominal_json.setdefault(name, family)
    names = sorted(name for name in nominal_json if all(name in r["inputs"] for r in records))
    inputs = {name: np.array([r["inputs"][name] for r in records], dtype=float) for name in names}
    return inputs, Product({name: family_from_json(nominal_json[name]) for name in names})


@dataclass(frozen=True)
class StageUpdate:
    proposal: Product
    level: float
    n_elite: int
    n_collisions: int
    #: Per proposed input, the screen's p-value on this stage's elite (screen_inputs); {} without a screen.
    screen: dict[str, float] = field(default_factory=dict)


def _effective_size(w: np.ndarray) -> float:
    return float(np.sum(w) ** 2 / np.sum(w**2)) if np.any(w > 0) else 0.0


def screen_p_value(nominal: Family, x: np.ndarray, w: np.ndarray) -> float:
    """How surely the elite's inputs `x` (weights `w` = p/q) come from a law other than `nominal`: the
    p-value of Pearson's chi-square statistic on the elite's effective size n_e = (sum w)^2 / sum w^2.

    Categorical: X^2 = n_e sum_k (phat_k - p_k)^2 / p_k with k - 1 degrees of freedom (phat the elite's
    weighted shares). Beta (the uniform draws): on the standardised input z = (x - mu) / sigma (mu, sigma
    the nominal's mean and sd), X^2 = n_e (zbar^2 + (mean z^2 - 1)^2 / (kappa - 1)) with 2 degrees of
    freedom (kappa the nominal's kurtosis, 1.8 for a uniform; zbar and z^2 are uncorrelated for a
    symmetric nominal, as every beta(1, 1) is). Normal: the exact laws of its mean and spread (below).
    Both catch an elite shifted (the ego fast) or narrowed (the pedestrian's timing near the ego's) away
    from the nominal. An elite of fewer than 2 effective draws selects nothing (p-value 1).
    """
    w = np.asarray(w, dtype=float)
    n_eff = _effective_size(w)
    if n_eff < 2.0:
        return 1.0
    x = np.asarray(x, dtype=float)
    if isinstance(nominal, Categorical):
        p = np.asarray(nominal.probabilities, dtype=float)
        p = p / p.sum()
        phat = np.bincount(x.astype(int), weights=w, minlength=len(p)) / np.sum(w)
        keep = p > 0
        statistic = n_eff * float(np.sum((phat[keep] - p[keep]) ** 2 / p[keep]))
        return float(stats.chi2.sf(statistic, max(int(keep.sum()) - 1, 1)))
    if isinstance(nominal, Normal):
        if nominal.sd <= 0:
            return 1.0
        # Exact laws for a normal sample (Cochran's theorem): n zbar^2 ~ chi2(1) and the sum of squares
        # about the mean ~ chi2(n - 1), independent; the spread's p-value two-sided; combined by Fisher's
        # method. (The moment statistic below selected 1.5-2% of unrelated normal inputs at p < 0.01 on
        # elites of 10-20, tests/sampling/test_stages.py.)
        z = (x - nominal.mean) / nominal.sd
        z_mean = float(np.sum(w * z) / np.sum(w))
        spread = n_eff * float(np.sum(w * (z - z_mean) ** 2) / np.sum(w))
        p_mean = float(stats.chi2.sf(n_eff * z_mean**2, 1))
        dof = n_eff - 1.0
        p_spread = min(1.0, 2.0 * min(float(stats.chi2.cdf(spread, dof)), float(stats.chi2.sf(spread, dof))))
        fisher = -2.0 * (math.log(max(p_mean, 1e-300)) + math.log(max(p_spread, 1e-300)))
        return float(stats.chi2.sf(fisher, 4))
    if isinstance(nominal, Beta):
        width = nominal.high - nominal.low
        mean_u, var_u, excess = stats.beta.stats(nominal.a, nominal.b, moments="mvk")
        mu, sigma, kurtosis = (
            nominal.low + width * float(mean_u),
            width * math.sqrt(float(var_u)),
            float(excess) + 3,
        )
    else:  # pragma: no cover - every family is one of the three
        raise TypeError(f"no screen for {type(nominal).__name__}")
    if sigma <= 0:
        return 1.0
    z = (x - mu) / sigma
    z_mean = float(np.sum(w * z) / np.sum(w))
    z2_mean = float(np.sum(w * z**2) / np.sum(w))
    statistic = n_eff * (z_mean**2 + (z2_mean - 1.0) ** 2 / (kurtosis - 1.0))
    return float(stats.chi2.sf(statistic, 2))


def cross_entropy_update(
    rows: pd.DataFrame,
    current: Mapping[str, Any],
    inputs_mode: str = INPUTS_ALL,
    min_spread: float = MIN_SPREAD_OF_NOMINAL,
    score: str = SCORE_CLEARANCE,
) -> StageUpdate:
    """The next stage's proposal from one finished stage's rows (both conditions; the SV ones are used).

    `current` holds the families the stage drew its proposed inputs from (empty at stage 0: nominal).
    Under `inputs_mode` "screened" the new proposal holds only the inputs already in `current` and those
    whose elite differs from the nominal at SCREEN_P_VALUE (screen_p_value); every other input stays
    nominal (drawn by its native call, weight factor 1). Under "all" every input is refitted. Every
    refitted family keeps at least `min_spread` times its nominal's spread (sampling.importance).
    """
    if inputs_mode not in INPUT_MODES:
        raise ValueError(f"inputs_mode must be one of {INPUT_MODES}, got {inputs_mode!r}")
    sv = rows[(rows["condition"] == ADAPT_CONDITION) & (rows["status"] == "ok")]
    sv = sv[sv["sampler_inputs"] != ""]
    if len(sv) < 2:
        raise ValueError(f"a pilot stage needs at least 2 finished {ADAPT_CONDITION} episodes, has {len(sv)}")
    inputs, nominal = _inputs_and_nominal(sv)
    scores = episode_scores(sv, score)
    weights = sv["weight"].to_numpy(dtype=float)
    level = min(COLLISION_SCORE, float(np.quantile(scores, 1.0 - ELITE_FRACTION)))
    elite = scores >= level
    proposal = Product({name: current.get(name, family) for name, family in nominal.families.items()})
    elite_inputs = {name: values[elite] for name, values in inputs.items()}
    refitted = proposal.refit(elite_inputs, weights[elite], SMOOTHING_ALPHA, nominal, min_spread)
    screen: dict[str, float] = {}
    if inputs_mode == INPUTS_SCREENED:
        screen = {
            name: screen_p_value(family, elite_inputs[name], weights[elite])
            for name, family in nominal.families.items()
        }
        chosen = {name for name, p_value in screen.items() if p_value < SCREEN_P_VALUE} | set(current)
        refitted = Product({name: f for name, f in refitted.families.items() if name in chosen})
    return StageUpdate(refitted, level, int(elite.sum()), int((scores >= COLLISION_SCORE).sum()), screen)


def finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None
