"""Proximity: how close the ego came to the pedestrian, whatever either was doing.

The Amini conflict model (conflict.py) needs both road users moving on crossing paths, so a pedestrian
standing at the kerb or stopped in the lane is never its candidate, and TTC is NaN for anyone the ego
passes without touching. These measures cover that:

- clearance (m) per step: the signed distance between the ego's body (oriented rectangle) and the
  pedestrian's body (circle), <= 0 in contact; `min_clearance_m` is its minimum over the encounter and
  `ego_speed_at_min_clearance_mps` the ego's speed at that step (first step on a tie).
- DRAC (m/s^2) per step: deceleration rate to avoid the crash (Cooper & Ferguson 1976, Traffic
  Engineering + Control 17:306; Almqvist, Hyden & Risser 1991), v^2 / (2 d) with v the ego's speed and
  d the distance it covers before contact when both keep their velocities: d = v TTC, so DRAC =
  v / (2 TTC). Defined while the pedestrian is in or entering the ego's path (TTC finite and > 0, ego
  moving), NaN otherwise; `drac_mps2` is the largest over the encounter.
- close pass: some step with clearance below `close_pass_clearance_m` while the ego moves faster than
  `close_pass_min_speed_mps` (parameters in params/defaults.toml [safety], with their sources).

Every function takes a log of the `pedsafe_sumo.safety.log` contract; only its kinematic columns are
needed (detection flags may be absent, e.g. a log built from SUMO FCD output), so any caller with
trajectories can use them. Formulas and what each measure catches: docs/safety_indexes.md.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from pedsafe_sumo.params import DEFAULTS_PATH
from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import FloatOrArray, rectangle_circle_distance_m
from pedsafe_sumo.safety.surrogates import ttc_steps_s

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

#: The parameter file section holding the thresholds.
PARAMS_SECTION = "safety"
PARAM_KEYS = ("close_pass_clearance_m", "close_pass_min_speed_mps", "drac_threshold_mps2")


@dataclass(frozen=True)
class ProximityModel:
    """Thresholds of the proximity measures (values and sources: params/defaults.toml [safety])."""

    #: a close pass: clearance below this, m ...
    close_pass_clearance_m: float
    #: ... while the ego moves faster than this, m/s
    close_pass_min_speed_mps: float
    #: DRAC above this is more braking than is comfortable, m/s^2 (the report counts such episodes)
    drac_threshold_mps2: float

    @classmethod
    def from_params(cls, params: Mapping[str, Any] | None = None) -> ProximityModel:
        """From a whole parameter set (its [safety] section), or the defaults file when None or absent."""
        section = params.get(PARAMS_SECTION) if params is not None else None
        if section is None:
            section = _default_section()
        return cls(**{key: float(section[key]) for key in PARAM_KEYS})


@functools.lru_cache(maxsize=1)
def default_proximity_model() -> ProximityModel:
    """The thresholds of the defaults file (read once)."""
    return ProximityModel.from_params(None)


def _default_section() -> dict[str, Any]:
    with open(DEFAULTS_PATH, "rb") as handle:
        return tomllib.load(handle)[PARAMS_SECTION]


def kinematic_arrays(log: Any) -> dict[str, np.ndarray]:
    """A log's columns as validated arrays (`steplog.as_arrays`); missing detection flags read as False."""
    names = list(log.columns) if hasattr(log, "columns") else list(log.keys()) if hasattr(log, "keys") else []
    if not names:
        return steplog.as_arrays(log)  # raises the contract's own message
    columns = {name: log[name] for name in names}
    length = len(np.asarray(columns[names[0]]).reshape(-1))
    for flag in steplog.BOOLEAN_COLUMNS:
        columns.setdefault(flag, np.zeros(length, dtype=bool))
    return steplog.as_arrays(columns)


def clearance_steps_m(log: Any) -> np.ndarray:
    """Per-step signed clearance between the ego rectangle and the pedestrian circle, m (<= 0: contact)."""
    return _clearance(kinematic_arrays(log))


