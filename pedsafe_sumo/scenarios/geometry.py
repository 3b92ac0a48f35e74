"""Where the scenarios happen on a site: the approach its roadside camera watches.

All three scenarios are staged on the approach of the main junction that the roadside unit watches
(on Xueqing, the southbound main carriageway of Xueqing Road: two vehicle lanes, a sidewalk on the
right, a signalised crosswalk at the stop line). Everything is derived from the network with sumolib,
never from hard-coded edge ids, so another site built by tools/build_network.py works the same way.

Traffic side: Approach.keep_side (network.traffic_side) is +1 where traffic keeps right and -1 where it
keeps left (a network built with netconvert --lefthand). Lane indices mean the same on both sides (0 the
kerb-side lane); every offset across the road is measured towards the median (Approach.across), and the
turns are named by their side: "right" is the near-side turn from the kerb lane across the kerb-side
crosswalk (SUMO's "r" in right-hand traffic, "l" in left-hand traffic), "left" the far-side turn from
the median lane across oncoming traffic (load_turn). So a site in left-hand traffic stages every
scenario mirrored.

Frames: SUMO network coordinates (x east, y north, metres); headings in radians counter-clockwise
from +x. Lane positions are metres from the start of the lane, as in SUMO: SUMO moves a vehicle in
lane-length metres and draws lane position p at p x (drawn length / lane length) along the lane's shape
(MSLane::interpolateLanePosToGeometryPos), and netconvert may set a lane's length apart from its drawn
shape (Xueqing's median lane: 181.63 m long, 181.16 m drawn; the junction's straight internal lanes are
all 42.36 m long, drawn 41.88-42.83 m). Every conversion between the two goes through
lane_pos_to_offset_m / offset_to_lane_pos_m below (the scenarios and the Euro NCAP staging alike).
"""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache

import sumolib

from pedsafe_sumo.network.approach_chain import ApproachChain
from pedsafe_sumo.network.approaches import legs_at
from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.network.traffic_side import KEEP_RIGHT, far_turn_letter, near_turn_letter, network_keep_side
from pedsafe_sumo.scenarios.chained import chain_approach, chain_lanes_before
from pedsafe_sumo.scenarios.upstream import UpstreamRoad, connection_lanes, free_through, upstream_road
from pedsafe_sumo.scenarios.walkways import Walkway, network_walkways
from pedsafe_sumo.sumo_net import read_net

#: A vehicle's way through the network as SUMO drives it: each lane's drawn shape (network frame, metres)
#: and SUMO length [m], in driving order (a lane, the junction's internal lane(s), the lane beyond).
LanePath = tuple[tuple[tuple[tuple[float, float], ...], float], ...]


def shape_length_m(shape) -> float:
    """Drawn length of a polyline [m]."""
    return sum(math.dist(p, q) for p, q in zip(shape[:-1], shape[1:]))


def lane_pos_to_offset_m(shape, length_m: float, pos_m: float) -> float:
    """Where SUMO draws lane position `pos_m` (lane-length metres): the offset along the drawn `shape`."""
    return pos_m * shape_length_m(shape) / length_m


def offset_to_lane_pos_m(shape, length_m: float, offset_m: float) -> float:
    """The lane position (lane-length metres) SUMO draws at `offset_m` along the drawn `shape`."""
    return offset_m * length_m / shape_length_m(shape)


def lane_path_in(net, lane, next_edge_id: str) -> LanePath:
    """The lanes a vehicle drives from sumolib `lane` onto the edge `next_edge_id`: the lane, the
    junction's internal lane(s) of the connection, and the lane it reaches there (a sumolib net read
    withInternal=True). ValueError when the lane has no connection to that edge."""
    connections = [c for c in lane.getOutgoing() if c.getTo().getID() == next_edge_id]
    if not connections:
        raise ValueError(f"lane {lane.getID()} has no connection to edge {next_edge_id}")
    return _as_lane_path(connection_lanes(net, connections[0]))


def _as_lane_path(lanes) -> LanePath:
    return tuple((tuple(tuple(p) for p in ln.getShape()), float(ln.getLength())) for ln in lanes)


