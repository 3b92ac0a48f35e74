"""The V2I factor of the joint proposal (sampling/v2i_factor.py): the contrast table against CIELAB
worked out here, h and the weights by hand, exact sampling through Draws, the fit of r, V2I's control."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import special, stats

from pedsafe_sumo.sampling.control_variate import condition_control
from pedsafe_sumo.sampling.draws import Draws, draw_lognormal
from pedsafe_sumo.sampling.importance import Beta, Categorical, Normal
from pedsafe_sumo.sampling.joint import GUARD_MIN_COLLISIONS, ContrastFactor, JointProposal, normalised
from pedsafe_sumo.sampling.joint_fit import joint_update
from pedsafe_sumo.sampling.stages import DEFENSIVE_SHARE
from pedsafe_sumo.sampling.v2i_factor import (
    low_contrast_table,
    v2i_only_count,
    v2i_only_engages,
    with_v2i_factor,
)
from pedsafe_sumo.scenarios.road_users import CAR_COLOURS_RGB, CLOTHING_COLOURS_RGB

LOG_MU, LOG_SIGMA = 1.5853, 0.3827
NOMINAL = {"ego_speed_log": Normal(LOG_MU, LOG_SIGMA), "conflict_offset_s": Beta(1.0, 1.0, -1.0, 1.5)}
#: pi_hat's features (sorted: conflict_offset_s, ego_speed_log): 1, z_o, z_o^2, z_e, z_e^2, z_o z_e.
COEFFICIENTS = (-5.0, 1.0, 0.0, 2.0, 0.0, 0.5)
#: The toy: SV collides when the ego is faster than 9 m/s and the offset above 0.5 s; V2I too when, on
#: top, the clothing is within the contrast threshold of the car's colour (the table L of the palettes).
TOY_SV_P = (1.0 - stats.norm.cdf((math.log(9.0) - LOG_MU) / LOG_SIGMA)) * (1.5 - 0.5) / 2.5
CAR = "occluder_1.colour"


def _lab(rgb: tuple[int, int, int]) -> np.ndarray:
    """sRGB 0-255 -> CIELAB (D65), the textbook formulas (IEC 61966-2-1, CIE 15), not OpenCV's."""
    c = np.asarray(rgb, dtype=float) / 255.0
    c = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    m = np.array(
        [
            [0.4124564, 0.3575761, 0.1804375],
            [0.2126729, 0.7151522, 0.0721750],
            [0.0193339, 0.1191920, 0.9503041],
        ]
    )
    xyz = m @ c / np.array([0.950456, 1.0, 1.088754])
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16 / 116)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def test_the_contrast_table_of_the_scenarios_palettes_against_cielab_by_hand() -> None:
    table = low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 15.0)
    for i, clothing in enumerate(CLOTHING_COLOURS_RGB):
        for j, car in enumerate(CAR_COLOURS_RGB):
            delta_e = float(np.linalg.norm(_lab(clothing) - _lab(car)))
            assert abs(delta_e - 15.0) > 1.0  # no pair so near the threshold that the two ways could differ
            assert table[i][j] == int(delta_e < 15.0), (clothing, car, delta_e)
    # Red on the red car, blue on the blue one, white on white, black on black: four of the 36.
    ones = {(i, j) for i in range(6) for j in range(6) if table[i][j]}
    assert ones == {(0, 4), (1, 5), (4, 0), (5, 1)}
    assert low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 0.0) == ((0,) * 6,) * 6


def _factor(coefficients: tuple[float, float] = (-3.0, 4.0)) -> ContrastFactor:
    return ContrastFactor(
        (CAR,), low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 15.0), coefficients
    )


def _proposal(coefficients: tuple[float, float] = (-3.0, 4.0)) -> JointProposal:
    factor = _factor(coefficients)
    return normalised({**NOMINAL, **factor.nominal()}, COEFFICIENTS, DEFENSIVE_SHARE, None, factor)


