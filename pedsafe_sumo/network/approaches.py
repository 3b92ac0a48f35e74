"""The intersection at a site's centre: its signal nodes, its arms, and the approach the scenarios use.

netconvert may split one intersection into several signal nodes (a junction of divided roads); the
approach is chosen among the roads entering any of them from outside.
"""

from __future__ import annotations

import math

import sumolib

from pedsafe_sumo.network.errors import BuildError
from pedsafe_sumo.network.sites import compass_sector

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


def choose_approach(net: sumolib.net.Net, group: list, preferred_arm: str | None = None):
    """(junction, arm) of the approach the scenarios are staged on: among the roads entering the signal
    nodes of `group` from outside it, the best by (the preferred arm, two or more vehicle lanes, a
    sidewalk, a crosswalk at the stop line, a leaving carriageway on the same arm, most vehicle lanes).
    BuildError when no road enters the intersection."""
    group_ids = {n.getID() for n in group}
    candidates = []
    for node in group:
        centre = node.getCoord()
        leaving_arms = {
            compass_sector(centre, e.getShape()[-1])
            for e in node.getOutgoing()
            if e.getFunction() == "" and _vehicle_lane_count(e) and e.getToNode().getID() not in group_ids
        }
        for edge in node.getIncoming():
            if edge.getFunction() or not _vehicle_lane_count(edge) or edge.getFromNode().getID() in group_ids:
                continue
            arm = compass_sector(centre, edge.getShape()[0])
            sidewalk = edge.getLane(0).getPermissions() == {"pedestrian"}
            score = (
                arm == preferred_arm,
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
    for arm in ("N", "E", "S", "W"):
        if arm in found:
            continue
        node, chosen = choose_approach(net, group, arm)
        if chosen == arm:
            found[arm] = node
    return found


def arm_axis(junction, arm: str) -> tuple[float, float]:
    """Unit vector from the junction centre along one arm (N/E/S/W sector of its roads' far ends)."""
    jx, jy = junction.getCoord()
    sums = [0.0, 0.0]
    for edge, far_end in [(e, e.getShape()[0]) for e in junction.getIncoming()] + [
        (e, e.getShape()[-1]) for e in junction.getOutgoing()
    ]:
        if edge.getFunction():
            continue
        dx, dy = far_end[0] - jx, far_end[1] - jy
        if compass_sector((jx, jy), far_end) == arm:
            norm = math.hypot(dx, dy) or 1.0
            sums[0] += dx / norm
            sums[1] += dy / norm
    norm = math.hypot(*sums)
    if norm == 0.0:
        raise BuildError(f"the main junction has no arm towards {arm}")
    return sums[0] / norm, sums[1] / norm
