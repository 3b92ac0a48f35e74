"""The batch's importance-sampling stages (sampling/stages.py) on episodes whose outcome is a known
function of their draws: the layout, the score, one cross-entropy update by hand, and the whole pilot +
final pipeline recovering a rare probability known in closed form."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.draws import Draws, draw_lognormal, draw_pedestrian_traits
from pedsafe_sumo.sampling.importance import SMOOTHING_ALPHA, is_estimate
from pedsafe_sumo.sampling.stages import (
    COLLISION_SCORE,
    DEFENSIVE_SHARE,
    ELITE_FRACTION,
    NO_APPROACH_SCORE,
    cross_entropy_update,
    episode_scores,
    stage_layout,
)

PEDESTRIANS = load_params()["pedestrians"]
LOG_MU, LOG_SIGMA = 1.5853, 0.3827  # the intersection speed fit of defaults.toml
#: The toy "collision": the ego faster than this [m/s]; nominal probability 1 - Phi((ln 14 - mu) / sigma).
TOY_SPEED_MPS = 14.0
TOY_P = 1.0 - stats.norm.cdf((math.log(TOY_SPEED_MPS) - LOG_MU) / LOG_SIGMA)


def test_stage_layout_numbers_the_pilots_then_the_final_stage():
    layout = stage_layout(3, 200, 1000)
    assert [(s.stage, s.first_episode, s.n_episodes) for s in layout] == [
        (0, 0, 200),
        (1, 200, 200),
        (2, 400, 200),
        (3, 600, 1000),
    ]


def test_score_orders_misses_below_collisions():
    rows = pd.DataFrame(
        {
            "collision": [True, False, False, True],
            "impact_speed_mps": [4.0, np.nan, np.nan, np.nan],
            "min_clearance_m": [0.0, 2.5, np.nan, 0.0],
        }
    )
    assert episode_scores(rows).tolist() == [5.0, -2.5, NO_APPROACH_SCORE, COLLISION_SCORE]


def _toy_rows(rng: np.random.Generator, proposal: dict, n: int) -> pd.DataFrame:
    """n SV rows drawn like draw_setup's first draws; collision iff the ego speed exceeds TOY_SPEED_MPS,
    the clearance the speed short of it (a continuous score that climbs towards the event)."""
    rows = []
    for _ in range(n):
        draws = Draws(rng, proposal, DEFENSIVE_SHARE if proposal else 0.0)
        draw_pedestrian_traits(draws, PEDESTRIANS)
        speed = draw_lognormal(draws, "ego_speed_log", LOG_MU, LOG_SIGMA)
        draws.uniform("conflict_offset_s", -1.0, 1.5)
        hit = speed > TOY_SPEED_MPS
        rows.append(
            {
                "condition": "sv",
                "status": "ok",
                "collision": hit,
                "impact_speed_mps": speed - TOY_SPEED_MPS if hit else np.nan,
                "min_clearance_m": 0.0 if hit else TOY_SPEED_MPS - speed,
                "weight": draws.weight,
                "sampler_inputs": json.dumps(draws.record()),
            }
        )
    return pd.DataFrame(rows)


def test_one_update_is_the_smoothed_weighted_fit_of_the_elite():
    """The new ego-speed family: mean = alpha * (elite mean of ln speed) + (1 - alpha) * nominal mean, the
    elite being the top 10% of the scores, recomputed here from the rows."""
    rows = _toy_rows(np.random.default_rng(3), {}, 300)
    update = cross_entropy_update(rows, {})
    scores = np.where(rows["collision"], 1.0 + rows["impact_speed_mps"].fillna(0), -rows["min_clearance_m"])
    level = min(1.0, float(np.quantile(scores, 1 - ELITE_FRACTION)))
    elite = scores >= level
    logs = np.array([json.loads(t)["inputs"]["ego_speed_log"] for t in rows["sampler_inputs"]])
    fitted_mean = logs[elite].mean()
    assert update.level == pytest.approx(level)
    assert update.n_elite == int(elite.sum())
    ego = update.proposal.families["ego_speed_log"]
    assert ego.mean == pytest.approx(SMOOTHING_ALPHA * fitted_mean + (1 - SMOOTHING_ALPHA) * LOG_MU)
    assert ego.mean > LOG_MU  # moved towards the fast speeds that come near the event
    # Inputs outside PROPOSED_INPUTS (age within the group, gender) get no proposal.
    assert "ped_female" not in update.proposal.families


@pytest.mark.parametrize("pilot_stages", [1, 3])
def test_pilots_then_final_stage_recover_a_rare_probability(pilot_stages):
    """P(ego speed > 14 m/s) = 0.0042 under the nominal; 1 or 3 pilot stages of 200 + 2,000 final draws
    give an estimate whose interval holds it; after 3 stages the interval is less than half as wide as
    plain MC's on as many draws, pilots included (1.96 sqrt(p(1-p)/n)): more than 4x fewer draws."""
    rng = np.random.default_rng(2026)
    current: dict = {}
    for _ in range(pilot_stages):
        current = dict(cross_entropy_update(_toy_rows(rng, current, 200), current).proposal.families)
    final = _toy_rows(rng, current, 2000)
    est = is_estimate(final["collision"].to_numpy(dtype=float), final["weight"].to_numpy(dtype=float))
    assert est.low <= TOY_P <= est.high, (est, TOY_P)
    n_total = 200 * pilot_stages + 2000
    mc_half = 1.96 * math.sqrt(TOY_P * (1 - TOY_P) / n_total)
    if pilot_stages == 3:  # the levels have reached the event: far narrower than MC on as many draws
        assert (est.high - est.low) / 2 < mc_half / 2
