"""Validator of the [safety] section of the parameter file (thresholds of the proximity measures)."""

from __future__ import annotations

import math
from typing import Any

from pedsafe_sumo.params import ParameterError, register_validator
from pedsafe_sumo.safety.proximity import PARAM_KEYS


@register_validator("safety")
def validate_safety(section: dict[str, Any], where: str) -> None:
    for key in PARAM_KEYS:
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ParameterError(f"{where}.{key} must be a finite number, got {value!r}")
        if value < 0:
            raise ParameterError(f"{where}.{key} must be >= 0, got {value}")
