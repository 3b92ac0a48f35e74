"""The static road map an AD stack reads: lanes (centrelines, widths, who may drive them), how route
edges connect through junctions, crosswalk polygons and signalised stop lines.

Read once per network file from the .net.xml (ElementTree; no SUMO process), and kept for the worker's
life. World frame: SUMO network x east, y north, metres.
"""

from __future__ import annotations

import functools
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pedsafe_sumo.control.agent import Crosswalk, LaneCentreline, RoadMap, StopLine

#: SUMO's lane width when the network does not give one [m] (netconvert default, --default.lanewidth).
SUMO_DEFAULT_LANE_WIDTH_M = 3.2
#: The vehicle class of the ego (SUMO's DEFAULT_VEHTYPE is a passenger car).
EGO_VCLASS = "passenger"


def _shape(text: str) -> tuple[tuple[float, float], ...]:
    return tuple((float(x), float(y)) for x, y in (p.split(",")[:2] for p in text.split()))


def _allows(lane: ET.Element, vclass: str) -> bool:
    allow, disallow = lane.get("allow"), lane.get("disallow")
    if allow is not None:
        classes = allow.split()
        return vclass in classes or "all" in classes
    if disallow is not None:
        classes = disallow.split()
        return vclass not in classes and "all" not in classes
    return True


@dataclass(frozen=True)
class NetMap:
    """Lanes by id, the lane ids of each edge by index, internal 'via' lanes between consecutive edges
    ((from edge, to edge) -> via lane ids), and the RoadMap of crosswalks and stop lines."""

    lanes: dict[str, LaneCentreline]
    edge_lanes: dict[str, tuple[str, ...]]
    vias: dict[tuple[str, str], tuple[str, ...]]
    road_map: RoadMap

    def on_road(self, x_m: float, y_m: float, lane_ids) -> bool:
        """Whether the point lies on one of the drivable lanes (within half the lane width of its
        centreline)."""
        for lane_id in lane_ids:
            lane = self.lanes.get(lane_id)
            if lane is None or not lane.drivable:
                continue
            if _distance_to_polyline(x_m, y_m, lane.shape_xy_m) <= lane.width_m / 2:
                return True
        return False


def _distance_to_polyline(x: float, y: float, shape) -> float:
    pts = np.asarray(shape, dtype=float)
    if pts.shape[0] == 1:
        return float(math.hypot(x - pts[0, 0], y - pts[0, 1]))
    a, b = pts[:-1], pts[1:]
    ab = b - a
    denom = np.maximum((ab * ab).sum(axis=1), 1e-12)
    t = np.clip(((x - a[:, 0]) * ab[:, 0] + (y - a[:, 1]) * ab[:, 1]) / denom, 0.0, 1.0)
    px, py = a[:, 0] + t * ab[:, 0], a[:, 1] + t * ab[:, 1]
    return float(np.min(np.hypot(x - px, y - py)))


def _offset_segment(p0, p1, offset_m):
    dx, dy = p1[0] - p0[0], p1[1] - p0[1]
    norm = math.hypot(dx, dy) or 1.0
    nx, ny = -dy / norm * offset_m, dx / norm * offset_m
    return (p0[0] + nx, p0[1] + ny), (p1[0] + nx, p1[1] + ny)


@functools.lru_cache(maxsize=8)
def load_net_map(net_file: str | Path) -> NetMap:
    """Parse the network once (cached per path)."""
    root = ET.parse(str(net_file)).getroot()
    lanes: dict[str, LaneCentreline] = {}
    edge_lanes: dict[str, tuple[str, ...]] = {}
    crossing_ids: list[tuple[str, LaneCentreline]] = []
    for edge in root.iter("edge"):
        eid = edge.get("id")
        function = edge.get("function", "normal")
        ids = []
        for lane in edge.iter("lane"):
            c = LaneCentreline(
                lane_id=lane.get("id"),
                edge_id=eid,
                index=int(lane.get("index")),
                width_m=float(lane.get("width", SUMO_DEFAULT_LANE_WIDTH_M)),
                speed_limit_mps=float(lane.get("speed")),
                shape_xy_m=_shape(lane.get("shape")),
                drivable=function in ("normal", "internal") and _allows(lane, EGO_VCLASS),
            )
            lanes[c.lane_id] = c
            ids.append(c.lane_id)
        edge_lanes[eid] = tuple(ids)
        if function == "crossing" and ids:
            crossing_ids.append((eid, lanes[ids[0]]))
    edge_to_junction = {e.get("id"): e.get("to") for e in root.iter("edge") if e.get("to")}
    vias: dict[tuple[str, str], list[str]] = {}
    crossing_tls: dict[str, str] = {}
    stop_lines: dict[str, StopLine] = {}
    for con in root.iter("connection"):
        src, dst, tl = con.get("from"), con.get("to"), con.get("tl", "")
        via = con.get("via")
        if via and not src.startswith(":"):
            vias.setdefault((src, dst), []).append(via)
        if dst.startswith(":") and tl:
            crossing_tls.setdefault(dst, tl)
        if tl and not src.startswith(":"):
            lane_id = f"{src}_{con.get('fromLane')}"
            approach_lane = lanes.get(lane_id)
            if (
                approach_lane is not None
                and approach_lane.drivable
                and lane_id not in stop_lines
                and len(approach_lane.shape_xy_m) >= 2
            ):
                end, before = approach_lane.shape_xy_m[-1], approach_lane.shape_xy_m[-2]
                dx, dy = end[0] - before[0], end[1] - before[1]
                norm = math.hypot(dx, dy) or 1.0
                half_width = approach_lane.width_m / 2
                nx, ny = -dy / norm * half_width, dx / norm * half_width
                stop_lines[lane_id] = StopLine(
                    lane_id, edge_to_junction.get(src, ""), (end[0] + nx, end[1] + ny),
                    (end[0] - nx, end[1] - ny), tl,
                )  # fmt: skip
    crosswalks = []
    for eid, crossing in crossing_ids:
        pts = crossing.shape_xy_m
        left = _offset_segment(pts[0], pts[-1], crossing.width_m / 2)
        right = _offset_segment(pts[0], pts[-1], -crossing.width_m / 2)
        polygon = (left[0], left[1], right[1], right[0])
        crosswalks.append(Crosswalk(eid, polygon, crossing_tls.get(eid, "")))
    road_map = RoadMap(tuple(crosswalks), tuple(stop_lines.values()))
    return NetMap(lanes, edge_lanes, {k: tuple(v) for k, v in vias.items()}, road_map)
