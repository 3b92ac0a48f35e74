"""Per-cell metrics of a Euro NCAP run, from its per-step log: TTC at brake onset, warning time, speed
reduction, peak deceleration.

- **Commanded deceleration** of a step: (the ego's speed - the speed the stack commands) / step length,
  what the stack asks of the next step. **Brake onset** is the first logged step at which it reaches
  protocol.toml `[metrics] brake_onset_decel_mps2`.
- **TTC** of a step, along the ego's path: the gap from the ego's front to the dummy's circle along the
  ego's heading, over the closing speed (the ego's speed minus the dummy's velocity along the ego's
  heading); infinite when not closing. For a dummy on a collision course at constant speeds it is the
  time left to the nominal impact.
- **Warning time**: the TTC at the first step whose log column `warning` is true. The agent interface
  (control/agent.py Command) has no warning output and the log no such column, so it is NaN for every
  stack here (`WARNING_ABSENT` says why).
- **Speed reduction**: the test speed minus the ego's speed at the first step of contact; the whole test
  speed when the cell is avoided (full avoidance).
- **Peak deceleration**: the largest drop of the ego's logged speed between two steps over the step
  length, up to the end of the run (the collision step included).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.ncap.protocol import KMH_PER_MPS

METRIC_COLUMNS = ("brake_onset_ttc_s", "warning_time_s", "speed_reduction_kmh", "peak_decel_mps2")
WARNING_ABSENT = "no warning output: the agent interface has none and the log no 'warning' column"


def ttc_along_path_s(log: pd.DataFrame) -> np.ndarray:
    """Per step: the ego's front to the dummy's circle along the ego's heading, over the closing speed."""
    cos_yaw, sin_yaw = np.cos(log["ego_yaw_rad"].to_numpy(float)), np.sin(log["ego_yaw_rad"].to_numpy(float))
    dx = log["ped_x_m"].to_numpy(float) - log["ego_x_m"].to_numpy(float)
    dy = log["ped_y_m"].to_numpy(float) - log["ego_y_m"].to_numpy(float)
    gap_m = dx * cos_yaw + dy * sin_yaw - log["ego_length_m"].to_numpy(float) / 2 - log["ped_radius_m"]
    ped_along_mps = log["ped_vx_mps"].to_numpy(float) * cos_yaw + log["ped_vy_mps"].to_numpy(float) * sin_yaw
    closing_mps = log["ego_speed_mps"].to_numpy(float) - ped_along_mps
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc = np.where(closing_mps > 0, np.maximum(gap_m, 0.0) / closing_mps, math.inf)
    return np.where(np.isnan(gap_m), math.inf, ttc)  # the dummy not in the scene yet


def cell_metrics(
    log: pd.DataFrame,
    step_length_s: float,
    test_speed_kmh: float,
    collided: bool,
    brake_onset_decel_mps2: float,
) -> dict[str, Any]:
    """The four metrics of one run (module docstring); NaN where the run has no such moment."""
    speed = log["ego_speed_mps"].to_numpy(float)
    commanded_decel = (speed - log["command_speed_mps"].to_numpy(float)) / step_length_s
    ttc = ttc_along_path_s(log)
    onset = np.flatnonzero(commanded_decel >= brake_onset_decel_mps2)
    brake_onset_ttc_s = float(ttc[onset[0]]) if onset.size else math.nan
    warning_time_s = math.nan
    if "warning" in log.columns:
        warned = np.flatnonzero(log["warning"].to_numpy(bool))
        warning_time_s = float(ttc[warned[0]]) if warned.size else math.nan
    reduction_kmh = test_speed_kmh - speed[-1] * KMH_PER_MPS if collided else test_speed_kmh
    peak = float(np.max(-np.diff(speed)) / step_length_s) if speed.size > 1 else 0.0
    return {
        "brake_onset_ttc_s": brake_onset_ttc_s,
        "warning_time_s": warning_time_s,
        "speed_reduction_kmh": float(reduction_kmh),
        "peak_decel_mps2": max(peak, 0.0),
    }
