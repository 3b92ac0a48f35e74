"""All safety indexes of one episode, under the column names of `episodes.parquet` (docs/design.md,
'Contracts')."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.collision import detect_collision
from pedsafe_sumo.safety.conflict import AMINI_2022, ConflictModel, episode_conflict
from pedsafe_sumo.safety.detection import first_detection
from pedsafe_sumo.safety.injury import SEVERE_INJURY_MODEL, episode_injury
from pedsafe_sumo.safety.proximity import ProximityModel, default_proximity_model, episode_proximity
from pedsafe_sumo.safety.surrogates import min_ttc_s, pet_s

#: The columns of episodes.parquet that `episode_indexes` fills, in the order of docs/design.md, 'Contracts'.
INDEX_COLUMNS = (
    "collision",
    "impact_speed_mps",
    "injury_probability",
    "conflict",
    "md_m",
    "tmd_s",
    "cs_mps",
    "conflict_probability",
    "min_ttc_s",
    "pet_s",
    "first_detection_distance_m",
    "first_detection_time_s",
    "detected_by",
    # the proximity measure: close passes whatever the pedestrian's speed
    "min_clearance_m",
    "ego_speed_at_min_clearance_mps",
    "drac_mps2",
    "close_pass",
    # contact with a standing ego: neither a collision nor an injury
    "contact_stationary",
    # a second injury index at a stated severity: P(MAIS 3+ or fatal), 0 without a collision
    "injury_mais3f_probability",
)


#: The indexes of an episode in whose log the pedestrian is never in the scene.
NO_PEDESTRIAN_INDEXES: dict[str, Any] = {
    "collision": False,
    "impact_speed_mps": math.nan,
    "injury_probability": 0.0,
    "conflict": False,
    "md_m": math.nan,
    "tmd_s": math.nan,
    "cs_mps": math.nan,
    "conflict_probability": math.nan,
    "min_ttc_s": math.nan,
    "pet_s": math.nan,
    "first_detection_distance_m": math.nan,
    "first_detection_time_s": math.nan,
    "detected_by": "",
    "min_clearance_m": math.nan,
    "ego_speed_at_min_clearance_mps": math.nan,
    "drac_mps2": math.nan,
    "close_pass": False,
    "contact_stationary": False,
    "injury_mais3f_probability": 0.0,
}


def steps_with_pedestrian(log: Any) -> Any:
    """The steps of an engine's log at which the pedestrian is in the scene: the log contract's rows
    (safety.log). The engine logs the steps before they appear and after they leave with a NaN position
    (ped_state "absent", "left"); those are dropped. The log itself when it has none (or no position
    columns: `steplog.as_arrays` then names what it lacks)."""
    names = log.columns if hasattr(log, "columns") else log.keys() if hasattr(log, "keys") else ()
    if steplog.PED_X not in names or steplog.PED_Y not in names:
        return log
    x = np.asarray(log[steplog.PED_X], dtype=float).reshape(-1)
    y = np.asarray(log[steplog.PED_Y], dtype=float).reshape(-1)
    present = np.isfinite(x) & np.isfinite(y)
    if present.all():
        return log
    if hasattr(log, "iloc"):
        return log[present].reset_index(drop=True)
    return {name: np.asarray(values).reshape(-1)[present] for name, values in log.items()}


def episode_indexes(
    log: Any,
    ped_age_years: float,
    injury_model: str = "saade2020",
    conflict_model: ConflictModel = AMINI_2022,
    proximity_model: ProximityModel | None = None,
    severe_injury_model: str = SEVERE_INJURY_MODEL,
) -> dict[str, Any]:
    """The safety indexes of one episode's per-step log (see `pedsafe_sumo.safety.log` for the contract).

    A collision is contact while the ego moves (at STATIONARY_SPEED_MPS or faster); contact with a
    standing ego is `contact_stationary`, neither a collision nor an injury. Conflict measures and TTC
    are taken over the steps up to and including the first collision step (all steps without a
    collision): what follows a collision says nothing about the encounter. PET is 0 for an
    episode with a collision (the two met), else computed from the whole trajectories. `conflict` is the
    raw flag; Table I counts `conflict and not collision` (`conflict_without_collision`).
    Values that do not exist are NaN (impact speed without a collision, measures without a candidate
    step, detection distance when never perceived); `injury_probability` is 0 without a collision.
    The proximity measures (`min_clearance_m`, `ego_speed_at_min_clearance_mps`, `drac_mps2`,
    `close_pass`) take the conflict measures' window; `proximity_model` None: the defaults file's.
    `injury_mais3f_probability` is `injury_probability` under `severe_injury_model` (any registered
    name; by default the MAIS 3+F risk of Monfort & Mueller 2025).
    Only the steps with the pedestrian in the scene count (`steps_with_pedestrian`); without any, the
    indexes are NO_PEDESTRIAN_INDEXES.
    """
    present = steps_with_pedestrian(log)
    if present is not log and not len(present[steplog.PED_X]):
        return dict(NO_PEDESTRIAN_INDEXES)
    log = present
    arrays = steplog.as_arrays(log)
    hit = detect_collision(arrays)
    conflict = episode_conflict(arrays, conflict_model, last_step=hit.step)
    detection = first_detection(arrays)
    proximity = episode_proximity(arrays, proximity_model or default_proximity_model(), hit.step)
    return {
        "collision": hit.collided,
        "impact_speed_mps": hit.impact_speed_mps,
        "injury_probability": episode_injury(hit.collided, hit.impact_speed_mps, ped_age_years, injury_model),
        "conflict": conflict.conflict,
        "md_m": conflict.md_m,
        "tmd_s": conflict.tmd_s,
        "cs_mps": conflict.cs_mps,
        "conflict_probability": conflict.conflict_probability,
        "min_ttc_s": min_ttc_s(arrays, last_step=hit.step),
        "pet_s": 0.0 if hit.collided else pet_s(arrays),
        "first_detection_distance_m": detection.distance_m,
        "first_detection_time_s": detection.time_s,
        "detected_by": detection.detected_by,
        "min_clearance_m": proximity.min_clearance_m,
        "ego_speed_at_min_clearance_mps": proximity.ego_speed_at_min_clearance_mps,
        "drac_mps2": proximity.drac_mps2,
        "close_pass": proximity.close_pass,
        "contact_stationary": hit.contact_stationary,
        "injury_mais3f_probability": episode_injury(
            hit.collided, hit.impact_speed_mps, ped_age_years, severe_injury_model
        ),
    }