def path_pos_m(path: LanePath, xy: tuple[float, float]) -> float:
    """SUMO distance (lane-length metres) from the start of `path` to its point nearest `xy`: what a
    vehicle's front at the path's start drives until it is drawn there."""
    best: tuple[float, float] | None = None
    done_m = 0.0
    for shape, length_m in path:
        offset_m = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(xy, shape, perpendicular=False)
        x, y = sumolib.geomhelper.positionAtShapeOffset(shape, offset_m)
        gap_m = math.dist((x, y), xy)
        if best is None or gap_m < best[0] - 1e-9:
            best = (gap_m, done_m + offset_to_lane_pos_m(shape, length_m, offset_m))
        done_m += length_m
    if best is None:
        raise ValueError("empty lane path")
    return best[1]


@dataclass(frozen=True)
class Approach:
    edge_id: str
    #: Vehicle lanes from the kerb side to the median side (right to left in right-hand traffic, left to
    #: right in left-hand traffic).
    lane_ids: tuple[str, ...]
    lane_shapes: tuple[tuple[tuple[float, float], ...], ...]
    lane_lengths_m: tuple[float, ...]
    lane_width_m: float
    sidewalk_lane_id: str
    sidewalk_width_m: float
    #: Edges of a straight-through route: the approach (the chain of edges before a stub: `chain`), then
    #: the outgoing road beyond the junction.
    through_route: tuple[str, ...]
    #: The crosswalk over the approach at the stop line, oriented from the kerb side to the far side.
    crosswalk_id: str
    crosswalk_path: tuple[tuple[float, float], tuple[float, float]]
    crosswalk_width_m: float
    junction_id: str
    #: Per vehicle lane (as lane_ids): the lanes of the straight-through movement from it onto
    #: through_route[-1] (the lane alone where it has no such movement).
    through_paths: tuple[LanePath, ...] = ()
    #: Vehicle lanes (indices as in lane_ids) with a straight movement onto through_route[-1].
    through_lanes: tuple[int, ...] = ()
    #: The approach's speed limit (its fastest vehicle lane's) [m/s].
    speed_limit_mps: float = math.nan
    #: Whether the kerb-side vehicle lane lies right beside the sidewalk (no lane between them): a car
    #: parked at the kerb of a one-lane approach stands next to that lane (kerb_staging_problem in
    #: placements/straight.py).
    sidewalk_beside_lane: bool = True
    #: The sidewalk's drawn centreline, towards the junction (network frame, m): approach staging's
    #: pedestrian walks in along it (scenarios/walkways.py).
    sidewalk_shape: tuple[tuple[float, float], ...] = ()
    #: Every sidewalk of the site's network (walkways.Walkway): approach staging's pedestrian walks on
    #: along the one they reach beyond the crossing.
    walkways: tuple[Walkway, ...] = ()
    #: The junction's centre (its node's coordinate, network frame, m).
    junction_xy: tuple[float, float] = (math.nan, math.nan)
    #: Per vehicle lane (as lane_ids): the road before it, straight on through the junctions before the
    #: approach over major links no traffic light controls (upstream.free_through), up to 500 m
    #: (upstream.UPSTREAM_MAX_M): approach staging starts the ego there when the lane is shorter than its
    #: drawn start distance (placements/straight.py).
    upstream_roads: tuple[UpstreamRoad, ...] = ()
    #: The side traffic keeps to (network.traffic_side): +1 right-hand (the median lies to the left of
    #: travel), -1 left-hand (to the right).
    keep_side: float = KEEP_RIGHT
    #: Where the junction's incoming edge is a stub, the chain of edges the approach is (scenarios/
    #: chained.py): lane_shapes, lane_lengths_m, through_paths, through_route and upstream_roads run
    #: along it, and the staged vehicles are put on its lanes (chained.land_scene). None: the approach is
    #: its incoming edge alone.
    chain: ApproachChain | None = None

    def pose(self, lane_index: int, pos_m: float) -> tuple[float, float, float]:
        """(x, y, heading) of the centre of vehicle lane `lane_index` at SUMO lane position `pos_m`, where
        SUMO draws a vehicle's front at that lane position."""
        shape = self.lane_shapes[lane_index]
        length_m = self.lane_lengths_m[lane_index]
        offset_m = lane_pos_to_offset_m(shape, length_m, min(max(pos_m, 0.0), length_m))
        x, y = sumolib.geomhelper.positionAtShapeOffset(shape, offset_m)
        # sumolib returns atan2(dy, dx) in radians: counter-clockwise from +x, as used here.
        return x, y, sumolib.geomhelper.rotationAtShapeOffset(shape, offset_m)

    def across(self, lane_index: int, pos_m: float, from_offset_m: float, to_offset_m: float):
        """Two points on the line across the road at a lane position, offsets measured from the centre
        of `lane_index` towards the median (negative: towards the kerb): to the left of travel in
        right-hand traffic, to the right in left-hand traffic (keep_side)."""
        x, y, heading = self.pose(lane_index, pos_m)
        median = (-self.keep_side * math.sin(heading), self.keep_side * math.cos(heading))
        return (
            (x + from_offset_m * median[0], y + from_offset_m * median[1]),
            (x + to_offset_m * median[0], y + to_offset_m * median[1]),
        )


