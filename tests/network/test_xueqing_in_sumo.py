"""In real SUMO (libsumo): a vehicle through every arm and a pedestrian across every crosswalk of the
main junction arrive, with no teleports and no errors."""

from __future__ import annotations

import math

import libsumo
import pytest

from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.sumo_net import read_net

SITE = get_site("xueqing")


def _main_junction(net):
    center = net.convertLonLat2XY(SITE.center_lon, SITE.center_lat)
    signalised = [n for n in net.getNodes() if n.getType() == "traffic_light"]
    return min(signalised, key=lambda n: math.dist(n.getCoord(), center))


def _vehicle_routes(net, junction):
    """One route per (incoming road, outgoing road of another arm) pair through the junction, from the
    study-area boundary to the boundary, so every arm is entered and left at least once."""

    def is_road(edge):
        return edge.getFunction() == "" and any(lane.allows("passenger") for lane in edge.getLanes())

    entries = [
        e for e in net.getEdges() if is_road(e) and not any(is_road(i) for i in e.getFromNode().getIncoming())
    ]
    exits = [
        e for e in net.getEdges() if is_road(e) and not any(is_road(o) for o in e.getToNode().getOutgoing())
    ]
    routes = {}
    for into in [e for e in junction.getIncoming() if is_road(e)]:
        for out in [e for e in junction.getOutgoing() if is_road(e)]:
            if not into.getConnections(out):
                continue
            head = min(
                (net.getShortestPath(s, into, vClass="passenger") for s in entries), key=lambda r: r[1]
            )[0]
            tail = min((net.getShortestPath(out, x, vClass="passenger") for x in exits), key=lambda r: r[1])[
                0
            ]
            if head and tail:
                routes[(into.getID(), out.getID())] = [e.getID() for e in head] + [e.getID() for e in tail]
    return routes


def _crossing_walks(net, junction):
    """For each crosswalk of the junction: the two roads whose sidewalks end nearest to its two ends, so a
    walk from one to the other has to use that crosswalk."""
    sidewalk_ends = []
    for edge in junction.getIncoming() + junction.getOutgoing():
        if edge.getFunction() == "" and edge.getLane(0).allows("pedestrian"):
            shape = edge.getLane(0).getShape()
            sidewalk_ends.append((edge.getID(), shape[-1] if edge in junction.getIncoming() else shape[0]))
    walks = {}
    for edge in net.getEdges(withInternal=True):
        if edge.getFunction() != "crossing" or not edge.getID().startswith(f":{junction.getID()}_c"):
            continue
        a, b = edge.getLane(0).getShape()[0], edge.getLane(0).getShape()[-1]
        # A sidewalk beyond each end of the crosswalk, seen along the crosswalk; a crosswalk that ends on
        # a median walks on over the next crosswalk to the first sidewalk beyond.
        start = _nearest_beyond(sidewalk_ends, a, b)
        end = _nearest_beyond(sidewalk_ends, b, a)
        walks[edge.getID()] = (start, end)
    return walks


def _nearest_beyond(sidewalk_ends, near, far):
    """The sidewalk end nearest to `near` among those lying past `near` when coming from `far`."""
    dx, dy = near[0] - far[0], near[1] - far[1]
    length_sq = dx * dx + dy * dy
    beyond = [
        (e, p) for e, p in sidewalk_ends if (p[0] - far[0]) * dx + (p[1] - far[1]) * dy >= 0.9 * length_sq
    ]
    return min(beyond, key=lambda item: math.dist(item[1], near))[0]


@pytest.mark.slow
def test_vehicles_through_every_arm_and_pedestrians_across_every_crosswalk(tmp_path):
    net = read_net(str(SITE.file("net.xml")), withInternal=True)
    junction = _main_junction(net)
    routes = _vehicle_routes(net, junction)
    walks = _crossing_walks(net, junction)
    # Each of the four arms is entered and left by some route.
    assert len({r[0] for r in routes}) >= 4 and len({r[1] for r in routes}) >= 4
    assert len(walks) >= 4

    log = tmp_path / "errors.log"
    libsumo.start(
        [
            "sumo",
            "-n",
            str(SITE.file("net.xml")),
            "--step-length",
            "0.5",
            "--no-step-log",
            "true",
            "--error-log",
            str(log),
            "--time-to-teleport",
            "300",
            "--collision.action",
            "warn",
        ]
    )
    try:
        for i, (_key, edges) in enumerate(sorted(routes.items())):
            libsumo.route.add(f"r{i}", edges)
            libsumo.vehicle.add(f"veh{i}", f"r{i}", depart=str(4.0 * i), departLane="best", departSpeed="max")
        visited: dict[str, set[str]] = {}
        incoming = {e.getID() for e in junction.getIncoming()}
        outgoing = {e.getID() for e in junction.getOutgoing()}
        for i, (_crossing, (start, end)) in enumerate(sorted(walks.items())):
            pid = f"ped{i}"
            # Start at the junction end of the sidewalk so the shortest walk is across the crosswalk.
            start_pos = libsumo.lane.getLength(f"{start}_0") - 1.0 if start in incoming else 1.0
            end_pos = 1.0 if end in outgoing else libsumo.lane.getLength(f"{end}_0") - 1.0
            libsumo.person.add(pid, start, pos=start_pos, depart=2.0 * i)
            libsumo.person.appendWalkingStage(pid, [start, end], arrivalPos=end_pos)
            visited[pid] = set()
        crossing_of = {f"ped{i}": c for i, c in enumerate(sorted(walks))}
        arrived_vehicles: set[str] = set()
        arrived_persons: set[str] = set()
        teleports = 0
        while libsumo.simulation.getMinExpectedNumber() > 0 and libsumo.simulation.getTime() < 1800:
            libsumo.simulation.step()
            teleports += libsumo.simulation.getStartingTeleportNumber()
            arrived_vehicles.update(libsumo.simulation.getArrivedIDList())
            arrived_persons.update(libsumo.simulation.getArrivedPersonIDList())
            for pid in libsumo.person.getIDList():
                visited[pid].add(libsumo.person.getRoadID(pid))
    finally:
        libsumo.close()

    assert teleports == 0
    assert arrived_vehicles == {f"veh{i}" for i in range(len(routes))}
    assert arrived_persons == set(visited)
    for pid, roads in visited.items():
        assert crossing_of[pid] in roads, f"{pid} did not use {crossing_of[pid]}"
    errors = [line for line in log.read_text().splitlines() if line.startswith("Error")]
    assert errors == []
