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
from pedsafe_sumo.sampling.importance import (
    SMOOTHING_ALPHA,
    SQRT_HALF,
    Beta,
    Categorical,
    Normal,
    is_estimate,
)
from pedsafe_sumo.sampling.stages import (
    COLLISION_SCORE,
    DEFENSIVE_SHARE,
    ELITE_FRACTION,
    INPUTS_ALL,
    INPUTS_SCREENED,
    NO_APPROACH_SCORE,
    SCREEN_P_VALUE,
    cross_entropy_update,
    episode_scores,
    screen_p_value,
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


def test_ttc_score_ranks_misses_by_their_time_to_collision():
    """--is-score ttc: a miss scores minus its smallest TTC [s], whatever its clearance: the pedestrian who
    stopped 0.5 m from a crawling car (TTC 4 s) ranks below the one the car passed 2 m away at speed
    (TTC 0.3 s); a collision still scores 1 + impact speed, no TTC at all the no-approach score."""
    rows = pd.DataFrame(
        {
            "collision": [False, False, True, False],
            "impact_speed_mps": [np.nan, np.nan, 3.0, np.nan],
            "min_clearance_m": [0.5, 2.0, 0.0, 4.0],
            "min_ttc_s": [4.0, 0.3, 0.0, np.nan],
        }
    )
    assert episode_scores(rows, "ttc").tolist() == [-4.0, -0.3, 4.0, NO_APPROACH_SCORE]
    assert episode_scores(rows).tolist() == [-0.5, -2.0, 4.0, -4.0]
    with pytest.raises(ValueError, match="score must be one of"):
        episode_scores(rows, "speed")


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


def test_once_collisions_fill_the_elite_the_level_is_the_event_and_every_collision_is_elite():
    """The multilevel rule (Rubinstein & Kroese 2004, alg. 3.4.1): the level never exceeds the event. A
    stage of 200 episodes with 40 collisions (20%, twice the elite share): the 90% quantile lies among
    the collisions' scores, the level is capped at COLLISION_SCORE, and the elite is all 40 collisions,
    not the 20 hardest impacts; the refit mean is the smoothed mean of the collided episodes' ln speeds."""
    rows = _toy_rows(np.random.default_rng(11), {}, 200)
    logs = np.array([json.loads(t)["inputs"]["ego_speed_log"] for t in rows["sampler_inputs"]])
    collided = logs >= np.sort(logs)[-40]  # the 40 fastest collide, their impact the speed above the cut
    rows["collision"] = collided
    rows["impact_speed_mps"] = np.where(collided, np.exp(logs) - np.exp(np.sort(logs)[-40]), np.nan)
    rows["min_clearance_m"] = np.where(collided, 0.0, 1.0)
    update = cross_entropy_update(rows, {})
    assert update.level == COLLISION_SCORE
    assert update.n_elite == update.n_collisions == 40
    ego = update.proposal.families["ego_speed_log"]
    expected = SMOOTHING_ALPHA * logs[collided].mean() + (1 - SMOOTHING_ALPHA) * LOG_MU
    assert ego.mean == pytest.approx(expected)


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


# ---------------------------------------------------------------- the input screen (--is-inputs screened)
@pytest.mark.parametrize(
    "nominal",
    [Normal(1.5853, 0.3827), Beta(1.0, 1.0, -1.0, 1.5), Categorical((0.2, 0.5, 0.3))],
    ids=["normal", "uniform", "categorical"],
)
def test_screen_selects_an_input_unrelated_to_the_event_about_one_time_in_a_hundred(nominal):
    """An 'elite' drawn from the nominal itself (the event does not depend on the input): the screen's
    p-value falls below SCREEN_P_VALUE = 0.01 in about 1% of 2,000 elites of 20; Binomial(2000, 0.01)
    stays within [8, 36] with probability > 0.999. Weighted elites (weights drawn at random, the
    statistic on their effective size) likewise. (A moment statistic for the normal failed this: 37.)"""
    rng = np.random.default_rng(11)
    for weighted in (False, True):
        hits = 0
        for _ in range(2000):
            x = nominal.sample(rng, 20)
            w = rng.uniform(0.5, 1.5, 20) if weighted else np.ones(20)
            hits += screen_p_value(nominal, x, w) < SCREEN_P_VALUE
        assert 8 <= hits <= 36, (weighted, hits)


def test_screen_p_value_worked_by_hand():
    # Normal(0, 1), elite [1, 2, 3] (w = 1, n_e = 3): n zbar^2 = 3 * 2^2 = 12, chi-square 1 df, p1 =
    # erfc(sqrt(12 / 2)); sum of squares about the mean = 2, chi-square 2 df: sf = exp(-1), two-sided
    # p2 = 2 exp(-1); Fisher's F = -2 ln(p1 p2), chi-square 4 df: sf(F) = exp(-F / 2) (1 + F / 2).
    p1, p2 = math.erfc(math.sqrt(6.0)), 2 * math.exp(-1.0)
    fisher = -2 * math.log(p1 * p2)
    p_value = screen_p_value(Normal(0.0, 1.0), np.array([1.0, 2.0, 3.0]), np.ones(3))
    assert p_value == pytest.approx(math.exp(-fisher / 2) * (1 + fisher / 2), rel=1e-9)
    # Uniform on [0, 1] (Beta(1, 1): mean 1/2, sd sqrt(1/12), kurtosis 1.8), elite [0.9, 0.9] (n_e = 2):
    # z = 0.4 sqrt(12), X^2 = 2 (z^2 + (z^2 - 1)^2 / 0.8), chi-square 2 df: sf = exp(-X^2 / 2).
    z2 = 0.16 * 12
    statistic = 2 * (z2 + (z2 - 1) ** 2 / 0.8)
    p_uniform = screen_p_value(Beta(1.0, 1.0, 0.0, 1.0), np.array([0.9, 0.9]), np.ones(2))
    assert p_uniform == pytest.approx(math.exp(-statistic / 2), rel=1e-9)
    # Categorical (0.5, 0.5), elite of 4 all in category 1, weights 1: X^2 = 4 (0.25 / 0.5 * 2) = 4, 1 df.
    p_cat = screen_p_value(Categorical((0.5, 0.5)), np.array([1.0, 1.0, 1.0, 1.0]), np.ones(4))
    assert p_cat == pytest.approx(math.erfc(math.sqrt(4.0 / 2)))  # chi-square 1 df: sf(x) = erfc(sqrt(x/2))
    # Fewer than 2 effective draws select nothing.
    assert screen_p_value(Normal(0.0, 1.0), np.array([9.0, 9.0]), np.array([1.0, 1e-9])) == 1.0


def test_screened_update_proposes_only_the_input_the_event_depends_on():
    """The toy's collision depends on the ego speed alone: the screened update proposes ego_speed_log and
    leaves the pedestrian's traits and the conflict offset nominal; 'all' refits every input."""
    rows = _toy_rows(np.random.default_rng(3), {}, 300)
    screened = cross_entropy_update(rows, {}, INPUTS_SCREENED)
    assert set(screened.proposal.families) == {"ego_speed_log"}
    assert screened.screen["ego_speed_log"] < 1e-6
    assert set(screened.screen) == set(cross_entropy_update(rows, {}, INPUTS_ALL).proposal.families)
    # An input once proposed stays proposed (the stage drew it from its proposal).
    again = cross_entropy_update(_toy_rows(np.random.default_rng(4), {}, 300), screened.proposal.families)
    assert "ego_speed_log" in again.proposal.families


@pytest.mark.slow
def test_screen_and_spread_floor_make_the_toy_estimate_efficient():
    """3 pilot stages of 200 + 2,000 final draws, spread floor sqrt(1/2), screened inputs: the interval
    holds the toy's probability and is as wide as plain MC's on at least 20 times as many draws (measured
    106-114x on six seeds, docs/sampling.md; the floor of 0.2 gave 0.1x-190x)."""
    rng = np.random.default_rng(2026)
    current: dict = {}
    for _ in range(3):
        update = cross_entropy_update(_toy_rows(rng, current, 200), current, INPUTS_SCREENED, SQRT_HALF)
        current = dict(update.proposal.families)
    assert set(current) == {"ego_speed_log"} and current["ego_speed_log"].sd >= SQRT_HALF * LOG_SIGMA
    final = _toy_rows(rng, current, 2000)
    est = is_estimate(final["collision"].to_numpy(dtype=float), final["weight"].to_numpy(dtype=float))
    assert est.low <= TOY_P <= est.high, (est, TOY_P)
    half = (est.high - est.low) / 2
    mc_draws_needed = TOY_P * (1 - TOY_P) * (1.959964 / half) ** 2
    assert mc_draws_needed / (3 * 200 + 2000) > 20
