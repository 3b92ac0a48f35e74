"""The study site as the demand generator sees it, derived from the SUMO network with sumolib.

Nothing here names an edge: entering lanes, exits, turning movements and pedestrian entry points are found
from the network's topology, so the same code serves the OpenStreetMap site and the hand-built test networks.

- A *fringe node* has exactly one neighbouring node over vehicle or pedestrian edges (a dead end where the
  clipped network stops); entering edges start at one, exiting edges end at one.
- A *movement* (left / straight / right / u-turn) of a route is the turn it makes where it crosses the
  signalised junction, from the headings of the edges arriving at and leaving the junction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import sumolib
from sumolib.geomhelper import positionAtShapeOffset

from pedsafe_sumo import NETWORKS_DIR
from pedsafe_sumo.sumo_net import read_net

VEHICLE_CLASS = "passenger"
PEDESTRIAN_CLASS = "pedestrian"
#: Heading change (degrees, counter-clockwise positive) below which a route counts as straight ahead; beyond
#: 135 degrees it is a u-turn. Symmetric 45-degree sectors are the usual movement classification.
STRAIGHT_MAX_DEG = 45.0
UTURN_MIN_DEG = 135.0


class SiteError(ValueError):
    """The site does not exist or its network cannot serve as a demand site; one-line message."""


@dataclass(frozen=True)
class SiteFiles:
    name: str
    directory: Path
    net_file: Path


def available_sites(networks_dir: Path = NETWORKS_DIR) -> list[str]:
    """Site names: folders of networks/ that hold <name>/<name>.net.xml."""
    if not networks_dir.is_dir():
        return []
    return sorted(d.name for d in networks_dir.iterdir() if (d / f"{d.name}.net.xml").is_file())


def site_files(site: str, networks_dir: Path = NETWORKS_DIR) -> SiteFiles:
    directory = networks_dir / site
    net_file = directory / f"{site}.net.xml"
    if not net_file.is_file():
        known = ", ".join(available_sites(networks_dir)) or "none"
        raise SiteError(f"unknown site '{site}': no {net_file} (known sites: {known})")
    return SiteFiles(site, directory, net_file)


@dataclass(frozen=True)
class Route:
    """A vehicle route from an entering edge to an exiting edge."""

    edges: tuple[str, ...]
    movement: str  # "left", "straight", "right"


@dataclass
class EnteringLane:
    """A lane on which background vehicles enter the site, with the routes a vehicle on it may take."""

    lane_id: str
    edge_id: str
    index: int
    speed_limit_mps: float
    length_m: float
    routes_by_movement: dict[str, list[Route]] = field(default_factory=dict)


@dataclass(frozen=True)
class PedestrianEnd:
    """Where pedestrians enter or leave: an edge with a sidewalk at the fringe, and the position there."""

    edge_id: str
    pos_m: float  # position along the edge at its fringe end
    fringe_node: str


@dataclass
class Site:
    files: SiteFiles
    net: sumolib.net.Net
    entering_lanes: list[EnteringLane]
    pedestrian_ends: list[PedestrianEnd]


def _neighbours(node) -> set[str]:
    ids = {e.getFromNode().getID() for e in node.getIncoming()}
    ids |= {e.getToNode().getID() for e in node.getOutgoing()}
    ids.discard(node.getID())
    return ids


def _is_fringe(node) -> bool:
    return node.getType() == "dead_end" or len(_neighbours(node)) <= 1


#: Length (m) of the stretch of an edge next to the junction whose direction is the edge's heading there:
#: long enough to ignore the small kinks netconvert puts at junction borders.
HEADING_BASE_M = 20.0


def _heading_deg(shape: list[tuple[float, float]], at_end: bool) -> float:
    """Heading (degrees, counter-clockwise from +x) of a polyline over HEADING_BASE_M at its end or start."""
    length = sum(math.dist(a, b) for a, b in zip(shape, shape[1:], strict=False))
    base = min(HEADING_BASE_M, length)
    if at_end:
        (x0, y0), (x1, y1) = positionAtShapeOffset(shape, length - base), shape[-1]
    else:
        (x0, y0), (x1, y1) = shape[0], positionAtShapeOffset(shape, base)
    return math.degrees(math.atan2(y1 - y0, x1 - x0))


def turn_movement(in_edge, out_edge) -> str:
    """'left', 'straight', 'right' or 'uturn' from the turn between the heading of `in_edge` where it ends
    and the heading of `out_edge` where it starts (left = counter-clockwise; +-45 degree sectors for
    straight; beyond 135 degrees a u-turn).

    Geometry rather than SUMO's connection direction: at a large joined junction (a dual carriageway with a
    wide median) netconvert labels some u-turns 'l' and continuations onto a parallel carriageway 'R'.
    """
    turn = _heading_deg(out_edge.getShape(), at_end=False) - _heading_deg(in_edge.getShape(), at_end=True)
    turn = (turn + 180.0) % 360.0 - 180.0
    if abs(turn) <= STRAIGHT_MAX_DEG:
        return "straight"
    if abs(turn) >= UTURN_MIN_DEG:
        return "uturn"
    return "left" if turn > 0 else "right"


def route_movement(path) -> str:
    """The movement of a route where it crosses the first signalised junction on it; a route crossing no
    traffic light is classified by the turn from its first to its last edge."""
    for here, there in zip(path, path[1:], strict=False):
        if here.getToNode().getType().startswith("traffic_light"):
            return turn_movement(here, there)
    return turn_movement(path[0], path[-1])


def _vehicle_edges(net):
    return [e for e in net.getEdges(withInternal=False) if e.getFunction() == "" and e.allows(VEHICLE_CLASS)]


def _lane_reaches(lane, edge) -> bool:
    return any(c.getTo().getID() == edge.getID() for c in lane.getOutgoing())


def _revisits_a_node(path) -> bool:
    nodes = [path[0].getFromNode().getID()] + [edge.getToNode().getID() for edge in path]
    return len(nodes) != len(set(nodes))


def find_entering_lanes(net) -> list[EnteringLane]:
    """Every vehicle lane on an edge that starts at a fringe node, with its routes to every exiting edge.

    A route is offered to a lane only when the lane connects to the route's second edge, so a vehicle never
    has to change lanes on the entering edge to follow its route (the lane keeps its own headway process). If
    a lane connects to no route at all, it gets every route of its edge and SUMO changes lanes as needed.
    """
    edges = _vehicle_edges(net)
    entries = sorted((e for e in edges if _is_fringe(e.getFromNode())), key=lambda e: e.getID())
    exits = sorted((e for e in edges if _is_fringe(e.getToNode())), key=lambda e: e.getID())
    lanes: list[EnteringLane] = []
    for entry in entries:
        routes: list[Route] = []
        for exit_edge in exits:
            if exit_edge is entry:
                continue
            path, _cost = net.getShortestPath(entry, exit_edge, vClass=VEHICLE_CLASS)
            if path is None:
                continue
            if _revisits_a_node(path):
                # A loop (e.g. through the junction, round a dead end's turnaround and back, where the
                # junction has no u-turn): nobody drives it, and its first turn would be counted as a
                # left or right turn.
                continue
            movement = route_movement(path)
            if movement == "uturn":
                continue  # u-turns are not part of the observed demand
            routes.append(Route(tuple(e.getID() for e in path), movement))
        if not routes:
            continue
        for lane in entry.getLanes():
            if not lane.allows(VEHICLE_CLASS):
                continue
            usable = [r for r in routes if len(r.edges) < 2 or _lane_reaches(lane, net.getEdge(r.edges[1]))]
            by_movement: dict[str, list[Route]] = {}
            for route in usable or routes:
                by_movement.setdefault(route.movement, []).append(route)
            lanes.append(
                EnteringLane(
                    lane.getID(),
                    entry.getID(),
                    lane.getIndex(),
                    lane.getSpeed(),
                    lane.getLength(),
                    by_movement,
                )
            )
    return lanes


def find_pedestrian_ends(net) -> list[PedestrianEnd]:
    """Edges with a pedestrian lane that touch a fringe node, with the position at that fringe end."""
    ends = []
    for edge in sorted(net.getEdges(withInternal=False), key=lambda e: e.getID()):
        if edge.getFunction() != "" or not edge.allows(PEDESTRIAN_CLASS):
            continue
        if _is_fringe(edge.getFromNode()):
            ends.append(PedestrianEnd(edge.getID(), 0.0, edge.getFromNode().getID()))
        elif _is_fringe(edge.getToNode()):
            ends.append(PedestrianEnd(edge.getID(), edge.getLength(), edge.getToNode().getID()))
    return ends


def load_site(site: str, networks_dir: Path = NETWORKS_DIR, net_file: Path | None = None) -> Site:
    """Read the site's network and derive its entering lanes and pedestrian ends."""
    files = site_files(site, networks_dir) if net_file is None else SiteFiles(site, net_file.parent, net_file)
    try:
        net = read_net(str(files.net_file), withInternal=True, withPedestrianConnections=True)
    except Exception as exc:  # sumolib raises bare SAX/XML errors; name the file instead of a traceback
        raise SiteError(f"cannot read network {files.net_file}: {exc}") from None
    lanes = find_entering_lanes(net)
    if not lanes:
        raise SiteError(f"network {files.net_file} has no vehicle lane entering from a fringe node")
    return Site(files, net, lanes, find_pedestrian_ends(net))