def leg_order_key(name: str) -> float:
    """A leg's place clockwise from north, from its name alone (N 0, NE 45, E 90, ..., B055 55)."""
    if name.startswith("B"):
        return float(name[1:])
    return {"N": 0.0, "NE": 45.0, "E": 90.0, "SE": 135.0, "S": 180.0, "SW": 225.0, "W": 270.0, "NW": 315.0}[
        name
    ]


def site_approaches(site: Site) -> dict[str, str]:
    """Arm -> signal node of every approach the site's build found (the site file's `approaches`; a site
    file from before them has only its watched arm, at the main junction)."""
    info = json.loads(site.file("site.json").read_text(encoding="utf-8"))
    found = info.get("approaches")
    if found:
        return {arm: entry["junction"] for arm, entry in found.items() if "skipped" not in entry}
    return {info["roadside_unit"]["watched_arm"]: info["main_junction"]}


def default_arm(site: Site) -> str:
    """The site's own approach: the arm its first roadside pole watches (what runs without --approach)."""
    info = json.loads(site.file("site.json").read_text(encoding="utf-8"))
    return str(info["roadside_unit"]["watched_arm"])


#: A leg more than this far from straight across [deg] is no opposite leg (opposite_leg). Assumption: half
#: the 90 degrees between the legs of a four-leg junction.
OPPOSITE_LEG_MAX_DEG = 45.0


def opposite_leg(site: Site, arm: str) -> str:
    """The leg of the site straight across from leg `arm` (the one whose nominal direction, leg_order_key,
    is nearest the reverse of its own, within OPPOSITE_LEG_MAX_DEG); ValueError when there is none."""
    reverse_deg = (leg_order_key(arm) + 180.0) % 360.0

    def off_deg(name: str) -> float:
        d = abs(leg_order_key(name) - reverse_deg) % 360.0
        return min(d, 360.0 - d)

    others = [name for name in site_approaches(site) if name != arm]
    if not others or off_deg(min(others, key=off_deg)) > OPPOSITE_LEG_MAX_DEG:
        raise ValueError(f"site {site.name}: no leg lies across from the {arm} leg")
    return min(others, key=off_deg)


#: Arms clockwise; a left turn leaves by the next arm clockwise, a right turn by the previous one.
_ARMS_CLOCKWISE = ("N", "E", "S", "W")


def exit_arm(arm: str, turn: str, side: float = KEEP_RIGHT) -> str:
    """The arm a `turn` (the scenarios' "left": far-side, or "right": near-side) from approach `arm` leaves
    by; in left-hand traffic (`side` -1) the far-side turn is a right turn and the near-side one a left."""
    step = {"left": 1, "right": -1}[turn] * (1 if side > 0 else -1)
    return _ARMS_CLOCKWISE[(_ARMS_CLOCKWISE.index(arm) + step) % 4]


def approach_unit_ids(
    unit_ids: tuple[str, ...], arm: str, site_arm: str, turn: str = "", side: float = KEEP_RIGHT
) -> tuple[str, ...]:
    """The poles a scenario's `roadside_units` name on approach `arm`: the site's own approach keeps the
    ids (rsu_camera_0, rsu_camera_1); the build names another approach's poles after its arm
    (rsu_camera_0_E, rsu_camera_1_E: tools/build_network.py). `rsu_camera_K@exit` names pole K of the
    arm a turning ego leaves by (left_turn's pedestrian walks on that arm's crosswalk), so a turn
    scenario names the right pole on every approach and every site."""
    arm = arm or site_arm

    def pole(index: str, of_arm: str) -> str:
        return f"rsu_camera_{index}" if of_arm == site_arm else f"rsu_camera_{index}_{of_arm}"

    ids = []
    for unit in unit_ids:
        own = re.fullmatch(r"rsu_camera_(\d+)", unit)
        leaving = re.fullmatch(r"rsu_camera_(\d+)@exit", unit)
        if own:
            ids.append(pole(own.group(1), arm))
        elif leaving and turn in ("left", "right") and arm in _ARMS_CLOCKWISE:
            ids.append(pole(leaving.group(1), exit_arm(arm, turn, side)))
        else:
            # A pole named otherwise (--set roadside_units=...) is taken as named.
            ids.append(unit)
    return tuple(ids)


