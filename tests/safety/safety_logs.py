"""Hand-built per-step logs with known answers.

The standard encounter: the ego (4 m x 2 m, yaw 0) drives along +x on y = 0 at 10 m/s; the pedestrian
(radius 0.3 m) walks along +y on x = 0 at 1.5 m/s. Their centre paths cross at the origin. Log steps of
0.1 s from 0 to 5 s.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

DT_S = 0.1
EGO_SPEED_MPS = 10.0
PED_SPEED_MPS = 1.5


def make_log(time_s, **columns) -> pd.DataFrame:
    """A log over `time_s`: given columns (scalars broadcast), every other column at a neutral default."""
    time_s = np.asarray(time_s, dtype=float)
    defaults = {
        "ego_x_m": 0.0,
        "ego_y_m": 0.0,
        "ego_yaw_rad": 0.0,
        "ego_speed_mps": 0.0,
        "ego_length_m": 4.0,
        "ego_width_m": 2.0,
        "ped_x_m": 50.0,
        "ped_y_m": 50.0,
        "ped_vx_mps": 0.0,
        "ped_vy_mps": 0.0,
        "ped_radius_m": 0.3,
        "detected_onboard_camera": False,
        "detected_onboard_lidar": False,
        "detected_roadside": False,
        "perceived": False,
    }
    data = {"time_s": time_s}
    for name, default in {**defaults, **columns}.items():
        data[name] = np.broadcast_to(np.asarray(columns.get(name, default)), time_s.shape).copy()
    return pd.DataFrame(data)


def crossing_log(ego_x0_m: float, ped_y0_m: float, duration_s: float = 5.0) -> pd.DataFrame:
    """The standard encounter: ego centre starts at (ego_x0_m, 0), pedestrian at (0, ped_y0_m)."""
    t = np.arange(int(round(duration_s / DT_S)) + 1) * DT_S
    return make_log(
        t,
        ego_x_m=ego_x0_m + EGO_SPEED_MPS * t,
        ego_speed_mps=EGO_SPEED_MPS,
        ped_x_m=0.0,
        ped_y_m=ped_y0_m + PED_SPEED_MPS * t,
        ped_vy_mps=PED_SPEED_MPS,
    )