def test_h_the_share_and_the_means_by_hand() -> None:
    proposal = _proposal()
    factor = proposal.v2i_factor
    assert factor is not None
    x = {"ego_speed_log": np.array([2.6, 1.2]), "conflict_offset_s": np.array([1.0, 0.0])}
    x |= {"clothing": np.array([0.0, 2.0]), CAR: np.array([4.0, 4.0])}  # red on red (low), green on red
    z_o = (x["conflict_offset_s"] - 0.25) / (2.5 / math.sqrt(12))
    z_e = (x["ego_speed_log"] - LOG_MU) / LOG_SIGMA
    pi = special.expit(-5.0 + z_o + 2.0 * z_e + 0.5 * z_o * z_e)
    r = special.expit(np.array([-3.0 + 4.0, -3.0]))
    a = factor.target_share
    assert proposal.pi_hat(x) == pytest.approx(pi)
    assert proposal.pi_v2i_hat(x) == pytest.approx(pi * r)
    assert proposal.root_pi(x) == pytest.approx(np.sqrt(pi * (a + (1 - a) * r)))
    assert proposal.q_over_p(x) == pytest.approx(
        DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * np.sqrt(pi * (a + (1 - a) * r)) / proposal.norm
    )
    # The nominal means by fresh draws (another seed): E_p[pi r] = E_p[pi] E_p[r], x and z independent,
    # E_p[r] = (4 expit(1) + 32 expit(-3)) / 36 (four low-contrast pairs of 36).
    rng = np.random.default_rng(8)
    draws = {name: family.sample(rng, 400_000) for name, family in NOMINAL.items()}
    mean_sv = float(np.mean(proposal.pi_hat(draws)))
    mean_r = (4 * special.expit(1.0) + 32 * special.expit(-3.0)) / 36
    assert proposal.mean_pi_hat == pytest.approx(mean_sv, rel=0.02)
    assert proposal.mean_pi_v2i == pytest.approx(mean_sv * mean_r, rel=0.02)
    assert a == pytest.approx(proposal.mean_pi_v2i**2 / (proposal.mean_pi_hat**2 + proposal.mean_pi_v2i**2))


def _episode(rng: np.random.Generator, proposal) -> tuple[dict, float, bool, bool]:
    """The toy episode through Draws: the factor's inputs drawn by name as the scenarios draw them."""
    draws = Draws(rng, proposal, DEFENSIVE_SHARE if proposal else 0.0)
    speed = draw_lognormal(draws, "ego_speed_log", LOG_MU, LOG_SIGMA)
    offset = draws.uniform("conflict_offset_s", -1.0, 1.5)
    clothing = draws.index("clothing", len(CLOTHING_COLOURS_RGB))
    car = draws.index(CAR, len(CAR_COLOURS_RGB))
    sv = bool(speed > 9.0 and offset > 0.5)
    low = low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 15.0)[clothing][car]
    return draws.record(), draws.weight, sv, bool(sv and low)


def test_draws_from_the_factor_proposal_are_exact_and_tilted_towards_low_contrast() -> None:
    """20,000 episodes through Draws: the mean weight is 1 (E_q[p/q] = 1), the weighted share of low
    contrast is its nominal 4/36, while the drawn share is above it (the proposal aims at V2I)."""
    proposal = _proposal()
    rng = np.random.default_rng(5)
    rows = [_episode(rng, proposal) for _ in range(20_000)]
    w = np.array([row[1] for row in rows])
    table = low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 15.0)
    low = np.array([table[int(r[0]["inputs"]["clothing"])][int(r[0]["inputs"][CAR])] for r in rows], float)
    se = w.std() / math.sqrt(len(w))
    assert abs(w.mean() - 1.0) < 4 * se
    assert abs(np.mean(w * low) - 4 / 36) < 4 * np.std(w * low) / math.sqrt(len(w))
    assert low.mean() > 4 / 36 + 4 * math.sqrt(4 / 36 * 32 / 36 / len(w))
    # The recorded weight is 1 / (q/p) of the recorded inputs, the factor's included.
    record = rows[0][0]
    x = {name: np.array([record["inputs"][name]]) for name in proposal.names}
    assert rows[0][1] == pytest.approx(1.0 / float(proposal.q_over_p(x)[0]))


