"""The baseline stack's planning geometry: where a tracked pedestrian will be against the ego's planned
path, which crosswalks that path crosses, and what the signal ahead asks of the ego.

Distances are along the planned path (reference.planned_path: the current lane, the junction's
internal lane(s), the lane beyond), lateral offsets square to it; the corridor is the path widened by
the ego's half width plus a margin on each side. Docs: docs/baseline_stack.md.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import OrderedDict, deque
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Any

import numpy as np

from pedsafe_sumo.control.agent import Crosswalk, EgoState, RoadMap, TrafficLightState
from pedsafe_sumo.control.kalman_tracker import Track
from pedsafe_sumo.control.path_kernels import first_ahead, first_in_corridor, project_points, widening_rows
from pedsafe_sumo.control.reference import PlannedPath, Segment

#: Spacing of the path samples used to find where the corridor meets a crosswalk [m].
_PATH_SAMPLE_M = 0.25
#: Half length of the straight path assumed when the observation has no route feed [m].
_STRAIGHT_REACH_M = 1000.0
#: Steps of the ego's own speed kept to look back to when a delivered signal state was measured (1 s).
_SPEED_HISTORY_STEPS = 20
#: SUMO's signal characters, by what they ask of an approaching vehicle.
RED_STATES = "rRu"  # red, and red-yellow (SUMO's 'u', shown before green): do not enter
YELLOW_STATES = "yY"
PERMISSIVE_GREEN = "g"  # green for a movement that must yield to conflicting streams (SUMO's minor link)


def straight_path(ego: EgoState) -> PlannedPath:
    """The path straight along the ego's heading (an observation without a route feed)."""
    ux, uy = math.cos(ego.yaw_rad), math.sin(ego.yaw_rad)
    start = Segment(ego.x_m - _STRAIGHT_REACH_M * ux, ego.y_m - _STRAIGHT_REACH_M * uy, ux, uy, 0.0, 0.0)
    segment = Segment(start.x_m, start.y_m, ux, uy, 0.0, 2 * _STRAIGHT_REACH_M)
    return PlannedPath((segment,), 1)


