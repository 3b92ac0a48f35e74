"""The reference AD stack: cruise, and brake for a perceived pedestrian whose path meets the ego's.

Behaviour: cruise at the episode's initial speed. When a perceived pedestrian, moved ahead
at constant velocity, enters the ego's corridor (its width plus a margin, along the path it will
drive) within the prediction horizon, the stack brakes after its system reaction time, with the
deceleration that stops it short of the pedestrian, at most `max_decel_mps2`. Once no pedestrian has
threatened for `clear_hold_s`, it accelerates back to the cruise speed.

The corridor follows the ego's planned path: the centrelines of its current lane, the junction's
internal lane(s) of its connection and the lane beyond, from the `route` feed (docs/ad_interface.md),
with the gap measured along it. On a straight path this is the straight corridor ahead along the ego's
heading; in a turn the straight corridor would look past the crosswalk the ego turns across (right_turn
and the Euro NCAP CPTA cells) and off a bending approach (CPLA). Without a route feed (an observation
built by hand) the corridor is straight ahead.

Its tracker estimates each pedestrian's velocity by a least-squares line through the positions of
the last `track_window_s` (a one-step difference of V2I positions with 0.2 m noise would be off by
several m/s). Signals and other vehicles are not its business: the scenarios put nothing else in its
path.

It has no object permanence: a pedestrian not detected this step is not in its world, so a gap in the
detections longer than `clear_hold_s` drops the threat, and the next detection starts the reaction time
over. That gap is how most of V2I's jaywalking collisions happen (the roadside camera loses the pedestrian
behind the queue; docs/engine.md); examples/tracking_stack.py is the same stack with a memory.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

from pedsafe_sumo.control.agent import KNOWN_SENSORS, Agent, Command, Observation, RouteAhead

#: Defaults of the reference stack; each can be overridden through the episode config (the
#: parameter file's [algorithm] section carries reaction_time_s and max_decel_mps2).
REACTION_TIME_S = 0.4  # system reaction time between first perceiving a threat and braking [s]
MAX_DECEL_MPS2 = 6.0  # hardest braking the stack commands [m/s2]
HORIZON_S = 4.0  # how far ahead the pedestrian's path is predicted [s]
LATERAL_MARGIN_M = 0.5  # corridor margin on each side of the ego, beyond its half width [m]
STOP_MARGIN_M = 2.0  # distance the stack aims to stop short of the pedestrian [m]
RESUME_ACCEL_MPS2 = 2.0  # acceleration back to cruise speed once clear [m/s2]
CLEAR_HOLD_S = 0.5  # a threat must be absent this long before the stack resumes [s]
TRACK_WINDOW_S = 0.5  # positions used to estimate a pedestrian's velocity [s]


@dataclass(frozen=True)
class TrackedPedestrian:
    ped_id: str
    x_m: float
    y_m: float
    vx_mps: float
    vy_mps: float


class Tracker:
    """Velocity of each perceived pedestrian from a least-squares fit over a short window."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._history: dict[str, deque] = {}

    def update(self, pedestrians, time_s: float) -> list[TrackedPedestrian]:
        tracked = []
        for ped in pedestrians:
            history = self._history.setdefault(ped.ped_id, deque())
            history.append((time_s, ped.x_m, ped.y_m))
            while history and history[0][0] < time_s - self.window_s - 1e-9:
                history.popleft()
            vx = vy = 0.0
            if len(history) >= 2:
                t = [h[0] for h in history]
                t_mean = sum(t) / len(t)
                denom = sum((ti - t_mean) ** 2 for ti in t)
                if denom > 0:
                    vx = sum((ti - t_mean) * h[1] for ti, h in zip(t, history)) / denom
                    vy = sum((ti - t_mean) * h[2] for ti, h in zip(t, history)) / denom
            tracked.append(TrackedPedestrian(ped.ped_id, ped.x_m, ped.y_m, vx, vy))
        return tracked


@dataclass(frozen=True)
class Threat:
    ped_id: str
    gap_m: float  # distance from the ego's front to where the pedestrian meets the corridor [m]
    time_s: float  # when the pedestrian is first inside the corridor [s from now]