def _rows(episodes: list[tuple[dict, float, bool, bool]], stage: int) -> pd.DataFrame:
    """Rows of both conditions as episodes.parquet holds them."""
    out = []
    for k, (record, weight, sv, v2i) in enumerate(episodes):
        text = json.dumps(record, sort_keys=True)
        for condition, hit in (("sv", sv), ("v2i", v2i)):
            out.append(
                {
                    "episode": stage * 100_000 + k,
                    "condition": condition,
                    "status": "ok",
                    "collision": hit,
                    "weight": weight,
                    "sampler_inputs": text,
                    "sampler_stage": stage,
                }
            )
    return pd.DataFrame(out)


def test_the_fit_finds_the_contrast_and_the_final_stage_recovers_both_rates() -> None:
    """Nominal pilot rows of the toy: joint_update with the table fits r with a large positive slope on
    the low-contrast column (V2I collides only there), and a final stage drawn from it estimates SV's
    and V2I's rates within their intervals, V2I with fewer episodes than the proposal of SV alone."""
    rng = np.random.default_rng(21)
    pilot = _rows([_episode(rng, None) for _ in range(6000)], 0)
    table = low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 15.0)
    with_factor, n_sv, guard = joint_update(pilot, "sv", DEFENSIVE_SHARE, None, False, table)
    without, _, _ = joint_update(pilot, "sv", DEFENSIVE_SHARE, None, False, None)
    assert not guard and n_sv == int(pilot[pilot.condition == "sv"]["collision"].sum())
    assert with_factor is not None and with_factor.v2i_factor is not None and without.v2i_factor is None
    intercept, slope = with_factor.v2i_factor.coefficients
    assert slope > 2.0 and intercept < -2.0
    assert with_factor.coefficients == without.coefficients  # pi_hat is the same fit
    proposals = {"factor": with_factor, "sv alone": without}
    variances = _final_stage_variances(rng, _episode, proposals, TOY_SV_P * 4 / 36)
    assert variances["factor", 3] < 0.5 * variances["sv alone", 3]


def _final_stage_variances(rng, episode, proposals: dict, v2i_p: float) -> dict:
    """4,000 episodes from each proposal: SV's and V2I's weighted means within 4 standard errors of the
    toy's rates (TOY_SV_P, v2i_p); the squared standard errors by (label, 2 for SV / 3 for V2I)."""
    variances = {}
    for label, proposal in proposals.items():
        final = [episode(rng, proposal) for _ in range(4000)]
        w = np.array([e[1] for e in final])
        for index, truth in ((2, TOY_SV_P), (3, v2i_p)):
            f = np.array([e[index] for e in final], dtype=float)
            mean, se = float(np.mean(w * f)), float(np.std(w * f) / math.sqrt(len(w)))
            assert abs(mean - truth) < 4 * se, (label, index, mean, truth, se)
            variances[label, index] = se**2
    return variances


def test_too_few_v2i_collisions_or_no_colours_leave_the_proposal_of_sv_alone() -> None:
    rng = np.random.default_rng(22)
    rows = _rows([_episode(rng, None) for _ in range(3000)], 0)
    base = normalised(NOMINAL, COEFFICIENTS, DEFENSIVE_SHARE)
    table = low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 15.0)
    v2i_hits = rows[(rows.condition == "v2i") & rows.collision]
    keep = set(v2i_hits["episode"].iloc[: GUARD_MIN_COLLISIONS - 1])
    few = rows.copy()
    few.loc[(few.condition == "v2i") & ~few["episode"].isin(keep), "collision"] = False
    assert with_v2i_factor(base, few, table) is None
    # Episodes that draw no vehicle colour: nothing to model.
    stripped = rows.copy()
    stripped["sampler_inputs"] = [
        json.dumps(
            {**json.loads(t), "inputs": {k: v for k, v in json.loads(t)["inputs"].items() if k != CAR}}
        )
        for t in rows["sampler_inputs"]
    ]
    assert with_v2i_factor(base, stripped, table) is None


