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

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.collision import clearance_m, collision_of_steps
from pedsafe_sumo.safety.conflict import (
    AMINI_2022,
    ConflictModel,
    conflict_columns_of_rows,
    conflict_of_columns,
)
from pedsafe_sumo.safety.geometry import first_polyline_crossing
from pedsafe_sumo.safety.proximity import (
    SCOPE_EPISODE,
    ProximityModel,
    default_proximity_model,
    drac_from_ttc_mps2,
    kinematic_arrays,
    proximity_of_steps,
)
from pedsafe_sumo.safety.surrogates import pet_at_crossing_s, ttc_of_rows


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
    #: the first crossing of the two centre paths (`first_polyline_crossing`, the PET's point); found
    #: only without a contact (PET is 0 with one), None then or when the paths never cross
    path_crossing: tuple[float, float] | None = None


@dataclass(frozen=True)
class StepMeasures:
    """The per-step measures of rows in the log contract's names, each row on its own: those of one log,
    or of many logs stacked (`part` gives back one log's steps, each value the same as in its own call)."""

    #: signed clearance between footprint and circle, m (<= 0: contact)
    clearance_m: np.ndarray
    #: TTC, s (NaN where never touching)
    ttc_s: np.ndarray
    #: DRAC, m/s^2 (NaN where not defined)
    drac_mps2: np.ndarray
    #: the Amini conflict measures (`conflict_columns_of_rows`)
    conflict: dict[str, np.ndarray]

    def part(self, start: int, stop: int) -> StepMeasures:
        """The steps start..stop-1 (views, no copy)."""
        return StepMeasures(
            self.clearance_m[start:stop],
            self.ttc_s[start:stop],
            self.drac_mps2[start:stop],
            {name: values[start:stop] for name, values in self.conflict.items()},
        )


def step_measures_of_rows(
    a: Mapping[str, np.ndarray], conflict_model: ConflictModel = AMINI_2022, ttc_s: np.ndarray | None = None
) -> StepMeasures:
    """The per-step measures of rows of columns in the log contract's names and units, checked by the
    caller (`ttc_s`: their TTC when computed already). Element by element, so one call can serve the
    rows of many logs, whose fixed cost (some hundred numpy operations) they then share."""
    ttc = ttc_of_rows(a) if ttc_s is None else ttc_s
    return StepMeasures(
        clearance_m=clearance_m(a),
        ttc_s=ttc,
        drac_mps2=drac_from_ttc_mps2(a[steplog.EGO_SPEED], ttc),
        conflict=conflict_columns_of_rows(a, conflict_model),
    )


def interaction_measures(
    log: Any, conflict_model: ConflictModel = AMINI_2022, ttc_s: np.ndarray | None = None
) -> InteractionMeasures:
    """All measures of one interaction's per-step log (see the module docstring for the rules).

    `ttc_s`: the log's per-step TTC when the caller has computed it already; None computes it here."""
    arrays = kinematic_arrays(log)
    return measures_of_steps(arrays, step_measures_of_rows(arrays, conflict_model, ttc_s), conflict_model)


def measures_of_steps(
    arrays: Mapping[str, np.ndarray],
    steps: StepMeasures,
    conflict_model: ConflictModel = AMINI_2022,
    paths_apart: bool = False,
) -> InteractionMeasures:
    """`interaction_measures` of one log's checked columns and its `StepMeasures` (one part of a stacked
    call, or its own). `paths_apart`: the caller has found that the two centre paths' bounding boxes are
    apart (`path_boxes_apart`, for many logs at once), so they do not cross and are not searched."""
    hit = collision_of_steps(steps.clearance_m, arrays[steplog.EGO_SPEED], arrays[steplog.TIME])
    # the closest approach of the pair over the whole interaction window, whatever the pedestrian does
    proximity = proximity_of_steps(arrays, steps.clearance_m, steps.drac_mps2, _episode_scope(), hit.step)
    ttc = steps.ttc_s
    if hit.step is not None:
        ttc = ttc[: hit.step + 1]
    k_ttc = int(np.nanargmin(ttc)) if np.isfinite(ttc).any() else None
    conflict = conflict_of_columns(steps.conflict, conflict_model, last_step=hit.step)
    path_crossing = None
    if not hit.collided and not paths_apart:
        path_crossing = first_polyline_crossing(
            arrays[steplog.EGO_X], arrays[steplog.EGO_Y], arrays[steplog.PED_X], arrays[steplog.PED_Y]
        )
    return InteractionMeasures(
        collision=hit.collided,
        contact_step=hit.step,
        min_clearance_m=proximity.min_clearance_m,
        min_clearance_step=proximity.step,
        ttc_s=float(ttc[k_ttc]) if k_ttc is not None else math.nan,
        ttc_step=k_ttc,
        pet_s=0.0 if hit.collided else pet_at_crossing_s(arrays, path_crossing),
        drac_mps2=proximity.drac_mps2,
        conflict=conflict.conflict,
        md_m=conflict.md_m,
        tmd_s=conflict.tmd_s,
        cs_mps=conflict.cs_mps,
        conflict_probability=conflict.conflict_probability,
        conflict_step=conflict.step,
        drac_step=proximity.drac_step,
        path_crossing=path_crossing,
    )


@functools.lru_cache(maxsize=1)
def _episode_scope() -> ProximityModel:
    """The interaction's proximity model: the default thresholds, every step in scope."""
    return replace(default_proximity_model(), scope=SCOPE_EPISODE)
