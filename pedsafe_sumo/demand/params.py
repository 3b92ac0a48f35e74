"""Validators of the `[traffic]` and `[pedestrians]` sections of the parameter file.

Registered with the loader in `pedsafe_sumo.params`, which imports this module before validating. Each
check raises `ParameterError` with a message naming the dotted key and the rule it breaks.
"""

from __future__ import annotations

import math
from typing import Any

from pedsafe_sumo.params import Bounds, ParameterError, check_upper_bounds, register_validator

#: Shares summing to 1 within this tolerance are accepted (TOML decimals such as 0.1 + 0.2 are inexact).
SHARE_SUM_TOLERANCE = 1e-6

TURN_MOVEMENTS = ("left", "straight", "right")
#: Values of traffic.desired_speed_law: the background's desired speeds drawn from the non-intersection fit,
#: or from the calibrated lognormal (pedsafe_sumo.demand.vehicles.desired_speed_distribution).
DESIRED_SPEED_LAWS = ("fit", "calibrated")
RISK_TYPES = ("unaware", "hasten", "yield")
AGE_GROUP_KEYS = ("age_min_years", "age_max_years", "weight_share", "speed_mean_mps", "speed_p15_mps")

#: A running human tops out at about 12.4 m/s (the 100 m sprint record): no pedestrian speed above it.
HUMAN_SPRINT_MPS = 12.5
TRAFFIC_UPPER_BOUNDS: Bounds = {
    # Demand is drawn for every entering lane over warm-up + episode: a huge rate never finishes drawing.
    "headway_rate_per_s": (1.0, "one departure a second per lane, twice a lane's saturation flow"),
    "speed_nonintersection_log_mu": (4.0, "a median speed of exp(4) = 55 m/s (197 km/h)"),
    "speed_intersection_log_mu": (4.0, "a median speed of exp(4) = 55 m/s (197 km/h)"),
    "speed_nonintersection_log_sigma": (2.0, "the site's fits are 0.38-0.49"),
    "speed_intersection_log_sigma": (2.0, "the site's fits are 0.38-0.49"),
    "desired_speed_calibrated_log_mu": (4.0, "a median speed of exp(4) = 55 m/s (197 km/h)"),
    "desired_speed_calibrated_log_sigma": (2.0, "four times the calibrated 0.53"),
    "fit_speed_limit_mps": (70.0, "252 km/h, above any posted speed limit"),
    "vehicle_length_m": (30.0, "longer than a truck with trailer (25 m)"),
    "vehicle_min_gap_m": (20.0, "four car lengths at standstill"),
}
PEDESTRIAN_UPPER_BOUNDS: Bounds = {
    "arrival_rate_per_h": (20_000.0, "5.5 pedestrians a second at one junction, a stadium crowd"),
    "speed_factor_female": (3.0, "triples the fitted walking speeds"),
    "speed_factor_male": (3.0, "triples the fitted walking speeds"),
    "awareness_ttc_s": (60.0, "a vehicle a minute away"),
    "reaction_time_s": (10.0, "ten times a typical pedestrian reaction"),
    "hasten_factor": (5.0, "five times the walking speed"),
    "hasten_max_speed_mps": (HUMAN_SPRINT_MPS, "a sprinter's top speed"),
    "step_back_speed_mps": (HUMAN_SPRINT_MPS, "a sprinter's top speed"),
    "corridor_half_width_m": (20.0, "wider than the study site's road"),
    "yield_clearance_m": (20.0, "wider than the study site's road"),
    "body_clearance_m": (5.0, "a pedestrian this far from every vehicle cannot move through a queue"),
    "body_graze_angle_deg": (45.0, "steeper is walking into the body, not along it"),
    "gap_startup_clearance_s": (60.0, "twenty times the HCM start-up time (3 s)"),
    "detour_wait_s": (600.0, "longer than any episode (at most 600 s): the rule would never act"),
    "detour_max_offset_m": (20.0, "wider than the study site's road"),
}
AGE_GROUP_UPPER_BOUNDS: Bounds = {
    "age_max_years": (120.0, "older than anyone recorded"),
    "speed_mean_mps": (HUMAN_SPRINT_MPS, "a sprinter's top speed"),
    "speed_p15_mps": (HUMAN_SPRINT_MPS, "a sprinter's top speed"),
}


def _number(section: dict[str, Any], key: str, where: str) -> float:
    if key not in section:
        raise ParameterError(f"parameter '{where}.{key}' is missing")
    value = section[key]
    # bool is an int subclass in Python; `true` is never a valid number here.
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ParameterError(f"parameter '{where}.{key}' must be a finite number, got {value!r}")
    return float(value)


def _positive(section: dict[str, Any], key: str, where: str) -> float:
    value = _number(section, key, where)
    if value <= 0:
        raise ParameterError(f"parameter '{where}.{key}' must be > 0, got {value!r}")
    return value


def _non_negative(section: dict[str, Any], key: str, where: str) -> float:
    value = _number(section, key, where)
    if value < 0:
        raise ParameterError(f"parameter '{where}.{key}' must be >= 0, got {value!r}")
    return value


def _share(section: dict[str, Any], key: str, where: str) -> float:
    value = _number(section, key, where)
    if not 0.0 <= value <= 1.0:
        raise ParameterError(f"parameter '{where}.{key}' is a share and must lie in [0, 1], got {value!r}")
    return value


