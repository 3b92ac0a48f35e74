"""The V2I factor: the joint proposal (sampling/joint.py) aimed at V2I's collisions too (`--is-v2i-factor`).

V2I's collisions lie inside SV's region, but there the proposable inputs leave V2I's outcome largely to
chance: on jaywalking 84% of V2I's collisions (4% of the SV-only ones) have the pedestrian's clothing within
the roadside camera's contrast threshold of the parked car behind them, which the camera's colour rule then
cannot tell apart (perception/sensors.py). So where the pilots' SV collisions hold at least
GUARD_MIN_COLLISIONS V2I collisions, the proposal also draws the clothing and the vehicles' colours (uniform
categories, as the scenarios draw them) and aims at V2I's collisions too, modelled as pi_v2i = pi_hat r(z)
with

    r(z) = P(V2I collision | SV collision, z) = expit(b_0 + sum_k b_k L[clothing, colour_k]),

L[i, j] = 1 where clothing colour i and car colour j differ by less than the roadside camera's
delta_e_threshold (CIE76), b a ridge logistic (RIDGE) on the pilots' pairs whose SV episode collided. Then
sqrt(pi_hat) becomes

    h(x, z) = sqrt(a pi_hat(x) + (1 - a) pi_hat(x) r(z)),    a = m_v2i^2 / (m_sv^2 + m_v2i^2),

m = the nominal means E_p[pi_hat] and E_p[pi_hat r]: the proposal ∝ p sqrt(pi_sv / P_sv^2 + pi_v2i / P_v2i^2)
that minimises the sum of the two rates' relative variances (Owen 2013, section 9.1, applied to the sum), with
the fits for the pi and m for the P. h <= 1, so the envelope B is unchanged; pi_hat r is V2I's control variate
(`mean_pi_v2i`). Where the clothing does not vary the contrast (background blending dresses the pedestrian in
the waiting car's colour) the fit leaves r nearly constant and the proposal nearly the SV one.

The V2I-only term. The factor models V2I's collisions as a subset of SV's. On Xueqing that holds (V2I-only
collisions are 0-8% of V2I's rate), but on the zhixin junction 41% of V2I's jaywalking collisions happen where
SV does not collide, and a proposal without the term draws them at about its defensive floor (V2I 0.15x
against MC). So where the pilot pairs hold enough V2I collisions whose SV episode did not collide
(`v2i_only_engages`; `--is-v2i-factor contrast+v2i-only`), the factor also carries pi_vo, a ridge logistic of
"V2I collides, SV does not" on every pilot pair over pi_hat's design, and V2I is modelled as

    pi_v2i = min(1, pi_hat r + pi_vo),    h = sqrt(a pi_hat + (1 - a) pi_v2i),

a by the same rule on m_v2i = E_p[pi_v2i]; pi_v2i is V2I's control variate. The factor then applies where
either count is enough (r fitted on what SV collisions there are). h <= 1 still, so B stands.

Enough: GUARD_MIN_COLLISIONS V2I-only collisions, or V2I_ONLY_MIN_COLLISIONS that make up at least the
defensive share lambda of the pilots' V2I collisions. The second arm is the case where leaving them out costs
most: a share s of V2I's rate drawn at the floor lambda p adds s / lambda times plain Monte Carlo's variance
to V2I's, so from s = lambda on, that region alone makes V2I's estimate no better than MC. Three zhixin runs'
pilots hold 2-3 such collisions at shares of 0.15-0.30; the term fitted on their 2 collisions takes V2I from
1.7 and 2.6 to 4.0 and 4.7 per final episode (offline, scored on MC pairs), and without it V2I's interval
misses the pooled MC reference in one seed of three. 21 runs' pilots on Xueqing hold 0-13 at shares of 0-0.11,
none with 2-4 at a share of 0.1 or more; there a term fitted on 1-3 would cost efficiency (blending's SV 18%
offline). The share is of the pilots' draws, which lean towards SV's collisions, so it understates the nominal
one.

The pilot pairs' data (`sv_v2i_pairs`, `v2i_only_count`), the rule (`v2i_only_engages`) and the fit
(`with_v2i_factor`) are here; the factor itself (ContrastFactor) is part of the proposal's JSON in
sampling/joint.py.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.perception.sensors import delta_e_cie76
from pedsafe_sumo.sampling.joint import (
    CLOTHING_INPUT,
    COLOUR_SUFFIX,
    GUARD_MIN_COLLISIONS,
    MAX_MEAN_TRIES,
    RIDGE,
    V2I_CONDITION,
    ContrastFactor,
    JointProposal,
    fit_logistic,
    normalised,
)
from pedsafe_sumo.sampling.stages import ADAPT_CONDITION

#: The V2I-only term's lower count (module docstring, "Enough"): a fit needs more than one point.
V2I_ONLY_MIN_COLLISIONS = 2


def low_contrast_table(
    clothing_rgb: Any, car_rgb: Any, delta_e_threshold: float
) -> tuple[tuple[int, ...], ...]:
    """`L[i][j]` = 1 where clothing colour i and car colour j differ by less than `delta_e_threshold` (CIE76,
    the cameras' rule: perception/sensors.py)."""
    clothing, cars = np.asarray(clothing_rgb, dtype=float), np.asarray(car_rgb, dtype=float)
    return tuple(
        tuple(int(delta_e_cie76(colour[None, :], car[None, :])[0] < delta_e_threshold) for car in cars)
        for colour in clothing
    )


def sv_v2i_pairs(rows: pd.DataFrame) -> pd.DataFrame:
    """The pairs of `rows` (both conditions, status ok on both sides) by episode: SV's collision and
    sampler_inputs, V2I's collision as `collision_v2i`."""
    ok = rows[rows["status"] == "ok"]
    sv = ok[ok["condition"] == ADAPT_CONDITION].set_index("episode")
    v2i = ok[ok["condition"] == V2I_CONDITION].set_index("episode")
    return sv[["collision", "sampler_inputs"]].join(
        v2i[["collision"]].rename(columns={"collision": "collision_v2i"}), how="inner"
    )


def v2i_only_count(rows: pd.DataFrame) -> int:
    """How many pairs of `rows` have a V2I collision and no SV collision (the V2I-only term's data)."""
    pairs = sv_v2i_pairs(rows)
    return int((~pairs["collision"].astype(bool) & pairs["collision_v2i"].astype(bool)).sum())


def v2i_only_engages(n_v2i_only: int, n_v2i: int, defensive_share: float) -> bool:
    """Whether pilot pairs holding `n_v2i_only` V2I-only collisions among `n_v2i` V2I collisions are enough
    for the V2I-only term (module docstring, "Enough")."""
    if n_v2i_only >= GUARD_MIN_COLLISIONS:
        return True
    return n_v2i_only >= V2I_ONLY_MIN_COLLISIONS and n_v2i_only >= defensive_share * n_v2i


def with_v2i_factor(
    proposal: JointProposal,
    rows: pd.DataFrame,
    low_contrast: tuple[tuple[int, ...], ...],
    v2i_only: bool = False,
) -> JointProposal | None:
    """`proposal` with the V2I factor (module docstring) fitted on the pairs of `rows` (pilot rows of both
    conditions) whose SV episode collided; None where they hold fewer than GUARD_MIN_COLLISIONS V2I
    collisions, the scenario draws no clothing or no vehicle colour in every pilot episode, or the
    envelope would be too loose (the proposal of SV alone then stands).

    With `v2i_only`, where the pairs hold enough V2I collisions whose SV episode did not collide
    (`v2i_only_engages`), the factor also carries the V2I-only term pi_vo, a ridge logistic of those on
    every pair over pi_hat's design (module docstring); the factor then applies where either count is
    enough."""
    pairs = sv_v2i_pairs(rows)
    hit = pairs[pairs["collision"].astype(bool)]
    y = hit["collision_v2i"].astype(float).to_numpy()
    y_only = (~pairs["collision"].astype(bool) & pairs["collision_v2i"].astype(bool)).to_numpy(dtype=float)
    n_v2i = int(pairs["collision_v2i"].astype(bool).sum())
    with_only = v2i_only and v2i_only_engages(int(y_only.sum()), n_v2i, proposal.defensive_share)
    if y.sum() < GUARD_MIN_COLLISIONS and not with_only:
        return None
    records = [json.loads(text)["inputs"] for text in pairs["sampler_inputs"]]
    colour_inputs = sorted(
        name for name in records[0] if name.endswith(COLOUR_SUFFIX) and all(name in r for r in records)
    )
    if not colour_inputs or not all(CLOTHING_INPUT in r for r in records):
        return None
    factor = ContrastFactor(tuple(colour_inputs), low_contrast, ())
    hit_records = [json.loads(text)["inputs"] for text in hit["sampler_inputs"]]
    z = {name: np.array([r[name] for r in hit_records], dtype=float) for name in factor.names}
    coefficients = fit_logistic(factor.design(z), y, RIDGE)
    factor = dataclasses.replace(factor, coefficients=tuple(float(b) for b in coefficients))
    if with_only:
        x = {name: np.array([r[name] for r in records], dtype=float) for name in proposal.names}
        only = fit_logistic(proposal.features(x), y_only, RIDGE)
        factor = dataclasses.replace(factor, v2i_only_coefficients=tuple(float(b) for b in only))
    nominal = {**proposal.nominal, **factor.nominal()}
    fitted = normalised(nominal, proposal.coefficients, proposal.defensive_share, proposal.kinematics, factor)
    return fitted if fitted.norm > 0 and fitted.bound <= MAX_MEAN_TRIES else None
