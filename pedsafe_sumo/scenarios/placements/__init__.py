"""The placements, registered by name: where and how a scenario is staged on the junction.

A ScenarioSpec names its placement; `placement_of(spec)` gives the object that stages it
(placements/base.py says what each provides). A new placement is one module here with a Placement
subclass, and one entry in PLACEMENTS.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.placements.base import Placement
from pedsafe_sumo.scenarios.placements.behind_waiting_vehicle import BehindWaitingVehicle
from pedsafe_sumo.scenarios.placements.crosswalk import Crosswalk
from pedsafe_sumo.scenarios.placements.midblock import Midblock
from pedsafe_sumo.scenarios.placements.turn import TurnPlacement

if TYPE_CHECKING:
    # Annotations only: specs.py imports this registry to validate a spec's placement.
    from pedsafe_sumo.scenarios.specs import ScenarioSpec

#: Placement name (ScenarioSpec.placement) -> the object that stages it.
PLACEMENTS: dict[str, Placement] = {
    placement.name: placement
    for placement in (Crosswalk(), Midblock(), BehindWaitingVehicle(), TurnPlacement())
}


def placement_of(spec: ScenarioSpec) -> Placement:
    """The placement that stages `spec`."""
    try:
        return PLACEMENTS[spec.placement]
    except KeyError:
        raise ScenarioError(
            f"unknown placement '{spec.placement}' (known: {', '.join(PLACEMENTS)})"
        ) from None
