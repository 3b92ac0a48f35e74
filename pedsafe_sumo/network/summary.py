"""A human summary of a built study site: the junction, its arms, crosswalks, occluders, roadside unit."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from pedsafe_sumo.network.approaches import angle_between_deg, bearing_deg, junction_arms, legs_at
from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.network.traffic_lights import junction_lights
from pedsafe_sumo.sumo_net import read_net


@dataclass
class Arm:
    direction: str
    names: list[str]
    lanes_in: int
    lanes_out: int
    crosswalks: int


@dataclass
class SiteSummary:
    name: str
    main_junction: str
    junction_type: str
    cycle_s: float
    phases: int
    arms: list[Arm]
    crosswalks_signalised: int
    road_edges: int
    road_length_m: float
    sidewalk_length_m: float
    polygons: Counter = field(default_factory=Counter)
    roadside_units: list[dict] = field(default_factory=list)
    #: The traffic lights on the main junction's connections (network.traffic_lights), by id.
    traffic_lights: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        lights = ", ".join(self.traffic_lights) or "none"
        out = [
            f"site {self.name}: main junction {self.main_junction} ({self.junction_type}, "
            f"{self.phases} phases, {self.cycle_s:.0f} s cycle)",
            f"  traffic light(s) on its connections: {lights}",
            f"  {len(self.arms)} arms:",
        ]
        for arm in self.arms:
            out.append(
                f"    {arm.direction}: {', '.join(arm.names) or '(unnamed)'} - {arm.lanes_in} lane(s) in, "
                f"{arm.lanes_out} out, {arm.crosswalks} signalised crosswalk(s)"
            )
        out += [
            f"  {self.crosswalks_signalised} signalised crosswalks; {self.road_edges} road edges, "
            f"{self.road_length_m / 1000:.2f} km of road, {self.sidewalk_length_m / 1000:.2f} km of sidewalk",
            "  occluders: " + (", ".join(f"{n} {t}" for t, n in sorted(self.polygons.items())) or "none"),
        ]
        out += [
            f"  roadside camera {rsu.get('id')} ({rsu.get('corner')}, watching {rsu.get('watched_arm')}): "
            f"x {rsu.get('x')} m, y {rsu.get('y')} m, {rsu.get('height_m')} m high, "
            f"yaw {rsu.get('yaw_deg')} deg, pitch {rsu.get('pitch_deg')} deg down"
            for rsu in self.roadside_units
        ]
        return out


def _is_road(edge) -> bool:
    return edge.getFunction() == "" and any(lane.allows("passenger") for lane in edge.getLanes())


def summarise(site: Site) -> SiteSummary:
    info = json.loads(site.file("site.json").read_text(encoding="utf-8"))
    net = read_net(str(site.file("net.xml")), withInternal=True)
    junction = net.getNode(info["main_junction"])
    jx, jy = junction.getCoord()
    root = ET.parse(site.file("net.xml")).getroot()
    # The junction's signal programme: the tlLogic its incoming connections name (netconvert may give a
    # joined signal an id of its own, or several nodes one signal).
    incoming = {e.getID() for e in junction.getIncoming()}
    tl_ids = {c.get("tl") for c in root.iter("connection") if c.get("tl") and c.get("from") in incoming}
    logics = [tl for tl in root.iter("tlLogic") if tl.get("id") in tl_ids]
    phases = [float(p.get("duration")) for p in logics[0].iter("phase")] if logics else []
    crossings = {
        e.get("id"): e.get("crossingEdges").split()
        for e in root.iter("edge")
        if e.get("function") == "crossing" and e.get("id").startswith(f":{junction.getID()}_")
    }
    signalised = {c.get("to") for c in root.iter("connection") if c.get("to") in crossings and c.get("tl")}

    # The junction's arms: its legs (network.approaches.junction_legs) and the directions roads only leave
    # by; a road is on the arm nearest the bearing of its far end.
    def far_bearing_deg(edge, incoming: bool) -> float:
        return bearing_deg((jx, jy), edge.getShape()[0] if incoming else edge.getShape()[-1])

    arm_bearings = junction_arms(
        legs_at(net, junction), [far_bearing_deg(e, False) for e in junction.getOutgoing() if _is_road(e)]
    )

    def direction(edge, incoming: bool) -> str:
        bearing = far_bearing_deg(edge, incoming)
        return min(arm_bearings, key=lambda name: angle_between_deg(arm_bearings[name], bearing))

    arms: dict[str, Arm] = {}
    edge_dir: dict[str, str] = {}
    for incoming, edges in ((True, junction.getIncoming()), (False, junction.getOutgoing())):
        for edge in edges:
            if not _is_road(edge):
                continue
            d = direction(edge, incoming)
            edge_dir[edge.getID()] = d
            arm = arms.setdefault(d, Arm(d, [], 0, 0, 0))
            if edge.getName() and edge.getName() not in arm.names:
                arm.names.append(edge.getName())
            lanes = sum(lane.allows("passenger") for lane in edge.getLanes())
            if incoming:
                arm.lanes_in += lanes
            else:
                arm.lanes_out += lanes
    for crossing, crossed in crossings.items():
        dirs = {edge_dir[e] for e in crossed if e in edge_dir}
        if crossing in signalised and dirs:
            arms[sorted(dirs)[0]].crosswalks += 1

    roads = [e for e in net.getEdges() if _is_road(e)]
    polygons = Counter(
        p.get("type", "").split(".")[0] for p in ET.parse(site.file("poly.xml")).getroot().iter("poly")
    )
    return SiteSummary(
        name=site.name,
        main_junction=junction.getID(),
        junction_type=junction.getType(),
        cycle_s=sum(phases),
        phases=len(phases),
        arms=[arms[name] for name in arm_bearings if name in arms],
        crosswalks_signalised=len(signalised),
        road_edges=len(roads),
        road_length_m=sum(e.getLength() for e in roads),
        sidewalk_length_m=sum(
            e.getLength()
            for e in net.getEdges()
            if e.getFunction() == ""
            and e.getLane(0).allows("pedestrian")
            and not e.getLane(0).allows("passenger")
        ),
        polygons=polygons,
        traffic_lights=list(junction_lights(site.file("net.xml"), junction.getID())),
        roadside_units=info.get("roadside_units", [info["roadside_unit"]]),
    )


def site_files(site: Site) -> list[Path]:
    return [site.file(s) for s in ("net.xml", "poly.xml", "rsu.add.xml", "sumocfg", "site.json")]
