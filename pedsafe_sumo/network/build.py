"""Build a study site from OpenStreetMap: clip, netconvert, polyconvert, roadside unit, sumocfg.

Everything is made in a staging directory under relative file names, so the configuration that
netconvert and polyconvert write into their headers is the same on every machine, and nothing in
the target directories is touched until every step has succeeded: a failed build leaves the
committed network as it was.

Usage (see tools/build_network.py):
    python tools/build_network.py --site xueqing
    python tools/build_network.py --osm big.osm --center 40.0064,116.3462 --radius 200 --name mysite \
        --out sites/mysite
    python tools/build_network.py --refresh sites/mysite    # after editing sites/mysite/mysite.net.xml

The folder written is a site (pedsafe_sumo.network.sites): every command takes it as --site DIR. Its
derived files (site file, poles, polygons) carry the digest of the network they were made from, so a
network edited afterwards is refused until --refresh re-derives them from it (docs/sites.md).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import sumo
import sumolib

from pedsafe_sumo import NETWORKS_DIR, OSM_ATTRIBUTION
from pedsafe_sumo.network.attribution import add_attribution_comment
from pedsafe_sumo.network.clip import ClipError, clip_osm, read_osm
from pedsafe_sumo.network.site_paths import check_site_folder, check_targets, clip_to_read, source_to_read
from pedsafe_sumo.network.sites import (
    SiteError,
    comparable_text,
    compass_sector,
    content_digest,
    derived_marker,
    resolve_site,
)
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.sumo_net import read_net

HERE = Path(__file__).resolve().parent
NETCONVERT_OPTIONS = HERE / "netconvert.netccfg"
URBAN_SPEEDS_TYPEMAP = HERE / "urban_speeds.typ.xml"
OCCLUDER_TYPEMAP = HERE / "occluders.typ.xml"
SUMO_TYPEMAPS = ("osmNetconvert.typ.xml", "osmNetconvertPedestrians.typ.xml")
PATCH_KINDS = {
    "nod": "--node-files",
    "edg": "--edge-files",
    "con": "--connection-files",
    "tll": "--tllogic-files",
}

#: Roadside unit defaults (issue 2): a camera pole about 6 m high at one corner of the intersection.
RSU_HEIGHT_M = 6.0
RSU_FOV_DEG = 90.0
#: How far behind the corner of the junction (away from its centre) the pole stands, so it is on the
#: pavement and not in the crosswalk.
RSU_SETBACK_M = 2.0
#: Where along the watched approach the camera's optical axis meets the ground (m from the junction
#: centre): the scenarios are staged between the crosswalk (~20 m) and ~50 m up the approach.
RSU_AIM_DISTANCE_M = 30.0
#: Clip radius of a new site when --radius is not given [m]: the junction and about 150 m of each arm.
DEFAULT_RADIUS_M = 200.0


class BuildError(RuntimeError):
    """A step of the build failed; the message says which and why."""


@dataclass
class BuildReport:
    name: str
    out_dir: Path
    clip_path: Path
    written: list[Path]
    unchanged: list[Path]
    main_junction: str
    seconds: float
    lane_defaults: dict | None = None
    signal_nodes: list | None = None


def _run(cmd: list[str], cwd: Path, step: str) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if proc.returncode != 0:
        errors = [line for line in (proc.stderr + proc.stdout).splitlines() if line.startswith("Error")]
        detail = errors[0] if errors else (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise BuildError(f"{step} failed: {detail}")
    return proc.stderr


def _add_comment(path: Path, text: str) -> None:
    """Insert an XML comment after the declaration of a generated file."""
    content = path.read_text(encoding="utf-8")
    end = content.index("?>") + 2 if content.startswith("<?xml") else 0
    path.write_text(content[:end] + f"\n<!-- {text} -->" + content[end:], encoding="utf-8")


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


def lane_defaults(osm_path: Path, typemap_paths: list[Path]) -> dict[str, dict]:
    """Road classes of the clip whose ways carry no lane tag, with how many such ways and the lanes per
    direction the build gives them (the last typemap that defines the class wins, as in netconvert)."""
    import xml.etree.ElementTree as ET

    lanes_by_type: dict[str, int] = {}
    for typemap in typemap_paths:
        for t in ET.parse(typemap).getroot().iter("type"):
            if t.get("numLanes"):
                lanes_by_type[t.get("id")] = int(t.get("numLanes"))
    kept = set()
    for option in ET.parse(NETCONVERT_OPTIONS).getroot().iter("keep-edges.by-type"):
        kept = set(option.get("value").split(","))
    _nodes, ways, _relations = read_osm(osm_path)
    found: dict[str, dict] = {}
    for way in ways.values():
        road_type = f"highway.{way.tags.get('highway', '')}"
        if road_type not in kept or any(k in way.tags for k in ("lanes", "lanes:forward", "lanes:backward")):
            continue
        entry = found.setdefault(road_type, {"ways": 0, "lanes_per_direction": lanes_by_type.get(road_type)})
        entry["ways"] += 1
    return dict(sorted(found.items()))


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


def _arm_axis(junction, arm: str) -> tuple[float, float]:
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
    ax, ay = _arm_axis(junction, watch_arm)
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

    def in_arm(edge, far_end) -> bool:
        return edge.getFunction() == "" and compass_sector((jx, jy), far_end) == watch_arm

    def vehicle_lanes(edge) -> list:
        return [lane for lane in edge.getLanes() if lane.allows("passenger")]

    incoming = [e for e in junction.getIncoming() if in_arm(e, e.getShape()[0]) and vehicle_lanes(e)]
    outgoing = [e for e in junction.getOutgoing() if in_arm(e, e.getShape()[-1]) and vehicle_lanes(e)]
    if not incoming:
        raise BuildError(f"the main junction's {watch_arm} arm has no incoming carriageway")
    approach = max(incoming, key=lambda e: len(vehicle_lanes(e)))
    kerb_lane = vehicle_lanes(approach)[0]

    def before_stop_line(distance_m: float) -> tuple[float, float]:
        return sumolib.geomhelper.positionAtShapeOffset(
            kerb_lane.getShape(), max(kerb_lane.getLength() - distance_m, 0.0)
        )

    abreast = before_stop_line(abreast_m)
    sidewalks = []
    if outgoing:
        leaving = min(outgoing, key=lambda e: _distance_to_shape(kerb_lane.getShape()[-1], e.getShape()))
        sidewalks = [lane for lane in leaving.getLanes() if lane.getPermissions() == {"pedestrian"}]
    if not sidewalks:
        # A one-way approach, or a leaving road without a sidewalk: the pole stands beyond the far
        # (left) edge of the approach itself, as far from its kerb lane as the far sidewalk would be.
        far_lane = vehicle_lanes(approach)[-1]
        x, y = abreast
        heading = sumolib.geomhelper.rotationAtShapeOffset(
            kerb_lane.getShape(), max(kerb_lane.getLength() - abreast_m, 0.0)
        )
        left_m = (len(vehicle_lanes(approach)) - 0.5) * far_lane.getWidth() + setback_m + 1.0
        pole = (x - left_m * math.sin(heading), y + left_m * math.cos(heading))
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


def _place_poles(stage: Path, name: str, net, junction, corner: str, arm: str, poly_file: str) -> list[dict]:
    """The two poles, each at the first placement tried where the scenarios that use it can be hosted
    (pedsafe_sumo.network.hosting: its camera sees where their pedestrians start and most of their
    path, past the buildings and trees of the site); the first placement when none is better."""
    from pedsafe_sumo.network.hosting import _site_world, hosted_count
    from pedsafe_sumo.network.sites import Site
    from pedsafe_sumo.scenarios.geometry import load_approach

    # Both cache by site: a staging folder's name may come back in a later build of this process.
    _site_world.cache_clear()
    load_approach.cache_clear()

    first = [
        {"id": "rsu_camera_0", **place_roadside_unit(net, junction, corner, arm)},
        {"id": "rsu_camera_1", **place_roadside_unit_across(net, junction, arm)},
    ]
    # The scenarios read the main junction and the watched arm from the site file.
    (stage / f"{name}.site.json").write_text(
        json.dumps({"main_junction": junction.getID(), "roadside_unit": first[0]}), encoding="utf-8"
    )
    site = Site(name, stage, "", 0.0, 0.0, 0.0, None, stage / f"{name}.osm", corner, arm)
    corners = [corner] + [c for c in ("NW", "NE", "SE", "SW") if c != corner]
    corner_poles = [
        {"id": "rsu_camera_0", **place_roadside_unit(net, junction, c, arm, setback_m=setback)}
        for c in corners
        for setback in RSU_SETBACKS_TRIED_M
    ]
    best0 = max(
        corner_poles,
        key=lambda pole: (hosted_count(site, [pole, first[1]], poly_file), -corner_poles.index(pole)),
    )
    across_poles = [
        {"id": "rsu_camera_1", **place_roadside_unit_across(net, junction, arm, setback_m=setback)}
        for setback in RSU_ACROSS_SETBACKS_TRIED_M
    ]
    best1 = max(
        across_poles,
        key=lambda pole: (hosted_count(site, [best0, pole], poly_file), -across_poles.index(pole)),
    )
    return [best0, best1]


def _distance_to_shape(point, shape) -> float:
    offset = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(point, shape)
    return math.dist(point, sumolib.geomhelper.positionAtShapeOffset(shape, offset))


def _write_rsu(path: Path, units: list[dict]) -> None:
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


def _write_sumocfg(path: Path, name: str) -> None:
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        "<!-- Open with: sumo-gui -c "
        + path.name
        + "   (or netedit -s "
        + name
        + ".net.xml to edit the network)\n"
        "     Demand is added by the episode engine or on the command line: -r ../../routes/"
        + name
        + ".*.rou.xml -->\n"
        "<configuration>\n"
        "    <input>\n"
        f'        <net-file value="{name}.net.xml"/>\n'
        f'        <additional-files value="{name}.poly.xml,{name}.rsu.add.xml"/>\n'
        "    </input>\n"
        "    <time>\n"
        '        <step-length value="0.05"/>\n'
        "    </time>\n"
        "    <processing>\n"
        '        <pedestrian.model value="striping"/>\n'
        '        <collision.check-junctions value="true"/>\n'
        "    </processing>\n"
        "    <gui_only>\n"
        f'        <gui-settings-file value="{name}.view.xml"/>\n'
        "    </gui_only>\n"
        "</configuration>\n",
        encoding="utf-8",
    )


def _write_view(path: Path, junction_xy: tuple[float, float]) -> None:
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        "<!-- sumo-gui view of the study site: centred on the main junction, real-world colours. -->\n"
        "<viewsettings>\n"
        '    <scheme name="real world"/>\n'
        f'    <viewport zoom="200" x="{junction_xy[0]:.2f}" y="{junction_xy[1]:.2f}"/>\n'
        '    <delay value="50"/>\n'
        "</viewsettings>\n",
        encoding="utf-8",
    )


def _netconvert(stage: Path, osm_name: str, type_files: str, net_file: str) -> None:
    _run(
        [
            sumo_binary("netconvert"),
            "-c",
            NETCONVERT_OPTIONS.name,
            "--osm-files",
            osm_name,
            "--type-files",
            type_files,
            "--output-file",
            net_file,
        ],
        stage,
        "netconvert",
    )


def _apply_patches(stage: Path, name: str, net_file: str, patches_dir: Path | None) -> list[str]:
    """netconvert over the network with the folder's patch files; the patch arguments used."""
    patch_args: list[str] = []
    if patches_dir is not None and patches_dir.is_dir():
        for kind, option in PATCH_KINDS.items():
            files = sorted(patches_dir.glob(f"*.{kind}.xml"))
            for patch in files:
                shutil.copyfile(patch, stage / patch.name)
            if files:
                patch_args += [option, ",".join(p.name for p in files)]
    if patch_args:
        patched = f"{name}.patched.net.xml"
        _run(
            [sumo_binary("netconvert"), "--sumo-net-file", net_file, *patch_args, "--output-file", patched],
            stage,
            "netconvert (patches)",
        )
        os.replace(stage / patched, stage / net_file)
    return patch_args


