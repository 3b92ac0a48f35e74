"""The intersection at a site's centre: its signal nodes, its legs (arms), and the approach the scenarios use.

netconvert may split one intersection into several signal nodes (a junction of divided roads); the
approach is chosen among the roads entering any of them from outside.

The legs come from the road geometry: the bearings (from the signal node they enter) of the far ends of
the carriageways that enter the intersection from outside with a vehicle lane, merged round the circle
when within LEG_MERGE_TOLERANCE_DEG of each other (junction_legs). A leg is named N, E, S or W when it is
the only leg in that 90-degree compass sector, else by its 45-degree point (NE, SE, SW, NW, or N/E/S/W of
the eight-point rose) when no other leg shares it, else by its bearing ("B055").
"""

from __future__ import annotations

import argparse
import math
import re
from dataclasses import dataclass

import sumolib

from pedsafe_sumo.network.errors import BuildError

#: The main junction is a signal node at most this far from the site's centre [m]: beyond it, the nearest
#: signal is another intersection (e.g. after the site's own signal was removed).
MAIN_JUNCTION_MAX_DISTANCE_M = 60.0


def find_main_junction(net: sumolib.net.Net, center_xy: tuple[float, float]) -> sumolib.net.node.Node:
    """The traffic-light junction nearest the site centre, within MAIN_JUNCTION_MAX_DISTANCE_M."""
    tls_nodes = [n for n in net.getNodes() if n.getType().startswith("traffic_light")]
    if not tls_nodes:
        raise BuildError("the network has no signalised junction; check the OSM signals near the centre")
    nearest = min(tls_nodes, key=lambda n: math.dist(n.getCoord(), center_xy))
    distance_m = math.dist(nearest.getCoord(), center_xy)
    if distance_m > MAIN_JUNCTION_MAX_DISTANCE_M:
        raise BuildError(
            f"the network has no signalised junction within {MAIN_JUNCTION_MAX_DISTANCE_M:g} m of the centre "
            f"(the nearest, {nearest.getID()}, is {distance_m:.0f} m away)"
        )
    return nearest


#: Signal nodes within this distance of the one nearest the centre belong to the same intersection:
#: netconvert splits a junction of divided roads (a T onto a dual carriageway, a wide median) into several
#: signal nodes when its OSM nodes lie further apart than junctions.join-dist [m].
SIGNAL_GROUP_DIST_M = 60.0

#: Kerb corner of each arm under right-hand traffic: vehicles approaching from the north drive on the
#: west half of that arm, so the pole that watches them stands on its north-west corner.
KERB_CORNER = {"N": "NW", "E": "NE", "S": "SE", "W": "SW"}

#: Incoming carriageways whose far ends lie within this angle of each other (seen from the junction, going
#: round the circle) are one leg [deg]. Assumption: the carriageways of one leg (a slip lane, a split
#: carriageway entering two signal nodes of the intersection) point within a few degrees of each other,
#: while distinct legs are far apart: 90 degrees at a regular four-leg junction, 72 and 60 at regular five-
#: and six-leg ones; 30 keeps legs down to about 35 degrees apart distinct with margin for either.
LEG_MERGE_TOLERANCE_DEG = 30.0

#: A leg's name: its compass sector, its eight-point direction, or "B" and its bearing in whole degrees.
LEG_NAME = re.compile(r"[NESW]|NE|SE|SW|NW|B\d{3}")

_EIGHT_POINTS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")


def is_leg_name(text: str) -> bool:
    """Whether `text` is a name a leg of a junction can have (N, E, S, W, NE, SE, SW, NW, B000..B359)."""
    return LEG_NAME.fullmatch(text) is not None and not (text.startswith("B") and int(text[1:]) >= 360)


def leg_argument(text: str) -> str:
    """argparse type of an --approach naming one leg."""
    if not is_leg_name(text):
        raise argparse.ArgumentTypeError(
            f"'{text}' is not a leg name (N, E, S, W, NE, SE, SW, NW or B000-B359)"
        )
    return text


