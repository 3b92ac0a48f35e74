"""Safety indexes computed after the run from the per-step log: pure functions, no SUMO, no plotting.

`episode_indexes(log, ped_age_years, injury_model)` gives one episode's row of `episodes.parquet`;
`stats.table_one` and `stats.paired_mcnemar` turn many rows into the paper's Table I; `proximity` holds
the close-pass measures (minimum clearance, DRAC), usable on any trajectories. The log's
contract (columns, frames, units) is in `pedsafe_sumo.safety.log`; formulas and choices in
docs/safety_indexes.md.
"""

from typing import Any

from pedsafe_sumo.safety.collision import CollisionResult, detect_collision
from pedsafe_sumo.safety.conflict import (
    AMINI_2022,
    ConflictModel,
    ConflictResult,
    conflict_steps,
    conflict_without_collision,
    episode_conflict,
)
from pedsafe_sumo.safety.detection import FirstDetection, first_detection
from pedsafe_sumo.safety.episode import INDEX_COLUMNS, episode_indexes
from pedsafe_sumo.safety.geometry import rectangle_circle_distance_m
from pedsafe_sumo.safety.injury import (
    INJURY_MODELS,
    InjuryModel,
    episode_injury,
    injury_probability,
    register_injury_model,
)
from pedsafe_sumo.safety.log import LogError
from pedsafe_sumo.safety.proximity import (
    ProximityModel,
    ProximityResult,
    clearance_steps_m,
    drac_mps2,
    drac_steps_mps2,
    episode_proximity,
    min_clearance_m,
)
from pedsafe_sumo.safety.surrogates import min_ttc_s, pet_s, ttc_steps_s

#: The statistics of many episodes (`stats`), loaded when first asked for: they need scipy.stats, which
#: the per-episode indexes and the conflicts tool do not (a third of that tool's start-up).
_STATS_NAMES = (
    "mcnemar_exact",
    "paired_counts",
    "paired_mcnemar",
    "table_one",
    "wilson_interval",
    "zero_inflated_mean_interval",
)


def __getattr__(name: str) -> Any:
    if name in _STATS_NAMES:
        from pedsafe_sumo.safety import stats  # on first use: see _STATS_NAMES

        return getattr(stats, name)
    raise AttributeError(f"module 'pedsafe_sumo.safety' has no attribute '{name}'")


__all__ = [
    "AMINI_2022",
    "INDEX_COLUMNS",
    "INJURY_MODELS",
    "CollisionResult",
    "ConflictModel",
    "ConflictResult",
    "FirstDetection",
    "InjuryModel",
    "LogError",
    "ProximityModel",
    "ProximityResult",
    "conflict_steps",
    "conflict_without_collision",
    "clearance_steps_m",
    "detect_collision",
    "drac_mps2",
    "drac_steps_mps2",
    "episode_conflict",
    "episode_indexes",
    "episode_injury",
    "episode_proximity",
    "first_detection",
    "injury_probability",
    "mcnemar_exact",
    "min_clearance_m",
    "min_ttc_s",
    "paired_counts",
    "paired_mcnemar",
    "pet_s",
    "rectangle_circle_distance_m",
    "register_injury_model",
    "table_one",
    "ttc_steps_s",
    "wilson_interval",
    "zero_inflated_mean_interval",
]
