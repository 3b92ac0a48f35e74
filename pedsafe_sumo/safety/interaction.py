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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.collision import STATIONARY_SPEED_MPS, clearance_m, collision_of_steps
from pedsafe_sumo.safety.conflict import (
    AMINI_2022,
    ConflictModel,
    conflict_columns_of_rows,
    conflict_of_columns,
)
from pedsafe_sumo.safety.geometry import first_polyline_crossing, path_boxes_apart
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
    arrays: Mapping[str, np.ndarray], steps: StepMeasures, conflict_model: ConflictModel = AMINI_2022
) -> InteractionMeasures:
    """`interaction_measures` of one log's checked columns and its `StepMeasures` (one part of a stacked
    call, or its own)."""
    hit = collision_of_steps(steps.clearance_m, arrays[steplog.EGO_SPEED], arrays[steplog.TIME])
    # the closest approach of the pair over the whole interaction window, whatever the pedestrian does
    proximity = proximity_of_steps(arrays, steps.clearance_m, steps.drac_mps2, _episode_scope(), hit.step)
    ttc = steps.ttc_s
    if hit.step is not None:
        ttc = ttc[: hit.step + 1]
    k_ttc = int(np.nanargmin(ttc)) if np.isfinite(ttc).any() else None
    conflict = conflict_of_columns(steps.conflict, conflict_model, last_step=hit.step)
    path_crossing = None
    if not hit.collided:
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


