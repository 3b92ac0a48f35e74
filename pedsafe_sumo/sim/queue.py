"""The kerb lane's queue, formed by SUMO before the episode starts (approach staging).

Under approach staging the vehicles standing in the kerb lane of jaywalking and background blending
(VehicleSetup.formed) are not added standing: before the episode's t = 0 they enter the kerb lane at its
start, one every `ARRIVAL_HEADWAY_S`, and SUMO's car-following (Krauss, no driver imperfection) drives
them down it while the lane's signal shows red. The first stops at the stop line (SUMO's junction model
stops a vehicle `jmStoplineGap`, 1 m by default, before a red stop line), each of the others behind the
one before it at its own minGap (VehicleSetup.min_gap_m: the gap the staging drew). The first is a
right-turner (its route turns right where the lane allows it), the others go straight on. Once every one
of them stands still (speed 0), the red is lifted (the junction's program goes back to the one it ran),
the episode's clock starts and the runner holds them where they stopped (speed mode 0, speed 0), as it
holds every other staged vehicle: through the episode's green the head waits, in the staging's story, for
the pedestrians on the crosswalk it turns across, and the vehicles behind it cannot pass it.

SUMO's positions are then checked against where the staging put the pedestrian's path: a vehicle that
stopped more than `FORMED_TOLERANCE_M` from its staged front is an error (the episode is refused, in one
line), not a silent difference. Measured on Xueqing (research/formed_queue.py, seeds 0-19): SUMO stops
each follower its minGap plus 1 mm behind its leader, so a queue of 14 ends 1.4 cm from the staged one.
"""

from __future__ import annotations

from collections.abc import Callable

from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup, VehicleSetup

#: The formed vehicles enter the kerb lane one this often [s]. Assumption: about the saturation headway
#: (1900 vehicles an hour per lane, HCM); where they stop does not depend on it (headways of 1.5, 2 and
#: 3 s gave the same stop positions to 0.001 mm on Xueqing), only how long the queue takes to form.
ARRIVAL_HEADWAY_S = 2.0
#: The longest the queue may take to form [s]: 14 vehicles on Xueqing's kerb lane stand still after
#: 45-61 s; a queue still moving after this is an error.
FORMING_LIMIT_S = 300.0
#: How far from its staged front a formed vehicle may stop [m]: SUMO stops a follower 1 mm beyond its
#: minGap (its numerical margin), so a queue of n vehicles ends up to n mm further back; 5 cm holds
#: any queue the kerb lane of a site can hold (50 vehicles) and is far below the pedestrian's 1.2 m gap.
FORMED_TOLERANCE_M = 0.05
#: The signal state of a link held red while the queue forms.
RED = "r"

#: How a formed vehicle is added to SUMO: (api, vehicle, route_id, depart), at the start of its lane (sim/
#: staging.py add_vehicle with upstream=True).
AddVehicle = Callable[[object, VehicleSetup, str, str], None]


def formed_queue(setup: EpisodeSetup) -> tuple[VehicleSetup, ...]:
    """The episode's vehicles that SUMO forms into a queue, from its head back (none under the fixed
    staging)."""
    return tuple(v for v in setup.parked if v.formed)


def lane_links(api, lane_id: str) -> tuple[str | None, list[int], dict[str, str]]:
    """(the traffic light controlling `lane_id`'s links or None, their link indices, the edge each of its
    movements leads to by SUMO's direction: "r" right, "s" straight, ...)."""
    exits: dict[str, str] = {}
    for link in api.lane.getLinks(lane_id):
        exits.setdefault(link[6], api.lane.getEdgeID(link[0]))
    for tls in api.trafficlight.getIDList():
        indices = [
            index
            for index, links in enumerate(api.trafficlight.getControlledLinks(tls))
            if any(link[0] == lane_id for link in links)
        ]
        if indices:
            return tls, indices, exits
    return None, [], exits


