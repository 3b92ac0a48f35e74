"""Collision: the first step at which the ego's footprint touches the pedestrian's circle."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import rectangle_circle_distance_m


@dataclass(frozen=True)
class CollisionResult:
    collided: bool
    #: index of the first step in contact (None without a collision)
    step: int | None
    #: simulation time of that step, s (NaN without a collision)
    time_s: float
    #: ego speed logged at that step, m/s (NaN without a collision)
    impact_speed_mps: float


def clearance_m(arrays: dict[str, np.ndarray]) -> np.ndarray:
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
    """The first logged step whose footprint and circle touch (clearance <= 0).

    Contact is found at the log's step resolution: the time is that step's time, and the impact speed
    is the ego speed logged at that step.
    """
    arrays = steplog.as_arrays(log)
    contact = np.flatnonzero(clearance_m(arrays) <= 0.0)
    if contact.size == 0:
        return CollisionResult(False, None, math.nan, math.nan)
    k = int(contact[0])
    return CollisionResult(True, k, float(arrays[steplog.TIME][k]), float(arrays[steplog.EGO_SPEED][k]))
