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


#: Allowed values of the [algorithm] keys that are words, not numbers (control/baseline.py reads it).
ALGORITHM_CHOICES: dict[str, tuple[str, ...]] = {
    "tracker_motion_model": ("cv", "imm"),
    "tracker_gate": ("precise", "reinitialise", "none"),
}


@register_validator("algorithm")
def validate_algorithm(section: dict[str, Any], where: str) -> None:
    for key, value in section.items():
        if key in ALGORITHM_CHOICES:
            if value not in ALGORITHM_CHOICES[key]:
                raise ParameterError(
                    f"{where}.{key} must be one of {', '.join(ALGORITHM_CHOICES[key])}, got {value!r}"
                )
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ParameterError(f"{where}.{key} must be a finite number, got {value!r}")
    if section["reaction_time_s"] < 0:
        raise ParameterError(f"{where}.reaction_time_s must be >= 0, got {section['reaction_time_s']}")
    if section["max_decel_mps2"] <= 0:
        raise ParameterError(f"{where}.max_decel_mps2 must be > 0, got {section['max_decel_mps2']}")
    check_upper_bounds(section, ALGORITHM_UPPER_BOUNDS, where)


VEHICLE_UPPER_BOUNDS: Bounds = {
    "max_decel_mps2": (15.0, "1.5 g, beyond the grip of tyres on dry asphalt"),
    "max_accel_mps2": (15.0, "1.5 g, beyond any road car's acceleration"),
}


@register_validator("vehicle")
def validate_vehicle(section: dict[str, Any], where: str) -> None:
    """[vehicle]: the ego's physical limits (sim/episode.py applies them to the stack's command)."""
    if not isinstance(section.get("physical_limits"), bool):
        raise ParameterError(f"{where}.physical_limits must be true or false")
    for key in ("max_decel_mps2", "max_accel_mps2"):
        value = section.get(key)
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or value <= 0
        ):
            raise ParameterError(f"{where}.{key} must be a finite number > 0, got {value!r}")
    check_upper_bounds(section, VEHICLE_UPPER_BOUNDS, where)