def test_v2i_takes_pi_hat_r_as_its_control_and_sv_pi_hat() -> None:
    proposal = _proposal()
    inputs = {"ego_speed_log": 2.5, "conflict_offset_s": 0.9, "clothing": 5.0, CAR: 1.0, "unused": 3.0}
    texts = [json.dumps({"inputs": inputs, "nominal": {}, "log_weight": 0.0})]
    x = {name: np.array([value]) for name, value in inputs.items()}
    g_sv, mean_sv, _ = condition_control(proposal, texts, "sv")
    g_v2i, mean_v2i, se_v2i = condition_control(proposal, texts, "v2i")
    assert g_sv == pytest.approx(proposal.pi_hat(x)) and mean_sv == proposal.mean_pi_hat
    assert g_v2i == pytest.approx(proposal.pi_hat(x) * special.expit(1.0))  # black on black: low contrast
    assert (mean_v2i, se_v2i) == (proposal.mean_pi_v2i, proposal.mean_pi_v2i_se)


def test_json_round_trip_keeps_the_factor_and_a_proposal_without_it_has_no_new_keys() -> None:
    proposal = _proposal()
    again = JointProposal.from_json(proposal.to_json())
    assert again == proposal
    plain = json.loads(normalised(NOMINAL, COEFFICIENTS, DEFENSIVE_SHARE).to_json())
    assert not {"v2i_factor", "mean_pi_v2i", "mean_pi_v2i_se"} & set(plain)
    assert isinstance(proposal.nominal["clothing"], Categorical)


# ---------------------------------------------------------------- the V2I-only term
#: The toy's V2I also collides where SV does not: a slow ego (below 3 m/s) with the offset below -0.8 s.
TOY_V2I_ONLY_P = stats.norm.cdf((math.log(3.0) - LOG_MU) / LOG_SIGMA) * 0.2 / 2.5
#: pi_vo's coefficients on pi_hat's design (1, z_o, z_o^2, z_e, z_e^2, z_o z_e).
ONLY = (-4.0, -1.5, 0.0, -2.0, 0.0, 0.3)


def _episode_with_v2i_only(rng: np.random.Generator, proposal) -> tuple[dict, float, bool, bool]:
    record, weight, sv, v2i = _episode(rng, proposal)
    speed, offset = math.exp(record["inputs"]["ego_speed_log"]), record["inputs"]["conflict_offset_s"]
    return record, weight, sv, bool(v2i or (speed < 3.0 and offset < -0.8))


