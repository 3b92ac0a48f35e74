"""Hand-built scenes for the perception tests.

Scene frame: the ego's box centre at the origin heading east (yaw 0), so the onboard camera sits at
(1.5, 0, 1.6) looking along +x and the LiDAR at (0, 0, 1.9).
"""

from __future__ import annotations

import numpy as np

from pedsafe_sumo.params import with_overrides
from pedsafe_sumo.perception import (
    EgoPose,
    Pedestrians,
    RoadsideUnit,
    SensorSuite,
    StaticOccluders,
    VehicleBoxes,
    WorldSnapshot,
)

RED = (200, 30, 30)
BLUE = (30, 60, 160)
YELLOW = (230, 200, 40)


def make_suite(params, overrides=None, units=()):
    p = with_overrides(params, overrides or {})
    return SensorSuite.from_params(p["perception"], units)


def ego_box(colour=(255, 255, 255)):
    return ("ego", 0.0, 0.0, 0.0, 4.5, 1.8, 1.5, colour)


def world(vehicles=(), peds=(), static=None, time_s=0.0):
    """vehicles: (id, x, y, yaw, length, width, height, rgb); peds: (id, x, y, radius, height, rgb)."""
    v = list(vehicles)
    vb = VehicleBoxes.build(*[[row[k] for row in v] for k in range(8)]) if v else VehicleBoxes.empty()
    p = list(peds)
    pb = Pedestrians.build(*[[row[k] for row in p] for k in range(6)]) if p else Pedestrians.empty()
    return WorldSnapshot(time_s, vb, pb, static if static is not None else StaticOccluders.empty())


EGO = EgoPose(0.0, 0.0, 0.0, "ego")


def pole(x=22.0, y=-12.0, height=6.0, sumo_yaw_deg=0.0, pitch_deg=30.0):
    """A roadside camera; sumo_yaw_deg 0 looks north."""
    return RoadsideUnit(
        "rsu_camera_0", x, y, height, float(np.radians(90.0 - sumo_yaw_deg)), float(np.radians(pitch_deg))
    )
