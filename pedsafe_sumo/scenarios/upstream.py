"""The road before an approach lane: the lanes that lead straight on into it, through the junctions before
it (their internal lanes included). Approach staging starts a vehicle there when its approach lane is
shorter than its run to the conflict: the ego (placements/straight.py, `Approach.upstream_roads`) and
left_turn's oncoming vehicle (scenarios/oncoming.py, `OncomingPath.extended`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

#: How far before a lane `upstream_road` follows the road [m]: beyond the longest start distance approach
#: staging may draw (specs.SPEC_UPPER_BOUNDS, ego_start_max_m 500 m).
UPSTREAM_MAX_M = 500.0


@dataclass(frozen=True)
class RoadLane:
    lane_id: str
    shape: tuple[tuple[float, float], ...]
    length_m: float  # SUMO's lane length [m]


@dataclass(frozen=True)
class UpstreamRoad:
    """The road before one approach lane, in driving order: its lanes (internal lanes included) and the
    edges a route through them names (internal edges left out)."""

    lanes: tuple[RoadLane, ...] = ()
    edges: tuple[str, ...] = ()

    @property
    def length_m(self) -> float:
        """SUMO distance from its start to the start of the approach lane [m]."""
        return sum(lane.length_m for lane in self.lanes)


def road_lane(lane) -> RoadLane:
    """The RoadLane of sumolib `lane`."""
    return RoadLane(lane.getID(), tuple(tuple(p) for p in lane.getShape()), float(lane.getLength()))


def connection_lanes(net, connection) -> list:
    """The sumolib lanes a vehicle drives through a connection: its from-lane, the junction's internal
    lane(s) (an internal junction, e.g. before a crosswalk, splits one in two: followed by its via lane,
    not its to-lane, which skips the second part), and its to-lane."""
    lanes = [connection.getFromLane()]
    via = connection.getViaLaneID()
    current = net.getLane(via) if via else connection.getToLane()
    for _ in range(8):  # internal lanes split at internal junctions, then the outgoing lane
        lanes.append(current)
        if current.getEdge().getFunction() != "internal":
            break
        following = current.getOutgoing()[0]
        via = following.getViaLaneID()
        current = net.getLane(via) if via else following.getToLane()
    return lanes


def free_through(connection) -> bool:
    """Whether a vehicle drives through the connection at its own speed: a major link (SUMO link state
    "M", the priority road) that no traffic light controls. The ego's upstream start follows only
    these: at a signalised junction or a link that yields its arrival would depend on a signal or on
    cross traffic that the staging does not place."""
    return connection.getState() == "M" and not connection.getTLSID()


def upstream_road(
    net, lane, max_m: float = UPSTREAM_MAX_M, follow: Callable[[object], bool] | None = None
) -> UpstreamRoad:
    """The lanes before sumolib `lane` (a net read withInternal=True) that lead straight on into it, through
    the junctions between, up to `max_m`; a connection `follow` refuses ends it (None: every straight one)."""
    lanes: list = []
    edges: list[str] = []
    done_m = 0.0
    current = lane
    while done_m < max_m:
        before = [
            c
            for ln in current.getIncoming()
            if ln.getEdge().getFunction() == ""
            for c in ln.getOutgoing()
            if c.getToLane() == current and c.getDirection() == "s"
        ]
        if not before or (follow is not None and not follow(before[0])):
            break
        driven = connection_lanes(net, before[0])[:-1]  # its lane and the junction's internal lane(s)
        if driven[0].getEdge().getID() in edges:
            break  # a loop
        lanes[:0] = driven
        edges.insert(0, driven[0].getEdge().getID())
        done_m += sum(float(ln.getLength()) for ln in driven)
        current = driven[0]
    return UpstreamRoad(tuple(road_lane(ln) for ln in lanes), tuple(edges))


def position_on(lanes: tuple[RoadLane, ...], front_pos_m: float) -> tuple[str, float]:
    """(lane id, position on it) of a front `front_pos_m` SUMO metres along `lanes`; beyond their end, the
    last lane's end."""
    done_m = 0.0
    for lane in lanes:
        if front_pos_m <= done_m + lane.length_m:
            return lane.lane_id, max(front_pos_m - done_m, 0.0)
        done_m += lane.length_m
    return lanes[-1].lane_id, lanes[-1].length_m
