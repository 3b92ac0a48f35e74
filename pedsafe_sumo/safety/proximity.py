"""Proximity: how close the ego came to the pedestrian while the pedestrian was in or entering its path.

The Amini conflict model (conflict.py) needs both road users moving on crossing paths, so a pedestrian
standing at the kerb or stopped in the lane is never its candidate, and TTC is NaN for anyone the ego
passes without touching. These measures cover that:

- clearance (m) per step: the signed distance between the ego's body (oriented rectangle) and the
  pedestrian's body (circle), <= 0 in contact; `min_clearance_m` is its minimum over the steps in scope
  and `ego_speed_at_min_clearance_mps` the ego's speed at that step (first step on a tie); both NaN
  when no step is in scope.
- steps in scope (`interaction_steps`), under `proximity_scope = "interaction"`: the pedestrian's body
  is in the ego's corridor (the strip of the ego's width plus `interaction_margin_m` on each side, along
  its heading, from the ego's rear forward: what its body covers and will sweep), or, walking on at its
  logged velocity, enters it within `interaction_horizon_s` before the ego's rear (the ego going on at
  its speed) has passed that point, or touches the ego. A pedestrian standing beside the lane, or
  walking away from the corridor, is not in scope, nor one the ego has passed. Under "episode" every
  step with the pedestrian is.
- DRAC (m/s^2) per step: deceleration rate to avoid the crash (Cooper & Ferguson 1976, Traffic
  Engineering + Control 17:306; Almqvist, Hyden & Risser 1991), v^2 / (2 d) with v the ego's speed and
  d the distance it covers before contact when both keep their velocities: d = v TTC, so DRAC =
  v / (2 TTC). Defined while the pedestrian is on a collision course (TTC finite and > 0, ego
  moving), NaN otherwise; `drac_mps2` is the largest over the encounter (whatever the scope).
- close pass: some step in scope with clearance below `close_pass_clearance_m` while the ego moves
  faster than `close_pass_min_speed_mps` (parameters in params/defaults.toml [safety], with their sources).

Steps without the pedestrian (NaN position) are in neither scope. Every function takes a log of the
`pedsafe_sumo.safety.log` contract; only its kinematic columns are needed (detection flags may be
absent, e.g. a log built from SUMO FCD output), so any caller with trajectories can use them. Formulas
and what each measure catches: docs/safety_indexes.md.
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
#: The numeric keys of the section (the validator checks each).
PARAM_KEYS = (
    "close_pass_clearance_m",
    "close_pass_min_speed_mps",
    "drac_threshold_mps2",
    "interaction_margin_m",
    "interaction_horizon_s",
)
#: The key naming which steps the clearance and the close pass are taken over.
SCOPE_KEY = "proximity_scope"
#: Only the steps at which the pedestrian is in or about to enter the ego's path (`interaction_steps`).
SCOPE_INTERACTION = "interaction"
#: Every step with the pedestrian, whatever either road user is doing.
SCOPE_EPISODE = "episode"
SCOPES = (SCOPE_INTERACTION, SCOPE_EPISODE)
#: The scope of a parameter set that names none (run.json of a run recorded before the key existed):
#: such runs took every step.
SCOPE_UNNAMED = SCOPE_EPISODE
#: A speed below this is no motion (as in the reference stack's corridor test), m/s.
_STILL_MPS = 1e-9


@dataclass(frozen=True)
class ProximityModel:
    """Thresholds of the proximity measures (values and sources: params/defaults.toml [safety])."""

    #: a close pass: clearance below this, m ...
    close_pass_clearance_m: float
    #: ... while the ego moves faster than this, m/s
    close_pass_min_speed_mps: float
    #: DRAC above this is more braking than is comfortable, m/s^2 (the report counts such episodes)
    drac_threshold_mps2: float
    #: the ego's corridor reaches this far beyond each side of its body, m
    interaction_margin_m: float
    #: how far ahead a pedestrian's constant-velocity walk is followed into the corridor, s
    interaction_horizon_s: float
    #: "interaction": clearance and close pass over the interaction steps only; "episode": every step
    scope: str

    @classmethod
    def from_params(cls, params: Mapping[str, Any] | None = None) -> ProximityModel:
        """From a whole parameter set (its [safety] section), or the defaults file when None or absent.

        A section without the corridor's keys (a run recorded before they existed) takes the defaults
        file's values for them and the scope `SCOPE_UNNAMED`, which is what such runs measured."""
        section = params.get(PARAMS_SECTION) if params is not None else None
        defaults = _default_section()
        if section is None:
            section = defaults
        values = {key: float(section.get(key, defaults[key])) for key in PARAM_KEYS}
        scope = str(section.get(SCOPE_KEY, SCOPE_UNNAMED))
        if scope not in SCOPES:
            raise ValueError(
                f"{PARAMS_SECTION}.{SCOPE_KEY} must be one of {', '.join(SCOPES)}, got {scope!r}"
            )
        return cls(scope=scope, **values)


