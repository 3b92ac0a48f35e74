"""The per-step log: the contract between the episode engine (which writes it) and the safety indexes.

One row per simulation step at which both the ego vehicle and the pedestrian of the scenario exist.
The engine's step logs also hold the steps before the pedestrian appears and after they leave, with a
NaN position (`ped_state` "absent", "left"): `safety.episode.steps_with_pedestrian` selects this
contract's rows from them (`episode_indexes` does so itself).
A log is a `pandas.DataFrame` or any mapping of column name -> 1-D array of equal length.

Frame and units
---------------
- World frame: SUMO's network frame, x east and y north in metres (the `.net.xml` coordinates).
- `ego_x_m`, `ego_y_m`: the **geometric centre** of the ego's footprint. SUMO reports the centre of the
  *front bumper*; the engine shifts it back by half the length along the heading
  (`sumo_front_to_centre`).
- `ego_yaw_rad`: heading counter-clockwise from +x (east). SUMO's angle is in degrees clockwise from
  north; convert with `sumo_angle_to_yaw_rad`.
- `ego_speed_mps` >= 0 along the heading; the ego velocity is speed * (cos yaw, sin yaw).
- `ego_length_m`, `ego_width_m`: the footprint, an oriented rectangle centred on (ego_x_m, ego_y_m).
- `ped_x_m`, `ped_y_m`: the pedestrian's centre; `ped_vx_mps`, `ped_vy_mps` its velocity in the world
  frame; `ped_radius_m` the radius of the circle that stands for the pedestrian.
- `time_s`: simulation time, strictly increasing.

Detections (booleans, one row per step)
---------------------------------------
- `detected_onboard_camera`, `detected_onboard_lidar`, `detected_roadside`: the sensor saw the
  pedestrian this step *and its output is available to the AD stack under the episode's condition*
  (under `sv` the roadside flag is always False). Further `detected_<sensor>` columns may be added by a
  sensor plugin; they are picked up as sensor names.
- `perceived`: the AD stack's perception output contains the pedestrian this step (after fusion,
  latency and tracking, so it may lag or outlast the raw sensor flags).

Every numeric value must be finite: the engine logs a step only when both road users exist.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre  # noqa: F401 - part of the log API

TIME = "time_s"
EGO_X, EGO_Y, EGO_YAW, EGO_SPEED = "ego_x_m", "ego_y_m", "ego_yaw_rad", "ego_speed_mps"
EGO_LENGTH, EGO_WIDTH = "ego_length_m", "ego_width_m"
PED_X, PED_Y, PED_VX, PED_VY, PED_RADIUS = "ped_x_m", "ped_y_m", "ped_vx_mps", "ped_vy_mps", "ped_radius_m"
PERCEIVED = "perceived"

#: Prefix of the per-sensor detection flags; the rest of the column name is the sensor's name.
SENSOR_PREFIX = "detected_"
#: The sensors every log carries, in the order `detected_by` lists them.
SENSOR_COLUMNS = ("detected_onboard_camera", "detected_onboard_lidar", "detected_roadside")

NUMERIC_COLUMNS = (
    TIME,
    EGO_X,
    EGO_Y,
    EGO_YAW,
    EGO_SPEED,
    EGO_LENGTH,
    EGO_WIDTH,
    PED_X,
    PED_Y,
    PED_VX,
    PED_VY,
    PED_RADIUS,
)
BOOLEAN_COLUMNS = (*SENSOR_COLUMNS, PERCEIVED)
REQUIRED_COLUMNS = NUMERIC_COLUMNS + BOOLEAN_COLUMNS


class LogError(ValueError):
    """A per-step log breaks the contract; the message names the column and the rule."""


class _ValidatedLog(dict[str, np.ndarray]):
    """What `as_arrays` returns: columns already checked. `episode_indexes` hands it to eight index
    functions, each of which calls `as_arrays` again; that call copies the mapping instead of checking
    every column once more (the arrays are shared either way: asarray of a float64 array is itself)."""


def is_validated(log: Any) -> bool:
    """Whether `log` is what `as_arrays` returned: checked, with every required column."""
    return type(log) is _ValidatedLog


def as_arrays(log: Any) -> dict[str, np.ndarray]:
    """Validate a log and return its columns as numpy arrays (float64 or bool), extra sensors included.

    Raises `LogError` on a missing column, an empty log, columns of unequal length, a non-finite or
    out-of-range number, a non-boolean flag, or a time column that does not strictly increase.
    """
    if type(log) is _ValidatedLog:
        return _ValidatedLog(log)
    if not isinstance(log, Mapping) and not hasattr(log, "columns"):
        raise LogError(f"a log is a DataFrame or a mapping of columns, not {type(log).__name__}")
    names = list(log.columns) if hasattr(log, "columns") else list(log.keys())
    missing = [c for c in REQUIRED_COLUMNS if c not in names]
    if missing:
        raise LogError(f"log lacks column(s): {', '.join(missing)}")
    extra_sensors = sorted(c for c in names if c.startswith(SENSOR_PREFIX) and c not in SENSOR_COLUMNS)
    out: dict[str, np.ndarray] = _ValidatedLog()
    for name in NUMERIC_COLUMNS:
        out[name] = np.asarray(log[name], dtype=float).reshape(-1)
    for name in (*BOOLEAN_COLUMNS, *extra_sensors):
        values = np.asarray(log[name])
        if values.dtype != bool:
            if values.dtype.kind not in "iuf" or not np.all(np.isin(values, (0, 1))):
                raise LogError(f"log column {name} must hold booleans")
            values = values.astype(bool)
        out[name] = values.reshape(-1)
    lengths = {len(v) for v in out.values()}
    if len(lengths) != 1:
        raise LogError("log columns differ in length")
    if lengths == {0}:
        raise LogError("log is empty")
    for name in NUMERIC_COLUMNS:
        if not np.all(np.isfinite(out[name])):
            raise LogError(f"log column {name} holds a non-finite value")
    for name in (EGO_SPEED, PED_RADIUS):
        if np.any(out[name] < 0):
            raise LogError(f"log column {name} must not be negative")
    for name in (EGO_LENGTH, EGO_WIDTH):
        if np.any(out[name] <= 0):
            raise LogError(f"log column {name} must be positive")
    if np.any(np.diff(out[TIME]) <= 0):
        raise LogError(f"log column {TIME} must strictly increase")
    return out


def logs_pass(columns: Mapping[str, np.ndarray], starts: Sequence[int]) -> bool:
    """Whether `as_arrays` accepts every one of many logs stacked one after another in `columns` (the
    numeric columns only; log k's rows begin at `starts[k]`, the first at 0), each with its flags all
    False: one pass over all their rows instead of one call per log."""
    n = len(columns[TIME])
    if any(len(columns[name]) != n for name in NUMERIC_COLUMNS) or len(starts) == 0 or starts[0] != 0:
        return False
    if n == 0 or len(set(starts)) != len(starts) or max(starts) >= n:
        return False  # an empty log among them
    if not all(np.all(np.isfinite(np.asarray(columns[name], dtype=float))) for name in NUMERIC_COLUMNS):
        return False
    if np.any(columns[EGO_SPEED] < 0) or np.any(columns[PED_RADIUS] < 0):
        return False
    if np.any(columns[EGO_LENGTH] <= 0) or np.any(columns[EGO_WIDTH] <= 0):
        return False
    rising = np.diff(columns[TIME]) > 0
    rising[np.asarray(starts[1:], dtype=int) - 1] = True  # from one log to the next: no order
    return bool(rising.all())


def sensor_columns(arrays: Mapping[str, np.ndarray]) -> list[str]:
    """The detection-flag columns of a validated log: the standard three first, then plugins' sorted."""
    extra = sorted(c for c in arrays if c.startswith(SENSOR_PREFIX) and c not in SENSOR_COLUMNS)
    return [*SENSOR_COLUMNS, *extra]


def ego_velocity_mps(arrays: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Ego velocity (vx, vy) in the world frame, m/s: speed along the heading."""
    speed, yaw = arrays[EGO_SPEED], arrays[EGO_YAW]
    return speed * np.cos(yaw), speed * np.sin(yaw)