@dataclass(frozen=True)
class PathArrays:
    """A planned path as arrays (one row per segment) for projecting many points at once."""

    x: np.ndarray
    y: np.ndarray
    ux: np.ndarray
    uy: np.ndarray
    start_m: np.ndarray
    length_m: np.ndarray
    current_count: int

    @classmethod
    def of(cls, path: PlannedPath) -> PathArrays:
        segs = path.segments
        return cls(
            np.array([s.x_m for s in segs]),
            np.array([s.y_m for s in segs]),
            np.array([s.ux for s in segs]),
            np.array([s.uy for s in segs]),
            np.array([s.start_m for s in segs]),
            np.array([s.length_m for s in segs]),
            path.current_count,
        )

    @property
    def end_m(self) -> float:
        return float(self.start_m[-1] + self.length_m[-1])

    def project(self, px: Any, py: Any, first: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Distance along the path and signed lateral offset (positive left) of points, against the
        segments from `first` on: the nearest one, the first extended backwards without end and the
        last forwards. Compiled (control/path_kernels.py): the same bits as `project_numpy`."""
        px, py = np.asarray(px, dtype=float), np.asarray(py, dtype=float)
        if px.ndim == 0:  # one point, as floats
            px, py = px.reshape(1), py.reshape(1)
        x, y, ux, uy, low, high, start = self._segment_rows(first)
        return project_points(px, py, x, y, ux, uy, low, high, start)

    def project_numpy(self, px: Any, py: Any, first: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """`project` in numpy (the reference the compiled form is checked against)."""
        px, py = np.atleast_1d(px), np.atleast_1d(py)
        x, y, ux, uy, neg_uy, low, high, start = self._from_segment(first)
        rx = px[:, None] - x
        ry = py[:, None] - y
        along = rx * ux + ry * uy
        clipped = np.minimum(np.maximum(along, low), high)
        lat = rx * neg_uy + ry * ux  # -rx * uy + ry * ux: the same products, negation being exact
        off = np.hypot(along - clipped, lat)
        best = np.argmin(off, axis=1)
        rows = np.arange(px.shape[0])
        s = start[best] + clipped[rows, best]
        side = np.sign(lat[rows, best])
        side[side == 0] = 1.0
        return s, side * off[rows, best]

    @cached_property
    def _segments_from(self) -> dict[int, tuple[np.ndarray, ...]]:
        return {}

    def _from_segment(self, first: int) -> tuple[np.ndarray, ...]:
        """The segments from `first` on as rows to broadcast against points (x, y, ux, uy, -uy), the
        bounds of the distance along each (the first open backwards, the last forwards), their starts:
        kept per `first`, the projection running several times a step."""
        kept = self._segments_from.get(first)
        if kept is None:
            k = slice(first, None)
            low = np.zeros_like(self.length_m[k])
            high = self.length_m[k].copy()
            low[0] = -np.inf
            high[-1] = np.inf
            rows = (self.x[k], self.y[k], self.ux[k], self.uy[k], -self.uy[k], low, high)
            kept = (*(row[None, :] for row in rows), self.start_m[k])
            self._segments_from[first] = kept
        return kept

    def _segment_rows(self, first: int) -> tuple[np.ndarray, ...]:
        """The segments from `first` on (x, y, ux, uy, the bounds of the distance along each, their
        starts), contiguous for the compiled projection: kept per `first`."""
        kept = self._segment_rows_from.get(first)
        if kept is None:
            x, y, ux, uy, _, low, high, start = self._from_segment(first)
            kept = tuple(np.ascontiguousarray(row.reshape(-1)) for row in (x, y, ux, uy, low, high, start))
            self._segment_rows_from[first] = kept
        return kept

    @cached_property
    def _segment_rows_from(self) -> dict[int, tuple[np.ndarray, ...]]:
        return {}

    @cached_property
    def _segment_floats(self) -> tuple[list[float], ...]:
        # Python floats for the per-step loops over segments: the same values, without numpy scalars.
        return tuple(a.tolist() for a in (self.x, self.y, self.ux, self.uy, self.start_m, self.length_m))

    @cached_property
    def _starts_m(self) -> list[float]:
        # Python floats: a lookup per predicted position, where numpy's per-call overhead dominates.
        return self.start_m.tolist()

    @cached_property
    def _normals(self) -> list[tuple[float, float]]:
        return [(-uy, ux) for ux, uy in zip(self.ux.tolist(), self.uy.tolist())]

    def segment_at(self, s_m: float) -> int:
        """The segment that `s_m` falls on: the last one starting at or before it (the first before the
        path's start)."""
        starts = self._starts_m
        return min(max(bisect_right(starts, s_m) - 1, 0), len(starts) - 1)

    def point_at(self, s_m: float) -> tuple[float, float]:
        k = self.segment_at(s_m)
        along = s_m - self.start_m[k]
        return float(self.x[k] + along * self.ux[k]), float(self.y[k] + along * self.uy[k])

    def normal_at(self, s_m: float) -> tuple[float, float]:
        """Unit vector square to the path (to its left) at distance `s_m`."""
        return self._normals[self.segment_at(s_m)]

    def normals_at(self, s_m: np.ndarray) -> np.ndarray:
        """normal_at for several distances: rows (nx, ny)."""
        # The last segment starting at or before each distance (searchsorted's index less one is at
        # most the last segment's), the first before the path's start.
        k = np.searchsorted(self.start_m, s_m, side="right") - 1
        np.maximum(k, 0, out=k)
        return self._normal_rows[k]

    @cached_property
    def _normal_rows(self) -> np.ndarray:
        normals = np.empty((len(self.ux), 2))
        normals[:, 0], normals[:, 1] = -self.uy, self.ux
        return normals

    def ego_position_m(self, ego: EgoState) -> tuple[float, int]:
        """The ego centre's distance along the path (projected onto its current lane) and the segment
        it is on."""
        best = None
        x, y, ux, uy, start, length = self._segment_floats
        for k in range(self.current_count):
            along = (ego.x_m - x[k]) * ux[k] + (ego.y_m - y[k]) * uy[k]
            along = min(along, length[k]) if k == 0 else min(max(along, 0.0), length[k])
            off = math.hypot(ego.x_m - x[k] - along * ux[k], ego.y_m - y[k] - along * uy[k])
            if best is None or off < best[0] - 1e-9:
                best = (off, k, float(start[k] + along))
        assert best is not None
        return best[2], best[1]


@dataclass(frozen=True)
class Threat:
    ped_id: str
    gap_m: float  # from the ego's front to where it must stop short of (the pedestrian, a crosswalk) [m]
    time_s: float  # when the pedestrian is first inside the corridor [s from now]; 0 for a crosswalk
    reason: str  # "path" (predicted into the corridor) or "crosswalk" (yielding at a crosswalk)


@lru_cache(maxsize=16)
def _sample_times(horizon_s: float, sample_s: float) -> np.ndarray:
    """The prediction's times [s from now] (read-only: the same every step)."""
    times = np.arange(0.0, horizon_s + 1e-9, sample_s)
    times.setflags(write=False)
    return times


def path_threat(
    track: Track,
    ego: EgoState,
    path: PathArrays,
    first: int,
    ego_s_m: float,
    horizon_s: float,
    half_width_m: float,
    sigma_factor: float,
    sample_s: float,
) -> Threat | None:
    """Whether the pedestrian is in the corridor, or is predicted into it within the horizon before the
    ego (at its current speed) has passed. The prediction moves the track at its velocity when that is
    told apart from standing (Track.moving), and widens the corridor by `sigma_factor` standard
    deviations of the predicted position square to the path; a standing track stays where it is."""
    times = _sample_times(horizon_s, sample_s)
    if track.moving:
        px, py = track.x_m + track.vx_mps * times, track.y_m + track.vy_mps * times
    else:
        times = times[:1]
        px, py = np.array([track.x_m]), np.array([track.y_m])
    s_arr, lat_arr = path.project(px, py, first)
    front_offset = ego.length_m / 2
    # Compiled scans (control/path_kernels.py), the same float operations in the same order as a loop
    # over the samples in Python: the standard deviations are worked out together, from the first
    # sample the ego has not passed on.
    start = first_ahead(s_arr, times, ego_s_m, ego.speed_mps, front_offset, ego.length_m)
    if start < 0:
        return None
    sigmas = (
        track.position_sigmas_of_rows(widening_rows(s_arr, times, start, path.start_m, path.ux, path.uy))
        if track.moving
        else _NO_SIGMAS
    )
    i = first_in_corridor(
        s_arr, lat_arr, times, start, sigmas, sigma_factor,
        ego_s_m, ego.speed_mps, front_offset, ego.length_m, half_width_m,
    )  # fmt: skip
    if i < 0:
        return None
    gap = (float(s_arr[i]) - ego_s_m) - front_offset
    return Threat(track.ped_id, max(gap, 0.0), float(times[i]), "path")


_NO_SIGMAS = np.zeros(0)


def point_in_polygon(x: float, y: float, polygon) -> bool:
    inside = False
    n = len(polygon)
    for i in range(n):
        (ax, ay), (bx, by) = polygon[i], polygon[(i + 1) % n]
        if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
            inside = not inside
    return inside


def distance_to_polygon_m(x: float, y: float, polygon) -> float:
    """0 inside, else the distance to the nearest edge."""
    if point_in_polygon(x, y, polygon):
        return 0.0
    best = math.inf
    n = len(polygon)
    for i in range(n):
        (ax, ay), (bx, by) = polygon[i], polygon[(i + 1) % n]
        dx, dy = bx - ax, by - ay
        t = ((x - ax) * dx + (y - ay) * dy) / max(dx * dx + dy * dy, 1e-12)
        t = min(max(t, 0.0), 1.0)
        best = min(best, math.hypot(x - ax - t * dx, y - ay - t * dy))
    return best


@dataclass(frozen=True)
class CrosswalkSpan:
    """A crosswalk the corridor crosses, and the stretch of the path inside it [m along the path]."""

    crosswalk: Crosswalk
    enter_m: float
    leave_m: float


#: Crosswalk spans already worked out, by (path, crosswalks, half width): a stack is made afresh for
#: every episode, and the episodes of a batch drive the same few paths on the same map again and again
#: (about 30 paths an episode at about 8 ms each: a quarter of an approach-staged episode's CPU).
_SPANS_CACHE: OrderedDict[tuple, tuple[CrosswalkSpan, ...]] = OrderedDict()
SPANS_CACHE_SIZE = 512


def crosswalk_spans(path: PathArrays, road_map: RoadMap, half_width_m: float) -> list[CrosswalkSpan]:
    """The crosswalks the corridor meets (a path sample within the half width of the polygon), ordered
    along the path. The same arguments give the same spans: kept for SPANS_CACHE_SIZE paths."""
    key = (
        path.x.tobytes(), path.y.tobytes(), path.ux.tobytes(), path.uy.tobytes(), path.start_m.tobytes(),
        path.length_m.tobytes(), road_map.crosswalks, half_width_m,
    )  # fmt: skip
    spans = _SPANS_CACHE.get(key)
    if spans is None:
        spans = _crosswalk_spans(path, road_map, half_width_m)
        _SPANS_CACHE[key] = spans
        if len(_SPANS_CACHE) > SPANS_CACHE_SIZE:
            _SPANS_CACHE.popitem(last=False)
    return list(spans)


def _crosswalk_spans(path: PathArrays, road_map: RoadMap, half_width_m: float) -> tuple[CrosswalkSpan, ...]:
    samples = np.arange(0.0, path.end_m, _PATH_SAMPLE_M)
    points = [path.point_at(float(s)) for s in samples]
    spans = []
    for crosswalk in road_map.crosswalks:
        inside = [
            s
            for s, (x, y) in zip(samples, points)
            if distance_to_polygon_m(x, y, crosswalk.polygon_xy_m) <= half_width_m
        ]
        if inside:
            spans.append(CrosswalkSpan(crosswalk, float(min(inside)), float(max(inside))))
    return tuple(sorted(spans, key=lambda span: span.enter_m))


@dataclass(frozen=True)
class SignalDemand:
    """What the signal ahead asks: the speed the ego may have now (inf: no limit) and why."""

    speed_cap_mps: float
    reason: str  # "", "red", "yellow_stop", "yellow_go", "committed" (red after a yellow gone through)
    #: Distance the ego is to stop within [m] (its stopping profile is sqrt(2 a room)); inf: none.
    room_m: float = math.inf


def speed_under_signal(
    target_mps: float, speed_mps: float, cap_mps: float, room_m: float, max_decel_mps2: float, dt_s: float
) -> float:
    """The speed to command once a signal's speed cap is applied to `target_mps`: the cap itself when
    the ego is at or below it; above it (a red seen late, a yellow decided late, the last decimetre),
    the deceleration that stops in the `room_m` left, at most `max_decel_mps2`, the hardest once the
    room is nearly gone."""
    if target_mps <= cap_mps:
        return target_mps
    if speed_mps <= cap_mps:
        return cap_mps
    decel = min(max_decel_mps2, speed_mps * speed_mps / (2 * room_m)) if room_m > 0.1 else max_decel_mps2
    return min(target_mps, max(0.0, speed_mps - decel * dt_s))


class SignalPolicy:
    """Stop for red; at a yellow's onset, stop when the ego can do so before the stop line at the
    comfortable deceleration, else go on through (the decision holds until the signal shows green
    again)."""

    def __init__(self, comfortable_decel_mps2: float, max_decel_mps2: float, stop_short_m: float) -> None:
        self.comfortable_decel_mps2 = comfortable_decel_mps2
        self.max_decel_mps2 = max_decel_mps2
        self.stop_short_m = stop_short_m
        self._yellow: dict[str, str] = {}  # tls id -> "stop" / "go", decided at the yellow's onset
        #: (time, speed) of the last steps: where the ego was, and how fast, when a delivered state was
        #: measured (a V2I state is `latency_s` old).
        self._speeds: deque[tuple[float, float]] = deque(maxlen=_SPEED_HISTORY_STEPS)

    def demand(self, light: TrafficLightState | None, speed_mps: float, time_s: float) -> SignalDemand:
        self._speeds.append((time_s, speed_mps))
        if light is None or not math.isfinite(light.distance_m) or light.distance_m < 0:
            return SignalDemand(math.inf, "")
        state = light.state
        decided = self._yellow.get(light.tls_id)
        if state not in YELLOW_STATES and state not in RED_STATES:
            self._yellow.pop(light.tls_id, None)
            return SignalDemand(math.inf, "")
        if decided is None:
            # Where the ego was, and its speed, when the state it reads was measured (V2I: latency
            # earlier): the speed of each step since then is the speed it drove that step at.
            speed_then, distance_then_m = speed_mps, light.distance_m
            history = list(self._speeds)
            for k, (t_k, v_k) in enumerate(history):
                if t_k > light.measured_at_s + 1e-9 and k > 0:
                    distance_then_m += v_k * (t_k - history[k - 1][0])
                elif t_k <= light.measured_at_s + 1e-9:
                    speed_then = v_k
            stopping_m = speed_then * speed_then / (2 * self.comfortable_decel_mps2)
            if state in YELLOW_STATES:
                decided = "stop" if stopping_m <= distance_then_m + 1e-9 else "go"
            else:  # red at first sight: stop if the hardest braking can
                can = speed_mps * speed_mps / (2 * self.max_decel_mps2) <= light.distance_m + 1e-9
                decided = "stop" if can else "go"
            self._yellow[light.tls_id] = decided
        if decided == "go":
            return SignalDemand(math.inf, "yellow_go" if state in YELLOW_STATES else "committed")
        # Stop `stop_short_m` before the line: the comfortable profile sqrt(2 a room) down to it.
        room_m = max(light.distance_m - self.stop_short_m, 0.0)
        cap = math.sqrt(2 * self.comfortable_decel_mps2 * room_m)
        return SignalDemand(cap, "red" if state in RED_STATES else "yellow_stop", room_m)
