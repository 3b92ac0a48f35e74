"""Hand-made OpenStreetMap data of one junction, for building sites whose signals netconvert joins.

OSM maps a junction's traffic signals as `highway=traffic_signals` nodes on each incoming road at its
stop line; the site build (pedsafe_sumo/network/netconvert.netccfg: `tls.guess-signals`, `tls.join`)
turns them into one traffic light whose id is netconvert's (`GS_<junction>`, `joinedS_...`), not the
junction's. `cross_osm` writes such a junction: four two-way arms of `lanes_per_direction` lanes each
way, a signal node `signal_m` before the centre on every arm, with `split_m` > 0 the north-south road as
two one-way carriageways `split_m` apart (two junctions, one light over both).
"""

from __future__ import annotations

import math
from pathlib import Path

#: Metres per degree of latitude (spherical Earth, as in the build's clip).
M_PER_DEG_LAT = 111_320.0


def _latlon(center: tuple[float, float], x_m: float, y_m: float) -> tuple[float, float]:
    lat0, lon0 = center
    return lat0 + y_m / M_PER_DEG_LAT, lon0 + x_m / (M_PER_DEG_LAT * math.cos(math.radians(lat0)))


def cross_osm(
    path: Path,
    center: tuple[float, float],
    arm_m: float = 180.0,
    signal_m: float = 15.0,
    lanes_per_direction: int = 2,
    split_m: float = 0.0,
    tags: dict[str, str] | None = None,
) -> Path:
    """Write the junction's OSM file; `tags` go on every way (e.g. {"driving_side": "left"})."""
    nodes: dict[str, tuple[float, float, bool]] = {}
    ways: list[tuple[list[str], dict[str, str]]] = []

    def node(name: str, x_m: float, y_m: float, signal: bool = False) -> str:
        nodes[name] = (x_m, y_m, signal)
        return name

    road = {"highway": "primary", "lanes": str(2 * lanes_per_direction), **(tags or {})}
    one_way = {"highway": "primary", "lanes": str(lanes_per_direction), "oneway": "yes", **(tags or {})}
    half = split_m / 2
    west_j = node("jw", -half, 0.0)
    east_j = node("je", half, 0.0) if split_m else west_j
    # East-west road, two-way, through both junctions.
    ways.append(([node("w", -arm_m, 0), node("sw", -half - signal_m, 0, True), west_j], road))
    ways.append(([east_j, node("se", half + signal_m, 0, True), node("e", arm_m, 0)], road))
    if split_m:
        ways.append(([west_j, east_j], road))
        # Right-hand traffic: the southbound carriageway is the western one.
        ways.append(([node("nw", -half, arm_m), node("snw", -half, signal_m, True), west_j,
                      node("sw_out", -half, -arm_m)], one_way))  # fmt: skip
        ways.append(([node("se_in", half, -arm_m), node("sse", half, -signal_m, True), east_j,
                      node("ne_out", half, arm_m)], one_way))  # fmt: skip
    else:
        ways.append(([node("n", 0, arm_m), node("sn", 0, signal_m, True), west_j], road))
        ways.append(([west_j, node("ss", 0, -signal_m, True), node("s", 0, -arm_m)], road))
    ids = {name: 1000 + i for i, name in enumerate(nodes)}
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="pedsafe_sumo tests">']
    for name, (x_m, y_m, signal) in nodes.items():
        lat, lon = _latlon(center, x_m, y_m)
        tag = '<tag k="highway" v="traffic_signals"/>' if signal else ""
        lines.append(f'  <node id="{ids[name]}" version="1" lat="{lat:.7f}" lon="{lon:.7f}">{tag}</node>')
    for index, (way_nodes, way_tags) in enumerate(ways):
        refs = "".join(f'<nd ref="{ids[n]}"/>' for n in way_nodes)
        tag_xml = "".join(f'<tag k="{k}" v="{v}"/>' for k, v in way_tags.items())
        lines.append(f'  <way id="{500 + index}" version="1">{refs}{tag_xml}</way>')
    lines.append("</osm>")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
