"""SUMO's frame conventions and ours, in one place (used by perception, safety and the engine).

SUMO reports a vehicle's position as the middle of its FRONT bumper and its angle in degrees
clockwise from north. pedsafe_sumo works with footprint centres and yaw in radians counter-clockwise
from +x (east). All functions take scalars or numpy arrays.
"""

from __future__ import annotations

import numpy as np


def sumo_angle_to_yaw_rad(angle_deg):
    """SUMO angle (degrees clockwise from north) -> yaw (radians counter-clockwise from east)."""
    return np.deg2rad(90.0 - np.asarray(angle_deg, dtype=float))


def yaw_rad_to_sumo_angle(yaw_rad):
    """Yaw (radians counter-clockwise from east) -> SUMO angle in [0, 360) degrees clockwise from north."""
    return np.mod(90.0 - np.rad2deg(np.asarray(yaw_rad, dtype=float)), 360.0)


def sumo_front_to_centre(x_m, y_m, yaw_rad, length_m):
    """Footprint centre from SUMO's vehicle position (middle of the front bumper): half a length back
    along the heading, world frame, metres."""
    x_m, y_m, yaw_rad, length_m = (np.asarray(a, dtype=float) for a in (x_m, y_m, yaw_rad, length_m))
    return x_m - 0.5 * length_m * np.cos(yaw_rad), y_m - 0.5 * length_m * np.sin(yaw_rad)
