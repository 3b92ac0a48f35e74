"""The lane and the pedestrian crossing at a point of a SUMO network (sumolib, internal lanes included)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import sumolib

from pedsafe_sumo.conflicts.meeting import MeetingRules
from pedsafe_sumo.sumo_net import read_net

#: Search radius around the point for lanes, m: wider than any lane, so a point on a lane finds it.
SEARCH_RADIUS_M = 5.0
#: Points whose lane is remembered (exact coordinates); the memory is emptied when full. Stated
#: assumption: a few thousand waiting places cover a district, at some 200 bytes each.
FOUND_POINTS = 4096


class NetError(ValueError):
    """The --net file cannot be read."""


class PlaceFinder:
    """`finder(x_m, y_m)` -> (lane_id, crossing_id): the nearest lane (crossings and walking areas
    included) within SEARCH_RADIUS_M, and the crossing edge when that lane lies on one ("" if none)."""

    def __init__(self, net_path: str | Path) -> None:
        path = Path(net_path)
        if not path.is_file():
            raise NetError(f"network file not found: {path}")
        try:
            self.net = read_net(str(path), withInternal=True, withPedestrianConnections=True)
        except Exception as exc:  # sumolib raises whatever its SAX parser raises on a broken file
            raise NetError(f"cannot read network {path}: {exc}") from None
        if not self.net.getEdges():
            raise NetError(f"network {path} has no edges")
        self.meeting = MeetingRules(self.net)
        self._found: dict[tuple[float, float], tuple[str, str]] = {}
        # Without the rtree package, sumolib's getNeighboringLanes falls back to a brute-force search
        # that first appends every lane of the net to a list it keeps (Net._allLanes) on every call:
        # about 1 kB per interaction on Xueqing (135 lanes), 47 MB over the 43,330 interactions of an
        # hour of the site's demand (BENCHMARKS.md). The same search, over lanes listed once, instead.
        self._lanes: list | None = None
        try:
            import rtree  # noqa: F401 - only whether sumolib can build its index
        except ImportError:
            lanes = [lane for edge in self.net.getEdges(withInternal=True) for lane in edge.getLanes()]
            shapes = [lane.getShape(True) for lane in lanes]
            self._lanes = list(zip(lanes, shapes))
            # Bounding boxes widened by the search radius: a lane outside cannot be within it.
            self._boxes = np.array(
                [
                    (
                        min(p[0] for p in shape) - SEARCH_RADIUS_M,
                        min(p[1] for p in shape) - SEARCH_RADIUS_M,
                        max(p[0] for p in shape) + SEARCH_RADIUS_M,
                        max(p[1] for p in shape) + SEARCH_RADIUS_M,
                    )
                    for shape in shapes
                ]
            )

    def _neighbouring_lanes(self, x_m: float, y_m: float) -> list:
        """(lane, distance) of the lanes closer than SEARCH_RADIUS_M, as sumolib's getNeighboringLanes
        (internal lanes and their junction-including shapes) gives them."""
        if self._lanes is None:
            return self.net.getNeighboringLanes(x_m, y_m, SEARCH_RADIUS_M, includeJunctions=True)
        b = self._boxes
        near = np.flatnonzero((b[:, 0] <= x_m) & (x_m <= b[:, 2]) & (b[:, 1] <= y_m) & (y_m <= b[:, 3]))
        found = []
        for k in near.tolist():
            lane, shape = self._lanes[k]
            d = sumolib.geomhelper.distancePointToPolygon((x_m, y_m), shape)
            if d < SEARCH_RADIUS_M:
                found.append((lane, d))
        return found

    def __call__(self, x_m: float, y_m: float) -> tuple[str, str]:
        if not (math.isfinite(x_m) and math.isfinite(y_m)):
            return "", ""
        # A person waiting at a kerb meets vehicle after vehicle at the same point: looked up once.
        known = self._found.get((x_m, y_m))
        if known is not None:
            return known
        if len(self._found) >= FOUND_POINTS:
            self._found.clear()
        found = self._find(x_m, y_m)
        self._found[(x_m, y_m)] = found
        return found

    def _find(self, x_m: float, y_m: float) -> tuple[str, str]:
        lanes = self._neighbouring_lanes(x_m, y_m)
        if not lanes:
            return "", ""
        lane, _ = min(lanes, key=lambda pair: (pair[1], pair[0].getID()))
        edge = lane.getEdge()
        return lane.getID(), edge.getID() if edge.getFunction() == "crossing" else ""
