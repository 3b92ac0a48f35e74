"""Pedestrian-vehicle conflicts after Amini, Yang & Antoniou 2022 (Accid. Anal. Prev. 175:106773).

Per step, both road users are extrapolated at constant velocity:
- candidate: the two straight paths (lines through each centre along its velocity) cross at a conflict
  point that neither has passed, and |TTC_vehicle - TTC_pedestrian| <= 3 s, where TTC_x is the distance
  of x's centre to the conflict point divided by x's speed. A road user standing still has no path.
- MD (m), TMD (s): minimum future distance between the two *centres* and the time to it,
  t* = max(0, -(dp.dv)/|dv|^2) (0 when dv = 0), MD = |dp + dv t*|, dp = p_ped - p_ego, dv = v_ped - v_ego.
  Centre distance, as the model was fitted on tracked centre points (see docs/safety_indexes.md).
- CS (m/s): ego speed at the minimum-distance moment; under constant velocity its current speed.
- risk p = sigmoid(4.327 - 2.898 MD - 3.067 TMD + 0.376 CS); a step is a conflict when it is a
  candidate, p >= 0.425 and CS > 1 m/s (speed evidence after Schmidt et al. 2019).

An episode has a conflict when any step does. Table I counts a conflict only without a collision:
`conflict_without_collision` is that rule; the `conflict` column holds the raw flag.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import FloatOrArray
from pedsafe_sumo.safety.logistic import expit

if TYPE_CHECKING:  # pandas only in annotations: importing it costs the conflicts tool 0.3 s
    import pandas as pd

#: Below this speed a road user is standing and has no path, m/s.
STANDING_SPEED_MPS = 1e-6


@dataclass(frozen=True)
class ConflictModel:
    """The pedestrian-car risk model of Amini et al. 2022 with the thresholds of docs/design.md, 'Sources of
    numbers'."""

    intercept: float = 4.327
    md_coef_per_m: float = -2.898
    tmd_coef_per_s: float = -3.067
    cs_coef_per_mps: float = 0.376
    #: a step is a conflict at or above this probability
    probability_threshold: float = 0.425
    #: ... and only above this conflicting speed, m/s (Schmidt et al. 2019)
    min_conflicting_speed_mps: float = 1.0
    #: candidate test: largest |TTC_vehicle - TTC_pedestrian|, s
    max_ttc_difference_s: float = 3.0

    def probability(self, md_m: FloatOrArray, tmd_s: FloatOrArray, cs_mps: FloatOrArray) -> np.ndarray:
        return expit(
            self.intercept
            + self.md_coef_per_m * np.asarray(md_m, dtype=float)
            + self.tmd_coef_per_s * np.asarray(tmd_s, dtype=float)
            + self.cs_coef_per_mps * np.asarray(cs_mps, dtype=float)
        )


AMINI_2022 = ConflictModel()


def minimum_distance(
    dpx_m: FloatOrArray, dpy_m: FloatOrArray, dvx_mps: FloatOrArray, dvy_mps: FloatOrArray
) -> tuple[np.ndarray, np.ndarray]:
    """(MD in m, TMD in s) of a relative position dp and relative velocity dv under constant velocity."""
    dpx, dpy = np.asarray(dpx_m, dtype=float), np.asarray(dpy_m, dtype=float)
    dvx, dvy = np.asarray(dvx_mps, dtype=float), np.asarray(dvy_mps, dtype=float)
    dv2 = dvx * dvx + dvy * dvy
    with np.errstate(divide="ignore", invalid="ignore"):
        t_star = np.where(dv2 > 0.0, np.maximum(0.0, -(dpx * dvx + dpy * dvy) / dv2), 0.0)
    return np.hypot(dpx + dvx * t_star, dpy + dvy * t_star), t_star


