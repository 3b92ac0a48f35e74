"""Validator of the [algorithm] section of the parameter file (settings handed to the AD stack)."""

from __future__ import annotations

import math
from typing import Any

from pedsafe_sumo.params import Bounds, ParameterError, check_upper_bounds, register_validator

ALGORITHM_UPPER_BOUNDS: Bounds = {
    "reaction_time_s": (10.0, "25 times the reference stack's 0.4 s"),
    # Tyres on dry asphalt give about 1 g (9.8 m/s2); SUMO would apply any deceleration commanded.
    "max_decel_mps2": (15.0, "1.5 g, beyond the grip of tyres on dry asphalt"),
}


@register_validator("algorithm")
def validate_algorithm(section: dict[str, Any], where: str) -> None:
    for key, value in section.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ParameterError(f"{where}.{key} must be a finite number, got {value!r}")
    if section["reaction_time_s"] < 0:
        raise ParameterError(f"{where}.reaction_time_s must be >= 0, got {section['reaction_time_s']}")
    if section["max_decel_mps2"] <= 0:
        raise ParameterError(f"{where}.max_decel_mps2 must be > 0, got {section['max_decel_mps2']}")
    check_upper_bounds(section, ALGORITHM_UPPER_BOUNDS, where)