@lru_cache(maxsize=16)
def load_approach(site: Site, arm: str | None = None) -> Approach:
    """The approach from leg `arm` (N, E, S, W or another leg name, network.approaches.junction_legs; None
    or "": the site's own approach, default_arm)."""
    info = json.loads(site.file("site.json").read_text(encoding="utf-8"))
    net = read_net(str(site.file("net.xml")), withInternal=True)
    arm = arm or info["roadside_unit"]["watched_arm"]
    approaches = site_approaches(site)
    if arm not in approaches:
        raise ValueError(
            f"site {site.name}: no approach from the {arm} (approaches: {', '.join(approaches) or 'none'})"
        )
    junction = net.getNode(approaches[arm])
    jx, jy = junction.getCoord()
    leg_edges = {edge_id for leg in legs_at(net, junction) if leg.name == arm for edge_id in leg.edge_ids}
    candidates = [
        e
        for e in junction.getIncoming()
        if e.getFunction() == ""
        and e.getID() in leg_edges
        and sum(lane.allows("passenger") for lane in e.getLanes()) >= 1
    ]
    if not candidates:
        raise ValueError(f"site {site.name}: the {arm} arm has no approach with a vehicle lane")
    edge = max(candidates, key=lambda e: e.getLaneNumber())
    vehicle_lanes = [lane for lane in edge.getLanes() if lane.allows("passenger")]
    sidewalk = edge.getLane(0)
    if not sidewalk.allows("pedestrian") or sidewalk.allows("passenger"):
        raise ValueError(f"site {site.name}: approach {edge.getID()} has no sidewalk")

    straight = [c.getTo() for lane in vehicle_lanes for c in lane.getOutgoing() if c.getDirection() == "s"]
    if not straight:
        raise ValueError(f"site {site.name}: no straight movement from {edge.getID()}")
    through_edge_id = straight[0].getID()

    def through_path(lane) -> LanePath:
        if any(c.getTo().getID() == through_edge_id for c in lane.getOutgoing()):
            return lane_path_in(net, lane, through_edge_id)
        return ((tuple(tuple(p) for p in lane.getShape()), float(lane.getLength())),)

    crossings = [
        c
        for c in net.getEdges(withInternal=True)
        if c.getFunction() == "crossing" and edge in c._crossingEdges
    ]
    # The one at the stop line: a crosswalk over the approach at its upstream end belongs to another
    # junction (Xueqing's west approach has one there, found first).
    crossing = next(
        (c for c in crossings if c.getFromNode() == junction), crossings[0] if crossings else None
    )
    if crossing is None:
        raise ValueError(f"site {site.name}: no crosswalk over {edge.getID()}")
    a, b = crossing.getLane(0).getShape()[0], crossing.getLane(0).getShape()[-1]
    kerb = sidewalk.getShape()[-1]
    if math.dist(b, kerb) < math.dist(a, kerb):
        a, b = b, a

    approach = Approach(
        edge_id=edge.getID(),
        lane_ids=tuple(lane.getID() for lane in vehicle_lanes),
        lane_shapes=tuple(tuple(map(tuple, lane.getShape())) for lane in vehicle_lanes),
        lane_lengths_m=tuple(lane.getLength() for lane in vehicle_lanes),
        lane_width_m=vehicle_lanes[0].getWidth(),
        sidewalk_lane_id=sidewalk.getID(),
        sidewalk_width_m=sidewalk.getWidth(),
        through_route=(edge.getID(), straight[0].getID()),
        crosswalk_id=crossing.getID(),
        crosswalk_path=(tuple(a), tuple(b)),
        crosswalk_width_m=crossing.getLane(0).getWidth(),
        junction_id=junction.getID(),
        through_paths=tuple(through_path(lane) for lane in vehicle_lanes),
        speed_limit_mps=max(lane.getSpeed() for lane in vehicle_lanes),
        sidewalk_beside_lane=vehicle_lanes[0].getIndex() == sidewalk.getIndex() + 1,
        sidewalk_shape=tuple((float(x), float(y)) for x, y in sidewalk.getShape()),
        walkways=network_walkways(net),
        junction_xy=(float(jx), float(jy)),
        through_lanes=tuple(
            k
            for k, lane in enumerate(vehicle_lanes)
            if any(c.getDirection() == "s" and c.getTo() == straight[0] for c in lane.getOutgoing())
        ),
        upstream_roads=tuple(upstream_road(net, lane, follow=free_through) for lane in vehicle_lanes),
        keep_side=network_keep_side(site.file("net.xml")),
    )
    return chain_approach(net, approach)