def _clearance(a: dict[str, np.ndarray]) -> np.ndarray:
    return rectangle_circle_distance_m(
        a[steplog.EGO_X],
        a[steplog.EGO_Y],
        a[steplog.EGO_YAW],
        a[steplog.EGO_LENGTH],
        a[steplog.EGO_WIDTH],
        a[steplog.PED_X],
        a[steplog.PED_Y],
        a[steplog.PED_RADIUS],
    )


def drac_from_ttc_mps2(ego_speed_mps: FloatOrArray, ttc_s: FloatOrArray) -> np.ndarray:
    """DRAC = v^2 / (2 d) with d = v TTC the ego's distance to contact: v / (2 TTC), m/s^2.

    NaN where the pedestrian is not in or entering the ego's path (TTC NaN), where they touch (TTC 0:
    no braking avoids it any more), or where the ego stands (v = 0: nothing to brake).
    """
    v, ttc = np.asarray(ego_speed_mps, dtype=float), np.asarray(ttc_s, dtype=float)
    defined = np.isfinite(ttc) & (ttc > 0.0) & (v > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(defined, v / (2.0 * ttc), np.nan)


def drac_steps_mps2(log: Any) -> np.ndarray:
    """Per-step DRAC of a log, m/s^2 (NaN where not defined, see `drac_from_ttc_mps2`)."""
    return _drac(kinematic_arrays(log))


def _drac(a: dict[str, np.ndarray]) -> np.ndarray:
    return drac_from_ttc_mps2(a[steplog.EGO_SPEED], ttc_steps_s(a))


def close_pass_steps(
    clearance_m: FloatOrArray, ego_speed_mps: FloatOrArray, model: ProximityModel
) -> np.ndarray:
    """Steps of a close pass: clearance below the threshold while the ego moves faster than the minimum."""
    clearance, speed = np.asarray(clearance_m, dtype=float), np.asarray(ego_speed_mps, dtype=float)
    return (clearance < model.close_pass_clearance_m) & (speed > model.close_pass_min_speed_mps)


def min_clearance_m(log: Any, last_step: int | None = None) -> tuple[float, float]:
    """(minimum clearance in m, ego speed at that step in m/s) over the steps up to `last_step` (all if
    None); the first step on a tie."""
    a = kinematic_arrays(log)
    clearance = _clearance(a)
    stop = len(clearance) if last_step is None else last_step + 1
    k = int(np.argmin(clearance[:stop]))
    return float(clearance[k]), float(a[steplog.EGO_SPEED][k])


def drac_mps2(log: Any, last_step: int | None = None) -> float:
    """Largest DRAC over the steps up to `last_step` (all if None), m/s^2; NaN if never defined."""
    drac = drac_steps_mps2(log)
    if last_step is not None:
        drac = drac[: last_step + 1]
    return float(np.nanmax(drac)) if np.isfinite(drac).any() else math.nan


@dataclass(frozen=True)
class ProximityResult:
    min_clearance_m: float
    ego_speed_at_min_clearance_mps: float
    #: index of the step of minimum clearance
    step: int
    drac_mps2: float
    close_pass: bool


def episode_proximity(log: Any, model: ProximityModel, last_step: int | None = None) -> ProximityResult:
    """The proximity measures of one episode over the steps up to and including `last_step` (the first
    contact, as for the conflict measures; all steps when None)."""
    a = kinematic_arrays(log)
    stop = len(a[steplog.TIME]) if last_step is None else last_step + 1
    clearance = _clearance(a)[:stop]
    speed = a[steplog.EGO_SPEED][:stop]
    drac = _drac(a)[:stop]
    k = int(np.argmin(clearance))
    return ProximityResult(
        min_clearance_m=float(clearance[k]),
        ego_speed_at_min_clearance_mps=float(speed[k]),
        step=k,
        drac_mps2=float(np.nanmax(drac)) if np.isfinite(drac).any() else math.nan,
        close_pass=bool(close_pass_steps(clearance, speed, model).any()),
    )
