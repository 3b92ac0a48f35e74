"""Upper bounds of the [conflicts] section of the parameter file (registered on import).

The conflicts tool checks these values are positive numbers itself (pedsafe_sumo/conflicts/__main__.py);
this validator adds the upper bound every parameter has, so that no value set in a parameter
file or with --set is accepted however far out of range."""

from __future__ import annotations

from typing import Any

from pedsafe_sumo.params import Bounds, check_upper_bounds, register_validator

CONFLICTS_UPPER_BOUNDS: Bounds = {
    # Every vehicle within the radius of a person is a candidate pair, at every FCD step.
    "interaction_radius_m": (1000.0, "a kilometre: every vehicle of a city district would be a candidate"),
    "vehicle_length_m": (30.0, "longer than a truck with trailer (25 m)"),
    "vehicle_width_m": (5.0, "wider than any road vehicle"),
    "person_width_m": (5.0, "wider than any pedestrian"),
    "ssm_ttc_threshold_s": (60.0, "every approach within a minute would count"),
    "ssm_drac_threshold_mps2": (15.0, "1.5 g, beyond the grip of tyres on dry asphalt"),
    "ssm_pet_threshold_s": (60.0, "every passage within a minute would count"),
}


@register_validator("conflicts")
def validate_conflicts(section: dict[str, Any], where: str) -> None:
    check_upper_bounds(section, CONFLICTS_UPPER_BOUNDS, where)