UNDERGROUND_POLY = re.compile(
    r"[ \t]*<poly [^>]*[^/]>(?:(?!</poly>|<poly ).)*?"
    r"(?:<param key=\"layer\" value=\"-|<param key=\"location\" value=\"underground)"
    r"(?:(?!</poly>|<poly ).)*?</poly>\n",
    re.DOTALL,
)


def _drop_underground(path: Path) -> int:
    """Remove the polygons OSM puts below ground (a negative layer, location=underground: subway
    stations drawn over the road) from a polyconvert file; they hide nothing from a camera. How many."""
    text = path.read_text(encoding="utf-8")
    kept, dropped = UNDERGROUND_POLY.subn("", text)
    if dropped:
        path.write_text(kept, encoding="utf-8")
    return dropped


def _insert_after_declaration(path: Path, line: str) -> None:
    text = path.read_text(encoding="utf-8")
    end = text.index("?>") + 2 if text.startswith("<?xml") else 0
    path.write_text(text[:end] + "\n" + line + text[end:], encoding="utf-8")


def _relative_to(folder: Path, path: Path | None) -> str | None:
    """`path` as the site file records it: relative to the site folder (so a checkout can move)."""
    if path is None:
        return None
    return os.path.relpath(os.path.abspath(path), os.path.abspath(folder))


