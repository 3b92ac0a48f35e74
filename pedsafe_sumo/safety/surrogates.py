"""Time to collision (TTC) and post-encroachment time (PET), with the road users' real shapes.

- TTC (s) at a step: the time until the ego's footprint (oriented rectangle) and the pedestrian's circle
  would first touch if both kept their current velocities (the ego does not turn). 0 when touching,
  NaN when they would never touch. The episode's `min_ttc_s` is the smallest over the steps.
- PET (s): the conflict point is where the centre paths actually driven and walked (the logged
  trajectories) first cross. The ego occupies it while it lies inside the footprint, the pedestrian
  while it lies inside the circle; PET is the time from the first road user leaving it to the second
  arriving, 0 if their stays overlap (a collision at the point), NaN if the paths never cross or either
  road user never reaches it. Arrival and departure times between steps are exact for straight motion
  in between. `episode_indexes` sets PET to 0 for an episode with a collision.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import (
    box_signed_distance_m,
    circle_entry_time_s,
    first_polyline_crossing,
    rectangle_circle_contact_time_s,
    slab_entry_time_s,
    to_rectangle_frame,
)

if TYPE_CHECKING:  # pandas only in annotations: importing it costs the conflicts tool 0.3 s
    import pandas as pd


def ttc_steps_s(log: pd.DataFrame) -> np.ndarray:
    """Per-step TTC, s (NaN where the two would never touch under constant velocity)."""
    return ttc_of_rows(steplog.as_arrays(log))


def ttc_of_rows(a: Mapping[str, np.ndarray]) -> np.ndarray:
    """TTC of each row of columns in the log contract's names and units, checked by the caller, s (NaN
    where never touching). Each row stands alone (no time order): the rows of many logs can be stacked
    into one call, each row's TTC the same as in its own log's `ttc_steps_s`."""
    evx, evy = steplog.ego_velocity_mps(a)
    yaw = a[steplog.EGO_YAW]
    lx, ly = to_rectangle_frame(a[steplog.PED_X], a[steplog.PED_Y], a[steplog.EGO_X], a[steplog.EGO_Y], yaw)
    rvx, rvy = a[steplog.PED_VX] - evx, a[steplog.PED_VY] - evy
    cos, sin = np.cos(yaw), np.sin(yaw)
    lvx, lvy = cos * rvx + sin * rvy, -sin * rvx + cos * rvy
    t = rectangle_circle_contact_time_s(
        lx, ly, lvx, lvy, 0.5 * a[steplog.EGO_LENGTH], 0.5 * a[steplog.EGO_WIDTH], a[steplog.PED_RADIUS]
    )
    return np.where(np.isfinite(t), t + 0.0, np.nan)  # + 0.0 turns -0.0 into 0.0


def min_ttc_s(log: pd.DataFrame, last_step: int | None = None) -> float:
    """Smallest per-step TTC over the steps up to `last_step` (all if None), s; NaN if never on course."""
    ttc = ttc_steps_s(log)
    if last_step is not None:
        ttc = ttc[: last_step + 1]
    return float(np.nanmin(ttc)) if np.isfinite(ttc).any() else math.nan


EntryFraction = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int], float]


def _stay_s(
    times_s: np.ndarray,
    local_x_m: np.ndarray,
    local_y_m: np.ndarray,
    inside: np.ndarray,
    entry: EntryFraction,
) -> tuple[float, float] | None:
    """(arrival, departure) of a road user's first stay on the conflict point, s; None if never on it.

    `local_*` is the point in the road user's frame at each step, `inside` whether the road user covers
    it. Between two steps the point moves on a straight line in that frame; `entry(p, q, v, w, k)` gives
    the fraction of that move (0..1) at which the point starting at (p, q) and moving by (v, w) enters the
    shape of step k. So an arrival or departure between steps is exact for straight motion. An arrival
    before the log starts is -inf, a departure after it ends +inf.
    """
    if not inside.any():
        return None

    def between(k_from: int, k_to: int) -> float:  # moment the point enters the shape going k_from -> k_to
        px, py = local_x_m[k_from], local_y_m[k_from]
        fraction = min(1.0, entry(px, py, local_x_m[k_to] - px, local_y_m[k_to] - py, k_to))
        return float(times_s[k_from] + (times_s[k_to] - times_s[k_from]) * fraction)

    k_in = int(np.argmax(inside))
    arrival = -math.inf if k_in == 0 else between(k_in - 1, k_in)
    outside_after = np.flatnonzero(~inside[k_in:])
    departure = math.inf
    if outside_after.size:
        k_out = k_in + int(outside_after[0])
        departure = between(k_out, k_out - 1)  # leaving forwards = entering backwards
    return arrival, departure


def pet_s(log: pd.DataFrame) -> float:
    """Post-encroachment time at the first crossing of the logged centre paths, s (NaN if none)."""
    a = steplog.as_arrays(log)
    point = first_polyline_crossing(a[steplog.EGO_X], a[steplog.EGO_Y], a[steplog.PED_X], a[steplog.PED_Y])
    return pet_at_crossing_s(a, point)


def pet_at_crossing_s(a: Mapping[str, np.ndarray], point: tuple[float, float] | None) -> float:
    """`pet_s` of a log's checked columns, given the first crossing of its centre paths
    (`first_polyline_crossing`, None if they never cross) found by the caller."""
    if point is None:
        return math.nan
    px, py = point
    t = a[steplog.TIME]
    half_l, half_w, radius = 0.5 * a[steplog.EGO_LENGTH], 0.5 * a[steplog.EGO_WIDTH], a[steplog.PED_RADIUS]
    # the point in the ego's frame, and relative to the pedestrian's centre
    ex, ey = to_rectangle_frame(px, py, a[steplog.EGO_X], a[steplog.EGO_Y], a[steplog.EGO_YAW])
    qx, qy = px - a[steplog.PED_X], py - a[steplog.PED_Y]
    ego = _stay_s(
        t,
        ex,
        ey,
        box_signed_distance_m(ex, ey, half_l, half_w) <= 0.0,
        lambda p, q, v, w, k: float(slab_entry_time_s(p, q, v, w, half_l[k], half_w[k])),
    )
    ped = _stay_s(
        t,
        qx,
        qy,
        np.hypot(qx, qy) <= radius,
        lambda p, q, v, w, k: float(circle_entry_time_s(p, q, v, w, 0.0, 0.0, radius[k])),
    )
    if ego is None or ped is None:
        return math.nan
    if max(ego[0], ped[0]) <= min(ego[1], ped[1]):
        return 0.0  # both on the point at once: they met there
    first, second = sorted((ego, ped), key=lambda stay: stay[1])
    return second[0] - first[1]  # disjoint stays: both ends are finite
