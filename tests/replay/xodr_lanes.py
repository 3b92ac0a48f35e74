"""A small OpenDRIVE reader for the tests: which lane of which road holds a point (x, y).

Written from the OpenDRIVE specification, independently of netconvert and of the exporter: reference
lines of `line`, `arc` and `paramPoly3` geometries (the kinds netconvert writes), sampled every
SAMPLE_M; lateral offsets from `laneOffset` and the lanes' `width` polynomials; t positive to the
left of the reference line, right lanes (negative ids) below the centre lane.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SAMPLE_M = 0.05


@dataclass(frozen=True)
class LaneHit:
    road_id: str
    lane_id: int
    lane_type: str
    #: Distance of the point from the lane's centre line, across the lane [m].
    off_centre_m: float
    width_m: float
    #: Direction of travel of the lane at the point (right lanes along the reference line), radians.
    heading_rad: float


def _poly(record: ET.Element, ds: float) -> float:
    a, b, c, d = (float(record.get(k, 0.0)) for k in "abcd")
    return a + b * ds + c * ds * ds + d * ds**3


def _at(records: list[ET.Element], s: float, key: str = "s") -> float:
    chosen = [r for r in records if float(r.get(key)) <= s + 1e-9]
    if not chosen:
        return 0.0
    record = chosen[-1]
    return _poly(record, s - float(record.get(key)))


def _geometry_samples(geometry: ET.Element) -> np.ndarray:
    """Rows (s, x, y, heading) along one planView geometry."""
    s0, x0, y0, hdg, length = (float(geometry.get(k)) for k in ("s", "x", "y", "hdg", "length"))
    n = max(2, int(math.ceil(length / SAMPLE_M)) + 1)
    ds = np.linspace(0.0, length, n)
    shape = geometry[0]
    if shape.tag == "line":
        u, v = ds, np.zeros_like(ds)
        du, dv = np.ones_like(ds), np.zeros_like(ds)
    elif shape.tag == "arc":
        k = float(shape.get("curvature"))
        if abs(k) < 1e-12:
            u, v, du, dv = ds, np.zeros_like(ds), np.ones_like(ds), np.zeros_like(ds)
        else:
            u, v = np.sin(k * ds) / k, (1 - np.cos(k * ds)) / k
            du, dv = np.cos(k * ds), np.sin(k * ds)
    elif shape.tag == "paramPoly3":
        c = {key: float(shape.get(key)) for key in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV")}
        p = ds / length if shape.get("pRange", "normalized") == "normalized" else ds
        u = c["aU"] + c["bU"] * p + c["cU"] * p**2 + c["dU"] * p**3
        v = c["aV"] + c["bV"] * p + c["cV"] * p**2 + c["dV"] * p**3
        du = c["bU"] + 2 * c["cU"] * p + 3 * c["dU"] * p**2
        dv = c["bV"] + 2 * c["cV"] * p + 3 * c["dV"] * p**2
    else:
        raise ValueError(f"geometry <{shape.tag}> is not read by this test helper")
    cos_h, sin_h = math.cos(hdg), math.sin(hdg)
    x = x0 + u * cos_h - v * sin_h
    y = y0 + u * sin_h + v * cos_h
    heading = hdg + np.arctan2(dv, du)
    return np.column_stack([s0 + ds, x, y, heading])


class OpenDrive:
    def __init__(self, path: Path) -> None:
        self.root = ET.parse(path).getroot()
        self.roads = []
        for road in self.root.iter("road"):
            samples = np.vstack([_geometry_samples(g) for g in road.find("planView").iter("geometry")])
            self.roads.append((road, samples))

    def header_offset_xy(self) -> tuple[float, float]:
        offset = self.root.find("header/offset")
        return float(offset.get("x")), float(offset.get("y"))

    def lanes_at(self, x: float, y: float) -> list[LaneHit]:
        """Every lane (of every road) whose band holds the point, nearest reference-line point first."""
        hits = []
        for road, samples in self.roads:
            d = np.hypot(samples[:, 1] - x, samples[:, 2] - y)
            i = int(np.argmin(d))
            s, rx, ry, heading = samples[i]
            if d[i] > 30.0:
                continue
            # Signed lateral offset, positive to the left of the reference line's direction.
            t = -(x - rx) * math.sin(heading) + (y - ry) * math.cos(heading)
            # The point must lie across the reference line, not beyond its ends.
            along = (x - rx) * math.cos(heading) + (y - ry) * math.sin(heading)
            if abs(along) > SAMPLE_M:
                continue
            lanes = road.find("lanes")
            centre_t = _at(list(lanes.iter("laneOffset")), s)
            section = [ls for ls in lanes.iter("laneSection") if float(ls.get("s")) <= s + 1e-9][-1]
            ds = s - float(section.get("s"))
            for side, sign in (("right", -1), ("left", 1)):
                group = section.find(side)
                if group is None:
                    continue
                border = centre_t
                for lane in sorted(group.iter("lane"), key=lambda e: abs(int(e.get("id")))):
                    width = _at(list(lane.iter("width")), ds, key="sOffset")
                    outer = border + sign * width
                    low, high = min(border, outer), max(border, outer)
                    if low <= t <= high:
                        lane_heading = heading if sign < 0 else heading + math.pi
                        hits.append(
                            LaneHit(
                                road.get("id"),
                                int(lane.get("id")),
                                lane.get("type"),
                                abs(t - (border + outer) / 2),
                                width,
                                lane_heading,
                            )
                        )
                    border = outer
        return hits
