"""Cars parked at the kerb of a one-lane approach, as SUMO parking spaces.

On a one-lane approach the vehicles that hide the pedestrian (crossing, jaywalking, background blending)
stand parked at the kerb beside the lane (VehicleSetup.kerb_offset_m > 0, scenarios/episode_setup.py). SUMO
knows where: each stands in a parking area of its own, one `<space>` at the kerb, written per episode as an
additional file. SUMO reports a vehicle parked in a space at the space's position and angle
(MSParkingArea::getVehiclePosition, getVehicleAngle), so the perception world (which reads SUMO's
positions), sumo-gui and the FCD output all put the car where the staging does.

Two facts of SUMO 1.28 shape this:
- A space's `x,y` is where the parked vehicle's FRONT is reported (vehicle.getPosition; sumo-gui draws
  the body behind it), and vehicle.getAngle reports 180 - the space's `angle` (getVehicleAngle returns
  angle - 90 degrees as a mathematical angle). So the space's angle is 90 + the lane's heading
  (degrees counter-clockwise from east) for a car parked along the lane.
- A vehicle cannot start parked: inserted on the lane at its stop, it parks in the following step
  (eclipse-sumo/sumo#2941, "still requires one simulation step to enter the parking state"). The episode
  therefore inserts the parked cars one step before everything else (`park_at_kerb`) and starts its clock
  one step later (EpisodeRunner.run): at the episode's first step they already stand at the kerb.

A parked vehicle is off the lane: SUMO's traffic drives past it, and SUMO's collision check does not see
it (no vehicle touches it: the ego drives the lane's centre, 0.7 m and more from its flank).
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup, VehicleSetup
from pedsafe_sumo.scenarios.geometry import Approach

#: How long a parked car's stop lasts [s]: beyond any episode (time_limit_s is at most 600 s).
PARKED_DURATION_S = 1.0e6


def kerb_parked(setup: EpisodeSetup) -> tuple[VehicleSetup, ...]:
    """The episode's vehicles parked at the kerb (none on an approach with a kerb lane)."""
    return tuple(v for v in setup.parked if v.kerb_offset_m > 0)


def parking_area_id(vehicle: VehicleSetup) -> str:
    return f"kerb_{vehicle.vehicle_id}"


def space_pose(approach: Approach, vehicle: VehicleSetup) -> tuple[float, float, float]:
    """(x, y, heading) where the parked vehicle's front stands: its lane's centre at its front's lane
    position, moved `kerb_offset_m` towards the kerb (to the right of travel; to the left in left-hand
    traffic, Approach.keep_side); heading in radians counter-clockwise from +x."""
    x, y, heading = approach.pose(approach.lane_ids.index(vehicle.lane_id), vehicle.front_pos_m)
    offset_m = approach.keep_side * vehicle.kerb_offset_m
    return x + offset_m * math.sin(heading), y - offset_m * math.cos(heading), heading


def parking_xml(approach: Approach, vehicles: tuple[VehicleSetup, ...]) -> str:
    """SUMO additional file: one parking area per parked vehicle, on its lane from its rear to its front,
    with one space at the kerb (space_pose). The area's `width` is the car's: sumo-gui draws the area
    lane width / 2 + width / 2 beside the lane (MSParkingArea's shape), over the car's footprint."""
    lines = ["<additional>"]
    for vehicle in vehicles:
        x, y, heading = space_pose(approach, vehicle)
        end_m = vehicle.front_pos_m
        start_m = max(0.0, end_m - vehicle.size.length_m)
        angle_deg = (90.0 + math.degrees(heading)) % 360.0
        lines += [
            f"    <parkingArea id={quoteattr(parking_area_id(vehicle))} lane={quoteattr(vehicle.lane_id)} "
            f'startPos="{start_m!r}" endPos="{end_m!r}" roadsideCapacity="0" '
            f'width="{vehicle.size.width_m!r}">',
            f'        <space x="{x!r}" y="{y!r}" angle="{angle_deg!r}" width="{vehicle.size.width_m!r}" '
            f'length="{vehicle.size.length_m!r}"/>',
            "    </parkingArea>",
        ]
    lines.append("</additional>")
    return "\n".join(lines) + "\n"


def with_additional(args: list[str], path: Path) -> list[str]:
    """SUMO options `args` with `path` added to its additional files (one -a option, comma-separated)."""
    args = list(args)
    for flag in ("-a", "--additional-files"):
        if flag in args:
            index = args.index(flag) + 1
            args[index] = f"{args[index]},{path}"
            return args
    return [*args, "-a", str(path)]


def park_at_kerb(api, vehicles: tuple[VehicleSetup, ...], add_vehicle) -> None:
    """Insert the parked vehicles on their lane with a stop in their parking area, and advance SUMO one
    step (they park in the next one). `add_vehicle(api, vehicle, route_id)` adds one at depart 0."""
    for vehicle in vehicles:
        route_id = f"kerb_parked_{vehicle.lane_id}"
        if route_id not in api.route.getIDList():
            api.route.add(route_id, [vehicle.lane_id.rsplit("_", 1)[0]])
        add_vehicle(api, vehicle, route_id)
        api.vehicle.setParkingAreaStop(
            vehicle.vehicle_id, parking_area_id(vehicle), duration=PARKED_DURATION_S
        )
    api.simulation.step()


def check_parked(api, vehicles: tuple[VehicleSetup, ...]) -> None:
    """RuntimeError unless every parked vehicle stands in its parking space."""
    for vehicle in vehicles:
        if not api.vehicle.isStoppedParking(vehicle.vehicle_id):
            raise RuntimeError(f"SUMO did not park vehicle '{vehicle.vehicle_id}' at the kerb")