@lru_cache(maxsize=16)
def refuge_walkingareas(site: Site) -> tuple[str, ...]:
    """The walking areas of the site's network that no sidewalk leads to or from: only crosswalks do
    (netconvert's median refuge between the two halves of a crosswalk over a divided road; on the zhixin
    clip `:..._w5` between the crosswalks over the west arm's two carriageways).

    SUMO 1.28 crashes (segmentation fault) when a person moved by `person.moveToXY` reaches one while its
    walking route ends there: MSPModel_Striping::PState::moveToXY asks getNextLane for the way on with no
    previous lane, the pedestrian router finds no way from the walking area to the route's end (itself),
    and the fallback for that case reads the previous lane (`prevLane->getLinkTo(...)`, a null pointer).
    The episode avoids it by giving the person a route whose end is a sidewalk (docs/sites.md)."""
    walking: set[str] = set()
    with_sidewalk: set[str] = set()
    for _, element in ET.iterparse(site.file("net.xml")):
        if element.tag == "edge" and element.get("function") == "walkingarea":
            walking.add(element.get("id", ""))
        elif element.tag == "connection":
            ends = (element.get("from", ""), element.get("to", ""))
            if not all(end.startswith(":") for end in ends):  # a normal edge (a sidewalk) on one side
                with_sidewalk.update(ends)
        if element.tag != "net":
            element.clear()
    return tuple(sorted(walking - with_sidewalk))


def straight_staging_problem(approach: Approach, ego_lane: int | None = None) -> str | None:
    """Why a straight-through ego cannot be staged in vehicle lane `ego_lane` of the approach (None: the
    lane next to the kerb lane, where crossing, jaywalking and background blending put it; on a one-lane
    approach the lane itself, the vehicles that hide the pedestrian parked at the kerb beside it:
    kerb_staging_problem in placements/straight.py says whether they fit), or None. A lane that only
    turns (on Xueqing's east approach the second lane turns left) would have the ego drive straight from
    a turning lane, against the lane's marking."""
    if ego_lane is None:
        ego_lane = 0 if len(approach.lane_ids) == 1 else 1
    if ego_lane >= len(approach.lane_ids):
        return (
            f"approach {approach.edge_id} has {len(approach.lane_ids)} vehicle lane(s): no lane beside the "
            "kerb lane for the ego to pass the vehicle that hides the pedestrian"
        )
    if ego_lane not in approach.through_lanes:
        return (
            f"lane {approach.lane_ids[ego_lane]}, where the ego drives, has no straight movement onto "
            f"{approach.through_route[-1]}"
        )
    return None


@dataclass(frozen=True)
class Turn:
    """A turning movement from the watched approach onto another arm of the junction."""

    #: The scenarios' name of the turn: "right" the near-side turn, "left" the far-side one (the physical
    #: right and left turns in right-hand traffic, mirrored in left-hand traffic: module docstring).
    direction: str
    #: Index (kerb to median, as in Approach.lane_ids) of the approach lane the turn starts from.
    lane_index: int
    #: The approach, then the road the ego turns into.
    route: tuple[str, ...]
    #: The ego's path: the approach lane's centreline, the junction's internal lane(s) of the
    #: connection, then the first lane of the road turned into (network frame, metres).
    path_xy: tuple[tuple[float, float], ...]
    #: Length of the approach lane (where the path enters the junction) [m].
    approach_length_m: float
    #: The crosswalk over the road turned into, oriented from the corner nearer the approach's stop
    #: line ("near": the corner the ego turns around on a near-side turn) to the other.
    crosswalk_id: str
    crosswalk_path: tuple[tuple[float, float], tuple[float, float]]
    #: The lane of the road turned into that the path ends on, and the SUMO distance along the path (lane
    #: lengths, as path_pos_m) at which it begins (where the junction ends) [m].
    exit_lane_id: str = ""
    exit_start_m: float = 0.0
    #: The lanes of path_xy with their SUMO lengths: SUMO distances along the path (path_pos_m).
    lanes: LanePath = ()