@functools.lru_cache(maxsize=1)
def default_proximity_model() -> ProximityModel:
    """The thresholds of the defaults file (read once)."""
    return ProximityModel.from_params(None)


def _default_section() -> dict[str, Any]:
    with open(DEFAULTS_PATH, "rb") as handle:
        return tomllib.load(handle)[PARAMS_SECTION]


def kinematic_arrays(log: Any) -> dict[str, np.ndarray]:
    """A log's columns as validated arrays (`steplog.as_arrays`); missing detection flags read as False."""
    if steplog.is_validated(log):
        return steplog.as_arrays(log)  # checked already, flags included: a copy of the mapping
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


def _clearance(a: Mapping[str, np.ndarray]) -> np.ndarray:
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


def _window_s(position: np.ndarray, rate: np.ndarray, low: np.ndarray, high: np.ndarray) -> tuple[Any, Any]:
    """Per step, the times t (any sign) with low <= position + rate t <= high, as (start, end); empty when
    start > end. Without motion: all times or none."""
    still = np.abs(rate) < _STILL_MPS
    inside = (low <= position) & (position <= high)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_low, t_high = (low - position) / rate, (high - position) / rate
    start = np.where(still, np.where(inside, -np.inf, np.inf), np.minimum(t_low, t_high))
    end = np.where(still, np.where(inside, np.inf, -np.inf), np.maximum(t_low, t_high))
    return start, end


def _interaction(a: Mapping[str, np.ndarray], clearance: np.ndarray, model: ProximityModel) -> np.ndarray:
    cos_yaw, sin_yaw = np.cos(a[steplog.EGO_YAW]), np.sin(a[steplog.EGO_YAW])
    dx, dy = a[steplog.PED_X] - a[steplog.EGO_X], a[steplog.PED_Y] - a[steplog.EGO_Y]
    vx, vy = a[steplog.PED_VX], a[steplog.PED_VY]
    # The pedestrian in the ego's frame at this step: lon ahead of the ego's centre, lat to its left.
    lon, lat = dx * cos_yaw + dy * sin_yaw, -dx * sin_yaw + dy * cos_yaw
    v_lon, v_lat = vx * cos_yaw + vy * sin_yaw, -vx * sin_yaw + vy * cos_yaw
    radius = a[steplog.PED_RADIUS]
    # The body overlaps the corridor while the centre is within its half width plus the radius ...
    half_m = a[steplog.EGO_WIDTH] / 2 + model.interaction_margin_m + radius
    lat_start, lat_end = _window_s(lat, v_lat, -half_m, half_m)
    # ... and is not behind the ego's rear, which goes on at the ego's speed: in the frame moving with
    # the ego, lon - speed t + radius >= -length / 2 (beside the body counts: the strip it sweeps).
    ahead_m = lon + radius + a[steplog.EGO_LENGTH] / 2
    lon_start, lon_end = _window_s(
        ahead_m, v_lon - a[steplog.EGO_SPEED], np.zeros_like(lon), np.full_like(lon, np.inf)
    )
    start = np.maximum(0.0, np.maximum(lat_start, lon_start))
    end = np.minimum(model.interaction_horizon_s, np.minimum(lat_end, lon_end))
    return np.isfinite(clearance) & ((start <= end) | (clearance <= 0.0))


def _steps_in_scope(a: Mapping[str, np.ndarray], clearance: np.ndarray, model: ProximityModel) -> np.ndarray:
    if model.scope == SCOPE_EPISODE:
        return np.isfinite(clearance)
    return _interaction(a, clearance, model)


