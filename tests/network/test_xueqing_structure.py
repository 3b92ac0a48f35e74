"""The Xueqing network is one a traffic engineer would accept, checked with sumolib.

Every number here is derived from the network file itself with sumolib or ElementTree, or is a
property of the real intersection (four arms, Xueqing Road with two lanes per direction); nothing
is read from the build tool's own summary.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections import defaultdict

import pytest
import sumolib

from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.sumo_net import read_net

SITE = get_site("xueqing")
NET_FILE = SITE.file("net.xml")


@pytest.fixture(scope="module")
def net():
    return read_net(str(NET_FILE), withInternal=True)


@pytest.fixture(scope="module")
def tree():
    return ET.parse(NET_FILE).getroot()


@pytest.fixture(scope="module")
def main_junction(net):
    center = net.convertLonLat2XY(SITE.center_lon, SITE.center_lat)
    signalised = [n for n in net.getNodes() if n.getType().startswith("traffic_light")]
    assert signalised, "no signalised junction in the network"
    return min(signalised, key=lambda n: math.dist(n.getCoord(), center))


def _is_road(edge) -> bool:
    return edge.getFunction() == "" and any(lane.allows("passenger") for lane in edge.getLanes())


def _arm_of(junction, edge, incoming: bool) -> str:
    """N/E/S/W sector of the far end of an edge, seen from the junction centre."""
    jx, jy = junction.getCoord()
    x, y = edge.getShape()[0] if incoming else edge.getShape()[-1]
    bearing_deg = math.degrees(math.atan2(x - jx, y - jy)) % 360.0
    return "NESW"[int(((bearing_deg + 45.0) % 360.0) // 90.0)]


def _arms(junction):
    arms = defaultdict(lambda: {"in": [], "out": []})
    for edge in junction.getIncoming():
        if _is_road(edge):
            arms[_arm_of(junction, edge, True)]["in"].append(edge)
    for edge in junction.getOutgoing():
        if _is_road(edge):
            arms[_arm_of(junction, edge, False)]["out"].append(edge)
    return arms


def test_main_junction_is_one_signalised_junction_near_the_osm_centre(net, main_junction):
    center = net.convertLonLat2XY(SITE.center_lon, SITE.center_lat)
    assert main_junction.getType() == "traffic_light"
    # The OSM centre of the intersection lies within the joined junction's footprint radius.
    assert math.dist(main_junction.getCoord(), center) < 25.0
    # No second traffic light within 100 m: the intersection was joined into one.
    others = [
        n
        for n in net.getNodes()
        if n.getType().startswith("traffic_light")
        and n is not main_junction
        and math.dist(n.getCoord(), main_junction.getCoord()) < 100.0
    ]
    assert others == []


def test_four_arms_each_with_entry_and_exit(main_junction):
    arms = _arms(main_junction)
    assert sorted(arms) == ["E", "N", "S", "W"]
    for name, arm in arms.items():
        assert arm["in"], f"arm {name} has no incoming road"
        assert arm["out"], f"arm {name} has no outgoing road"


def test_xueqing_road_keeps_two_lanes_per_direction(main_junction):
    arms = _arms(main_junction)
    for name in ("N", "S"):
        for direction in ("in", "out"):
            xueqing = [e for e in arms[name][direction] if e.getName() == "学清路"]
            lanes = max(sum(lane.allows("passenger") for lane in e.getLanes()) for e in xueqing)
            assert lanes >= 2, f"Xueqing Road {direction} on arm {name} has {lanes} lane(s)"


def test_every_arm_has_a_signalised_crosswalk_with_green_time(tree, main_junction):
    jid = main_junction.getID()
    arms = _arms(main_junction)
    edge_arm = {e.getID(): name for name, arm in arms.items() for e in arm["in"] + arm["out"]}
    crossings = {
        e.get("id"): e.get("crossingEdges").split()
        for e in tree.iter("edge")
        if e.get("function") == "crossing" and e.get("id").startswith(f":{jid}_c")
    }
    link_index = {
        c.get("to"): int(c.get("linkIndex"))
        for c in tree.iter("connection")
        if c.get("to") in crossings and c.get("tl") == jid
    }
    phases = [
        (float(p.get("duration")), p.get("state"))
        for tl in tree.iter("tlLogic")
        if tl.get("id") == jid
        for p in tl.iter("phase")
    ]
    cycle_s = sum(d for d, _ in phases)
    crossing_arms = defaultdict(list)
    for crossing, crossed in crossings.items():
        assert crossing in link_index, f"crosswalk {crossing} is not controlled by the traffic light"
        green_s = sum(d for d, state in phases if state[link_index[crossing]] in "Gg")
        # Long enough for the slowest group (over 60: 1.03 m/s, the paper's walking speeds) to cross a 6.4 m
        # carriageway.
        assert green_s >= 6.4 / 1.03, f"crosswalk {crossing} has {green_s} s green in a {cycle_s} s cycle"
        for edge_id in crossed:
            if edge_id in edge_arm:
                crossing_arms[edge_arm[edge_id]].append(crossing)
    assert sorted(crossing_arms) == ["E", "N", "S", "W"]


def test_sidewalks_on_both_sides_of_every_arm(net, main_junction):
    jx, jy = main_junction.getCoord()
    for name, arm in _arms(main_junction).items():
        sides = set()
        for edge in arm["in"] + arm["out"]:
            sidewalk = edge.getLane(0)
            assert sidewalk.allows("pedestrian") and not sidewalk.allows("passenger"), (
                f"{edge.getID()} has no sidewalk"
            )
            # Which side of the arm's axis (junction centre -> far end) the sidewalk runs on.
            far = edge.getShape()[0] if edge in arm["in"] else edge.getShape()[-1]
            mid = sidewalk.getShape()[len(sidewalk.getShape()) // 2]
            cross = (far[0] - jx) * (mid[1] - jy) - (far[1] - jy) * (mid[0] - jx)
            sides.add(cross > 0)
        assert sides == {True, False}, f"arm {name} has sidewalks on one side only"


def test_every_incoming_vehicle_lane_leads_to_another_arm(main_junction):
    arms = _arms(main_junction)
    arm_of_out = {e.getID(): name for name, arm in arms.items() for e in arm["out"]}
    for name, arm in arms.items():
        for edge in arm["in"]:
            for lane in edge.getLanes():
                if not lane.allows("passenger"):
                    continue
                targets = {c.getTo().getID() for c in lane.getOutgoing()}
                assert targets, f"lane {lane.getID()} ends at the junction"
                assert any(arm_of_out.get(t, name) != name for t in targets), (
                    f"lane {lane.getID()} only turns back into arm {name}"
                )


def test_no_dead_ends_or_disconnected_pieces_inside_the_study_area(net):
    center = net.convertLonLat2XY(SITE.center_lon, SITE.center_lat)
    roads = [e for e in net.getEdges() if _is_road(e)]
    for node in {n for e in roads for n in (e.getFromNode(), e.getToNode())}:
        road_in = [e for e in node.getIncoming() if _is_road(e)]
        road_out = [e for e in node.getOutgoing() if _is_road(e)]
        if not road_in or not road_out:
            # Only where the clip circle cut a road may a road start or end.
            assert math.dist(node.getCoord(), center) == pytest.approx(SITE.radius_m, abs=3.0), (
                f"dead end {node.getID()} inside the study area"
            )
    entries = [e for e in roads if not any(_is_road(i) for i in e.getFromNode().getIncoming())]
    exits = [e for e in roads if not any(_is_road(o) for o in e.getToNode().getOutgoing())]
    assert len(entries) >= 4 and len(exits) >= 4
    # Every exit is reachable from every entry by car (one connected network, no islands).
    for entry in entries:
        for exit_edge in exits:
            route, _ = net.getShortestPath(entry, exit_edge, vClass="passenger")
            assert route, f"no route from {entry.getID()} to {exit_edge.getID()}"


def test_street_names_and_attribution_are_kept():
    text = NET_FILE.read_text(encoding="utf-8")
    assert re.search(r'name="学清路"', text)
    assert re.search(r'name="石板房南路"', text)
    assert "OpenStreetMap contributors" in text and "ODbL" in text


def _rsu_pose():
    poi = ET.parse(SITE.file("rsu.add.xml")).getroot().find("poi")
    params = {p.get("key"): p.get("value") for p in poi.iter("param")}
    return float(poi.get("x")), float(poi.get("y")), params


def test_roadside_camera_pole_stands_at_a_corner_off_the_carriageway(net, main_junction):
    x, y, params = _rsu_pose()
    assert float(params["height_m"]) == pytest.approx(6.0, abs=1.0)
    # Near the junction (a corner), but on no lane that vehicles use.
    assert math.dist((x, y), main_junction.getCoord()) < 40.0
    for lane, dist in [(lane, d) for lane, d in net.getNeighboringLanes(x, y, r=5.0)]:
        if lane.allows("passenger"):
            assert dist > lane.getWidth() / 2 + 0.5, f"pole stands on lane {lane.getID()}"


def test_roadside_camera_sees_the_watched_crosswalk_and_approach(net, main_junction):
    """Horizontal field of view (90 deg about the yaw, SUMO angle: clockwise from north) contains the
    crosswalks of the watched arm and the approach centreline 20-45 m from the junction; the pitch
    (degrees below the horizon) aims at the ground between them: atan(6 / d) for d in 15..45 m."""
    x, y, params = _rsu_pose()
    yaw_deg, pitch_deg, fov_deg = (float(params[k]) for k in ("yaw_deg", "pitch_deg", "fov_deg"))
    arm = params["watched_arm"]

    def in_fov(px, py):
        bearing = math.degrees(math.atan2(px - x, py - y)) % 360.0
        return abs((bearing - yaw_deg + 180.0) % 360.0 - 180.0) <= fov_deg / 2

    arms = _arms(main_junction)
    watched = {e.getID() for e in arms[arm]["in"] + arms[arm]["out"]}
    crosswalks = [
        e
        for e in net.getEdges(withInternal=True)
        if e.getFunction() == "crossing"
        and e.getID().startswith(f":{main_junction.getID()}_c")
        and {c.getID() for c in e._crossingEdges} & watched
    ]
    assert crosswalks
    for crossing in crosswalks:
        shape = crossing.getLane(0).getShape()
        mid = ((shape[0][0] + shape[-1][0]) / 2, (shape[0][1] + shape[-1][1]) / 2)
        assert in_fov(*mid), f"crosswalk {crossing.getID()} outside the roadside camera's view"
    approach = max(arms[arm]["in"], key=lambda e: e.getLaneNumber())
    lane = approach.getLane(approach.getLaneNumber() - 1)
    for offset_m in (20.0, 30.0, 45.0):
        px, py = sumolib.geomhelper.positionAtShapeOffset(lane.getShape(), lane.getLength() - offset_m)
        assert in_fov(px, py), f"approach {offset_m} m from the stop line outside the view"
    assert math.degrees(math.atan(6.0 / 45.0)) <= pitch_deg <= math.degrees(math.atan(6.0 / 15.0))


def test_far_side_pole_stands_on_the_far_sidewalk_and_aims_at_the_stop_line_queue(net, main_junction):
    """rsu_camera_1: on (1 m behind) a pedestrian-only lane across the median from the watched
    approach, off every vehicle lane, with the kerb lane's last 3-12 m (where a vehicle waiting at the
    stop line ends) inside its 90-degree field of view and its optical axis meeting the ground there."""
    pois = {p.get("id"): p for p in ET.parse(SITE.file("rsu.add.xml")).getroot().iter("poi")}
    poi = pois["rsu_camera_1"]
    x, y = float(poi.get("x")), float(poi.get("y"))
    params = {p.get("key"): float(p.get("value")) for p in poi.iter("param") if p.get("key").endswith("deg")}
    for lane, dist in net.getNeighboringLanes(x, y, r=6.0):
        if lane.allows("passenger"):
            assert dist > lane.getWidth() / 2 + 0.5, f"pole stands on lane {lane.getID()}"
    sidewalks = [
        (lane, dist)
        for lane, dist in net.getNeighboringLanes(x, y, r=3.0)
        if lane.getPermissions() == {"pedestrian"}
    ]
    assert sidewalks and min(d for _, d in sidewalks) <= 1.0 + 1.5 + 0.01
    kerb_lane = net.getLane("177353854#0_1")  # the scenarios' approach (southbound Xueqing Road), kerb lane
    stop_x, stop_y = kerb_lane.getShape()[-1]
    # Across the approach: the pole and the kerb are on opposite sides of the approach's median lane.
    median_lane = net.getLane("177353854#0_2")
    assert x > median_lane.getShape()[-1][0] > stop_x
    for back_m in (3.0, 6.0, 12.0):
        px, py = sumolib.geomhelper.positionAtShapeOffset(
            kerb_lane.getShape(), kerb_lane.getLength() - back_m
        )
        bearing = math.degrees(math.atan2(px - x, py - y)) % 360.0
        assert abs((bearing - params["yaw_deg"] + 180.0) % 360.0 - 180.0) <= params["fov_deg"] / 2
    aim_ground_m = 6.0 / math.tan(math.radians(params["pitch_deg"]))
    assert aim_ground_m == pytest.approx(math.dist((x, y), (stop_x, stop_y)), rel=0.3)