def build_site(
    osm_path: Path,
    center_lat: float,
    center_lon: float,
    radius_m: float,
    name: str,
    out_dir: Path,
    clip_out: Path,
    clip: bool = True,
    patches_dir: Path | None = None,
    rsu_corner: str | None = "NW",
    rsu_watch_arm: str | None = "N",
    description: str = "",
    source_osm: Path | None = None,
    net_from: Path | None = None,
) -> BuildReport:
    """Build the site folder `out_dir` from an OSM file; see the module docstring.

    With `net_from` (a .net.xml, e.g. one edited in netedit) no netconvert runs: that network is kept as
    it is and the polygons (polyconvert over `osm_path`, projected with the network's own geo-reference),
    roadside poles, sumocfg and site file are derived from it. `source_osm` is recorded in the site file
    as where the data came from (default: `osm_path` when it is clipped)."""
    started = time.perf_counter()
    if not re.fullmatch(r"[A-Za-z0-9_-]+", name):
        raise BuildError(f"site name '{name}' must be letters, digits, '_' or '-'")
    osm_path = Path(osm_path)
    if source_osm is None and clip and net_from is None:
        source_osm = osm_path
    with tempfile.TemporaryDirectory(prefix=f"pedsafe_build_{name}_") as tmp:
        stage = Path(tmp)
        staged_osm = stage / f"{name}.osm"
        try:
            if clip and net_from is None:
                clip_osm(osm_path, staged_osm, center_lat, center_lon, radius_m)
            else:
                read_osm(osm_path)  # validates that it is OSM data
                shutil.copyfile(osm_path, staged_osm)
        except ClipError as exc:
            raise BuildError(str(exc)) from None

        for typemap in SUMO_TYPEMAPS:
            shutil.copyfile(Path(sumo.SUMO_HOME) / "data" / "typemap" / typemap, stage / typemap)
        shutil.copyfile(URBAN_SPEEDS_TYPEMAP, stage / URBAN_SPEEDS_TYPEMAP.name)
        shutil.copyfile(OCCLUDER_TYPEMAP, stage / OCCLUDER_TYPEMAP.name)
        shutil.copyfile(NETCONVERT_OPTIONS, stage / NETCONVERT_OPTIONS.name)

        net_file = f"{name}.net.xml"
        type_files = ",".join([*SUMO_TYPEMAPS, URBAN_SPEEDS_TYPEMAP.name])
        if net_from is not None:
            # The network as the user left it: nothing of it is rebuilt.
            try:
                shutil.copyfile(net_from, stage / net_file)
            except OSError as exc:
                raise BuildError(f"cannot read {net_from}: {exc.strerror}") from None
        else:
            _netconvert(stage, staged_osm.name, type_files, net_file)
            patch_args = _apply_patches(stage, name, net_file, patches_dir)
            if patch_args:
                # SUMO's header now shows only the patch pass: say how the network was made.
                patched_with = ", ".join(
                    f"{patch_args[i].lstrip('-')}={patch_args[i + 1]}" for i in range(0, len(patch_args), 2)
                )
                _add_comment(
                    stage / net_file,
                    f"Built by tools/build_network.py: netconvert with {NETCONVERT_OPTIONS.name}, "
                    f"osm-files={staged_osm.name}, type-files={type_files}; then patched with "
                    f"{patched_with} (from networks/{name}/patches/).",
                )

        poly_file = f"{name}.poly.xml"
        _run(
            [
                sumo_binary("polyconvert"),
                "--net-file",
                net_file,
                "--osm-files",
                staged_osm.name,
                "--type-file",
                OCCLUDER_TYPEMAP.name,
                "--osm.keep-full-type",
                "true",
                "--all-attributes",
                "true",
                "--discard",
                "true",
                "--output-file",
                poly_file,
            ],
            stage,
            "polyconvert",
        )

        dropped_underground = _drop_underground(stage / poly_file)
        try:
            net = read_net(str(stage / net_file), withInternal=True)
        except Exception as exc:  # sumolib raises bare SAX errors on a broken network
            raise BuildError(f"cannot read the network {net_from or net_file}: {exc}") from None
        center_xy = net.convertLonLat2XY(center_lon, center_lat)
        # The approach the scenarios use: the watched arm when given, else the best one of every signal
        # node of the intersection (netconvert may split it into several); its node is the main junction.
        group = signal_group(net, center_xy)
        junction, chosen_arm = choose_approach(net, group, rsu_watch_arm)
        if rsu_watch_arm is not None and chosen_arm != rsu_watch_arm:
            raise BuildError(f"the main junction has no arm towards {rsu_watch_arm}")
        rsu_watch_arm = chosen_arm
        rsu_corner = rsu_corner or KERB_CORNER[rsu_watch_arm]
        # Two poles per approach: the corner pole watches the approach and its crosswalk (crossing,
        # jaywalking); the far-side pole looks across at the approach's stop-line queue (background
        # blending). The site's own approach (the watched arm) first, with the ids the scenarios name;
        # every other approach's poles carry its arm in their ids (scenarios.geometry.approach_unit_ids).
        approaches = approach_nodes(net, group, rsu_watch_arm, junction)
        rsu_units = _place_poles(stage, name, net, junction, rsu_corner, rsu_watch_arm, poly_file)
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
                    for pole in _place_poles(stage, name, net, node, KERB_CORNER[arm], arm, poly_file)
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
        _write_rsu(stage / f"{name}.rsu.add.xml", rsu_units)
        _write_view(stage / f"{name}.view.xml", junction.getCoord())
        _write_sumocfg(stage / f"{name}.sumocfg", name)

        products = [net_file, poly_file, f"{name}.rsu.add.xml", f"{name}.view.xml", f"{name}.sumocfg"]
        for product in products:
            add_attribution_comment(stage / product)
        # The derived files name the network they were made from (pedsafe_sumo.network.sites checks it).
        marker = derived_marker(stage / net_file)
        for derived in (poly_file, f"{name}.rsu.add.xml"):
            _insert_after_declaration(stage / derived, marker)
        defaults = lane_defaults(
            staged_osm,
            [*(stage / t for t in SUMO_TYPEMAPS), stage / URBAN_SPEEDS_TYPEMAP.name],
        )
        site_info = {
            "name": name,
            "description": description,
            "center_lat": center_lat,
            "center_lon": center_lon,
            "radius_m": radius_m,
            "source_osm": _relative_to(out_dir, source_osm),
            "clip_osm": _relative_to(out_dir, clip_out),
            "rsu_corner": rsu_corner,
            "rsu_watch_arm": rsu_watch_arm,
            "main_junction": junction.getID(),
            "main_junction_xy": [round(c, 2) for c in junction.getCoord()],
            # Every signal node of the intersection (more than one when netconvert split it).
            "signal_nodes": [n.getID() for n in group],
            # OSM road classes without a lane tag and the lanes per direction the build gave them.
            "lane_defaults": defaults,
            # Polygons OSM puts below ground, left out of the occluders (_drop_underground).
            "underground_polygons_dropped": dropped_underground,
            # "roadside_unit": the corner pole, whose watched arm is the scenarios' approach.
            "roadside_unit": rsu_units[0],
            # Every approach (arm -> its signal node and poles), the site's own first: --approach ARM.
            "approaches": approach_info,
            "roadside_units": rsu_units,
            "sumo_version": sumolib.version.gitDescribe(),
            "attribution": OSM_ATTRIBUTION,
            "net_sha256": content_digest(stage / net_file),
            "derived_sha256": {p: content_digest(stage / p) for p in (poly_file, f"{name}.rsu.add.xml")},
        }
        (stage / f"{name}.site.json").write_text(
            json.dumps(site_info, indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
        )

        # Every step succeeded: only now touch the target directories.
        out_dir.mkdir(parents=True, exist_ok=True)
        written, unchanged = [], []
        targets = [(stage / p, out_dir / p) for p in [*products, f"{name}.site.json"]]
        if clip and net_from is None:
            clip_out.parent.mkdir(parents=True, exist_ok=True)
            targets.append((staged_osm, clip_out))
        for staged, target in targets:
            # A file that differs only in SUMO's "generated on" time is left as it is, so rebuilding an
            # unchanged site does not touch the checkout.
            if target.exists() and comparable_text(target) == comparable_text(staged):
                unchanged.append(target)
                continue
            tmp_target = target.with_name(target.name + ".tmp")
            shutil.copyfile(staged, tmp_target)
            os.replace(tmp_target, target)
            written.append(target)
    return BuildReport(
        name,
        out_dir,
        clip_out,
        written,
        unchanged,
        junction.getID(),
        time.perf_counter() - started,
        defaults,
        [n.getID() for n in group],
    )


def _parse_center(text: str) -> tuple[float, float]:
    try:
        lat, lon = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"centre must be LAT,LON in degrees, got '{text}'") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise argparse.ArgumentTypeError(f"centre {text} is not a latitude,longitude pair")
    return lat, lon