def predict_threat(
    observation: Observation, pedestrian: TrackedPedestrian, horizon_s: float, lateral_margin_m: float
) -> Threat | None:
    """Whether a pedestrian moving at constant velocity enters the ego's corridor ahead within the
    horizon, before the ego (moving at its current speed) has passed that point."""
    ego = observation.ego
    cos_yaw, sin_yaw = math.cos(ego.yaw_rad), math.sin(ego.yaw_rad)
    dx, dy = pedestrian.x_m - ego.x_m, pedestrian.y_m - ego.y_m
    # Pedestrian in the ego frame: lon ahead of the ego centre, lat to its left.
    lon = dx * cos_yaw + dy * sin_yaw
    lat = -dx * sin_yaw + dy * cos_yaw
    vlon = pedestrian.vx_mps * cos_yaw + pedestrian.vy_mps * sin_yaw
    vlat = -pedestrian.vx_mps * sin_yaw + pedestrian.vy_mps * cos_yaw
    half_width = ego.width_m / 2 + lateral_margin_m
    # Time interval during which |lat + vlat t| <= half_width.
    if abs(vlat) < 1e-9:
        if abs(lat) > half_width:
            return None
        t_in, t_out = 0.0, horizon_s
    else:
        t_a, t_b = (-half_width - lat) / vlat, (half_width - lat) / vlat
        t_in, t_out = max(0.0, min(t_a, t_b)), min(horizon_s, max(t_a, t_b))
    if t_in > t_out:
        return None
    front_offset = ego.length_m / 2
    # Longitudinal gap between the ego's front and the pedestrian while in the corridor; the ego has
    # passed when the pedestrian is behind its rear.
    ped_lon_in = lon + vlon * t_in
    ego_travel = ego.speed_mps * t_in
    if ped_lon_in - ego_travel < -front_offset:
        return None
    gap_m = lon + vlon * t_in - front_offset
    if gap_m < -ego.length_m:
        return None
    return Threat(pedestrian.ped_id, gap_m=max(gap_m, 0.0), time_s=t_in)


#: Lane shapes closer than this at their ends are taken as joined (netconvert joins them exactly) [m].
_JOIN_TOLERANCE_M = 0.1


@dataclass(frozen=True)
class Segment:
    """One straight piece of the planned path: start point, unit direction, distance of its start
    along the path, and length [m]."""

    x_m: float
    y_m: float
    ux: float
    uy: float
    start_m: float
    length_m: float


@dataclass(frozen=True)
class PlannedPath:
    """The centreline the ego will drive, as segments; the first `current_count` are its current lane."""

    segments: tuple[Segment, ...]
    current_count: int


def planned_path(route: RouteAhead) -> PlannedPath | None:
    """The ego's path from the route feed: its current lane from the lane's start, then, lane after lane,
    the drivable route lane that begins where the previous one ends (the junction's internal lane(s) of
    its connection, then the lane beyond; the least turning one where two begin there). None when the
    feed does not hold the current lane."""
    by_id = {lane.lane_id: lane for lane in route.lanes}
    current = by_id.get(route.current_lane_id)
    if current is None or len(current.shape_xy_m) < 2:
        return None
    lanes = [current]
    used = {current.lane_id}
    while True:
        shape = lanes[-1].shape_xy_m
        end = shape[-1]
        heading = math.atan2(shape[-1][1] - shape[-2][1], shape[-1][0] - shape[-2][0])
        following = [
            lane
            for lane in route.lanes
            if lane.drivable
            and lane.lane_id not in used
            and len(lane.shape_xy_m) >= 2
            and math.dist(lane.shape_xy_m[0], end) < _JOIN_TOLERANCE_M
        ]
        if not following:
            break
        turns = [_turn_rad(lane.shape_xy_m, heading) for lane in following]
        nxt = following[turns.index(min(turns))]
        lanes.append(nxt)
        used.add(nxt.lane_id)
    segments: list[Segment] = []
    current_count = 0
    done_m = 0.0
    for k, lane in enumerate(lanes):
        for (ax, ay), (bx, by) in zip(lane.shape_xy_m[:-1], lane.shape_xy_m[1:]):
            length = math.hypot(bx - ax, by - ay)
            if length < 1e-6:
                continue
            segments.append(Segment(ax, ay, (bx - ax) / length, (by - ay) / length, done_m, length))
            done_m += length
        if k == 0:
            current_count = len(segments)
    if current_count == 0:
        return None
    return PlannedPath(tuple(segments), current_count)


