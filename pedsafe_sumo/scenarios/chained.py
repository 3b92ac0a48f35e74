"""An approach over its chain of edges (network/approach_chain.py), and the staged vehicles put back on the
lanes SUMO knows.

Where the junction's incoming edge is a stub, the approach's lanes are its chain: each vehicle lane's
shape, length and straight-through path run from the chain's start (the first lane, the nodes' internal
lanes, the stub) to the stop line, its route names the chain's edges, and the road before it (approach
staging's upstream start) begins where the chain does. The placements measure along these lanes as along
any approach lane: a vehicle is staged on the stop line's lane (Approach.lane_ids) at a position along
its chain. `land_scene` then puts each on the lane of the chain its front stands on, at its position
there, with a route from that lane's edge (SUMO inserts a vehicle on its route's first edge); a front on a
node's internal lane is inserted on a lane before it where its body has room and moved there before the
first step (VehicleSetup.internal_lane_id), as the ego starting on the road before its approach. What
cannot be staged so is refused in one line (land_scene, check_conflict_off_nodes).

An approach whose incoming edge is no stub is that edge alone: its Approach and staged vehicles are
unchanged.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import sumolib

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
    # The person is added on the sidewalk edge 1 m from its start (sim/staging.py add_pedestrian): the stop
    # line's own sidewalk when it holds that and half a metre more, else the longest of the chain.
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
        sidewalk_shape=(
            _joined(lane.getShape() for lane in sidewalks) if sidewalks else approach.sidewalk_shape
        ),
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


#: A vehicle standing on a node's internal lane of the chain is inserted this far from any other vehicle
#: SUMO inserts on the same lane [m]. Assumption: the staged vehicles' minGap (VehicleSetup.min_gap_m,
#: 0.5 m) twice over, so SUMO's insertion check at speed 0 never finds them too close.
INSERTION_CLEARANCE_M = 1.0


def _land(approach: Approach, vehicle: VehicleSetup) -> tuple[VehicleSetup, int | None]:
    """(`vehicle` on the chain's lane its front stands on, its vehicle lane index), or (`vehicle`, None)
    for one staged elsewhere, or whose front lies before the chain's start or beyond the stop line (the
    batch's staging check refuses it). A front on a node's internal lane: on the end of the lane before
    it for now (`_insertion_spots` finds where SUMO inserts it), the internal lane in internal_lane_id."""
    chain = approach.chain
    if chain is None or vehicle.approach_lane_id or vehicle.lane_id not in approach.lane_ids:
        return vehicle, None
    k = approach.lane_ids.index(vehicle.lane_id)
    if not 0.0 <= vehicle.front_pos_m <= chain.length_m(k):
        return vehicle, None
    lane_id, pos_m, internal_id, internal_pos_m = _on_chain(chain, k, vehicle.front_pos_m)
    if (vehicle.formed or vehicle.kerb_offset_m > 0) and (lane_id != vehicle.lane_id or internal_id):
        what = "formed into a queue" if vehicle.formed else "parked at the kerb"
        raise ValueError(
            f"vehicle '{vehicle.vehicle_id}' would be {what} on {internal_id or lane_id}, before the stub "
            f"{approach.edge_id} its approach enters the junction on: SUMO stages such vehicles on the stop "
            "line's lane only"
        )
    landed = dataclasses.replace(
        vehicle,
        lane_id=lane_id,
        front_pos_m=pos_m,
        internal_lane_id=internal_id,
        internal_pos_m=internal_pos_m,
        approach_lane_id=vehicle.lane_id,
    )
    return landed, k


def _free_front_m(length_m: float, taken: list[tuple[float, float]], body_m: float) -> float | None:
    """The furthest front position on a lane `length_m` long where a body `body_m` long keeps
    INSERTION_CLEARANCE_M from every (rear, front) of `taken`, or None."""
    gap_m = INSERTION_CLEARANCE_M
    for front_m in sorted([length_m, *(rear - gap_m for rear, _ in taken)], reverse=True):
        if front_m > length_m or front_m - body_m < 0.0:
            continue
        if all(front_m + gap_m <= rear or front_m - body_m - gap_m >= front for rear, front in taken):
            return front_m
    return None


def _insertion_spots(approach: Approach, landed: list[tuple[VehicleSetup, int | None]]) -> list:
    """`landed` with every vehicle that stands on a node's internal lane inserted where SUMO can insert it:
    on the nearest lane before it on its chain (then on the road before the chain) with room for its body
    clear of every other vehicle SUMO inserts there; sim/staging.py moves it onto its internal lane before
    the episode's first step. Two vehicles on one internal lane cannot both be inserted at the end of the
    lane before it. ValueError when no lane before it has room."""
    chain = approach.chain
    assert chain is not None
    taken: dict[str, list[tuple[float, float]]] = {}
    for vehicle, _ in landed:
        if not vehicle.internal_lane_id and vehicle.kerb_offset_m <= 0 and not vehicle.formed:
            taken.setdefault(vehicle.lane_id, []).append(
                (vehicle.front_pos_m - vehicle.size.length_m, vehicle.front_pos_m)
            )
    out = []
    for vehicle, k in landed:
        if k is None or not vehicle.internal_lane_id:
            out.append((vehicle, k))
            continue
        lanes = list(chain.lanes[k])
        before = lanes[: next(i for i, lane in enumerate(lanes) if lane.lane_id == vehicle.internal_lane_id)]
        upstream = approach.upstream_roads[k].lanes if approach.upstream_roads else ()
        lanes_before = [(lane.lane_id, lane.length_m) for lane in upstream] + [
            (lane.lane_id, lane.length_m) for lane in before
        ]
        candidates = [(i, m) for i, m in reversed(lanes_before) if not i.startswith(":")]
        for lane_id, length_m in candidates:
            front_m = _free_front_m(length_m, taken.get(lane_id, []), vehicle.size.length_m)
            if front_m is not None:
                vehicle = dataclasses.replace(vehicle, lane_id=lane_id, front_pos_m=front_m)
                taken.setdefault(lane_id, []).append((front_m - vehicle.size.length_m, front_m))
                break
        else:
            raise ValueError(
                f"vehicle '{vehicle.vehicle_id}' stands on {vehicle.internal_lane_id}, a node's internal "
                f"lane of the chain of approach {approach.edge_id}: no lane before it has room to insert it"
            )
        out.append((vehicle, k))
    return out


def _route_from(approach: Approach, k: int, edge_id: str, route: tuple[str, ...]) -> tuple[str, ...]:
    """`route` (from the stop line's edge or the chain's start) from the edge `edge_id` on: the chain and
    the road before it first where it starts after them."""
    chain = approach.chain
    assert chain is not None
    if route and route[0] == approach.edge_id:
        route = (*chain.edges[:-1], *route)
    if route and route[0] == chain.edges[0] and approach.upstream_roads:
        route = (*approach.upstream_roads[k].edges, *route)
    return route[route.index(edge_id) :] if edge_id in route else route


def land_scene(approach: Approach, scene: StagedScene) -> StagedScene:
    """`scene` with its ego and the vehicles staged on the approach's lanes (a position along its chain)
    on the lanes of the chain, each with a route from its lane's edge: the ego's route, a driving
    vehicle's own, the chain's edges for one that stands (sim/staging.py adds a route for every vehicle
    with one). The scene itself where the approach is one edge. ValueError for a vehicle SUMO forms into a
    queue or parks at the kerb off the stop line's lane (both are staged on one lane: sim/queue.py,
    sim/kerb.py), or one standing on an internal lane with no room to insert it (_insertion_spots)."""
    if approach.chain is None:
        return scene
    chain = approach.chain
    if scene.ego.stop_line_lane_id in approach.lane_ids:
        check_conflict_off_nodes(
            approach, approach.lane_ids.index(scene.ego.stop_line_lane_id), scene.conflict_xy
        )
    landed = _insertion_spots(approach, [_land(approach, v) for v in (scene.ego, *scene.parked)])
    (ego, ego_k), parked_landed = landed[0], landed[1:]
    ego_route = scene.ego_route
    if ego_k is not None:
        ego_route = _route_from(approach, ego_k, ego.lane_id.rsplit("_", 1)[0], ego_route)
    parked = tuple(
        vehicle
        if k is None
        else dataclasses.replace(
            vehicle,
            route=_route_from(approach, k, vehicle.lane_id.rsplit("_", 1)[0], vehicle.route or chain.edges),
        )
        for vehicle, k in parked_landed
    )
    return dataclasses.replace(scene, ego=ego, ego_route=ego_route, parked=parked)


#: A conflict point this close to a node's internal lane of the chain lies on it [m]. Assumption: half a
#: lane's width (3.2 m lanes): the straight placements put it on the centre of the ego's lane.
ON_LANE_M = 1.6


def check_conflict_off_nodes(approach: Approach, lane_index: int, conflict_xy) -> None:
    """ValueError when the conflict point lies on a node's internal lane of vehicle lane `lane_index`'s
    chain: the pedestrian would cross inside the junction area of a node before the approach, where
    SUMO 1.28 maps a person moved by moveToXY onto that node's crosswalks and walking areas and can crash
    (a segmentation fault, measured on the Aguascalientes clip: docs/sites.md)."""
    chain = approach.chain
    if chain is None:
        return
    best: tuple[float, str] | None = None
    for lane in chain.lanes[lane_index]:
        offset_m = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(
            conflict_xy, lane.shape, perpendicular=False
        )
        gap_m = math.dist(sumolib.geomhelper.positionAtShapeOffset(lane.shape, offset_m), conflict_xy)
        if best is None or gap_m < best[0]:
            best = (gap_m, lane.lane_id)
    if best is not None and best[1].startswith(":") and best[0] <= ON_LANE_M:
        node = best[1][1:].rsplit("_", 2)[0]
        raise ValueError(
            f"the pedestrian would cross the ego's lane inside node {node} before approach "
            f"{approach.edge_id} (on its internal lane {best[1]}), not on a road"
        )


def chain_lanes_before(approach: Approach, lane_index: int, net) -> list:
    """The sumolib lanes of vehicle lane `lane_index`'s chain before the stop line's lane (none where the
    approach is one edge): a turn's path starts with them (geometry.load_turn)."""
    if approach.chain is None:
        return []
    return [net.getLane(lane.lane_id) for lane in approach.chain.lanes[lane_index][:-1]]
