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
#: Points looked up together by `PlaceFinder.many`: a points x lanes table of a few MB at most (Xueqing:
#: 135 lanes), and the distances of each point to the segments of the lanes near it only.
POINTS_AT_ONCE = 512


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
            # Every lane's segments, lane after lane: the distances of one lookup in a few numpy calls
            # (a net with a lane of one point, which sumolib measures as INVALID_DISTANCE: lane by lane).
            self._seg_lane: np.ndarray | None = None
            if all(len(shape) >= 2 for shape in shapes):
                self._segments(shapes)

    def _segments(self, shapes: list) -> None:
        starts, ends, owner = [], [], []
        for k, shape in enumerate(shapes):
            points = [(float(p[0]), float(p[1])) for p in shape]
            starts += points[:-1]
            ends += points[1:]
            owner += [k] * (len(points) - 1)
        self._seg_start = np.array(starts, dtype=float).reshape(-1, 2)
        self._seg_end = np.array(ends, dtype=float).reshape(-1, 2)
        self._seg_lane = np.array(owner, dtype=int)
        # each lane's place in id order
        ids = [lane.getID() for lane, _ in self._lanes or []]
        self._id_rank = np.argsort(np.argsort(np.array(ids, dtype=object), kind="stable"), kind="stable")

    def _neighbouring_lanes(self, x_m: float, y_m: float) -> list:
        """(lane, distance) of the lanes closer than SEARCH_RADIUS_M, as sumolib's getNeighboringLanes
        (internal lanes and their junction-including shapes) gives them."""
        if self._lanes is None:
            return self.net.getNeighboringLanes(x_m, y_m, SEARCH_RADIUS_M, includeJunctions=True)
        b = self._boxes
        in_box = (b[:, 0] <= x_m) & (x_m <= b[:, 2]) & (b[:, 1] <= y_m) & (y_m <= b[:, 3])
        found = []
        if self._seg_lane is None:
            for k in np.flatnonzero(in_box).tolist():
                lane, shape = self._lanes[k]
                d = sumolib.geomhelper.distancePointToPolygon((x_m, y_m), shape)
                if d < SEARCH_RADIUS_M:
                    found.append((lane, d))
            return found
        segments = np.flatnonzero(in_box[self._seg_lane])
        if segments.size == 0:
            return found
        distance = _point_to_segments_m(x_m, y_m, self._seg_start[segments], self._seg_end[segments])
        lane_of = self._seg_lane[segments]
        first = np.flatnonzero(np.r_[True, lane_of[1:] != lane_of[:-1]])
        # a lane's distance: the least over its segments (sumolib's distancePointToPolygon)
        for k, d in zip(lane_of[first].tolist(), np.minimum.reduceat(distance, first).tolist()):
            if d < SEARCH_RADIUS_M:
                found.append((self._lanes[k][0], d))
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

    def many(self, x_m: np.ndarray, y_m: np.ndarray) -> list[tuple[str, str]]:
        """`finder(x, y)` of many points: the distances of all of them to the segments of the lanes near
        them in a few numpy calls (POINTS_AT_ONCE points at a time), element for element the floats of
        the lookup of one point."""
        xs, ys = np.asarray(x_m, dtype=float).tolist(), np.asarray(y_m, dtype=float).tolist()
        found: list[tuple[str, str] | None] = [self._found.get((x, y)) for x, y in zip(xs, ys)]
        if self._lanes is None or self._seg_lane is None:  # sumolib's own search, or a lane of one point
            return [known if known is not None else self(x, y) for known, x, y in zip(found, xs, ys)]
        todo = [
            k
            for k, known in enumerate(found)
            if known is None and math.isfinite(xs[k]) and math.isfinite(ys[k])
        ]
        for first in range(0, len(todo), POINTS_AT_ONCE):
            part = todo[first : first + POINTS_AT_ONCE]
            px, py = np.array([xs[k] for k in part]), np.array([ys[k] for k in part])
            for k, answer in zip(part, self._nearest_lanes(px, py)):
                if len(self._found) >= FOUND_POINTS:
                    self._found.clear()
                found[k] = self._found[(xs[k], ys[k])] = answer
        return [known if known is not None else ("", "") for known in found]

    def _nearest_lanes(self, px: np.ndarray, py: np.ndarray) -> list[tuple[str, str]]:
        """(lane, crossing) of each point from its distances to the lanes near it (`_neighbouring_lanes` and
        `_find` for many points: a lane outside a point's widened box is left out as there)."""
        x, y = px[:, None], py[:, None]
        b = self._boxes
        in_box = (b[:, 0] <= x) & (x <= b[:, 2]) & (b[:, 1] <= y) & (y <= b[:, 3])  # points x lanes
        # The distances of each point to the segments of the lanes whose widened box holds it, and to no
        # others (a point has a few such lanes among a net's hundreds): (point, segment) pairs by point,
        # then segment, so each lane's segments are one run within a point's.
        seg_lane = self._seg_lane
        assert seg_lane is not None  # `many` asks only a net whose every lane has segments
        point, segment = np.nonzero(in_box[:, seg_lane])
        lane_distance = np.full(in_box.shape, np.inf)
        if point.size:
            distance = _point_to_segments_m(
                px[point], py[point], self._seg_start[segment], self._seg_end[segment]
            )
            lane = seg_lane[segment]
            run = np.flatnonzero(np.r_[True, (point[1:] != point[:-1]) | (lane[1:] != lane[:-1])])
            # a lane's distance: the least over its segments (sumolib's distancePointToPolygon)
            lane_distance[point[run], lane[run]] = np.minimum.reduceat(distance, run)
        lane_distance = np.where(lane_distance < SEARCH_RADIUS_M, lane_distance, np.inf)
        nearest = lane_distance.min(axis=1, keepdims=True)
        # the nearest lane, ties to the smallest id: the least id rank among the lanes at that distance
        rank = np.where(lane_distance == nearest, self._id_rank, len(self._id_rank)).argmin(axis=1)
        answers = []
        lanes = self._lanes or []
        for k, d in zip(rank.tolist(), nearest[:, 0].tolist()):
            if d == math.inf:
                answers.append(("", ""))
                continue
            lane = lanes[k][0]
            edge = lane.getEdge()
            answers.append((lane.getID(), edge.getID() if edge.getFunction() == "crossing" else ""))
        return answers

    def _find(self, x_m: float, y_m: float) -> tuple[str, str]:
        lanes = self._neighbouring_lanes(x_m, y_m)
        if not lanes:
            return "", ""
        lane, _ = min(lanes, key=lambda pair: (pair[1], pair[0].getID()))
        edge = lane.getEdge()
        return lane.getID(), edge.getID() if edge.getFunction() == "crossing" else ""


def _point_to_segments_m(
    x_m: float | np.ndarray, y_m: float | np.ndarray, start: np.ndarray, end: np.ndarray
) -> np.ndarray:
    """Distance from the point to each segment start[i] -> end[i], m: sumolib's
    `geomhelper.distancePointToLine` (not perpendicular) operation for operation, so the same floats. With
    arrays of points as long as the segments' (point i to segment i), each element the same float."""
    sx, sy, ex, ey = start[:, 0], start[:, 1], end[:, 0], end[:, 1]
    length = np.sqrt((sx - ex) * (sx - ex) + (sy - ey) * (sy - ey))
    u = (x_m - sx) * (ex - sx) + (y_m - sy) * (ey - sy)
    outside = (length == 0.0) | (u < 0.0) | (u > length * length)
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = np.where(outside, np.where(u < 0.0, 0.0, length), u / length)
        fraction = offset / length
    ix, iy = sx + fraction * (ex - sx), sy + fraction * (ey - sy)
    to_start = np.sqrt((x_m - sx) * (x_m - sx) + (y_m - sy) * (y_m - sy))
    return np.where(offset == 0.0, to_start, np.sqrt((x_m - ix) * (x_m - ix) + (y_m - iy) * (y_m - iy)))