def path_crossing_times_s(
    ego_x_m: FloatOrArray,
    ego_y_m: FloatOrArray,
    ego_vx_mps: FloatOrArray,
    ego_vy_mps: FloatOrArray,
    ped_x_m: FloatOrArray,
    ped_y_m: FloatOrArray,
    ped_vx_mps: FloatOrArray,
    ped_vy_mps: FloatOrArray,
) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) for the ego and the pedestrian to reach the crossing point of their straight paths.

    Solves p_ego + v_ego s = p_ped + v_ped u. Negative when the point is behind; NaN when there is no
    crossing point (parallel paths, or a road user standing still).
    """
    dpx = np.asarray(ped_x_m, dtype=float) - ego_x_m
    dpy = np.asarray(ped_y_m, dtype=float) - ego_y_m
    evx, evy = np.asarray(ego_vx_mps, dtype=float), np.asarray(ego_vy_mps, dtype=float)
    pvx, pvy = np.asarray(ped_vx_mps, dtype=float), np.asarray(ped_vy_mps, dtype=float)
    cross = evx * pvy - evy * pvx
    ego_speed, ped_speed = np.hypot(evx, evy), np.hypot(pvx, pvy)
    ok = (ego_speed > STANDING_SPEED_MPS) & (ped_speed > STANDING_SPEED_MPS)
    ok &= np.abs(cross) > 1e-9 * ego_speed * ped_speed
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (dpx * pvy - dpy * pvx) / cross
        u = (dpx * evy - dpy * evx) / cross
    return np.where(ok, s, np.nan), np.where(ok, u, np.nan)


def conflict_steps(log: pd.DataFrame, model: ConflictModel = AMINI_2022) -> pd.DataFrame:
    """The per-step conflict measures of a log: one row per step.

    Columns: time_s, ttc_vehicle_s, ttc_pedestrian_s (to the conflict point, NaN if the paths do not
    cross), candidate, md_m, tmd_s, cs_mps, conflict_probability, conflict (candidate and p over the
    threshold and CS over the minimum speed).
    """
    import pandas as pd  # here, not at the top: the conflicts tool never calls this; 0.3 s of its start-up

    return pd.DataFrame(_conflict_columns(log, model))


def _conflict_columns(log: Any, model: ConflictModel) -> dict[str, np.ndarray]:
    """The columns of `conflict_steps` as arrays (no DataFrame: `episode_conflict` runs once per
    interaction, and building a DataFrame cost more than the measures themselves)."""
    return conflict_columns_of_rows(steplog.as_arrays(log), model)


def conflict_columns_of_rows(a: Mapping[str, np.ndarray], model: ConflictModel) -> dict[str, np.ndarray]:
    """The columns of `conflict_steps` of rows of columns in the log contract's names, checked by the
    caller. Each row stands alone (no time order): the rows of many logs can be stacked into one call."""
    evx, evy = steplog.ego_velocity_mps(a)
    dpx, dpy = a[steplog.PED_X] - a[steplog.EGO_X], a[steplog.PED_Y] - a[steplog.EGO_Y]
    md, tmd = minimum_distance(dpx, dpy, a[steplog.PED_VX] - evx, a[steplog.PED_VY] - evy)
    cs = a[steplog.EGO_SPEED]
    s, u = path_crossing_times_s(
        a[steplog.EGO_X],
        a[steplog.EGO_Y],
        evx,
        evy,
        a[steplog.PED_X],
        a[steplog.PED_Y],
        a[steplog.PED_VX],
        a[steplog.PED_VY],
    )
    with np.errstate(invalid="ignore"):
        candidate = (s >= 0.0) & (u >= 0.0) & (np.abs(s - u) <= model.max_ttc_difference_s)
    p = model.probability(md, tmd, cs)
    conflict = candidate & (p >= model.probability_threshold) & (cs > model.min_conflicting_speed_mps)
    return {
        "time_s": a[steplog.TIME],
        "ttc_vehicle_s": s,
        "ttc_pedestrian_s": u,
        "candidate": candidate,
        "md_m": md,
        "tmd_s": tmd,
        "cs_mps": cs,
        "conflict_probability": p,
        "conflict": conflict,
    }


@dataclass(frozen=True)
class ConflictResult:
    #: some step is a conflict (raw flag: says nothing about a collision)
    conflict: bool
    #: the reported step: the eligible step (candidate with CS over the minimum) of highest p; None if none
    step: int | None
    md_m: float
    tmd_s: float
    cs_mps: float
    conflict_probability: float


def episode_conflict(
    log: pd.DataFrame, model: ConflictModel = AMINI_2022, last_step: int | None = None
) -> ConflictResult:
    """The episode's conflict flag and the measures at its riskiest eligible step.

    Eligible steps are candidates whose CS exceeds the minimum conflicting speed; among them the one of
    highest p (the first on a tie) is reported, so `conflict == (conflict_probability >= threshold)`.
    Steps after `last_step` (e.g. after the first contact) are ignored. All NaN without an eligible step.
    """
    return conflict_of_columns(_conflict_columns(log, model), model, last_step)


def conflict_of_columns(
    columns: Mapping[str, np.ndarray], model: ConflictModel = AMINI_2022, last_step: int | None = None
) -> ConflictResult:
    """`episode_conflict` from a log's `conflict_columns_of_rows`."""
    stop = None if last_step is None else last_step + 1
    candidate, cs = columns["candidate"][:stop], columns["cs_mps"][:stop]
    eligible = candidate & (cs > model.min_conflicting_speed_mps)
    if not eligible.any():
        return ConflictResult(False, None, math.nan, math.nan, math.nan, math.nan)
    probability = columns["conflict_probability"][:stop]
    k = int(np.argmax(np.where(eligible, probability, -np.inf)))
    return ConflictResult(
        conflict=bool(columns["conflict"][:stop].any()),
        step=k,
        md_m=float(columns["md_m"][k]),
        tmd_s=float(columns["tmd_s"][k]),
        cs_mps=float(cs[k]),
        conflict_probability=float(probability[k]),
    )


def conflict_without_collision(conflict: FloatOrArray, collision: FloatOrArray) -> np.ndarray:
    """Table I's conflict: a conflict in an episode without a collision (element-wise on arrays)."""
    return np.logical_and(conflict, np.logical_not(collision))
