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
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.sampling.draws import family_from_json
from pedsafe_sumo.sampling.importance import SMOOTHING_ALPHA, Product

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
#: Condition whose outcome the proposal is adapted to (the paired V2I episodes share the draws).
ADAPT_CONDITION = "sv"
#: Pilot settings: defaults and bounds of --is-pilot-stages and --is-pilot-episodes. Three stages of 200
#: pairs cost 600 pairs per scenario; at least 20 pairs so the elite (10%) holds 2 episodes.
DEFAULT_PILOT_STAGES = 3
MAX_PILOT_STAGES = 10
DEFAULT_PILOT_EPISODES = 200
MIN_PILOT_EPISODES = 20
MAX_PILOT_EPISODES = 100_000


@dataclass(frozen=True)
class StageRange:
    stage: int
    first_episode: int
    n_episodes: int


def stage_layout(pilot_stages: int, pilot_episodes: int, final_episodes: int) -> list[StageRange]:
    """The episode ranges of the stages of one scenario (module docstring)."""
    stages = [StageRange(s, s * pilot_episodes, pilot_episodes) for s in range(pilot_stages)]
    return [*stages, StageRange(pilot_stages, pilot_stages * pilot_episodes, final_episodes)]


def episode_scores(rows: pd.DataFrame) -> np.ndarray:
    """The cross-entropy score of each row (module docstring)."""
    collision = rows["collision"].astype("boolean").fillna(False).to_numpy(dtype=bool)
    impact = rows["impact_speed_mps"].to_numpy(dtype=float)
    clearance = rows["min_clearance_m"].to_numpy(dtype=float)
    miss = np.where(np.isfinite(clearance), -np.maximum(clearance, 0.0), NO_APPROACH_SCORE)
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


def cross_entropy_update(rows: pd.DataFrame, current: Mapping[str, Any]) -> StageUpdate:
    """The next stage's proposal from one finished stage's rows (both conditions; the SV ones are used).

    `current` holds the families the stage drew its proposed inputs from (empty at stage 0: nominal).
    """
    sv = rows[(rows["condition"] == ADAPT_CONDITION) & (rows["status"] == "ok")]
    sv = sv[sv["sampler_inputs"] != ""]
    if len(sv) < 2:
        raise ValueError(f"a pilot stage needs at least 2 finished {ADAPT_CONDITION} episodes, has {len(sv)}")
    inputs, nominal = _inputs_and_nominal(sv)
    scores = episode_scores(sv)
    weights = sv["weight"].to_numpy(dtype=float)
    level = min(COLLISION_SCORE, float(np.quantile(scores, 1.0 - ELITE_FRACTION)))
    elite = scores >= level
    proposal = Product({name: current.get(name, family) for name, family in nominal.families.items()})
    elite_inputs = {name: values[elite] for name, values in inputs.items()}
    refitted = proposal.refit(elite_inputs, weights[elite], SMOOTHING_ALPHA, nominal)
    return StageUpdate(refitted, level, int(elite.sum()), int((scores >= COLLISION_SCORE).sum()))


def finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None