def measures_of_stacked_steps(
    columns: Mapping[str, np.ndarray],
    steps: StepMeasures,
    starts: Sequence[int],
    conflict_model: ConflictModel = AMINI_2022,
) -> list[InteractionMeasures]:
    """`measures_of_steps` of many logs stacked one after another (log k: the rows from starts[k] up to
    the next start, or to the end; one row at least) from their checked columns and their stacked
    `StepMeasures`: the first contact and the least and greatest values of each log found for all logs
    in a few numpy calls over the stack, each the step and the float of the log's own call (its first
    step on a tie, as argmin and argmax give); the crossing of the two paths and PET log by log, where
    the bounding boxes of its paths meet (`path_boxes_apart`: elsewhere there is no crossing to find)."""
    n_rows = len(columns[steplog.TIME])
    first = np.asarray(starts, dtype=np.intp)
    n_logs = len(first)
    counts = np.diff(np.r_[first, n_rows])
    owner = np.repeat(np.arange(n_logs), counts)
    clearance, speed = steps.clearance_m, columns[steplog.EGO_SPEED]
    # the first contact while the vehicle moves (`collision_of_steps`)
    strike = _first_rows(np.flatnonzero((clearance <= 0.0) & (speed >= STATIONARY_SPEED_MPS)), owner, n_logs)
    collided = strike >= 0
    # each log's window: its steps up to and including the first contact (all without one)
    in_window = np.arange(n_rows) < np.where(collided, strike + 1, first + counts)[owner]
    # the minimum clearance over the steps in scope (every step with a finite clearance:
    # `_episode_scope`), the largest DRAC and the smallest TTC, the first step on a tie
    k_clearance = _first_least(np.where(in_window & np.isfinite(clearance), clearance, np.inf), first, owner)
    drac, ttc = steps.drac_mps2, steps.ttc_s
    k_drac = _first_least(np.where(in_window & ~np.isnan(drac), -drac, np.inf), first, owner)
    k_ttc = _first_least(np.where(in_window & ~np.isnan(ttc), ttc, np.inf), first, owner)
    # `nanargmax` / `nanargmin` are asked only where some value of the window is finite
    drac_defined = _any_per_log(in_window & np.isfinite(drac), owner, n_logs)
    ttc_defined = _any_per_log(in_window & np.isfinite(ttc), owner, n_logs)
    scoped = _any_per_log(in_window & np.isfinite(clearance), owner, n_logs)
    # the Amini conflict at the riskiest eligible step (`conflict_of_columns`)
    c = steps.conflict
    eligible = in_window & c["candidate"] & (c["cs_mps"] > conflict_model.min_conflicting_speed_mps)
    probability = c["conflict_probability"]
    if np.isnan(probability[eligible]).any():  # argmax would take the NaN: each log on its own
        return [
            measures_of_steps(
                {name: values[a:b] for name, values in columns.items()},
                steps.part(a, b),
                conflict_model,
            )
            for a, b in zip(first.tolist(), (first + counts).tolist())
        ]
    k_conflict = _first_least(np.where(eligible, -probability, np.inf), first, owner)
    has_eligible = _any_per_log(eligible, owner, n_logs)
    has_conflict = _any_per_log(in_window & c["conflict"], owner, n_logs)
    apart = path_boxes_apart(
        columns[steplog.EGO_X], columns[steplog.EGO_Y], columns[steplog.PED_X], columns[steplog.PED_Y], first
    ).tolist()
    measures = []
    for k, (a, b) in enumerate(zip(first.tolist(), (first + counts).tolist())):
        hit = bool(collided[k])
        path_crossing = None
        log = None
        if not hit and not apart[k]:
            log = {name: values[a:b] for name, values in columns.items()}
            path_crossing = first_polyline_crossing(
                log[steplog.EGO_X], log[steplog.EGO_Y], log[steplog.PED_X], log[steplog.PED_Y]
            )
        i_clearance, i_drac, i_ttc, i_conflict = (
            int(k_clearance[k]),
            int(k_drac[k]),
            int(k_ttc[k]),
            int(k_conflict[k]),
        )
        eligible_k = bool(has_eligible[k])
        measures.append(
            InteractionMeasures(
                collision=hit,
                contact_step=int(strike[k]) - a if hit else None,
                min_clearance_m=float(clearance[i_clearance]) if scoped[k] else math.nan,
                min_clearance_step=i_clearance - a if scoped[k] else -1,
                ttc_s=float(ttc[i_ttc]) if ttc_defined[k] else math.nan,
                ttc_step=i_ttc - a if ttc_defined[k] else None,
                pet_s=0.0 if hit else pet_at_crossing_s(log, path_crossing) if log is not None else math.nan,
                drac_mps2=float(drac[i_drac]) if drac_defined[k] else math.nan,
                conflict=bool(has_conflict[k]) if eligible_k else False,
                md_m=float(c["md_m"][i_conflict]) if eligible_k else math.nan,
                tmd_s=float(c["tmd_s"][i_conflict]) if eligible_k else math.nan,
                cs_mps=float(c["cs_mps"][i_conflict]) if eligible_k else math.nan,
                conflict_probability=float(probability[i_conflict]) if eligible_k else math.nan,
                conflict_step=i_conflict - a if eligible_k else None,
                drac_step=i_drac - a if drac_defined[k] else None,
                path_crossing=path_crossing,
            )
        )
    return measures


def _first_rows(rows: np.ndarray, owner: np.ndarray, n_logs: int) -> np.ndarray:
    """Per log, the first of `rows` (ascending row numbers) that is one of its rows; -1 where none is."""
    found = np.full(n_logs, -1, dtype=np.intp)
    if rows.size:
        logs = owner[rows]
        new = np.flatnonzero(np.r_[True, logs[1:] != logs[:-1]])
        found[logs[new]] = rows[new]
    return found


def _first_least(values: np.ndarray, first: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """Per log, the row of its least value, the first on a tie (`np.argmin` of its slice); meaningful
    only where some value of the log is below inf (no NaN among `values`)."""
    least = np.minimum.reduceat(values, first)
    return _first_rows(np.flatnonzero(values == least[owner]), owner, len(first))


def _any_per_log(flags: np.ndarray, owner: np.ndarray, n_logs: int) -> np.ndarray:
    return np.bincount(owner[flags], minlength=n_logs) > 0


@functools.lru_cache(maxsize=1)
def _episode_scope() -> ProximityModel:
    """The interaction's proximity model: the default thresholds, every step in scope."""
    return replace(default_proximity_model(), scope=SCOPE_EPISODE)
