"""An independent collision witness: the episode's per-step log judged with shapely's geometry.

SUMO's own collision check sees vehicles on junction lanes against persons on crossings and walking areas
only; everywhere else the loop's verdict (pedsafe_sumo.safety.collision) has no second opinion. The witness
reads the same per-step log and decides, with a separate geometry library and none of the loop's geometry
code, whether and when the moving ego and the pedestrian first touch:

- the ego's footprint is the shapely polygon of its four corners, built from the logged box centre
  (ego_x_m, ego_y_m), heading (ego_yaw_rad, counter-clockwise from +x), length and width;
- the pedestrian's body is `Point(ped_x_m, ped_y_m).buffer(ped_radius_m, quad_segs)`, a polygon inscribed
  in the circle whose chords lie at most `CIRCLE_TOLERANCE_M` inside it (`quad_segs_for`): a touch that
  overlaps the circle by less than that may be missed, never one that is deeper;
- a step is a contact when the two polygons intersect (shapely.intersects), and a collision when the ego
  moves then (ego_speed_mps >= STATIONARY_SPEED_MPS, the definition of a collision shared with the loop);
- steps where the pedestrian is not in the scene (NaN position or radius: the approach staging logs the
  steps before it appears so) are skipped.

A broad phase keeps it cheap: only steps whose centre distance is within the footprint's half diagonal plus
the radius (a bound no contact can exceed) build polygons.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely

from pedsafe_sumo.safety.collision import STATIONARY_SPEED_MPS

#: How far the pedestrian's polygon may lie inside its circle, m: 0.1 mm, a tenth of the 1 mm the witness
#: promises, and far below the logged positions' own step resolution (an ego at 10 m/s moves 0.5 m a step).
CIRCLE_TOLERANCE_M = 1e-4
#: The least number of segments per quarter circle, whatever the radius (shapely's default is 8 or 16).
MIN_QUAD_SEGS = 8
#: The log columns the witness reads.
WITNESS_LOG_COLUMNS = (
    "time_s",
    "ego_x_m",
    "ego_y_m",
    "ego_yaw_rad",
    "ego_speed_mps",
    "ego_length_m",
    "ego_width_m",
    "ped_x_m",
    "ped_y_m",
    "ped_radius_m",
)


@dataclass(frozen=True)
class WitnessVerdict:
    collided: bool
    #: time_s of the first step at which the moving ego and the pedestrian's body touch (NaN without)
    time_s: float
    #: index of that step in the log (None without)
    step: int | None


def quad_segs_for(radius_m: float, tolerance_m: float = CIRCLE_TOLERANCE_M) -> int:
    """Segments per quarter circle so that the inscribed polygon's chords lie at most `tolerance_m` inside
    a circle of `radius_m`: a chord spanning the angle a lies r (1 - cos(a / 2)) inside at its middle, and a
    quarter circle in n chords spans a = (pi / 2) / n each, so n = ceil((pi / 4) / acos(1 - tol / r))."""
    if not radius_m > tolerance_m:
        return MIN_QUAD_SEGS
    return max(MIN_QUAD_SEGS, math.ceil((math.pi / 4) / math.acos(1.0 - tolerance_m / radius_m)))


def ego_footprints(
    x_m: np.ndarray, y_m: np.ndarray, yaw_rad: np.ndarray, length_m: np.ndarray, width_m: np.ndarray
) -> np.ndarray:
    """The ego's footprint at each step as a shapely polygon: its four corners, front left first,
    counter-clockwise. The corners are the centre plus the half length along the heading (cos, sin)
    and the half width across it (-sin, cos)."""
    along_x, along_y = 0.5 * length_m * np.cos(yaw_rad), 0.5 * length_m * np.sin(yaw_rad)
    across_x, across_y = -0.5 * width_m * np.sin(yaw_rad), 0.5 * width_m * np.cos(yaw_rad)
    corners = np.stack(
        [
            np.stack([x_m + sa * along_x + sc * across_x, y_m + sa * along_y + sc * across_y], axis=-1)
            for sa, sc in ((1, 1), (-1, 1), (-1, -1), (1, -1))
        ],
        axis=1,
    )
    return shapely.polygons(corners)


def pedestrian_bodies(x_m: np.ndarray, y_m: np.ndarray, radius_m: np.ndarray) -> np.ndarray:
    """The pedestrian's body at each step: its circle as a polygon within CIRCLE_TOLERANCE_M of it."""
    quad_segs = quad_segs_for(float(np.max(radius_m))) if len(radius_m) else MIN_QUAD_SEGS
    return shapely.buffer(shapely.points(x_m, y_m), radius_m, quad_segs=quad_segs)


def _column(log: Any, name: str) -> np.ndarray:
    return np.asarray(log[name], dtype=float)


def witness_collision(log: Any) -> WitnessVerdict:
    """The witness's verdict on one episode's per-step log (a DataFrame or a mapping of columns).

    The first step at which the ego, moving at STATIONARY_SPEED_MPS or faster, and the pedestrian's body
    intersect; steps without the pedestrian (NaN position or radius) or with a non-finite ego are skipped.
    """
    if isinstance(log, Mapping):
        missing = [c for c in WITNESS_LOG_COLUMNS if c not in log]
    else:
        missing = [c for c in WITNESS_LOG_COLUMNS if c not in log.columns]
    if missing:
        raise KeyError(f"the step log lacks {', '.join(missing)}")
    time_s, speed = _column(log, "time_s"), _column(log, "ego_speed_mps")
    ex, ey, yaw = _column(log, "ego_x_m"), _column(log, "ego_y_m"), _column(log, "ego_yaw_rad")
    length, width = _column(log, "ego_length_m"), _column(log, "ego_width_m")
    px, py, radius = _column(log, "ped_x_m"), _column(log, "ped_y_m"), _column(log, "ped_radius_m")
    with np.errstate(invalid="ignore"):
        present = np.isfinite(px) & np.isfinite(py) & np.isfinite(radius)
        present &= np.isfinite(ex) & np.isfinite(ey) & np.isfinite(yaw) & np.isfinite(length)
        present &= np.isfinite(width) & np.isfinite(speed)
        # Broad phase: no point of the footprint lies further from its centre than its half diagonal.
        reach = 0.5 * np.hypot(length, width) + radius
        near = present & (speed >= STATIONARY_SPEED_MPS) & (np.hypot(px - ex, py - ey) <= reach)
    candidates = np.flatnonzero(near)
    if candidates.size == 0:
        return WitnessVerdict(False, math.nan, None)
    c = candidates
    touching = shapely.intersects(
        ego_footprints(ex[c], ey[c], yaw[c], length[c], width[c]), pedestrian_bodies(px[c], py[c], radius[c])
    )
    hits = c[np.asarray(touching, dtype=bool)]
    if hits.size == 0:
        return WitnessVerdict(False, math.nan, None)
    k = int(hits[0])
    return WitnessVerdict(True, float(time_s[k]), k)
