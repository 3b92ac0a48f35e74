"""Validator of the [algorithm] section of the parameter file (settings handed to the AD stack)."""

from __future__ import annotations

import math
from typing import Any

from pedsafe_sumo.params import ParameterError, register_validator


@register_validator("algorithm")
def validate_algorithm(section: dict[str, Any], where: str) -> None:
    for key, value in section.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ParameterError(f"{where}.{key} must be a finite number, got {value!r}")
    if section["reaction_time_s"] < 0:
        raise ParameterError(f"{where}.reaction_time_s must be >= 0, got {section['reaction_time_s']}")
    if section["max_decel_mps2"] <= 0:
        raise ParameterError(f"{where}.max_decel_mps2 must be > 0, got {section['max_decel_mps2']}")