def _turn_rad(shape, heading_rad: float) -> float:
    """How far the first segment of `shape` turns away from `heading_rad` [rad, 0 to pi]."""
    (ax, ay), (bx, by) = shape[:2]
    return abs((math.atan2(by - ay, bx - ax) - heading_rad + math.pi) % (2 * math.pi) - math.pi)


def _interval(position: float, velocity: float, low: float, high: float) -> tuple[float, float]:
    """Times at which position + velocity t lies in [low, high] (unbounded: +-inf)."""
    if abs(velocity) < 1e-9:
        return (-math.inf, math.inf) if low <= position <= high else (math.inf, -math.inf)
    t_a, t_b = (low - position) / velocity, (high - position) / velocity
    return min(t_a, t_b), max(t_a, t_b)


def predict_threat_on_path(
    observation: Observation,
    pedestrian: TrackedPedestrian,
    path: PlannedPath,
    horizon_s: float,
    lateral_margin_m: float,
) -> Threat | None:
    """Whether a pedestrian moving at constant velocity enters the ego's corridor along its planned path
    within the horizon, before the ego (moving at its current speed) has passed that point.

    The corridor is the union of one rectangle per path segment, half width wide on each side and
    lengthened by it at both ends (so that it has no gaps on the outside of a bend); the one the ego is
    on extends backwards without end, the last forwards without end: on a straight path, the straight
    corridor of `predict_threat`. Distances are along the path; the ego is where its centre projects
    onto its current lane."""
    ego = observation.ego
    half_width = ego.width_m / 2 + lateral_margin_m
    segments = path.segments
    # The ego on its current lane: the nearest of its segments (extended backwards at the lane's start).
    best = None
    for k in range(path.current_count):
        seg = segments[k]
        along = (ego.x_m - seg.x_m) * seg.ux + (ego.y_m - seg.y_m) * seg.uy
        along = min(along, seg.length_m) if k == 0 else min(max(along, 0.0), seg.length_m)
        off = math.hypot(ego.x_m - seg.x_m - along * seg.ux, ego.y_m - seg.y_m - along * seg.uy)
        if best is None or off < best[0] - 1e-9:
            best = (off, k, seg.start_m + along)
    assert best is not None
    _, first, ego_s = best
    candidates = []
    last = len(segments) - 1
    for k in range(first, len(segments)):
        seg = segments[k]
        rx, ry = pedestrian.x_m - seg.x_m, pedestrian.y_m - seg.y_m
        along = rx * seg.ux + ry * seg.uy
        lat = -rx * seg.uy + ry * seg.ux
        v_along = pedestrian.vx_mps * seg.ux + pedestrian.vy_mps * seg.uy
        v_lat = -pedestrian.vx_mps * seg.uy + pedestrian.vy_mps * seg.ux
        lat_in, lat_out = _interval(lat, v_lat, -half_width, half_width)
        low = -math.inf if k == first else -half_width
        high = math.inf if k == last else seg.length_m + half_width
        lon_in, lon_out = _interval(along, v_along, low, high)
        t_in, t_out = max(0.0, lat_in, lon_in), min(horizon_s, lat_out, lon_out)
        if t_in > t_out:
            continue
        candidates.append((t_in, seg.start_m + along + v_along * t_in))
    front_offset = ego.length_m / 2
    for t_in, ped_s in sorted(candidates):
        # Longitudinal gap between the ego's front and the pedestrian along the path; the ego has passed
        # when the pedestrian is behind its rear.
        ped_lon_in = ped_s - ego_s
        if ped_lon_in - ego.speed_mps * t_in < -front_offset:
            continue
        gap_m = ped_lon_in - front_offset
        if gap_m < -ego.length_m:
            continue
        return Threat(pedestrian.ped_id, gap_m=max(gap_m, 0.0), time_s=t_in)
    return None


