"""The safety indexes of one vehicle-pedestrian interaction, by the same functions as a batch episode.

An interaction is a stretch of steps at which one vehicle and one pedestrian are near each other; its
per-step log follows the contract of `pedsafe_sumo.safety.log` (the vehicle in the ego's columns). The
detection flags mean nothing outside an episode: a log without them gets them all False.

The rules are those of `episode_indexes`: TTC, the conflict and the proximity measures (minimum clearance,
DRAC: `pedsafe_sumo.safety.proximity`) are taken over the steps up to and including the first contact,
PET is 0 for an interaction with a contact. So an episode's log gives back its row of `episodes.parquet`
(tests/replay/test_conflicts_roundtrip.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from pedsafe_sumo.safety.collision import detect_collision
from pedsafe_sumo.safety.conflict import AMINI_2022, ConflictModel, episode_conflict
from pedsafe_sumo.safety.proximity import (
    SCOPE_EPISODE,
    default_proximity_model,
    episode_proximity,
    kinematic_arrays,
)
from pedsafe_sumo.safety.surrogates import pet_s, ttc_steps_s


@dataclass(frozen=True)
class InteractionMeasures:
    collision: bool
    #: first step in contact; None without a contact
    contact_step: int | None
    #: smallest signed clearance between footprint and circle up to the first contact, m (<= 0: contact)
    min_clearance_m: float
    #: step of the smallest clearance (the first on a tie)
    min_clearance_step: int
    #: smallest TTC up to the first contact, s, and its step (NaN / None if never on a collision course)
    ttc_s: float
    ttc_step: int | None
    pet_s: float
    drac_mps2: float
    conflict: bool
    md_m: float
    tmd_s: float
    cs_mps: float
    conflict_probability: float
    #: the reported conflict step (riskiest eligible step); None if no step is eligible
    conflict_step: int | None
    #: step of the largest DRAC up to the first contact (the first on a tie); None without a DRAC
    drac_step: int | None = None


def interaction_measures(
    log: Any, conflict_model: ConflictModel = AMINI_2022, ttc_s: np.ndarray | None = None
) -> InteractionMeasures:
    """All measures of one interaction's per-step log (see the module docstring for the rules).

    `ttc_s`: the log's per-step TTC when the caller has computed it already (`ttc_of_rows` over the rows
    of many logs at once); None computes it here."""
    arrays = kinematic_arrays(log)
    hit = detect_collision(arrays)
    ttc = ttc_steps_s(arrays) if ttc_s is None else ttc_s
    # the closest approach of the pair over the whole interaction window, whatever the pedestrian does
    proximity = episode_proximity(
        arrays, replace(default_proximity_model(), scope=SCOPE_EPISODE), hit.step, ttc_s=ttc
    )
    if hit.step is not None:
        ttc = ttc[: hit.step + 1]
    k_ttc = int(np.nanargmin(ttc)) if np.isfinite(ttc).any() else None
    conflict = episode_conflict(arrays, conflict_model, last_step=hit.step)
    return InteractionMeasures(
        collision=hit.collided,
        contact_step=hit.step,
        min_clearance_m=proximity.min_clearance_m,
        min_clearance_step=proximity.step,
        ttc_s=float(ttc[k_ttc]) if k_ttc is not None else math.nan,
        ttc_step=k_ttc,
        pet_s=0.0 if hit.collided else pet_s(arrays),
        drac_mps2=proximity.drac_mps2,
        conflict=conflict.conflict,
        md_m=conflict.md_m,
        tmd_s=conflict.tmd_s,
        cs_mps=conflict.cs_mps,
        conflict_probability=conflict.conflict_probability,
        conflict_step=conflict.step,
        drac_step=proximity.drac_step,
    )