def interaction_steps(log: Any, model: ProximityModel) -> np.ndarray:
    """Per step, whether it is in the model's scope (see the module docstring): under "interaction",
    whether the pedestrian is in or about to enter the ego's corridor before its rear passes, or touches it;
    under "episode", whether the pedestrian is there at all (position not NaN)."""
    a = kinematic_arrays(log)
    return _steps_in_scope(a, _clearance(a), model)


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


def min_clearance_m(
    log: Any, last_step: int | None = None, model: ProximityModel | None = None
) -> tuple[float, float]:
    """(minimum clearance in m, ego speed at that step in m/s) over the steps up to `last_step` (all if
    None) in the model's scope (every step with the pedestrian when None); the first step on a tie; NaN
    twice when no step is in scope."""
    result = episode_proximity(log, model or _EVERY_STEP_MODEL, last_step)
    return result.min_clearance_m, result.ego_speed_at_min_clearance_mps


def drac_mps2(log: Any, last_step: int | None = None) -> float:
    """Largest DRAC over the steps up to `last_step` (all if None), m/s^2; NaN if never defined."""
    drac = drac_steps_mps2(log)
    if last_step is not None:
        drac = drac[: last_step + 1]
    return float(np.nanmax(drac)) if np.isfinite(drac).any() else math.nan


@dataclass(frozen=True)
class ProximityResult:
    #: NaN when no step is in scope (no interaction)
    min_clearance_m: float
    ego_speed_at_min_clearance_mps: float
    #: index of the step of minimum clearance; -1 when no step is in scope
    step: int
    drac_mps2: float
    close_pass: bool
    #: number of steps in scope up to the window's end
    steps_in_scope: int
    #: index of the step of the largest DRAC (the first on a tie); None when no DRAC is defined
    drac_step: int | None = None


def episode_proximity(
    log: Any, model: ProximityModel, last_step: int | None = None, ttc_s: np.ndarray | None = None
) -> ProximityResult:
    """The proximity measures of one episode over the steps up to and including `last_step` (the first
    contact, as for the conflict measures; all steps when None). Clearance and close pass take only the
    steps in the model's scope (`interaction_steps`). `ttc_s`: the log's `ttc_steps_s`, when the caller
    has it already (the DRAC rests on it)."""
    a = kinematic_arrays(log)
    clearance = _clearance(a)
    ttc = ttc_steps_s(a) if ttc_s is None else ttc_s
    drac = drac_from_ttc_mps2(a[steplog.EGO_SPEED], ttc)
    return proximity_of_steps(a, clearance, drac, model, last_step)


def proximity_of_steps(
    a: Mapping[str, np.ndarray],
    clearance_m: np.ndarray,
    drac_mps2: np.ndarray,
    model: ProximityModel,
    last_step: int | None = None,
) -> ProximityResult:
    """`episode_proximity` from a log's checked columns and its per-step clearance (`clearance_steps_m`)
    and DRAC (`drac_from_ttc_mps2`), computed by the caller (e.g. over the rows of many logs at once)."""
    stop = len(a[steplog.TIME]) if last_step is None else last_step + 1
    in_scope = _steps_in_scope(a, clearance_m, model)[:stop]
    clearance = clearance_m[:stop]
    speed = a[steplog.EGO_SPEED][:stop]
    drac = drac_mps2[:stop]
    drac_defined = np.isfinite(drac).any()
    drac_max = float(np.nanmax(drac)) if drac_defined else math.nan
    drac_step = int(np.nanargmax(drac)) if drac_defined else None
    if not in_scope.any():
        return ProximityResult(math.nan, math.nan, -1, drac_max, False, 0, drac_step)
    k = int(np.argmin(np.where(in_scope, clearance, np.inf)))
    return ProximityResult(
        min_clearance_m=float(clearance[k]),
        ego_speed_at_min_clearance_mps=float(speed[k]),
        step=k,
        drac_mps2=drac_max,
        close_pass=bool((close_pass_steps(clearance, speed, model) & in_scope).any()),
        steps_in_scope=int(in_scope.sum()),
        drac_step=drac_step,
    )


#: The model of `min_clearance_m` called without one: every step (the thresholds play no part there).
_EVERY_STEP_MODEL = ProximityModel(
    close_pass_clearance_m=0.0,
    close_pass_min_speed_mps=0.0,
    drac_threshold_mps2=0.0,
    interaction_margin_m=0.0,
    interaction_horizon_s=0.0,
    scope=SCOPE_EPISODE,
)