#: The turns by the scenarios' names: SUMO's connection direction (https://sumo.dlr.de/docs/Networks/
#: PlainXML.html) as a function of keep_side, and the change of heading (+1 anticlockwise) in right-hand
#: traffic (mirrored by keep_side).
_TURN_DIRECTIONS = {"right": (near_turn_letter, -1.0), "left": (far_turn_letter, 1.0)}


def turn_name(direction: str, side: float) -> str:
    """How a turn the scenarios name `direction` reads on a site keeping to `side`: "right turn" and "left
    turn" in right-hand traffic; in left-hand traffic the mirror, with the scenarios' name."""
    if side > 0:
        return f"{direction} turn"
    physical = {"right": "left", "left": "right"}[direction]
    side_name = {"right": "near-side", "left": "far-side"}[direction]
    return f"{side_name} turn ({physical} turn in left-hand traffic)"


@lru_cache(maxsize=32)
def load_turn(site: Site, direction: str, arm: str | None = None) -> Turn:
    """The `direction` turn of the approach from `arm` (None: the site's own): from the kerb lane ("right":
    near-side) or the median lane ("left": far-side), onto the arm whose heading differs by the nearest to
    90 degrees; raises ValueError when the approach has no such connection or the arm no crosswalk."""
    if direction not in _TURN_DIRECTIONS:
        raise ValueError(f"unknown turn '{direction}' (known: {', '.join(_TURN_DIRECTIONS)})")
    approach = load_approach(site, arm)
    net = read_net(str(site.file("net.xml")), withInternal=True)
    lane_index = 0 if direction == "right" else len(approach.lane_ids) - 1
    lane = net.getLane(approach.lane_ids[lane_index])
    letter_of, turn_sign = _TURN_DIRECTIONS[direction]
    connections = [c for c in lane.getOutgoing() if c.getDirection() == letter_of(approach.keep_side)]
    if not connections:
        raise ValueError(
            f"site {site.name}: no {turn_name(direction, approach.keep_side)} from lane {lane.getID()}"
        )
    (ax, ay), (bx, by) = lane.getShape()[-2:]
    heading_in = math.atan2(by - ay, bx - ax)
    wanted = approach.keep_side * turn_sign * math.pi / 2

    def turn_error(connection) -> float:
        (px, py), (qx, qy) = connection.getToLane().getShape()[:2]
        change = (math.atan2(qy - py, qx - px) - heading_in + math.pi) % (2 * math.pi) - math.pi
        return abs(change - wanted)

    connection = min(connections, key=turn_error)
    driven = chain_lanes_before(approach, lane_index, net) + connection_lanes(net, connection)
    path = [tuple(p) for ln in driven for p in ln.getShape()]
    exit_lane = driven[-1]
    # Drop repeated points where one lane's shape ends at the next one's start.
    path_xy = [path[0]]
    for point in path[1:]:
        if math.dist(point, path_xy[-1]) > 1e-6:
            path_xy.append(point)
    # In SUMO's lane-length metres along the driven lanes, as every distance on the path (path_pos_m):
    # where the exit lane begins, the junction's internal lanes behind.
    exit_start_m = float(sum(ln.getLength() for ln in driven[:-1]))
    target = connection.getTo()
    crossing = next(
        (
            c
            for c in net.getEdges(withInternal=True)
            if c.getFunction() == "crossing"
            and target in c._crossingEdges
            and c.getToNode().getID() == approach.junction_id
        ),
        None,
    )
    if crossing is None:
        raise ValueError(
            f"site {site.name}: no crosswalk over {target.getID()}, the road the {direction} turn enters"
        )
    a, b = (tuple(p) for p in (crossing.getLane(0).getShape()[0], crossing.getLane(0).getShape()[-1]))
    stop_line = approach.lane_shapes[lane_index][-1]
    if math.dist(b, stop_line) < math.dist(a, stop_line):
        a, b = b, a
    return Turn(
        direction=direction,
        lane_index=lane_index,
        route=(*approach.through_route[:-1], target.getID()),
        path_xy=tuple(path_xy),
        approach_length_m=approach.lane_lengths_m[lane_index],
        crosswalk_id=crossing.getID(),
        crosswalk_path=(a, b),
        exit_lane_id=exit_lane.getID(),
        exit_start_m=exit_start_m,
        lanes=_as_lane_path(driven),
    )
