"""The joint proposal (sampling/joint.py) fitted on the pilot rows, stage by stage (`joint_update`).

The fit: pi_hat a ridge logistic regression of the SV collision on every pilot row so far (`fit_joint`),
then c estimated by `normalised`; where the run asks for it and the pilots hold enough V2I collisions,
the V2I factor joins (sampling/v2i_factor.py).

The guard: a 200-pair nominal stage 0 of a scenario whose collision rate is 0.75% (crossing) holds no
collision one time in five, and a fit on one or two collisions hardly beats the nominal (crossing at seed
23: 3.6x per final episode). So a PILOT stage whose pooled pilot rows hold fewer than GUARD_MIN_COLLISIONS
SV collisions draws from the region proposal instead (`region_proposal`): pi_hat a steep step down at
margin_s = 0, q ≈ lambda p + (1 - lambda) p 1{margin_s < 0} / P_p(margin_s < 0). It needs no fit: on the
rows of paper-v5's 10,000-pair MC run, 75 of 75 crossing collisions, 220 of 220 right_turn, 293 of 299
jaywalking (but 303 of 504 blending) have margin_s < 0, where the collision rate is 17-71%. The final
stage is always the fit on the pooled pilot rows (which the guard's stage makes rich in collisions).
Pilot rows only train pi_hat, so a guard that misses collisions costs efficiency, never bias.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from pedsafe_sumo.sampling.importance import Categorical, Family
from pedsafe_sumo.sampling.joint import (
    GUARD_MIN_COLLISIONS,
    KINEMATIC_INPUTS,
    MAX_MEAN_TRIES,
    NORM_SEED,
    RIDGE,
    JointProposal,
    Kinematics,
    fit_logistic,
    normalised,
)
from pedsafe_sumo.sampling.stages import _inputs_and_nominal
from pedsafe_sumo.sampling.v2i_factor import with_v2i_factor

#: The guard's step: pi_hat = expit(-GUARD_STEEPNESS margin_s / sd(margin_s)).
GUARD_STEEPNESS = 200.0


def margin_column(nominal: Mapping[str, Family]) -> int:
    """The design column of the standardised braking margin's linear term (JointProposal.features: the
    intercept, each input's indicators or z and z^2 in sorted order, then v, 1/w and margin_s)."""
    column = 1
    for name in sorted(nominal):
        family = nominal[name]
        column += len(family.probabilities) - 1 if isinstance(family, Categorical) else 2
    return column + 4


def region_proposal(
    nominal: Mapping[str, Family], kinematics: Kinematics | None, defensive_share: float
) -> JointProposal | None:
    """The guard of a pilot with few collisions (module docstring): pi_hat a steep logistic step down at
    margin_s = 0, so that q ≈ lambda p + (1 - lambda) p 1{margin_s < 0} / P_p(margin_s < 0); None where the
    scenario lacks a kinematic input."""
    if kinematics is None or not set(KINEMATIC_INPUTS) <= set(nominal):
        return None
    kinematics = kinematics.with_moments(nominal)
    mean_s, sd_s = kinematics.moments[2]
    shell = JointProposal(dict(nominal), (), 1.0, defensive_share, kinematics=kinematics)
    probe = shell.features(shell.sample_nominal(np.random.default_rng(NORM_SEED), 1))
    coefficients = np.zeros(probe.shape[1])
    # eta = -GUARD_STEEPNESS margin_s / sd: pi_hat = 1/2 at margin_s = 0, sqrt(pi_hat) 4.5e-5 at +0.1 sd.
    coefficients[margin_column(nominal)] = -GUARD_STEEPNESS
    coefficients[0] = -GUARD_STEEPNESS * mean_s / sd_s
    proposal = normalised(nominal, coefficients, defensive_share, kinematics)
    return proposal if proposal.norm > 0 and proposal.bound <= MAX_MEAN_TRIES else None


def fit_joint(
    inputs: Mapping[str, np.ndarray],
    collision: np.ndarray,
    nominal: Mapping[str, Family],
    defensive_share: float,
    ridge: float = RIDGE,
    kinematics: Kinematics | None = None,
) -> JointProposal | None:
    """The joint proposal fitted on pilot rows (`inputs` name -> values, `collision` 0/1); None when the
    rows hold no collision (the next stage then stays nominal) or the envelope would be too loose. With
    `kinematics`, the kinematic features join the design where every KINEMATIC_INPUTS input is drawn."""
    y = np.asarray(collision, dtype=float)
    if not y.any():
        return None
    if kinematics is not None:
        kinematics = kinematics.with_moments(nominal) if set(KINEMATIC_INPUTS) <= set(nominal) else None
    shell = JointProposal(dict(nominal), (), 1.0, defensive_share, kinematics=kinematics)
    proposal = normalised(
        nominal, fit_logistic(shell.features(inputs), y, ridge), defensive_share, kinematics
    )
    if not proposal.norm > 0 or proposal.bound > MAX_MEAN_TRIES:
        return None
    return proposal


def joint_update(
    rows: pd.DataFrame,
    condition: str,
    defensive_share: float,
    kinematics: Kinematics | None = None,
    pilot_stage: bool = False,
    low_contrast: tuple[tuple[int, ...], ...] | None = None,
    v2i_only: bool = False,
) -> tuple[JointProposal | None, int, bool]:
    """The proposal of the next stage from every pilot row so far of `condition` (status ok), their
    collisions, and whether it is the guard's region proposal (a `pilot_stage` with fewer than
    GUARD_MIN_COLLISIONS collisions, where the scenario has the kinematic inputs) rather than the fit.
    With `low_contrast` (the V2I factor's table L), the fit gains the V2I factor where with_v2i_factor
    finds it can (the pairs of `rows` with both conditions), with `v2i_only` its V2I-only term."""
    both = rows
    rows = rows[(rows["condition"] == condition) & (rows["status"] == "ok")]
    inputs, nominal = _inputs_and_nominal(rows)
    y = rows["collision"].astype(float).to_numpy()
    n_collisions = int(y.sum())
    if pilot_stage and kinematics is not None and n_collisions < GUARD_MIN_COLLISIONS:
        region = region_proposal(nominal.families, kinematics, defensive_share)
        if region is not None:
            return region, n_collisions, True
    proposal = fit_joint(inputs, y, nominal.families, defensive_share, kinematics=kinematics)
    if proposal is not None and low_contrast is not None:
        proposal = with_v2i_factor(proposal, both, low_contrast, v2i_only) or proposal
    return proposal, n_collisions, False
