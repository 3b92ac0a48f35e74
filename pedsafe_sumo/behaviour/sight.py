"""A pedestrian's line of sight to a vehicle, through the geometry the sensors see.

The pedestrian reacts to the ego only when they can see it: rays from their eyes to a few
points of the ego are cast with the perception layer's ray casting (`perception.raycast.cast_rays`)
through the same world snapshot as the sensors: buildings, tree trunks and crowns, hedges and every
vehicle box. Pure geometry, no SUMO.
"""

from __future__ import annotations

import math

import numpy as np

from pedsafe_sumo.perception.raycast import cast_rays
from pedsafe_sumo.perception.surfaces import KIND_VEHICLE
from pedsafe_sumo.perception.world import WorldSnapshot

#: Points of the vehicle a pedestrian looks for: along its centreline at these fractions of its half
#: length (front, middle, rear), at SIGHT_TARGET_HEIGHT_FRACTION of its height (about the windows).
#: One ray each: any part of the car in view is enough to notice it.
SIGHT_TARGETS_HALF_LENGTH = (0.9, 0.0, -0.9)
SIGHT_TARGET_HEIGHT_FRACTION = 0.8


def ego_in_sight(
    snapshot: WorldSnapshot, ego_index: int, eye_xyz: tuple[float, float, float], looker_index: int = 0
) -> bool:
    """Whether eyes at `eye_xyz` (world frame, m) see vehicle `ego_index` of the snapshot.

    One ray per point of SIGHT_TARGETS_HALF_LENGTH; pedestrian `looker_index` (the one looking, whose
    own body the rays start in) is skipped. In sight when any ray's first hit is the vehicle's own box.
    """
    vehicles = snapshot.vehicles
    cx, cy = vehicles.x_m[ego_index], vehicles.y_m[ego_index]
    yaw, half_l = vehicles.yaw_rad[ego_index], 0.5 * vehicles.length_m[ego_index]
    fractions = np.asarray(SIGHT_TARGETS_HALF_LENGTH)
    n = len(fractions)
    targets = np.column_stack(
        (
            cx + fractions * half_l * math.cos(yaw),
            cy + fractions * half_l * math.sin(yaw),
            np.full(n, SIGHT_TARGET_HEIGHT_FRACTION * vehicles.height_m[ego_index]),
        )
    )
    origin = np.ascontiguousarray(np.broadcast_to(np.asarray(eye_xyz, dtype=float), targets.shape))
    delta = targets - origin
    distance = np.linalg.norm(delta, axis=1)
    hits = cast_rays(
        snapshot,
        origin,
        delta / distance[:, None],
        distance + 1e-6,
        np.arange(n, dtype=np.int64),  # one ray per group
        np.ones(n, dtype=np.int64),
        np.full(n, looker_index, dtype=np.int64),
    )
    return bool(np.any((hits.kind == KIND_VEHICLE) & (hits.index == ego_index)))
