"""Validator of the [safety] section of the parameter file (thresholds of the proximity measures)."""

from __future__ import annotations

import math
from typing import Any

from pedsafe_sumo.params import Bounds, ParameterError, check_upper_bounds, register_validator
from pedsafe_sumo.safety.proximity import PARAM_KEYS, SCOPE_KEY, SCOPES

SAFETY_UPPER_BOUNDS: Bounds = {
    "close_pass_clearance_m": (20.0, "wider than the study site's road: every step would be a close pass"),
    "close_pass_min_speed_mps": (50.0, "the ego's vehicle type is capped at 50 m/s"),
    "drac_threshold_mps2": (15.0, "1.5 g, beyond the grip of tyres on dry asphalt"),
    "interaction_margin_m": (20.0, "wider than the study site's road: every pedestrian would be in the path"),
    "interaction_horizon_s": (60.0, "a minute of walking crosses any road of the study site many times over"),
}


@register_validator("safety")
def validate_safety(section: dict[str, Any], where: str) -> None:
    for key in PARAM_KEYS:
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ParameterError(f"{where}.{key} must be a finite number, got {value!r}")
        if value < 0:
            raise ParameterError(f"{where}.{key} must be >= 0, got {value}")
    if section[SCOPE_KEY] not in SCOPES:
        raise ParameterError(
            f"{where}.{SCOPE_KEY} must be one of {', '.join(SCOPES)}, got {section[SCOPE_KEY]!r}"
        )
    check_upper_bounds(section, SAFETY_UPPER_BOUNDS, where)
