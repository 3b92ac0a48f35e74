"""An approach over its chain of edges (network/approach_chain.py), and the staged vehicles put back on the
lanes SUMO knows.

Where the junction's incoming edge is a stub, the approach's lanes are its chain: each vehicle lane's
shape, length and straight-through path run from the chain's start (the first lane, the nodes' internal
lanes, the stub) to the stop line, its route names the chain's edges, and the road before it (approach
staging's upstream start) begins where the chain does. The placements measure along these lanes as along
any approach lane: a vehicle is staged on the stop line's lane (Approach.lane_ids) at a position along
its chain. `land_scene` then puts each on the lane of the chain its front stands on, at its position
there, with a route from that lane's edge (SUMO inserts a vehicle on its route's first edge); a front on a
node's internal lane is inserted at the end of the lane before it and moved there before the first step
(VehicleSetup.internal_lane_id), as the ego starting on the road before its approach.

An approach whose incoming edge is no stub is that edge alone: its Approach and staged vehicles are
unchanged.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

from pedsafe_sumo.network.approach_chain import ApproachChain, approach_chain
from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.upstream import RoadLane, free_through, position_on, upstream_road

if TYPE_CHECKING:
    # Annotations only: geometry.py calls chain_approach while building its Approach.
    from pedsafe_sumo.scenarios.geometry import Approach
    from pedsafe_sumo.scenarios.placements.base import StagedScene


def _joined(shapes) -> tuple[tuple[float, float], ...]:
    """One polyline from consecutive shapes, a point shared by two of them kept once."""
    points: list[tuple[float, float]] = []
    for shape in shapes:
        for p in shape:
            if not points or math.dist(p, points[-1]) > 1e-6:
                points.append((float(p[0]), float(p[1])))
    return tuple(points)


def chain_approach(net, approach: Approach) -> Approach:
    """`approach` over its chain (module docstring): unchanged when its edge is no stub."""
    chain = approach_chain(net, net.getEdge(approach.edge_id))
    if len(chain.edges) == 1:
        return approach
    before = [lanes[:-1] for lanes in chain.lanes]  # per vehicle lane: the chain before the stop line's lane
    through_paths = tuple(
        tuple((lane.shape, lane.length_m) for lane in lanes) + path
        for lanes, path in zip(before, approach.through_paths, strict=True)
    )
    sidewalks = [
        lane
        for edge_id in chain.edges
        for lane in [net.getEdge(edge_id).getLane(0)]
        if lane.allows("pedestrian") and not lane.allows("passenger")
    ]
    # The person is added on the sidewalk edge at 1 m (sim/staging.py add_pedestrian): the stop line's
    # own sidewalk when it is that long, else the longest of the chain.
    sidewalk = net.getLane(approach.sidewalk_lane_id)
    if sidewalk.getLength() < 1.5 and sidewalks:
        sidewalk = max(sidewalks, key=lambda lane: lane.getLength())
    return dataclasses.replace(
        approach,
        lane_shapes=tuple(_joined(lane.shape for lane in lanes) for lanes in chain.lanes),
        lane_lengths_m=tuple(chain.length_m(k) for k in range(len(chain.lanes))),
        through_route=(*chain.edges, *approach.through_route[1:]),
        through_paths=through_paths,
        sidewalk_lane_id=sidewalk.getID(),
        sidewalk_shape=_joined(lane.getShape() for lane in sidewalks) if sidewalks else approach.sidewalk_shape,
        upstream_roads=tuple(
            upstream_road(net, net.getLane(lanes[0].lane_id), follow=free_through) for lanes in chain.lanes
        ),
        chain=chain,
    )


def _on_chain(chain: ApproachChain, lane_index: int, front_pos_m: float) -> tuple[str, float, str, float]:
    """(lane, position) SUMO inserts a front `front_pos_m` along vehicle lane `lane_index`'s chain on, and
    the internal lane and position it is moved to ("", 0 when it stands on that lane)."""
    lanes = tuple(RoadLane(lane.lane_id, lane.shape, lane.length_m) for lane in chain.lanes[lane_index])
    lane_id, pos_m = position_on(lanes, front_pos_m)
    if not lane_id.startswith(":"):
        return lane_id, pos_m, "", 0.0
    index = next(k for k, lane in enumerate(lanes) if lane.lane_id == lane_id)
    before = next(lane for lane in reversed(lanes[:index]) if not lane.lane_id.startswith(":"))
    return before.lane_id, before.length_m, lane_id, pos_m


def land_vehicle(
    approach: Approach, vehicle: VehicleSetup, ego_route: tuple[str, ...] | None = None
) -> tuple[VehicleSetup, tuple[str, ...] | None]:
    """`vehicle` (staged on a lane of the approach at a position along its chain) on the chain's lane its
    front stands on, and `ego_route` (the ego's route, None for another vehicle) from that lane's edge;
    another vehicle gets a route of its own from there (its own route, or the chain's edges for one
    that stands: sim/staging.py adds a route for every vehicle with one). A vehicle staged elsewhere, or
    a front before the chain's start or beyond the stop line (the batch's staging check refuses it), is
    left where it is. ValueError for a vehicle SUMO forms into a queue or parks at the kerb off the stop
    line's lane: both are staged on one lane (sim/queue.py, sim/kerb.py)."""
    chain = approach.chain
    if chain is None or vehicle.approach_lane_id or vehicle.lane_id not in approach.lane_ids:
        return vehicle, ego_route
    k = approach.lane_ids.index(vehicle.lane_id)
    if not 0.0 <= vehicle.front_pos_m <= chain.length_m(k):
        return vehicle, ego_route
    lane_id, pos_m, internal_id, internal_pos_m = _on_chain(chain, k, vehicle.front_pos_m)
    if (vehicle.formed or vehicle.kerb_offset_m > 0) and (lane_id != vehicle.lane_id or internal_id):
        what = "formed into a queue" if vehicle.formed else "parked at the kerb"
        raise ValueError(
            f"vehicle '{vehicle.vehicle_id}' would be {what} on {lane_id}, before the stub {approach.edge_id} "
            "its approach enters the junction on: SUMO stages such vehicles on the stop line's lane only"
        )
    edge_id = lane_id.rsplit("_", 1)[0]

    def from_edge(route: tuple[str, ...]) -> tuple[str, ...]:
        if route and route[0] == approach.edge_id:  # from the stop line's edge: the chain before it first
            route = (*chain.edges[:-1], *route)
        return route[route.index(edge_id) :] if edge_id in route else route

    landed = dataclasses.replace(
        vehicle,
        lane_id=lane_id,
        front_pos_m=pos_m,
        internal_lane_id=internal_id,
        internal_pos_m=internal_pos_m,
        approach_lane_id=vehicle.lane_id,
    )
    if ego_route is not None:
        return landed, from_edge(ego_route)
    return dataclasses.replace(landed, route=from_edge(vehicle.route or chain.edges)), None


