"""The road an approach is: the chain of edges that leads unambiguously into the edge entering the junction.

netconvert splits a road where a node lies on it: where a slip lane leaves, where the OSM way was split,
where it joined the nodes of a divided road's junction. Such a split can sit right before the stop line:
on the Aguascalientes clip every road enters its junction on an edge 0.2 m long (a "stub"), its node
where a right-turn slip lane leaves or the divided carriageways' nodes were joined. The approach the
scenarios are staged on is the chain of edges before the junction's incoming edge, followed upstream as
past stubs (edges shorter than STUB_MAX_M, on which no car stands whole) as long as it is unambiguous
(`predecessor_lanes`): each of its vehicle lanes comes from one lane of one edge, straight on over a
major link no traffic light controls, every lane from its own lane. The chain stops at the first edge
that is no stub, at a signalised node, where another road feeds its lanes (a side road merging in, a
lane added), at the network's edge, or after CHAIN_MAX_M. An approach whose incoming edge is no stub is
that edge alone.

Lanes that leave the chain (a slip lane turning off) do not stop it: they take no lane of the approach.
"""

from __future__ import annotations

from dataclasses import dataclass

#: How far upstream of the stop line a chain is followed at most [m]: beyond the road any placement stages
#: on (jaywalking's mid-block line is at most 200 m before the stop line: specs.SPEC_UPPER_BOUNDS) and
#: as far as approach staging's road before the approach (scenarios/upstream.py, UPSTREAM_MAX_M).
CHAIN_MAX_M = 500.0
#: An edge shorter than this is a stub the chain looks past [m]. Assumption: one car (4.5 m, scenarios/
#: road_users.py VEHICLE_CLASSES) and the 0.5 m gap the fixed staging leaves before the stop line: no
#: car stands whole on it. netconvert's stubs are 0.1-0.4 m (0.2 m on the Aguascalientes clip).
STUB_MAX_M = 5.0


def vehicle_lanes(edge) -> list:
    """The sumolib lanes of `edge` a passenger car may drive, kerb side first."""
    return [lane for lane in edge.getLanes() if lane.allows("passenger")]


def _straight_free(connection) -> bool:
    """A straight link that a vehicle drives at its own speed: major (SUMO state "M"), no traffic light."""
    return connection.getDirection() == "s" and connection.getState() == "M" and not connection.getTLSID()


def predecessor_lanes(edge) -> tuple[str, list] | None:
    """(the edge before `edge` on its chain, its lane before each vehicle lane of `edge`, kerb side first),
    or None where the chain stops: a signalised node, a vehicle lane fed by no lane or by another road, a
    link that is not straight on, major and free of a traffic light, or one lane feeding two."""
    node = edge.getFromNode()
    if node.getType().startswith("traffic_light"):
        return None
    lanes = vehicle_lanes(edge)
    if not lanes:
        return None
    before: list = []
    from_edge = None
    for lane in lanes:
        feeding = [
            c
            for incoming in lane.getIncoming()
            if incoming.getEdge().getFunction() == ""
            for c in incoming.getOutgoing()
            if c.getToLane() == lane
        ]
        if len(feeding) != 1 or not _straight_free(feeding[0]):
            return None
        pred = feeding[0].getFromLane()
        if from_edge is None:
            from_edge = pred.getEdge()
        if pred.getEdge() != from_edge or pred in before:
            return None
        before.append(pred)
    if from_edge is None or from_edge.getFromNode() == edge.getToNode():
        return None  # no lane, or a U-turn onto the same junction
    # The lanes keep their order across the road: the kerb lane comes from the kerb-side lane.
    if [p.getIndex() for p in before] != sorted(p.getIndex() for p in before):
        return None
    return from_edge.getID(), before


@dataclass(frozen=True)
class ChainLane:
    """One lane a vehicle drives along an approach's chain: a lane of an edge or a node's internal lane."""

    lane_id: str
    shape: tuple[tuple[float, float], ...]
    length_m: float  # SUMO's lane length [m]


def _chain_lane(lane) -> ChainLane:
    return ChainLane(
        lane.getID(), tuple((float(x), float(y)) for x, y in lane.getShape()), float(lane.getLength())
    )


def _via_lanes(net, from_lane, to_lane) -> list:
    """The internal lane(s) of the node between `from_lane` and `to_lane` (sumolib net read withInternal)."""
    connection = next(c for c in from_lane.getOutgoing() if c.getToLane() == to_lane)
    lanes = []
    via = connection.getViaLaneID()
    current = net.getLane(via) if via else None
    for _ in range(8):  # an internal junction splits an internal lane in two
        if current is None or current.getEdge().getFunction() != "internal":
            break
        lanes.append(current)
        following = current.getOutgoing()[0]
        via = following.getViaLaneID()
        current = net.getLane(via) if via else None
    return lanes


@dataclass(frozen=True)
class ApproachChain:
    """An approach's chain: its edges in driving order (the junction's incoming edge last) and, per vehicle
    lane of that edge (kerb side first), the lanes a vehicle drives along it, internal lanes included."""

    edges: tuple[str, ...]
    lanes: tuple[tuple[ChainLane, ...], ...]

    def length_m(self, lane_index: int) -> float:
        """SUMO distance from the chain's start to the stop line along vehicle lane `lane_index` [m]."""
        return sum(lane.length_m for lane in self.lanes[lane_index])


def approach_chain(net, edge, max_m: float = CHAIN_MAX_M) -> ApproachChain:
    """The chain of `edge` (a sumolib edge entering the junction; net read withInternal=True): the edges
    before it while the first one is a stub (STUB_MAX_M) and predecessor_lanes finds the one before, up
    to `max_m` of its kerb-side vehicle lane."""
    edges = [edge.getID()]
    per_lane: list[list] = [[lane] for lane in vehicle_lanes(edge)]
    done_m = min((lane.getLength() for lane in vehicle_lanes(edge)), default=0.0)
    current = edge
    while done_m < max_m and min(lane.getLength() for lane in vehicle_lanes(current)) < STUB_MAX_M:
        found = predecessor_lanes(current)
        if found is None:
            break
        before_id, before = found
        if before_id in edges:
            break  # a loop
        for lanes, pred in zip(per_lane, before, strict=True):
            lanes[:0] = [pred, *_via_lanes(net, pred, lanes[0])]
        edges.insert(0, before_id)
        current = net.getEdge(before_id)
        done_m += before[0].getLength()
    return ApproachChain(
        edges=tuple(edges),
        lanes=tuple(tuple(_chain_lane(lane) for lane in lanes) for lanes in per_lane),
    )


def kerb_lane_along_chain(net, edge) -> tuple[tuple[tuple[float, float], ...], float]:
    """(drawn shape, SUMO length [m]) of the kerb-side vehicle lane of `edge` along its chain (the roadside
    poles are placed by distances before its stop line, network/poles.py): the lane's own where `edge` is
    no stub."""
    chain = approach_chain(net, edge)
    if len(chain.edges) == 1:
        lane = vehicle_lanes(edge)[0]
        return tuple(tuple(p) for p in lane.getShape()), lane.getLength()
    points: list[tuple[float, float]] = []
    for lane in chain.lanes[0]:
        for p in lane.shape:
            if not points or p != points[-1]:
                points.append(p)
    return tuple(points), chain.length_m(0)
