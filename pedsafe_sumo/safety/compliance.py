"""How the ego kept to the rules of the road in one episode, from its per-step log and the signal it had
at every step: braking for a pedestrian who stood still outside its path (for at least a second if they
had walked before), the signal when it crossed the stop line, and whether it could have stopped at the
yellow's onset. Columns of episodes.parquet (docs/columns.md): false_brake, stopline_signal,
could_stop_at_yellow.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

#: Columns of episodes.parquet that `episode_compliance` fills.
COMPLIANCE_COLUMNS = ("false_brake", "stopline_signal", "could_stop_at_yellow")
#: A pedestrian slower than this stands still [m/s] (the logged, true speed): a tenth of a slow walk
#: (older pedestrians' 1.03 m/s mean); V2I's 0.2 m position noise is not in it.
STANDING_SPEED_MPS = 0.2
#: How long a pedestrian who moved must have stood still before a braking step counts as a false brake
#: [s] (one who has stood ever since entering the scene counts at once). A stop must be observable
#: before a stack can release brakes it applied while they walked towards its path: a least-squares
#: velocity through 20 Hz positions with V2I's 0.2 m noise over a window T has a standard deviation of
#: 0.2 x sqrt(12 / (20 T^3)) = 0.155 / T^1.5 m/s, below the 0.2 m/s standing threshold only from
#: T = 0.84 s; exact onboard positions need the estimator's window to pass the stop (0.5 s for the
#: paper-v7 stack's least squares); the reference stack's Kalman filter takes about 1 s on V2I alone
#: (docs/baseline_stack.md). 1 s covers all three; braking later than that is charged.
#: Measurement: docs/decisions/2026-11-27-false-brake-definition.md.
MIN_STANDING_S = 1.0
#: The ego's corridor: its half width plus the pedestrian's radius plus this margin on each side of its
#: heading line [m] (the margin of the shipped stacks' corridor, control/reference.py LATERAL_MARGIN_M).
CORRIDOR_MARGIN_M = 0.5
#: A speed command this far below the current speed, per second of step, is braking even where the
#: stack's `braking` flag says nothing [m/s2]. Assumption: above the 0.2-0.5 m/s2 with which rolling and
#: air resistance alone slow a coasting car at urban speeds.
BRAKE_DECEL_MPS2 = 1.0
#: Comfortable deceleration of the yellow test [m/s2]: 10 ft/s2 (3.05 m/s2), the deceleration of ITE's
#: yellow change interval (Institute of Transportation Engineers, "Determining Vehicle Signal Change and
#: Clearance Intervals", 1994), rounded down.
COMFORTABLE_DECEL_MPS2 = 3.0
#: Colours (scenarios/signals.py colour_of) that ask a vehicle not to enter.
_STOP_COLOURS = ("yellow", "red")


def front_distance_to_line_m(
    log: pd.DataFrame, line_xy_m: tuple[float, float], line_dir: tuple[float, float]
) -> np.ndarray:
    """Per step, the distance from the ego's front (centre + half its length along its heading) to the
    stop line, along the lane's direction at its end (positive: before the line)."""
    yaw = log["ego_yaw_rad"].to_numpy(float)
    half = log["ego_length_m"].to_numpy(float) / 2
    fx = log["ego_x_m"].to_numpy(float) + half * np.cos(yaw)
    fy = log["ego_y_m"].to_numpy(float) + half * np.sin(yaw)
    return (line_xy_m[0] - fx) * line_dir[0] + (line_xy_m[1] - fy) * line_dir[1]


def stop_line_of(
    lane_shape_xy_m: Sequence[tuple[float, float]],
) -> tuple[tuple[float, float], tuple[float, float]]:
    """The stop line of an approach lane: its centreline's end point and the unit direction of its last
    segment."""
    (ax, ay), (bx, by) = lane_shape_xy_m[-2], lane_shape_xy_m[-1]
    length = math.hypot(bx - ax, by - ay) or 1.0
    return (bx, by), ((bx - ax) / length, (by - ay) / length)


def standing_duration_s(time_s: np.ndarray, standing: np.ndarray, present: np.ndarray) -> np.ndarray:
    """Per step, how long the pedestrian has stood still since they last moved in the scene [s]: the
    time since the last step at which they were present and not standing; infinite while they have
    stood ever since they entered the scene (nothing they did suggested motion); 0 at a step where they
    move or are absent."""
    n = len(time_s)
    if n == 0:
        return np.zeros(0)
    moving = present & ~standing
    index = np.arange(n)
    # Index of the last moving step at or before each step (-1: none yet).
    last = np.maximum.accumulate(np.where(moving, index, -1))
    since = np.where(last >= 0, time_s - time_s[np.maximum(last, 0)], np.inf)
    return np.where(standing & present, since, 0.0)