@dataclass(frozen=True)
class Leg:
    """One leg of the intersection: the carriageways entering it from one direction."""

    name: str
    #: Mean bearing of the far ends of its incoming carriageways, clockwise from north [deg].
    bearing_deg: float
    #: Its incoming carriageways (edge ids) and the signal nodes they enter.
    edge_ids: tuple[str, ...]
    node_ids: tuple[str, ...]
    #: The road's name(s) on the network (edge `name`), "" when the network has none.
    road_name: str


def bearing_deg(centre_xy, point_xy) -> float:
    """Bearing of `point_xy` seen from `centre_xy`, clockwise from north (network frame, y north) [deg]."""
    return math.degrees(math.atan2(point_xy[0] - centre_xy[0], point_xy[1] - centre_xy[1])) % 360.0


def angle_between_deg(a_deg: float, b_deg: float) -> float:
    """The smaller angle between two bearings [deg]."""
    d = abs(a_deg - b_deg) % 360.0
    return min(d, 360.0 - d)


def _mean_bearing_deg(bearings: list[float]) -> float:
    x = sum(math.sin(math.radians(b)) for b in bearings)
    y = sum(math.cos(math.radians(b)) for b in bearings)
    return math.degrees(math.atan2(x, y)) % 360.0


def cluster_bearings(
    bearings: list[float], tolerance_deg: float = LEG_MERGE_TOLERANCE_DEG
) -> list[list[int]]:
    """Indices of `bearings` grouped into legs: sorted round the circle, neighbours within `tolerance_deg`
    join one group (the gap across north included). Groups in order of their first bearing."""
    if not bearings:
        return []
    order = sorted(range(len(bearings)), key=lambda i: bearings[i])
    groups = [[order[0]]]
    for prev, cur in zip(order, order[1:]):
        if bearings[cur] - bearings[prev] <= tolerance_deg:
            groups[-1].append(cur)
        else:
            groups.append([cur])
    if len(groups) > 1 and bearings[order[0]] + 360.0 - bearings[order[-1]] <= tolerance_deg:
        groups[0] = groups.pop() + groups[0]  # the last group wraps round north onto the first
    return groups