def form_queue(api, queue: tuple[VehicleSetup, ...], add: AddVehicle, near_turn: str = "r") -> None:
    """Form `queue` (its head first, all on one lane) in SUMO before the episode's start: red on the
    lane's links, the vehicles in from the lane's start one every ARRIVAL_HEADWAY_S, stepped until all
    stand still, then the junction's program back. The head turns by `near_turn` (SUMO's direction of
    the kerb lane's near-side turn: "r", "l" in left-hand traffic). RuntimeError when the queue does not
    form where it was staged (module docstring). Where no traffic light controls the lane, the head
    stops for a SUMO stop at its staged front instead of the red."""
    lane_id = queue[0].lane_id
    edge_id = lane_id.rsplit("_", 1)[0]
    tls, indices, exits = lane_links(api, lane_id)
    program = ""
    if tls is not None:
        program = api.trafficlight.getProgram(tls)
        state = list(api.trafficlight.getRedYellowGreenState(tls))
        for index in indices:
            state[index] = RED
        api.trafficlight.setRedYellowGreenState(tls, "".join(state))
    through = exits.get("s") or next(iter(exits.values()), "")
    routes = {"queue_right": exits.get(near_turn) or through, "queue_through": through}
    for route_id, exit_edge in routes.items():
        api.route.add(route_id, [edge_id, exit_edge] if exit_edge else [edge_id])
    start_s = api.simulation.getTime()
    for k, vehicle in enumerate(queue):
        depart_s = start_s + k * ARRIVAL_HEADWAY_S
        add(api, vehicle, "queue_right" if k == 0 else "queue_through", repr(depart_s))
        # Its speed factor not SUMO's draw: the queue arrives the same way whatever SUMO's seed.
        api.vehicle.setSpeedFactor(vehicle.vehicle_id, 1.0)
        # In its lane: followers free to change would pass the standing queue in the next lane.
        api.vehicle.setLaneChangeMode(vehicle.vehicle_id, 0)
    if tls is None:
        head = queue[0]
        api.vehicle.setStop(head.vehicle_id, edge_id, head.front_pos_m, int(lane_id.rsplit("_", 1)[1]), 1.0e6)
    ids = [v.vehicle_id for v in queue]
    while True:
        api.simulation.step()
        now_s = api.simulation.getTime()
        present = set(api.vehicle.getIDList())
        if all(vid in present for vid in ids) and all(api.vehicle.getSpeed(vid) == 0.0 for vid in ids):
            break
        if now_s - start_s > FORMING_LIMIT_S:
            raise RuntimeError(
                f"the kerb-lane queue of {len(queue)} vehicles on {lane_id} did not stand still within "
                f"{FORMING_LIMIT_S:g} s"
            )
    if tls is not None:
        api.trafficlight.setProgram(tls, program)
    check_formed(api, queue)


def formed_positions_m(api, queue: tuple[VehicleSetup, ...]) -> list[float]:
    """Where SUMO's queue stands: each vehicle's front, lane-length metres from its lane's start."""
    return [float(api.vehicle.getLanePosition(v.vehicle_id)) for v in queue]


def check_formed(api, queue: tuple[VehicleSetup, ...]) -> None:
    """RuntimeError (one line) when a vehicle of `queue` stopped off its lane or more than
    FORMED_TOLERANCE_M from its staged front."""
    for vehicle, front_m in zip(queue, formed_positions_m(api, queue), strict=True):
        lane_id = api.vehicle.getLaneID(vehicle.vehicle_id)
        if lane_id != vehicle.lane_id or abs(front_m - vehicle.front_pos_m) > FORMED_TOLERANCE_M:
            raise RuntimeError(
                f"the kerb-lane queue did not form where it was staged: {vehicle.vehicle_id} stopped on "
                f"{lane_id} at {front_m:.3f} m, staged at {vehicle.front_pos_m:.3f} m on {vehicle.lane_id}"
            )