def _refresh(parser, folder: Path) -> BuildReport:
    """Re-derive a site folder's site file, poles and polygons from its (edited) network."""
    try:
        site = resolve_site(folder if "/" in str(folder) else f"./{folder}", verify=False)
    except SiteError as exc:
        parser.exit(2, f"build_network: error: {exc}\n")
    clip_to_read(site)  # a clip where the site file may name it, and no link out (docs/trust.md)
    check_targets(None, site.directory, site.name, None)
    if not site.clip_osm.is_file():
        parser.exit(
            2,
            f"build_network: error: {site.clip_osm} (the site's OSM clip, for the polygons) is missing\n",
        )
    return build_site(
        site.clip_osm,
        site.center_lat,
        site.center_lon,
        site.radius_m,
        site.name,
        site.directory,
        site.clip_osm,
        clip=False,
        rsu_corner=site.rsu_corner,
        rsu_watch_arm=site.rsu_watch_arm,
        description=site.description,
        source_osm=site.source_osm,
        net_from=site.file("net.xml"),
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="build_network",
        description="Build a SUMO study site folder (net, polygons, roadside units, sumocfg, site file) from "
        "OpenStreetMap; every command takes the folder as --site.",
    )
    parser.add_argument(
        "--site",
        default="xueqing",
        help="existing site (name or folder) whose settings are the defaults [xueqing]",
    )
    parser.add_argument("--osm", type=Path, help="OSM XML file to clip (default: the site's source extract)")
    parser.add_argument(
        "--center", type=_parse_center, help="LAT,LON of the intersection (default: the site's)"
    )
    parser.add_argument("--radius", type=float, help="clip radius in metres (default: the site's)")
    parser.add_argument("--name", help="name of the built site (default: --site's)")
    parser.add_argument("--description", help="one line saying where the junction is")
    parser.add_argument(
        "--out",
        "--out-dir",
        dest="out_dir",
        type=Path,
        help="the site folder to write (default: networks/NAME)",
    )
    parser.add_argument("--osm-out", type=Path, help="where the clipped OSM goes (default: the site's clip)")
    parser.add_argument(
        "--patches",
        type=Path,
        help="folder of *.nod/edg/con/tll.xml patches (default: networks/NAME/patches)",
    )
    parser.add_argument("--rsu-corner", choices=["NE", "NW", "SE", "SW"], help="corner of the camera pole")
    parser.add_argument("--rsu-watch", choices=list("NESW"), help="arm the roadside camera watches")
    parser.add_argument(
        "--no-clip",
        action="store_true",
        help="use --osm as it is (an already clipped file, e.g. osm/xueqing.osm)",
    )
    parser.add_argument(
        "--refresh",
        type=Path,
        metavar="DIR",
        help="keep the network of site folder DIR as it is (e.g. edited in netedit) and re-derive its site "
        "file, poles and polygons from it",
    )
    args = parser.parse_args(argv)
    try:
        if args.refresh is not None:
            report = _refresh(parser, args.refresh)
        else:
            report = _build(parser, args)
    except (BuildError, SiteError) as exc:
        parser.exit(2, f"build_network: error: {exc}\n")
    print(f"built {report.name} in {report.seconds:.1f} s: main junction {report.main_junction}")
    if report.signal_nodes and len(report.signal_nodes) > 1:
        print(
            f"  the intersection has {len(report.signal_nodes)} signal nodes: "
            + ", ".join(report.signal_nodes)
        )
    for road_type, entry in (report.lane_defaults or {}).items():
        print(
            f"  lane default: {entry['ways']} {road_type} way(s) without a lane tag get "
            f"{entry['lanes_per_direction']} lane(s) per direction"
        )
    for path in report.written:
        print(f"  wrote     {path}")
    for path in report.unchanged:
        print(f"  unchanged {path}")
    from pedsafe_sumo.network.hosting import hosting_lines

    print("scenarios:")
    for line in hosting_lines(resolve_site(str(report.out_dir.resolve()))):
        print(line)
    print(f"  use it: --site {report.out_dir}")
    return 0