def leg_names(bearings: list[float]) -> list[str]:
    """Names of legs at these bearings: N/E/S/W for a leg alone in its compass sector, else its eight-point
    direction when no other such leg shares it, else "B" and its bearing ("B055")."""

    def sector(b: float) -> str:
        return "NESW"[int(((b + 45.0) % 360.0) // 90.0)]

    def point(b: float) -> str:
        return _EIGHT_POINTS[int(((b + 22.5) % 360.0) // 45.0)]

    sectors = [sector(b) for b in bearings]
    names = [s if sectors.count(s) == 1 else point(b) for s, b in zip(sectors, bearings)]
    # A lone leg's sector name cannot be any other leg's eight-point name (that leg would share its sector).
    return [n if names.count(n) == 1 else f"B{round(b) % 360:03d}" for n, b in zip(names, bearings)]


def _is_carriageway(edge) -> bool:
    return edge.getFunction() == "" and _vehicle_lane_count(edge) > 0


def junction_legs(group: list) -> list[Leg]:
    """The legs of the intersection whose signal nodes are `group`, clockwise from north-west: its incoming
    carriageways from outside the group, clustered by bearing (cluster_bearings), named (leg_names)."""
    group_ids = {n.getID() for n in group}
    entering = [
        (edge, node)
        for node in group
        for edge in node.getIncoming()
        if _is_carriageway(edge) and edge.getFromNode().getID() not in group_ids
    ]
    bearings = [bearing_deg(node.getCoord(), edge.getShape()[0]) for edge, node in entering]
    clusters = [
        (_mean_bearing_deg([bearings[i] for i in members]), members) for members in cluster_bearings(bearings)
    ]
    # Clockwise from the start of the north sector (bearing 315): N, E, S, W in that order.
    clusters.sort(key=lambda c: (c[0] + 45.0) % 360.0)
    names = leg_names([b for b, _ in clusters])
    legs = []
    for name, (bearing, members) in zip(names, clusters):
        edges = sorted(members, key=lambda i: entering[i][0].getID())
        roads: list[str] = []
        for i in edges:
            road = entering[i][0].getName()
            if road and road not in roads:
                roads.append(road)
        legs.append(
            Leg(
                name=name,
                bearing_deg=bearing,
                edge_ids=tuple(entering[i][0].getID() for i in edges),
                node_ids=tuple(dict.fromkeys(entering[i][1].getID() for i in edges)),
                road_name=" / ".join(roads),
            )
        )
    return legs


def legs_at(net: sumolib.net.Net, junction) -> list[Leg]:
    """The legs of the intersection `junction` (a signal node) belongs to; a junction without a signal
    is taken on its own."""
    if junction.getType().startswith("traffic_light"):
        return junction_legs(signal_group(net, junction.getCoord()))
    return junction_legs([junction])


def leg_towards(legs: list[Leg], bearing: float) -> str:
    """Name of the leg nearest `bearing` (e.g. of a leaving carriageway's far end); "" without legs."""
    if not legs:
        return ""
    return min(legs, key=lambda leg: angle_between_deg(leg.bearing_deg, bearing)).name


def leg_named(legs: list[Leg], name: str) -> Leg:
    """The leg called `name`; BuildError naming the legs there are when none is."""
    for leg in legs:
        if leg.name == name:
            return leg
    raise BuildError(
        f"the main junction has no leg {name} (legs: {', '.join(leg.name for leg in legs) or 'none'})"
    )


def junction_arms(legs: list[Leg], leaving_bearings: list[float]) -> dict[str, float]:
    """Name -> bearing of every arm of a junction, clockwise from north-west: its legs, and the directions
    roads only leave by (leaving bearings further than LEG_MERGE_TOLERANCE_DEG from every leg, clustered
    as legs are). Those are named by the rule of leg_names over all the arms, by bearing ("B090") where
    that name is a leg's; the legs keep theirs."""
    out_only = [
        b
        for b in leaving_bearings
        if all(angle_between_deg(b, leg.bearing_deg) > LEG_MERGE_TOLERANCE_DEG for leg in legs)
    ]
    out_means = [_mean_bearing_deg([out_only[i] for i in members]) for members in cluster_bearings(out_only)]
    names = leg_names([leg.bearing_deg for leg in legs] + out_means)[len(legs) :]
    arms = {leg.name: leg.bearing_deg for leg in legs}
    for name, bearing in zip(names, out_means):
        arms[name if name not in arms else f"B{round(bearing) % 360:03d}"] = bearing
    return dict(sorted(arms.items(), key=lambda arm: (arm[1] + 45.0) % 360.0))


def kerb_corner(leg: Leg) -> str:
    """The corner (NE, SE, SW or NW) the pole watching a leg stands on: the one 45 degrees anticlockwise of
    the leg (right-hand traffic: KERB_CORNER for a leg due N, E, S or W)."""
    if leg.name in KERB_CORNER:
        return KERB_CORNER[leg.name]
    corner_deg = (leg.bearing_deg - 45.0) % 360.0
    return ("NE", "SE", "SW", "NW")[int(corner_deg // 90.0)]


def signal_group(net: sumolib.net.Net, center_xy: tuple[float, float]) -> list:
    """The signal nodes of the intersection at the centre: the one nearest it and every signal node within
    SIGNAL_GROUP_DIST_M of that one."""
    main = find_main_junction(net, center_xy)
    tls_nodes = [n for n in net.getNodes() if n.getType().startswith("traffic_light")]
    group = [n for n in tls_nodes if math.dist(n.getCoord(), main.getCoord()) <= SIGNAL_GROUP_DIST_M]
    return sorted(group, key=lambda n: n.getID() != main.getID())


def _vehicle_lane_count(edge) -> int:
    return sum(lane.allows("passenger") for lane in edge.getLanes())


def _has_crossing(net, node, edge) -> bool:
    return any(
        c.getFunction() == "crossing"
        and edge in c._crossingEdges
        and c.getID().startswith(f":{node.getID()}_")
        for c in net.getEdges(withInternal=True)
    )


def _ego_lane_goes_straight(edge) -> bool:
    """Whether the vehicle lane the straight scenarios drive the ego in (the one next to the kerb lane; on a
    one-lane approach the lane itself: scenarios.geometry.straight_staging_problem) has a straight movement.
    Without one, crossing, jaywalking and background blending cannot be staged on the road (the stem of a T,
    a lane that only turns)."""
    vehicle_lanes = [lane for lane in edge.getLanes() if lane.allows("passenger")]
    ego_lane = vehicle_lanes[1 if len(vehicle_lanes) >= 2 else 0]
    return any(c.getDirection() == "s" for c in ego_lane.getOutgoing())


def choose_approach(net: sumolib.net.Net, group: list, preferred_arm: str | None = None):
    """(junction, arm) of the approach the scenarios are staged on: among the roads entering the signal
    nodes of `group` from outside it, the best by (the preferred arm, a straight movement from the lane
    the ego drives in, two or more vehicle lanes, a sidewalk, a crosswalk at the stop line, a leaving
    carriageway on the same arm, most vehicle lanes). BuildError when no road enters the intersection."""
    group_ids = {n.getID() for n in group}
    legs = junction_legs(group)
    leg_of = {edge_id: leg.name for leg in legs for edge_id in leg.edge_ids}
    candidates = []
    for node in group:
        centre = node.getCoord()
        leaving_arms = {
            leg_towards(legs, bearing_deg(centre, e.getShape()[-1]))
            for e in node.getOutgoing()
            if e.getFunction() == "" and _vehicle_lane_count(e) and e.getToNode().getID() not in group_ids
        }
        for edge in node.getIncoming():
            if edge.getFunction() or not _vehicle_lane_count(edge) or edge.getFromNode().getID() in group_ids:
                continue
            arm = leg_of[edge.getID()]
            sidewalk = edge.getLane(0).getPermissions() == {"pedestrian"}
            score = (
                arm == preferred_arm,
                _ego_lane_goes_straight(edge),
                _vehicle_lane_count(edge) >= 2,
                sidewalk,
                _has_crossing(net, node, edge),
                arm in leaving_arms,
                _vehicle_lane_count(edge),
            )
            candidates.append((score, edge.getID(), node, arm))
    if not candidates:
        raise BuildError("no road enters the signalised junction at the centre")
    _score, _edge, node, arm = max(candidates, key=lambda c: (c[0], c[1]))
    return node, arm


def approach_nodes(net: sumolib.net.Net, group: list, own_arm: str, own_node) -> dict:
    """Arm -> signal node of every arm of the intersection a road with vehicle lanes enters from outside
    (choose_approach with that arm preferred), the site's own arm first."""
    found = {own_arm: own_node}
    for arm in [leg.name for leg in junction_legs(group)]:
        if arm in found:
            continue
        node, chosen = choose_approach(net, group, arm)
        if chosen == arm:
            found[arm] = node
    return found


def arm_axis(net: sumolib.net.Net, junction, arm: str) -> tuple[float, float]:
    """Unit vector from the junction centre along one leg (the mean direction of the far ends of the roads
    in and out of `junction` nearest that leg, leg_towards)."""
    jx, jy = junction.getCoord()
    legs = legs_at(net, junction)
    sums = [0.0, 0.0]
    for edge, far_end in [(e, e.getShape()[0]) for e in junction.getIncoming()] + [
        (e, e.getShape()[-1]) for e in junction.getOutgoing()
    ]:
        if edge.getFunction():
            continue
        dx, dy = far_end[0] - jx, far_end[1] - jy
        if leg_towards(legs, bearing_deg((jx, jy), far_end)) == arm:
            norm = math.hypot(dx, dy) or 1.0
            sums[0] += dx / norm
            sums[1] += dy / norm
    norm = math.hypot(*sums)
    if norm == 0.0:
        raise BuildError(f"the main junction has no arm towards {arm}")
    return sums[0] / norm, sums[1] / norm