class PlannedPathCache:
    """The planned path of an observation's route, rebuilt only when the ego's lane or route changes."""

    def __init__(self) -> None:
        self._key: tuple | None = None
        self._path: PlannedPath | None = None

    def of(self, observation: Observation) -> PlannedPath | None:
        """None without a route feed (an observation built by hand)."""
        route = observation.route
        if route is None:
            return None
        key = (route.current_lane_id, route.edges)
        if key != self._key:
            self._key, self._path = key, planned_path(route)
        return self._path


class ReferenceStack(Agent):
    """Cruise, brake for pedestrians in the path (after the reaction time), resume once clear."""

    def setup(self, config: dict[str, Any]) -> None:
        self.cruise_speed_mps = float(config["initial_speed_mps"])
        self.reaction_time_s = float(config.get("reaction_time_s", REACTION_TIME_S))
        self.max_decel_mps2 = float(config.get("max_decel_mps2", MAX_DECEL_MPS2))
        self.horizon_s = float(config.get("horizon_s", HORIZON_S))
        self.lateral_margin_m = float(config.get("lateral_margin_m", LATERAL_MARGIN_M))
        self.stop_margin_m = float(config.get("stop_margin_m", STOP_MARGIN_M))
        self.resume_accel_mps2 = float(config.get("resume_accel_mps2", RESUME_ACCEL_MPS2))
        self.clear_hold_s = float(config.get("clear_hold_s", CLEAR_HOLD_S))
        self._threat_since_s: float | None = None
        self._last_threat_s: float | None = None
        self._last_gap_m = math.inf
        self.tracker = Tracker(float(config.get("track_window_s", TRACK_WINDOW_S)))
        self._paths = PlannedPathCache()

    def sensors(self) -> list[str]:
        """The three detection sources, and the route its corridor follows."""
        return [*KNOWN_SENSORS, "route"]

    def run_step(self, observation: Observation, time_s: float) -> Command:
        path = self._paths.of(observation)
        tracked = self.tracker.update(observation.pedestrians, time_s)
        if path is None:
            found = [predict_threat(observation, p, self.horizon_s, self.lateral_margin_m) for p in tracked]
        else:
            found = [
                predict_threat_on_path(observation, p, path, self.horizon_s, self.lateral_margin_m)
                for p in tracked
            ]
        threats = [t for t in found if t is not None]
        speed = observation.ego.speed_mps
        dt = observation.step_length_s
        if threats:
            nearest = min(threats, key=lambda t: t.gap_m)
            self._last_gap_m = nearest.gap_m
            self._last_threat_s = time_s
            if self._threat_since_s is None:
                self._threat_since_s = time_s
        elif self._last_threat_s is not None and time_s - self._last_threat_s > self.clear_hold_s:
            self._threat_since_s = None
            self._last_threat_s = None
            self._last_gap_m = math.inf

        braking = (
            self._threat_since_s is not None and time_s - self._threat_since_s >= self.reaction_time_s - 1e-9
        )
        if braking:
            room_m = self._last_gap_m - self.stop_margin_m
            needed = speed * speed / (2 * room_m) if room_m > 0.1 else self.max_decel_mps2
            decel = min(self.max_decel_mps2, max(needed, 0.0))
            target = max(0.0, speed - decel * dt)
            return Command(target, {"braking": True, "decel_mps2": decel, "threat_gap_m": self._last_gap_m})
        if self._threat_since_s is not None:  # perceived, reaction time still running: hold speed
            return Command(speed, {"braking": False, "reacting": True})
        target = min(self.cruise_speed_mps, speed + self.resume_accel_mps2 * dt)
        return Command(target, {"braking": False})