def land_scene(approach: Approach, scene: StagedScene) -> StagedScene:
    """`scene` with its ego and the vehicles staged on the approach's lanes on the lanes of its chain
    (land_vehicle); the scene itself where the approach is one edge."""
    if approach.chain is None:
        return scene
    ego, ego_route = land_vehicle(approach, scene.ego, scene.ego_route)
    parked = tuple(land_vehicle(approach, vehicle)[0] for vehicle in scene.parked)
    check_insertion(approach, (ego, *parked))
    return dataclasses.replace(scene, ego=ego, ego_route=ego_route or scene.ego_route, parked=parked)


def check_insertion(approach: Approach, vehicles) -> None:
    """ValueError when a vehicle that stands on a node's internal lane of the chain would be inserted (at
    the end of the lane before it, VehicleSetup.internal_lane_id) where another vehicle's body is: SUMO
    would not insert it ("SUMO did not insert vehicle ..."). Two vehicles on one internal lane are
    inserted at the same place."""
    landed = [v for v in vehicles if v.internal_lane_id and v.approach_lane_id]
    for vehicle in landed:
        rear_m = vehicle.front_pos_m - vehicle.size.length_m
        for other in vehicles:
            if other is vehicle or other.lane_id != vehicle.lane_id or other.kerb_offset_m > 0:
                continue
            if other.front_pos_m > rear_m and other.front_pos_m - other.size.length_m < vehicle.front_pos_m:
                raise ValueError(
                    f"vehicle '{vehicle.vehicle_id}' stands on {vehicle.internal_lane_id}, a node's internal "
                    f"lane of the chain of approach {approach.edge_id}: SUMO inserts it at the end of "
                    f"{vehicle.lane_id}, where '{other.vehicle_id}' stands"
                )


def chain_lanes_before(approach: Approach, lane_index: int, net) -> list:
    """The sumolib lanes of vehicle lane `lane_index`'s chain before the stop line's lane (none where the
    approach is one edge): a turn's path starts with them (geometry.load_turn)."""
    if approach.chain is None:
        return []
    return [net.getLane(lane.lane_id) for lane in approach.chain.lanes[lane_index][:-1]]

