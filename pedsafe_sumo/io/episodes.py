"""The episodes.parquet contract (docs/design.md, 'Contracts'): one row per episode and condition.

Written by the batch runner, read by the report; both take the column names and types from here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

#: Columns, in the order of docs/design.md, 'Contracts'.
EPISODE_COLUMNS = (
    "scenario", "condition", "episode", "seed", "ped_age", "ped_gender", "ped_risk", "ped_speed_mps",
    "ego_initial_speed_mps", "collision", "impact_speed_mps", "injury_probability", "conflict", "md_m",
    "tmd_s", "cs_mps", "conflict_probability", "min_ttc_s", "pet_s", "first_detection_distance_m",
    "first_detection_time_s", "detected_by", "sumo_collision", "status", "error",
    # the proximity measure (pedsafe_sumo.safety.proximity)
    "min_clearance_m", "ego_speed_at_min_clearance_mps", "drac_mps2", "close_pass",
    # collision semantics and end conditions (safety.collision, sim.episode)
    "contact_stationary", "end_reason",
    # Signal each road user had at the conflict (green, yellow, red or none).
    "ego_signal", "ped_signal",
    # The arm the ego came in on (N, E, S, W; batch --approach).
    "approach",
    # Importance sampling (sampling/draws.py, docs/sampling.md): the episode's likelihood ratio
    # (1 under plain Monte Carlo), its sampler stage (0..k-1 the cross-entropy pilots, k the final stage;
    # 0 under mc) and its random inputs as JSON.
    "weight", "sampler_stage", "sampler_inputs",
    # Staging (docs/columns.md): the ego's start along its path to the conflict point, when the
    # pedestrian entered the scene, and who struck whom (COLLISION_TYPES).
    "ego_start_distance_m", "ped_appear_time_s", "collision_type",
    # The independent collision witness (safety/witness.py): its verdict and its first contact's time.
    "witness_collision", "witness_collision_time_s",
    # A second injury index at a stated severity (docs/safety_indexes.md): P(MAIS 3+ or fatal).
    "injury_mais3f_probability",
)  # fmt: skip
#: collision_type: no collision; the moving ego's front or corner strikes the pedestrian; the pedestrian
#: walks or runs into the side of the moving ego. A contact with a standing ego is no collision
#: (contact_stationary).
COLLISION_TYPES = ("none", "ego_strikes_pedestrian", "pedestrian_strikes_side")
#: Flags every row states (True or False; an errored episode's writer states False): the Table I rates
#: count them, so a row without one is refused, never filled with a guess.
BOOL_COLUMNS = ("collision", "conflict", "close_pass", "contact_stationary")
#: Flags every row that ran states (True or False): an errored row (status not "ok") that leaves one out
#: states False, as nothing ran to be witnessed; a row that ran without one is refused.
RAN_BOOL_COLUMNS = ("witness_collision",)
#: Booleans that may be unknown (pandas "boolean", null = NA): sumo_collision is null where SUMO does not
#: check vehicle-person contact (a pedestrian off crossings and walking areas at the closest approach).
NULLABLE_BOOL_COLUMNS = ("sumo_collision",)
STRING_COLUMNS = (
    "scenario", "condition", "ped_gender", "ped_risk", "detected_by", "status", "error", "end_reason",
    "ego_signal", "ped_signal", "approach", "sampler_inputs", "collision_type",
)  # fmt: skip
INT_COLUMNS = ("episode", "seed", "sampler_stage")
#: Values of the sampling columns in rows written before they existed (plain Monte Carlo).
SAMPLER_DEFAULTS = {"weight": 1.0, "sampler_stage": 0}
_NOT_FLOAT = (*BOOL_COLUMNS, *RAN_BOOL_COLUMNS, *NULLABLE_BOOL_COLUMNS, *STRING_COLUMNS, *INT_COLUMNS)
FLOAT_COLUMNS = tuple(c for c in EPISODE_COLUMNS if c not in _NOT_FLOAT)
CONDITION_ORDER = {"sv": 0, "v2i": 1}
#: The status of an episode that ran to its end (the others: "error", "timeout").
OK_STATUS = "ok"


class EpisodeRowError(ValueError):
    """A row that breaks the contract: a flag missing or not a boolean."""


def _is_flag(value: Any) -> bool:
    return isinstance(value, (bool, np.bool_))


def to_table(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """Rows in a fixed order (scenario, episode, condition) and fixed dtypes, whatever order they came in.

    EpisodeRowError when a row lacks one of BOOL_COLUMNS or holds something else than a boolean there
    (pandas would turn a NaN or the text "False" into True), or, having run (status "ok"), one of
    RAN_BOOL_COLUMNS; sumo_collision may be missing (unknown).
    """
    table = pd.DataFrame(rows, columns=list(EPISODE_COLUMNS))
    for column, value in SAMPLER_DEFAULTS.items():
        table[column] = table[column].fillna(value)
    for column in RAN_BOOL_COLUMNS:
        unstated = table[column].isna() & (table["status"] != OK_STATUS)
        table[column] = table[column].astype(object).where(~unstated, False)
    for column in (*BOOL_COLUMNS, *RAN_BOOL_COLUMNS):
        values = table[column].astype(object)
        bad = ~values.map(_is_flag).astype(bool)
        if bad.any():
            first = table[bad].iloc[0]
            raise EpisodeRowError(
                f"episode row {first['scenario']}/{first['episode']}/{first['condition']}: {column} is "
                f"{values[bad].iloc[0]!r}, not True or False ({int(bad.sum())} such row(s))"
            )
        table[column] = values.astype(bool)
    for column in NULLABLE_BOOL_COLUMNS:
        values = table[column].astype(object)
        bad = ~values.map(
            lambda v: v is None or v is pd.NA or _is_flag(v) or (isinstance(v, float) and np.isnan(v))
        )
        if bad.astype(bool).any():
            raise EpisodeRowError(
                f"{column} is {values[bad.astype(bool)].iloc[0]!r}: True, False or missing (unknown) only"
            )
        table[column] = table[column].astype("boolean")
    for column in INT_COLUMNS:
        table[column] = table[column].astype("int64")
    for column in STRING_COLUMNS:
        table[column] = table[column].astype(object).where(table[column].notna(), "").astype(str)
    for column in FLOAT_COLUMNS:
        table[column] = table[column].astype(float)
    return sort_rows(table)


def sort_rows(table: pd.DataFrame) -> pd.DataFrame:
    """Rows ordered by (scenario, approach, episode, sv before v2i), index 0..n-1. The key is unique in a
    run, so the order is the same whichever chunks, workers or sessions the rows came from."""
    table = table.sort_values(
        ["scenario", "approach", "episode", "condition"]
        if "approach" in table
        else ["scenario", "episode", "condition"],
        key=lambda s: s.map(CONDITION_ORDER) if s.name == "condition" else s,
        kind="stable",
    )
    return table.reset_index(drop=True)
