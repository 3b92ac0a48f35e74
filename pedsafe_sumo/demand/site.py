"""The study site as the demand generator sees it, derived from the SUMO network with sumolib.

Nothing here names an edge: entering lanes, exits, turning movements and pedestrian entry points are found
from the network's topology, so the same code serves the OpenStreetMap site and the hand-built test networks.

- A *fringe node* has exactly one neighbouring node over vehicle or pedestrian edges (a dead end where the
  clipped network stops); entering edges start at one, exiting edges end at one.
- A *movement* (left / straight / right / u-turn) of a route is SUMO's connection direction where the route
  crosses the signalised junction; a route that crosses no traffic light is classified by the turn between its
  entering and exiting edges' headings (node coordinates, independent of how OSM split the roads).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import sumolib

from pedsafe_sumo import NETWORKS_DIR

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


def _heading_deg(edge) -> float:
    (x0, y0), (x1, y1) = edge.getFromNode().getCoord(), edge.getToNode().getCoord()
    return math.degrees(math.atan2(y1 - y0, x1 - x0))


def classify_movement(entry_edge, exit_edge) -> str:
    """'left', 'straight', 'right' or 'uturn' from the heading change between two edges (driving on the right
    or left alike: left means counter-clockwise)."""
    turn = (_heading_deg(exit_edge) - _heading_deg(entry_edge) + 180.0) % 360.0 - 180.0
    if abs(turn) <= STRAIGHT_MAX_DEG:
        return "straight"
    if abs(turn) >= UTURN_MIN_DEG:
        return "uturn"
    return "left" if turn > 0 else "right"


_DIRECTION_MOVEMENT = {"s": "straight", "l": "left", "L": "left", "r": "right", "R": "right", "t": "uturn"}


def route_movement(net, path) -> str:
    """The movement of a route at the first signalised junction it crosses, from SUMO's own connection
    direction there; a route crossing no traffic light is classified by its overall heading change."""
    for here, there in zip(path, path[1:], strict=False):
        if here.getToNode().getType().startswith("traffic_light"):
            for conn in here.getConnections(there):
                movement = _DIRECTION_MOVEMENT.get(conn.getDirection())
                if movement is not None:
                    return movement
    return classify_movement(path[0], path[-1])


def _vehicle_edges(net):
    return [e for e in net.getEdges(withInternal=False) if e.getFunction() == "" and e.allows(VEHICLE_CLASS)]


def _lane_reaches(lane, edge) -> bool:
    return any(c.getTo().getID() == edge.getID() for c in lane.getOutgoing())


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
            movement = route_movement(net, path)
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
        net = sumolib.net.readNet(str(files.net_file), withInternal=True, withPedestrianConnections=True)
    except Exception as exc:  # sumolib raises bare SAX/XML errors; name the file instead of a traceback
        raise SiteError(f"cannot read network {files.net_file}: {exc}") from None
    lanes = find_entering_lanes(net)
    if not lanes:
        raise SiteError(f"network {files.net_file} has no vehicle lane entering from a fringe node")
    return Site(files, net, lanes, find_pedestrian_ends(net))