def _shares_sum_to_one(section: dict[str, Any], keys: list[str], where: str) -> None:
    total = sum(_share(section, key, where) for key in keys)
    if abs(total - 1.0) > SHARE_SUM_TOLERANCE:
        names = ", ".join(f"{where}.{key}" for key in keys)
        raise ParameterError(f"shares {names} must sum to 1, they sum to {total:.6g}")


@register_validator("traffic")
def validate_traffic(section: dict[str, Any], where: str = "traffic") -> None:
    """Rates and sigmas > 0, mus finite, turn shares in [0, 1] summing to 1, lengths > 0."""
    _positive(section, "headway_rate_per_s", where)
    for fit in ("nonintersection", "intersection"):
        _number(section, f"speed_{fit}_log_mu", where)
        _positive(section, f"speed_{fit}_log_sigma", where)
    _positive(section, "fit_speed_limit_mps", where)
    if not isinstance(section.get("background_speed_limit_scaled"), bool):
        raise ParameterError(
            f"parameter '{where}.background_speed_limit_scaled' must be true or false, "
            f"got {section.get('background_speed_limit_scaled')!r}"
        )
    law = section.get("desired_speed_law")
    if law not in DESIRED_SPEED_LAWS:
        raise ParameterError(
            f"parameter '{where}.desired_speed_law' must be one of {', '.join(DESIRED_SPEED_LAWS)}, "
            f"got {law!r}"
        )
    _number(section, "desired_speed_calibrated_log_mu", where)
    _positive(section, "desired_speed_calibrated_log_sigma", where)
    _shares_sum_to_one(section, [f"turn_share_{m}" for m in TURN_MOVEMENTS], where)
    sigma = _number(section, "driver_imperfection_sigma", where)
    if not 0.0 <= sigma <= 1.0:
        raise ParameterError(
            f"parameter '{where}.driver_imperfection_sigma' must lie in [0, 1], got {sigma!r}"
        )
    _positive(section, "vehicle_length_m", where)
    _non_negative(section, "vehicle_min_gap_m", where)
    check_upper_bounds(section, TRAFFIC_UPPER_BOUNDS, where)


@register_validator("pedestrians")
def validate_pedestrians(section: dict[str, Any], where: str = "pedestrians") -> None:
    """Rates > 0, shares in [0, 1] summing to 1, age groups ordered and not overlapping, speeds sensible."""
    _positive(section, "arrival_rate_per_h", where)
    _share(section, "gender_female_share", where)
    _positive(section, "speed_factor_female", where)
    _positive(section, "speed_factor_male", where)
    _shares_sum_to_one(section, [f"risk_share_{r}" for r in RISK_TYPES], where)
    _non_negative(section, "awareness_ttc_s", where)
    _non_negative(section, "reaction_time_s", where)
    if _positive(section, "hasten_factor", where) < 1.0:
        raise ParameterError(f"parameter '{where}.hasten_factor' must be >= 1 (hasten means faster)")
    _positive(section, "hasten_max_speed_mps", where)
    _positive(section, "step_back_speed_mps", where)
    _non_negative(section, "yield_clearance_m", where)
    _non_negative(section, "body_clearance_m", where)
    _non_negative(section, "body_graze_angle_deg", where)
    _non_negative(section, "gap_startup_clearance_s", where)
    _non_negative(section, "detour_wait_s", where)
    _non_negative(section, "detour_max_offset_m", where)
    if not 0.0 < _positive(section, "eye_height_fraction", where) <= 1.0:
        raise ParameterError(f"parameter '{where}.eye_height_fraction' must lie in (0, 1]")
    check_upper_bounds(section, PEDESTRIAN_UPPER_BOUNDS, where)

    groups = section.get("age_groups")
    if not isinstance(groups, dict) or not groups:
        raise ParameterError(f"parameter '{where}.age_groups' must be a non-empty table of age groups")
    spans = []
    for name, group in groups.items():
        gwhere = f"{where}.age_groups.{name}"
        if not isinstance(group, dict):
            raise ParameterError(f"parameter '{gwhere}' must be a table")
        for key in AGE_GROUP_KEYS:
            _number(group, key, gwhere)
        low, high = group["age_min_years"], group["age_max_years"]
        if int(low) != low or int(high) != high or not 0 <= low <= high:
            raise ParameterError(
                f"parameters '{gwhere}.age_min_years'/'age_max_years' must be whole years with "
                f"0 <= min <= max, got {low!r}..{high!r}"
            )
        spans.append((low, high, name))
        check_upper_bounds(group, AGE_GROUP_UPPER_BOUNDS, gwhere)
        _share(group, "weight_share", gwhere)
        mean = _positive(group, "speed_mean_mps", gwhere)
        p15 = _positive(group, "speed_p15_mps", gwhere)
        if p15 >= mean:
            # A lognormal's 15th percentile lies below its mean; the sigma derivation needs mean > p15.
            raise ParameterError(
                f"parameter '{gwhere}.speed_p15_mps' ({p15}) must be below '{gwhere}.speed_mean_mps' ({mean})"
            )
    spans.sort()
    for (_, high_a, name_a), (low_b, _, name_b) in zip(spans, spans[1:], strict=False):
        if low_b <= high_a:
            raise ParameterError(f"age groups '{where}.age_groups.{name_a}' and '{name_b}' overlap")
    total = sum(float(g["weight_share"]) for g in groups.values())
    if abs(total - 1.0) > SHARE_SUM_TOLERANCE:
        raise ParameterError(
            f"shares {where}.age_groups.*.weight_share must sum to 1, they sum to {total:.6g}"
        )