def test_the_v2i_only_term_by_hand_and_its_json() -> None:
    factor = dataclasses.replace(_factor(), v2i_only_coefficients=ONLY)
    proposal = normalised({**NOMINAL, **factor.nominal()}, COEFFICIENTS, DEFENSIVE_SHARE, None, factor)
    x = {"ego_speed_log": np.array([2.6, 0.9]), "conflict_offset_s": np.array([1.0, -0.9])}
    x |= {"clothing": np.array([0.0, 2.0]), CAR: np.array([4.0, 4.0])}
    z_o = (x["conflict_offset_s"] - 0.25) / (2.5 / math.sqrt(12))
    z_e = (x["ego_speed_log"] - LOG_MU) / LOG_SIGMA
    pi = special.expit(-5.0 + z_o + 2.0 * z_e + 0.5 * z_o * z_e)
    r = special.expit(np.array([-3.0 + 4.0, -3.0]))
    only = special.expit(-4.0 - 1.5 * z_o - 2.0 * z_e + 0.3 * z_o * z_e)
    a = proposal.v2i_factor.target_share
    assert proposal.pi_v2i_hat(x) == pytest.approx(np.minimum(1.0, pi * r + only))
    assert proposal.root_pi(x) == pytest.approx(np.sqrt(a * pi + (1 - a) * (pi * r + only)))
    rng = np.random.default_rng(9)
    draws = {name: family.sample(rng, 400_000) for name, family in {**NOMINAL, **factor.nominal()}.items()}
    assert proposal.mean_pi_v2i == pytest.approx(float(np.mean(proposal.pi_v2i_hat(draws))), rel=0.02)
    assert a == pytest.approx(proposal.mean_pi_v2i**2 / (proposal.mean_pi_hat**2 + proposal.mean_pi_v2i**2))
    assert proposal.bound == pytest.approx(DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) / proposal.norm)
    assert JointProposal.from_json(proposal.to_json()) == proposal
    assert json.loads(proposal.to_json())["v2i_factor"]["v2i_only_coefficients"] == list(ONLY)
    assert "v2i_only_coefficients" not in json.loads(_proposal().to_json())["v2i_factor"]
    texts = [json.dumps({"inputs": {k: float(v[1]) for k, v in x.items()}, "nominal": {}, "log_weight": 0.0})]
    g_v2i, mean_v2i, _ = condition_control(proposal, texts, "v2i")
    assert g_v2i == pytest.approx([pi[1] * r[1] + only[1]]) and mean_v2i == proposal.mean_pi_v2i


def test_the_v2i_only_term_is_fitted_where_the_pilots_hold_enough_and_aims_at_those_collisions() -> None:
    """Nominal pilots of the toy with a V2I-only region: contrast+v2i-only fits pi_vo (high in the slow,
    early corner), 'contrast' does not; drawn from it, both rates are recovered within their intervals
    and V2I's variance falls below half that of the factor without the term."""
    rng = np.random.default_rng(23)
    pilot = _rows([_episode_with_v2i_only(rng, None) for _ in range(6000)], 0)
    table = low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 15.0)
    with_only, _, _ = joint_update(pilot, "sv", DEFENSIVE_SHARE, None, False, table, v2i_only=True)
    contrast, _, _ = joint_update(pilot, "sv", DEFENSIVE_SHARE, None, False, table)
    assert with_only.v2i_factor.v2i_only_coefficients and not contrast.v2i_factor.v2i_only_coefficients
    assert with_only.v2i_factor.coefficients == contrast.v2i_factor.coefficients  # r is the same fit
    corner = {
        "ego_speed_log": np.array([math.log(2.5), math.log(12.0)]),
        "conflict_offset_s": np.array([-0.9, 1.0]),
    }
    corner |= {"clothing": np.array([2.0, 2.0]), CAR: np.array([4.0, 4.0])}
    assert with_only.pi_v2i_hat(corner)[0] > 0.2 > contrast.pi_v2i_hat(corner)[0]
    proposals = {"v2i-only": with_only, "contrast": contrast}
    v2i_p = TOY_SV_P * 4 / 36 + TOY_V2I_ONLY_P
    variances = _final_stage_variances(rng, _episode_with_v2i_only, proposals, v2i_p)
    assert variances["v2i-only", 3] < 0.5 * variances["contrast", 3]


def test_enough_v2i_only_collisions_by_hand() -> None:
    """5 always; 2 to 4 where they make up at least the defensive share of the V2I collisions; never 1."""
    assert v2i_only_engages(GUARD_MIN_COLLISIONS, 1000, 0.1)
    assert v2i_only_engages(2, 20, 0.1) and not v2i_only_engages(2, 21, 0.1)
    assert v2i_only_engages(4, 40, 0.1) and not v2i_only_engages(4, 41, 0.1)
    assert not v2i_only_engages(1, 1, 0.1) and not v2i_only_engages(0, 0, 0.1)
    assert v2i_only_engages(3, 100, 0.03) and not v2i_only_engages(3, 100, 0.031)