def _build(parser, args) -> BuildReport:
    new_site = args.name is not None and args.center is not None and args.osm is not None
    site = None
    if not new_site:
        try:
            site = resolve_site(args.site, verify=False)
        except SiteError as exc:
            parser.exit(2, f"build_network: error: {exc}\n")
    name = args.name or site.name
    same_site = site is not None and site.name == name
    lat, lon = args.center or (site.center_lat, site.center_lon)
    radius_m = args.radius if args.radius is not None else (site.radius_m if site else DEFAULT_RADIUS_M)
    if radius_m <= 0:
        parser.exit(2, f"build_network: error: radius must be positive, got {radius_m}\n")
    out_dir = args.out_dir or (site.directory.parent / name if site else NETWORKS_DIR / name)
    if site is not None and args.osm is None:
        osm = clip_to_read(site) if args.no_clip else source_to_read(site, refuse=True)
        if osm is None:
            parser.exit(2, f"build_network: error: site {site.name} records no source OSM: give --osm\n")
    else:
        osm = args.osm
    # The clip stays where the site keeps it (osm/xueqing.osm for the shipped site), else in its folder.
    default_clip = site.clip_osm if same_site and args.out_dir is None else out_dir / f"{name}.osm"
    if site is not None and args.out_dir is None and args.name is None:  # what the site file decides
        check_site_folder(site, out_dir)  # network/site_paths.py, docs/trust.md
    site_clip = same_site and args.out_dir is None and args.osm_out is None and not args.no_clip
    check_targets(site, out_dir, name, default_clip if site_clip else None)
    return build_site(
        osm,
        lat,
        lon,
        radius_m,
        name,
        out_dir,
        args.osm_out or default_clip,
        clip=not args.no_clip,
        patches_dir=args.patches or (site.directory if same_site else out_dir) / "patches",
        # A new site's watched arm is chosen by the build (choose_approach), its pole on that arm's kerb.
        rsu_corner=args.rsu_corner or (site.rsu_corner if same_site else None),
        rsu_watch_arm=args.rsu_watch or (site.rsu_watch_arm if same_site else None),
        description=args.description if args.description is not None else (site.description if site else ""),
        source_osm=(site.source_osm if same_site else None) if args.no_clip else osm,
    )


if __name__ == "__main__":
    raise SystemExit(main())
