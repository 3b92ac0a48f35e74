"""Collision: the first step at which the moving ego's footprint touches the pedestrian's circle.

A collision is the ego striking the pedestrian: contact (clearance <= 0) while the ego moves at
`STATIONARY_SPEED_MPS` or faster. Contact while the ego stands (slower than that) is recorded apart,
as `contact_stationary`: it is neither a collision nor an injury (eq. 4 has a non-zero intercept, so
counting a 0 km/h touch as an impact would give it an injury probability of 0.07-0.30).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import rectangle_circle_distance_m

#: Below this ego speed a contact is a stationary contact, not a collision [m/s]: the 0.1 m/s
#: below which the ego counts as standing, as in the pedestrian behaviour model.
STATIONARY_SPEED_MPS = 0.1


@dataclass(frozen=True)
class CollisionResult:
    collided: bool
    #: index of the first step in contact while the ego moves (None without a collision)
    step: int | None
    #: simulation time of that step, s (NaN without a collision)
    time_s: float
    #: ego speed logged at that step, m/s (NaN without a collision; >= STATIONARY_SPEED_MPS with one)
    impact_speed_mps: float
    #: contact while the ego stood (slower than STATIONARY_SPEED_MPS) before any collision
    contact_stationary: bool = False


def clearance_m(arrays: Mapping[str, np.ndarray]) -> np.ndarray:
    """Per-step signed clearance between the ego footprint and the pedestrian circle, m (<= 0: contact)."""
    return rectangle_circle_distance_m(
        arrays[steplog.EGO_X],
        arrays[steplog.EGO_Y],
        arrays[steplog.EGO_YAW],
        arrays[steplog.EGO_LENGTH],
        arrays[steplog.EGO_WIDTH],
        arrays[steplog.PED_X],
        arrays[steplog.PED_Y],
        arrays[steplog.PED_RADIUS],
    )


def detect_collision(log: Any) -> CollisionResult:
    """The first logged step whose footprint and circle touch (clearance <= 0) while the ego moves.

    Contact is found at the log's step resolution: the time is that step's time, and the impact speed
    is the ego speed logged at that step. Steps in contact at a speed below STATIONARY_SPEED_MPS
    before it make `contact_stationary` true (and without a later moving contact there is no collision).
    """
    arrays = steplog.as_arrays(log)
    return collision_of_steps(clearance_m(arrays), arrays[steplog.EGO_SPEED], arrays[steplog.TIME])


def collision_of_steps(
    clearance: np.ndarray, ego_speed_mps: np.ndarray, time_s: np.ndarray
) -> CollisionResult:
    """`detect_collision` from a log's per-step clearance (`clearance_m`), ego speed and time."""
    contact = clearance <= 0.0
    moving = ego_speed_mps >= STATIONARY_SPEED_MPS
    strikes = np.flatnonzero(contact & moving)
    if strikes.size == 0:
        return CollisionResult(False, None, math.nan, math.nan, bool(contact.any()))
    k = int(strikes[0])
    return CollisionResult(True, k, float(time_s[k]), float(ego_speed_mps[k]), bool(contact[:k].any()))