def test_too_few_v2i_only_collisions_leave_the_factor_without_the_term() -> None:
    """The toy's pilots cut down to k V2I-only collisions: one is never enough; two are where they make up
    at least the defensive share of V2I's collisions (2 of 10 here), not where SV's collisions all carry a V2I
    one too (2 of 55); without the term the factor is 'contrast''s."""
    rng = np.random.default_rng(24)
    rows = _rows([_episode_with_v2i_only(rng, None) for _ in range(3000)], 0)
    base = normalised(NOMINAL, COEFFICIENTS, DEFENSIVE_SHARE)
    table = low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, 15.0)
    pairs = rows.pivot(index="episode", columns="condition", values="collision")
    only = pairs.index[~pairs["sv"] & pairs["v2i"]]

    def keeping(k: int, every_sv_collision_in_v2i: bool = False) -> pd.DataFrame:
        few = rows.copy()
        v2i = few.condition == "v2i"
        few.loc[v2i & few["episode"].isin(only[k:]), "collision"] = False
        if every_sv_collision_in_v2i:
            few.loc[v2i & few["episode"].isin(pairs.index[pairs["sv"]]), "collision"] = True
        return few

    assert len(only) > GUARD_MIN_COLLISIONS and int((pairs["sv"] & pairs["v2i"]).sum()) == 8
    one = with_v2i_factor(base, keeping(1), table, v2i_only=True)
    assert one is not None and not one.v2i_factor.v2i_only_coefficients
    assert one == with_v2i_factor(base, keeping(1), table)
    two = with_v2i_factor(base, keeping(2), table, v2i_only=True)  # 2 of 10
    assert two is not None and two.v2i_factor.v2i_only_coefficients
    diluted = keeping(2, every_sv_collision_in_v2i=True)
    assert int(pairs["sv"].sum()) == 53  # 2 of 55
    fitted = with_v2i_factor(base, diluted, table, v2i_only=True)
    assert fitted is not None and not fitted.v2i_factor.v2i_only_coefficients
    assert fitted == with_v2i_factor(base, diluted, table)


def test_the_v2i_only_pilot_count_and_the_tables_note() -> None:
    """v2i_only_count against the pairs counted here; Table I's note where the last stage's pilots saw
    V2I-only collisions and the proposal has no term for them, and none otherwise or without the count."""
    from pedsafe_sumo.report.tables import v2i_only_note

    rng = np.random.default_rng(25)
    rows = _rows([_episode_with_v2i_only(rng, None) for _ in range(800)], 0)
    pairs = rows.pivot(index="episode", columns="condition", values="collision")
    assert v2i_only_count(rows) == int((~pairs["sv"] & pairs["v2i"]).sum()) > 0
    rows.loc[
        (rows.condition == "v2i") & (rows.episode == int(pairs.index[~pairs["sv"] & pairs["v2i"]][0])),
        "status",
    ] = "error"
    assert v2i_only_count(rows) == int((~pairs["sv"] & pairs["v2i"]).sum()) - 1  # a failed side: no pair
    levels = {
        "jaywalking": [{"after_stage": 0}, {"after_stage": 1, "v2i_only_pilot_collisions": 3}],
        "crossing": [{"after_stage": 1, "v2i_only_pilot_collisions": 0}],
        "right_turn": [{"after_stage": 1, "v2i_only_pilot_collisions": 7, "v2i_only_terms": 28}],
    }
    note = v2i_only_note({"sampler_levels": levels})
    assert note.startswith("note: jaywalking: V2I collided where SV did not in 3 pilot pair(s)")
    assert "crossing" not in note and "right_turn" not in note and len(note.splitlines()) == 1
    assert v2i_only_note({"sampler_levels": {"jaywalking": [{"after_stage": 1}]}}) == ""
    assert v2i_only_note(None) == ""