def false_brake(
    log: pd.DataFrame,
    ego_colours: Sequence[str],
    ped_colours: Sequence[str],
    before_line: np.ndarray,
    min_standing_s: float = MIN_STANDING_S,
) -> bool:
    """Whether the ego braked (its `braking` flag, or a command BRAKE_DECEL_MPS2 x the step below its
    speed) at a step where it perceived the pedestrian, who stood still (true speed below
    STANDING_SPEED_MPS) since entering the scene or for at least `min_standing_s` since they last moved
    (standing_duration_s), outside its corridor (lateral offset from its heading line beyond half its
    width, the pedestrian's radius and CORRIDOR_MARGIN_M, or behind its rear), with neither a yellow or
    red ahead of it (front before the stop line) nor a walk signal for the pedestrian (yielding to
    someone about to cross on walk is no false brake)."""
    if not len(log):
        return False
    time_s = log["time_s"].to_numpy(float)
    step_s = np.diff(time_s, prepend=time_s[0] - (time_s[1] - time_s[0] if len(time_s) > 1 else 0.05))
    speed = log["ego_speed_mps"].to_numpy(float)
    braked = log["braking"].to_numpy(bool) | (
        log["command_speed_mps"].to_numpy(float) < speed - BRAKE_DECEL_MPS2 * step_s
    )
    yaw = log["ego_yaw_rad"].to_numpy(float)
    dx = log["ped_x_m"].to_numpy(float) - log["ego_x_m"].to_numpy(float)
    dy = log["ped_y_m"].to_numpy(float) - log["ego_y_m"].to_numpy(float)
    lon = dx * np.cos(yaw) + dy * np.sin(yaw)
    lat = -dx * np.sin(yaw) + dy * np.cos(yaw)
    half_corridor = (
        log["ego_width_m"].to_numpy(float) / 2 + log["ped_radius_m"].to_numpy(float) + CORRIDOR_MARGIN_M
    )
    outside = (np.abs(lat) > half_corridor) | (lon < -log["ego_length_m"].to_numpy(float) / 2)
    standing = (
        np.hypot(log["ped_vx_mps"].to_numpy(float), log["ped_vy_mps"].to_numpy(float)) < STANDING_SPEED_MPS
    )
    present = np.isfinite(log["ped_x_m"].to_numpy(float))
    stood = standing_duration_s(time_s, standing, present) >= min_standing_s - 1e-9
    signal_stop = np.isin(np.asarray(ego_colours), _STOP_COLOURS) & before_line
    walk = np.asarray(ped_colours) == "green"
    found = braked & log["perceived"].to_numpy(bool) & stood & outside & ~signal_stop & ~walk
    return bool(found.any())


def episode_compliance(
    log: pd.DataFrame,
    ego_colours: Sequence[str],
    ped_colours: Sequence[str],
    stop_line: tuple[tuple[float, float], tuple[float, float]] | None,
    comfortable_decel_mps2: float = COMFORTABLE_DECEL_MPS2,
) -> dict[str, Any]:
    """The compliance columns of one episode. `ego_colours`, `ped_colours`: the colour (green, yellow,
    red, none) of each road user's signal at every logged step; `stop_line`: the stop line of the ego's
    approach lane (stop_line_of), None when it has none.

    stopline_signal: the ego's colour at the first step its front is past the stop line (none: no stop
    line or signal, it started past it, or it never crossed). could_stop_at_yellow: at the first step of
    a yellow while its front was before the line, whether v^2 / (2 a) <= the distance to it (NA: no
    yellow began before it crossed)."""
    n = len(log)
    if stop_line is None or n == 0:
        before = np.ones(n, dtype=bool)
        distance = np.full(n, np.nan)
    else:
        distance = front_distance_to_line_m(log, *stop_line)
        before = distance > 0
    result: dict[str, Any] = {
        "false_brake": false_brake(log, ego_colours, ped_colours, before),
        "stopline_signal": "none",
        "could_stop_at_yellow": None,
    }
    if stop_line is None or n == 0 or not before[0]:
        return result
    crossed = np.flatnonzero(~before)
    cross = int(crossed[0]) if len(crossed) else n
    if cross < n:
        result["stopline_signal"] = ego_colours[cross]
    speed = log["ego_speed_mps"].to_numpy(float)
    for k in range(cross):
        if ego_colours[k] == "yellow" and (k == 0 or ego_colours[k - 1] != "yellow"):
            stopping_m = speed[k] ** 2 / (2 * comfortable_decel_mps2)
            result["could_stop_at_yellow"] = bool(stopping_m <= distance[k])
            break
    return result
