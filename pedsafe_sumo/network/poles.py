"""The roadside camera poles of a site: two per approach of the intersection.

The corner pole stands behind a corner of the junction and watches the approach and its crosswalk
(crossing, jaywalking); the far-side pole stands on the far sidewalk and looks across at the approach's
stop-line queue (background blending). Each is placed at the first of a few placements where the
scenarios that use it can be hosted, which the caller judges (`HostingScorer`): the network layer knows
the geometry, the scenarios know what their cameras have to see.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import sumolib

from pedsafe_sumo.network.approach_chain import kerb_lane_along_chain
from pedsafe_sumo.network.approaches import (
    arm_axis,
    bearing_deg,
    kerb_corner,
    leg_named,
    leg_towards,
    legs_at,
)
from pedsafe_sumo.network.errors import BuildError
from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.network.traffic_side import KEEP_RIGHT, network_keep_side

#: Given the staged site of one approach (its site file names that approach's junction and corner pole),
#: the function that counts how many of the scenarios staged there a pole pair lets the site host:
#: ``hosting_scorer(site)(poles, poly_file)`` (the scenarios' hosting check). Called once per approach,
#: so that what the scorer caches by site describes that approach.
HostingScorer = Callable[[Site], Callable[[list[dict], str], int]]

#: Roadside unit defaults: a camera pole about 6 m high at one corner of the intersection.
RSU_HEIGHT_M = 6.0
RSU_FOV_DEG = 90.0

#: How far behind the corner of the junction (away from its centre) the pole stands, so it is on the
#: pavement and not in the crosswalk.
RSU_SETBACK_M = 2.0

#: Where along the watched approach the camera's optical axis meets the ground (m from the junction
#: centre): the scenarios are staged between the crosswalk (~20 m) and ~50 m up the approach.
RSU_AIM_DISTANCE_M = 30.0


def place_roadside_unit(
    net: sumolib.net.Net,
    junction,
    corner: str = "NW",
    watch_arm: str = "N",
    aim_distance_m: float = RSU_AIM_DISTANCE_M,
    setback_m: float = RSU_SETBACK_M,
) -> dict:
    """Pole on one corner of the junction, its camera watching one approach and its crosswalk.

    The corner is the walking area of the junction that lies furthest towards `corner`; the pole
    stands RSU_SETBACK_M behind it. The camera aims at the point `aim_distance_m` out along
    `watch_arm` from the junction centre, so that arm's crosswalk and the first ~50 m of its
    approach are in view (beyond ~54 m a 1.7 m pedestrian is under 20 px at f = 640 px).
    Angles follow SUMO's POI convention: yaw in degrees clockwise from north; pitch in degrees
    below the horizon.
    """
    jx, jy = junction.getCoord()
    toward = {"NE": (1, 1), "NW": (-1, 1), "SE": (1, -1), "SW": (-1, -1)}[corner]
    corners = []
    for edge in net.getEdges(withInternal=True):
        if edge.getFunction() == "walkingarea" and edge.getID().startswith(f":{junction.getID()}_w"):
            shape = edge.getLane(0).getShape()
            corners.append((sum(p[0] for p in shape) / len(shape), sum(p[1] for p in shape) / len(shape)))
    if not corners:
        corners = [tuple(p) for p in junction.getShape()]
    cx, cy = max(corners, key=lambda p: toward[0] * (p[0] - jx) + toward[1] * (p[1] - jy))
    dx, dy = cx - jx, cy - jy
    dist = math.hypot(dx, dy) or 1.0
    px, py = cx + setback_m * dx / dist, cy + setback_m * dy / dist
    ax, ay = arm_axis(net, junction, watch_arm)
    aim_xy = (jx + aim_distance_m * ax, jy + aim_distance_m * ay)
    return _pole_aimed_at((px, py), aim_xy, corner, watch_arm)


def _pole_aimed_at(pole_xy, aim_xy, corner: str, watch_arm: str) -> dict:
    """A pole RSU_HEIGHT_M high at `pole_xy` whose optical axis meets the ground at `aim_xy`: yaw in
    degrees clockwise from north, pitch in degrees below the horizon (SUMO's POI convention)."""
    dx, dy = aim_xy[0] - pole_xy[0], aim_xy[1] - pole_xy[1]
    return {
        "x": round(pole_xy[0], 2),
        "y": round(pole_xy[1], 2),
        "height_m": RSU_HEIGHT_M,
        "yaw_deg": round(math.degrees(math.atan2(dx, dy)) % 360.0, 2),
        "pitch_deg": round(math.degrees(math.atan2(RSU_HEIGHT_M, math.hypot(dx, dy))), 2),
        "fov_deg": RSU_FOV_DEG,
        "corner": corner,
        "watched_arm": watch_arm,
    }


#: The far-side pole (see place_roadside_unit_across): it stands abreast of the point this far before the
#: watched approach's stop line, and aims at the kerb lane this far before it, where a vehicle waiting
#: at the stop line ends (car lengths 4.6-5.0 m) and a pedestrian standing behind it is.
RSU_ACROSS_ABREAST_M = 10.0
RSU_ACROSS_AIM_M = 6.0

#: How far beyond the outer edge of the far sidewalk's centre line the far-side pole stands [m].
RSU_ACROSS_SETBACK_M = 1.0


def place_roadside_unit_across(
    net: sumolib.net.Net,
    junction,
    watch_arm: str = "N",
    abreast_m: float = RSU_ACROSS_ABREAST_M,
    aim_m: float = RSU_ACROSS_AIM_M,
    setback_m: float = RSU_ACROSS_SETBACK_M,
    side: float = KEEP_RIGHT,
) -> dict:
    """Pole on the far sidewalk of one arm, looking across at the approach's stop-line queue.

    The approach is the arm's incoming carriageway with the most vehicle lanes; the far sidewalk is
    the outermost pedestrian lane of the arm's leaving carriageway. The pole stands on that
    sidewalk, RSU_ACROSS_SETBACK_M beyond it, abreast of the point `abreast_m` before the stop line
    of the approach's kerb lane, and aims at the kerb lane `aim_m` before the stop line. Seen from
    there, a pedestrian standing right behind a vehicle that waits at the stop line is in side view
    with the road and pavement behind them, not the vehicle: the corner pole of
    place_roadside_unit looks at them over the vehicle's front and sees only the vehicle.
    """
    jx, jy = junction.getCoord()
    legs = legs_at(net, junction)

    def in_arm(edge, far_end) -> bool:
        return edge.getFunction() == "" and leg_towards(legs, bearing_deg((jx, jy), far_end)) == watch_arm

    def vehicle_lanes(edge) -> list:
        return [lane for lane in edge.getLanes() if lane.allows("passenger")]

    incoming = [e for e in junction.getIncoming() if in_arm(e, e.getShape()[0]) and vehicle_lanes(e)]
    outgoing = [e for e in junction.getOutgoing() if in_arm(e, e.getShape()[-1]) and vehicle_lanes(e)]
    if not incoming:
        raise BuildError(f"the main junction's {watch_arm} arm has no incoming carriageway")
    approach = max(incoming, key=lambda e: len(vehicle_lanes(e)))
    kerb_lane = vehicle_lanes(approach)[0]
    # Along the chain of edges before a stub approach (network/approach_chain.py).
    kerb_shape, kerb_length_m = kerb_lane_along_chain(net, approach)

    def before_stop_line(distance_m: float) -> tuple[float, float]:
        return sumolib.geomhelper.positionAtShapeOffset(kerb_shape, max(kerb_length_m - distance_m, 0.0))

    abreast = before_stop_line(abreast_m)
    sidewalks = []
    if outgoing:
        leaving = min(outgoing, key=lambda e: _distance_to_shape(kerb_lane.getShape()[-1], e.getShape()))
        sidewalks = [lane for lane in leaving.getLanes() if lane.getPermissions() == {"pedestrian"}]
    if not sidewalks:
        # A one-way approach, or a leaving road without a sidewalk: the pole stands beyond the far
        # (median-side: left of travel, right in left-hand traffic, `side`) edge of the approach itself,
        # as far from its kerb lane as the far sidewalk would be.
        far_lane = vehicle_lanes(approach)[-1]
        x, y = abreast
        heading = sumolib.geomhelper.rotationAtShapeOffset(kerb_shape, max(kerb_length_m - abreast_m, 0.0))
        median_m = side * ((len(vehicle_lanes(approach)) - 0.5) * far_lane.getWidth() + setback_m + 1.0)
        pole = (x - median_m * math.sin(heading), y + median_m * math.cos(heading))
        return _pole_aimed_at(pole, before_stop_line(aim_m), "across", watch_arm)
    sidewalk = sidewalks[0]  # lane 0: the outermost

    offset = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(abreast, sidewalk.getShape())
    sx, sy = sumolib.geomhelper.positionAtShapeOffset(sidewalk.getShape(), offset)
    dx, dy = sx - abreast[0], sy - abreast[1]
    dist = math.hypot(dx, dy) or 1.0
    px = sx + (sidewalk.getWidth() / 2 + setback_m) * dx / dist
    py = sy + (sidewalk.getWidth() / 2 + setback_m) * dy / dist
    return _pole_aimed_at((px, py), before_stop_line(aim_m), "across", watch_arm)


#: Where the build tries the poles, in order (the first placement is the one described above): the corner
#: pole behind each corner of the junction, the watched arm's kerb corner first, at these setbacks [m];
#: the far-side pole at these setbacks beyond the far sidewalk [m].
RSU_SETBACKS_TRIED_M = (RSU_SETBACK_M, 4.0, 6.0)
RSU_ACROSS_SETBACKS_TRIED_M = (RSU_ACROSS_SETBACK_M, 3.0, 5.0)


def place_poles(
    stage: Path,
    name: str,
    net,
    junction,
    corner: str,
    arm: str,
    poly_file: str,
    hosting_scorer: HostingScorer,
) -> list[dict]:
    """The two poles of one approach, each at the first placement tried where the scenarios that use it
    can be hosted (`hosting_scorer`: its camera sees where their pedestrians start and most of their
    path, past the buildings and trees of the site); the first placement when none is better."""
    side = network_keep_side(stage / f"{name}.net.xml")
    first = [
        {"id": "rsu_camera_0", **place_roadside_unit(net, junction, corner, arm)},
        {"id": "rsu_camera_1", **place_roadside_unit_across(net, junction, arm, side=side)},
    ]
    # The scenarios read the main junction and the watched arm from the site file.
    (stage / f"{name}.site.json").write_text(
        json.dumps({"main_junction": junction.getID(), "roadside_unit": first[0]}), encoding="utf-8"
    )
    site = Site(name, stage, "", 0.0, 0.0, 0.0, None, stage / f"{name}.osm", corner, arm)
    hosted_count = hosting_scorer(site)
    corners = [corner] + [c for c in ("NW", "NE", "SE", "SW") if c != corner]
    corner_poles = [
        {"id": "rsu_camera_0", **place_roadside_unit(net, junction, c, arm, setback_m=setback)}
        for c in corners
        for setback in RSU_SETBACKS_TRIED_M
    ]
    best0 = max(
        corner_poles,
        key=lambda pole: (hosted_count([pole, first[1]], poly_file), -corner_poles.index(pole)),
    )
    across_poles = [
        {"id": "rsu_camera_1", **place_roadside_unit_across(net, junction, arm, setback_m=setback, side=side)}
        for setback in RSU_ACROSS_SETBACKS_TRIED_M
    ]
    best1 = max(
        across_poles,
        key=lambda pole: (hosted_count([best0, pole], poly_file), -across_poles.index(pole)),
    )
    return [best0, best1]


def side_kerb_corner(leg, side: float) -> str:
    """The corner the pole watching `leg` stands on: its kerb's. In right-hand traffic
    approaches.kerb_corner (45 degrees anticlockwise of the leg); in left-hand traffic the kerb lies on
    the other side of the arriving traffic, 45 degrees clockwise of the leg."""
    if side > 0:
        return kerb_corner(leg)
    return ("NE", "SE", "SW", "NW")[int(((leg.bearing_deg + 45.0) % 360.0) // 90.0)]


def place_approach_poles(
    stage: Path,
    name: str,
    net,
    approaches: dict,
    rsu_corner: str,
    rsu_watch_arm: str,
    poly_file: str,
    hosting_scorer: HostingScorer,
) -> tuple[list[dict], dict]:
    """(every pole, arm -> its approach as the site file records it) for the arms of `approaches` (arm ->
    signal node), the site's own (watched) arm first with the pole ids the scenarios name; every other
    approach's poles carry its arm in their ids (scenarios.geometry.approach_unit_ids)."""
    junction = approaches[rsu_watch_arm]
    rsu_units = place_poles(stage, name, net, junction, rsu_corner, rsu_watch_arm, poly_file, hosting_scorer)
    approach_info = {
        rsu_watch_arm: {
            "junction": junction.getID(),
            "corner": rsu_corner,
            "poles": [u["id"] for u in rsu_units],
        }
    }
    for arm, node in approaches.items():
        if arm == rsu_watch_arm:
            continue
        try:
            poles = [
                {**pole, "id": f"{pole['id']}_{arm}"}
                for pole in place_poles(
                    stage,
                    name,
                    net,
                    node,
                    side_kerb_corner(
                        leg_named(legs_at(net, node), arm), network_keep_side(stage / f"{name}.net.xml")
                    ),
                    arm,
                    poly_file,
                    hosting_scorer,
                )
            ]
        except BuildError as exc:
            # An arm the poles cannot be placed on (no incoming carriageway of its own at that node):
            # the approach is left out, and the site file says why.
            approach_info[arm] = {"junction": node.getID(), "skipped": str(exc), "poles": []}
            continue
        approach_info[arm] = {
            "junction": node.getID(),
            "corner": poles[0]["corner"],
            "poles": [u["id"] for u in poles],
        }
        rsu_units += poles
    return rsu_units, approach_info


def _distance_to_shape(point, shape) -> float:
    offset = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(point, shape)
    return math.dist(point, sumolib.geomhelper.positionAtShapeOffset(shape, offset))


def write_rsu(path: Path, units: list[dict]) -> None:
    """All roadside camera poles of the site as POIs of one additional file."""
    pois = []
    for rsu in units:
        params = "\n".join(
            f'        <param key="{key}" value="{rsu[key]}"/>'
            for key in ("height_m", "yaw_deg", "pitch_deg", "fov_deg", "corner", "watched_arm")
        )
        pois.append(
            f'    <poi id="{rsu["id"]}" type="roadside_camera" color="0,90,255" layer="100" '
            f'x="{rsu["x"]:.2f}" y="{rsu["y"]:.2f}" width="2.00" height="2.00" '
            f'angle="{rsu["yaw_deg"]:.2f}">\n'
            f"{params}\n"
            "    </poi>\n"
        )
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        "<!-- Roadside units of the study site: the camera poles of the V2I condition. Position in network\n"
        "     coordinates (m); yaw in degrees clockwise from north (SUMO's angle convention), pitch in\n"
        "     degrees below the horizon. Written by tools/build_network.py. -->\n"
        "<additional>\n" + "".join(pois) + "</additional>\n",
        encoding="utf-8",
    )
