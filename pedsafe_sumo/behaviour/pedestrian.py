"""Pedestrian behaviour on an approaching vehicle, by risk preference (paper section IV-A).

A pedestrian walks a polyline path (a crosswalk, or a jaywalking line across the road) at their own
walking speed. The points before `kerb_index` are their walk along the sidewalk to the step-off point
(state "walking_in", at walking speed, without stopping); at `path_xy[kerb_index]` they wait their start
delay, then cross. With `leaves_scene` they walk on to the end of the path and leave the scene there
(state "left"); otherwise they stand at its end ("finished"). Each step the model computes where the
ego's path (a straight line along its heading) crosses the pedestrian's crossing (the path from the
step-off point on): the conflict point, and the time the ego's front needs to reach it.
When that time falls below `awareness_ttc_s` and the pedestrian can see the ego (a line of sight from
their eyes, which the episode loop casts through the sensors' geometry), a pedestrian who is not
`unaware` reacts, after their reaction time:

- `unaware` keeps their speed (they have not noticed the vehicle);
- `hasten` speeds up (x `hasten_factor`, at most `max_speed_mps`) to pass before the vehicle;
- `yield` stops `yield_clearance_m` short of the ego's flank; if already closer, steps back to that
  distance ("step backward to yield", paper section IV-A); if already past the ego's centreline, walks
  on out of its path. With `yield_at_kerb`, a yielder who notices the ego before stepping off (while
  still at the kerb, the start delay included) waits at the kerb instead, stepping back onto it if the
  reaction time took them into the road.

A yielder resumes only when the ego's rear has passed their path, or when the gap is safe by gap
acceptance: the ego's time to reach their path is at least the time they need to walk clear of it
plus a start-up and clearance time (HCM's critical headway t_c = L / S_p + t_s). A vehicle that stands
still counts as an infinite gap only once it has been seen standing for a reaction time ("visibly
stopped for them"); before that the pedestrian waits.

Nobody walks into a standing vehicle's body (the body rule): a step that would overlap a vehicle
footprint, or that heads towards one while closer than `body_clearance_m` to it, is not taken (state
"blocked"). Without `body_rule_needs_notice` the rule holds for moving vehicles too. With it, it holds for
a moving vehicle only if the pedestrian has noticed it: the ego once they reacted to it (saw it and their
reaction time passed); any other moving vehicle unless they are `unaware` (distracted) or running
(hastening above their walking speed, eyes on the ego). So an unaware pedestrian can walk into the side
of a moving car. Without vehicle speeds (`VehicleBodies.speed_mps` None) every body counts as standing.
"Heads towards" means the distance falls by more than sin(`body_graze_angle_deg`) of the step: someone
standing against a bumper walks along it and out, as people do, instead of freezing because their path
runs a fraction of a degree off the bumper's line. A vehicle moving into a standing pedestrian is then the
vehicle striking them.

A pedestrian whose forward step standing vehicles have refused for `detour_wait_s` walks round them, as
people walk round a car stopped on a crosswalk: they step sideways, off their line, round the nearer end
of the vehicle(s) in the way (in front of or behind it), at most `detour_max_offset_m` aside (within the
crosswalk or just beside it), then walk on at that offset. Sidesteps obey the same body rule. A vehicle
that still moves, or one that cannot be passed within that offset, keeps them blocked.

The model is pure: the episode loop feeds it the ego's pose, the vehicle footprints and a line-of-sight
test, and moves the SUMO person to the returned position (traci person.moveToXY), so it works on and
off the crosswalks alike.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pedsafe_sumo.safety.geometry import rectangle_circle_distance_m
from pedsafe_sumo.safety.geometry_kernels import walks_into_body

RISK_PREFERENCES = ("unaware", "hasten", "yield")


@dataclass(frozen=True)
class BehaviourParams:
    risk: str
    walking_speed_mps: float
    reaction_time_s: float = 1.0  # pedestrian perception-reaction time [s]
    awareness_ttc_s: float = 3.0  # reacts when the vehicle's front is this close in time to their path [s]
    hasten_factor: float = 1.5  # speed multiplier when hastening [-]
    max_speed_mps: float = 2.5  # fastest a hastening pedestrian moves (a brisk run) [m/s]
    step_back_speed_mps: float = 0.8  # speed of stepping back away from the vehicle's path [m/s]
    yield_clearance_m: float = 1.0  # a yielder's body edge to the vehicle's flank [m]
    body_clearance_m: float = 0.1  # nearest a pedestrian steps towards any vehicle body [m]
    body_graze_angle_deg: float = 5.0  # inside the clearance, steps this close to parallel go on [deg]
    gap_startup_clearance_s: float = 3.0  # gap acceptance: start-up and clearance time t_s [s]
    detour_wait_s: float = 2.0  # blocked this long by standing vehicles, they walk round them [s]
    detour_max_offset_m: float = 3.0  # farthest they step aside from their line to walk round [m]
    yield_at_kerb: bool = True  # a yielder who notices the ego before stepping off waits at the kerb
    body_rule_needs_notice: bool = True  # the body rule holds for a moving vehicle only once noticed
    stopped_speed_mps: float = 0.1  # a vehicle slower than this stands still [m/s]
    radius_m: float = 0.3  # the pedestrian's body circle [m]
    avoids_bodies: bool = True  # False: a test-track dummy that keeps its path into a vehicle

    def __post_init__(self) -> None:
        if self.risk not in RISK_PREFERENCES:
            raise ValueError(f"unknown risk preference '{self.risk}' (known: {', '.join(RISK_PREFERENCES)})")
        if self.walking_speed_mps <= 0:
            raise ValueError(f"walking speed must be positive, got {self.walking_speed_mps} m/s")
        for name in ("yield_at_kerb", "body_rule_needs_notice", "avoids_bodies"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class PedestrianPose:
    x_m: float
    y_m: float
    heading_rad: float  # direction of motion, counter-clockwise from +x
    speed_mps: float  # signed along the path: negative when stepping back
    #: "walking_in" (on the sidewalk to the step-off point), "waiting", "walking", "reacting",
    #: "hastening", "yielding", "stepping_back", "clearing", "blocked", "detouring" (a sidestep round
    #: standing vehicles), "finished" (standing at the end of the path), "left" (gone from the scene there)
    state: str


@dataclass(frozen=True)
class VehicleBodies:
    """Footprints of the vehicles around the pedestrian: centres, headings, lengths, widths (arrays)."""

    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    length_m: np.ndarray
    width_m: np.ndarray
    #: Half diagonals (circumscribed radii) of the footprints; computed when not given. The episode
    #: loop passes them, rebuilt only when vehicles enter or leave, to keep the per-step cost down.
    half_diagonal_m: np.ndarray | None = None
    #: Speeds [m/s]; None: every body counts as standing (the body rule holds for all).
    speed_mps: np.ndarray | None = None
    #: Index of the ego among the bodies (-1: not among them).
    ego_index: int = -1


def _float_arrays(*arrays) -> tuple[np.ndarray, ...]:
    """The arrays as float64 (no copy when they are already, as the episode loop's are)."""
    return tuple(np.asarray(a, dtype=float) for a in arrays)


def _conflict_point(path_xy, ego_xy: tuple[float, float], ego_yaw_rad: float, start_s_m: float = 0.0):
    """Distance along the pedestrian path where the ego's heading line crosses it, and the ego's
    signed distance to that point along its heading. None when the lines do not cross.
    `path_xy`: a sequence of (x, y) points (plain floats are several times faster than numpy rows), the
    path from `start_s_m` along it on."""
    ex, ey = ego_xy
    dx, dy = math.cos(ego_yaw_rad), math.sin(ego_yaw_rad)
    walked = start_s_m
    for (ax, ay), (bx, by) in zip(path_xy[:-1], path_xy[1:]):
        sx, sy = bx - ax, by - ay
        seg_len = math.hypot(sx, sy)
        denom = dx * sy - dy * sx
        if abs(denom) > 1e-9 and seg_len > 0:
            # Solve ego + d * dir = a + u * seg.
            d_ego = ((ax - ex) * sy - (ay - ey) * sx) / denom
            u = ((ax - ex) * dy - (ay - ey) * dx) / denom
            if 0.0 <= u <= 1.0:
                return walked + u * seg_len, d_ego
        walked += seg_len
    return None


class PedestrianWalker:
    """State of one pedestrian along their path; `step` advances it by one simulation step."""

    def __init__(
        self,
        path_xy,
        params: BehaviourParams,
        start_delay_s: float = 0.0,
        kerb_index: int = 0,
        appear_time_s: float = 0.0,
        leaves_scene: bool = False,
    ) -> None:
        """`kerb_index`: the path's step-off point (the points before it are the walk to it);
        `appear_time_s`: when they enter the scene at the path's start and start walking;
        `start_delay_s`: how long they wait at the step-off point; `leaves_scene`: at the path's end
        they leave the scene (else they stand there)."""
        self.path_xy = np.asarray(path_xy, dtype=float)
        if self.path_xy.ndim != 2 or len(self.path_xy) < 2:
            raise ValueError("a pedestrian path needs at least two points")
        if not 0 <= kerb_index < len(self.path_xy) - 1:
            raise ValueError(f"kerb_index {kerb_index} must name a point of the path before its last")
        self._path_points = [(float(x), float(y)) for x, y in self.path_xy]
        # The crossing: the path from the step-off point on (the conflict point is sought there only).
        self._crossing_points = self._path_points[kerb_index:]
        # The conflict point of the last ego pose asked for: the loop asks twice per step (cleared, step).
        self._conflict_cache: tuple = (None, None)
        self.params = params
        seg = np.diff(self.path_xy, axis=0)
        self._seg_len = np.hypot(seg[:, 0], seg[:, 1])
        self._cum = np.concatenate([[0.0], np.cumsum(self._seg_len)])
        self.length_m = float(self._cum[-1])
        self._cum_list = [float(c) for c in self._cum]
        self.start_delay_s = start_delay_s
        self.appear_time_s = appear_time_s
        self.leaves_scene = leaves_scene
        #: Distance along the path of the step-off point.
        self.kerb_s_m = self._cum_list[kerb_index]
        #: When they reached the step-off point (None: still walking to it), and when they step off.
        self.kerb_reached_s: float | None = appear_time_s if kerb_index == 0 else None
        self.crossing_from_s = (
            math.inf if self.kerb_reached_s is None else self.kerb_reached_s + start_delay_s
        )
        self.s_m = 0.0  # distance walked along the path
        self.speed_mps = 0.0
        self._aware_since_s: float | None = None
        self._yielding = False  # reacted by yielding, and not yet resumed
        self._hastening = False  # reacted by hastening, until across or the ego has passed
        self._seen_ego = False  # has had the ego in sight during this encounter
        self._noticed_ego = False  # has reacted to the ego (seen, reaction time passed) in this encounter
        self._aware_at_kerb = False  # began noticing the ego before stepping off
        self._kerb_yield = False  # yielding at the kerb (yield_at_kerb)
        self._ego_stopped_since_s: float | None = None
        # Walking round standing vehicles: the offset from the path (left of the walking direction
        # positive); since when the way ahead has been blocked by the same standing bodies, and their
        # centres at the last blocked step; the offset that passes them.
        self.offset_m = 0.0
        self._blocked_since_s: float | None = None
        self._blocker_xy: np.ndarray | None = None
        self._detour_to_m: float | None = None
        self.state = "waiting"

    def position(self, s_m: float) -> tuple[float, float, float]:
        """(x, y, heading of the segment) at distance `s_m` along the path (clipped to it)."""
        s = min(max(s_m, 0.0), self.length_m)
        cum = self._cum_list  # plain floats: this runs several times a step
        i = min(bisect.bisect_right(cum, s) - 1, len(cum) - 2)
        (ax, ay), (bx, by) = self._path_points[i], self._path_points[i + 1]
        seg_len = cum[i + 1] - cum[i]
        u = (s - cum[i]) / seg_len if seg_len > 0 else 0.0
        return ax + u * (bx - ax), ay + u * (by - ay), math.atan2(by - ay, bx - ax)

    def _xy(self, s_m: float, offset_m: float) -> tuple[float, float, float]:
        """As `position`, moved `offset_m` to the left of the walking direction (a detour)."""
        x, y, heading = self.position(s_m)
        if offset_m:
            x, y = x - offset_m * math.sin(heading), y + offset_m * math.cos(heading)
        return x, y, heading

    @property
    def finished(self) -> bool:
        return self.s_m >= self.length_m - 1e-9

    def cleared(
        self, ego_xy: tuple[float, float], ego_yaw_rad: float, ego_length_m: float, ego_width_m: float
    ) -> tuple[bool, bool] | None:
        """(ego cleared, pedestrian cleared) the conflict area, or None when their paths do not cross.

        The ego has cleared it when its rear is past the pedestrian's path by their radius; the
        pedestrian when their body is past the ego's far flank, or they reached the end of their path.
        """
        conflict = self._conflict(ego_xy, ego_yaw_rad)
        if conflict is None:
            return None
        s_conflict, d_ego = conflict
        r = self.params.radius_m
        ego_clear = d_ego < -(ego_length_m / 2 + r)
        ped_clear = self.finished or self.s_m > s_conflict + ego_width_m / 2 + r
        return ego_clear, ped_clear

    def _conflict(self, ego_xy: tuple[float, float], ego_yaw_rad: float):
        key = (float(ego_xy[0]), float(ego_xy[1]), float(ego_yaw_rad))
        if self._conflict_cache[0] != key:
            self._conflict_cache = (
                key,
                _conflict_point(self._crossing_points, ego_xy, ego_yaw_rad, self.kerb_s_m),
            )
        return self._conflict_cache[1]

    def _sees(self, sees_ego: Callable[[], bool] | None) -> bool:
        """Whether the ego has been in sight; the line of sight is cast only until it first is."""
        if not self._seen_ego:
            self._seen_ego = True if sees_ego is None else bool(sees_ego())
        return self._seen_ego

    def step(
        self,
        dt_s: float,
        time_s: float,
        ego_xy: tuple[float, float],
        ego_yaw_rad: float,
        ego_speed_mps: float,
        ego_length_m: float = 4.5,
        ego_width_m: float = 1.8,
        sees_ego: Callable[[], bool] | None = None,
        bodies: VehicleBodies | None = None,
    ) -> PedestrianPose:
        """Advance one step. `sees_ego()` answers whether the ego is in the pedestrian's sight now (None:
        always); `bodies` are the vehicle footprints no step may walk into (None: none)."""
        p = self.params
        if time_s < self.crossing_from_s:
            if self.kerb_reached_s is None:
                return self._walk_in(dt_s, time_s)
            if not (p.yield_at_kerb and p.risk == "yield"):
                x, y, heading = self.position(self.s_m)
                return PedestrianPose(x, y, heading, 0.0, "waiting")
            # A yielder notices the ego while waiting at the kerb (yield_at_kerb), and stays there.
            self._track_ego_stopped(time_s, ego_speed_mps)
            _, state, _ = self._respond(
                time_s, ego_xy, ego_yaw_rad, ego_speed_mps, ego_length_m, ego_width_m, sees_ego
            )
            x, y, heading = self.position(self.s_m)
            state = "yielding" if self._yielding else ("reacting" if state == "reacting" else "waiting")
            self.state = state
            return PedestrianPose(x, y, heading, 0.0, state)
        if self.finished:
            x, y, heading = self._xy(self.length_m, self.offset_m)
            self.state = "left" if self.leaves_scene else "finished"
            return PedestrianPose(x, y, heading, 0.0, self.state)

        self._track_ego_stopped(time_s, ego_speed_mps)
        speed, state, target_s = self._respond(
            time_s, ego_xy, ego_yaw_rad, ego_speed_mps, ego_length_m, ego_width_m, sees_ego
        )

        if state == "yielding":
            new_s = self.s_m
        elif state == "stepping_back":
            new_s = max(target_s or 0.0, self.s_m + speed * dt_s, 0.0)  # target_s is set when stepping back
        else:
            new_s = min(self.length_m, self.s_m + speed * dt_s)
        sidestep_m = 0.0
        if new_s != self.s_m and p.avoids_bodies and bodies is not None and len(bodies.x_m):
            running = state == "hastening" and speed > p.walking_speed_mps
            bodies = self._heeded(bodies, running, abs(new_s - self.s_m))
        if new_s != self.s_m and p.avoids_bodies and bodies is not None and len(bodies.x_m):
            if new_s > self.s_m and self._detour_to_m is not None:
                # A detour under way: sideways until at the offset that passes the bodies, then on.
                sidestep_m = self._sidestep(bodies, new_s - self.s_m)
            if sidestep_m:
                new_s = self.s_m
            elif self._walks_into(bodies, self.s_m, new_s):
                if new_s > self.s_m:
                    sidestep_m = self._detour_step(bodies, time_s, dt_s, new_s - self.s_m)
                new_s, speed, state = self.s_m, 0.0, "blocked"
            elif self._blocked_since_s is not None:
                self._blocked_since_s, self._blocker_xy, self._detour_to_m = None, None, None
        self.s_m = new_s
        if sidestep_m:
            # Sideways at the step's pace; the pose's heading is the direction of the sidestep.
            self.offset_m += sidestep_m
            speed, state = abs(sidestep_m) / dt_s, "detouring"
        self.speed_mps = speed
        self.state = state
        x, y, heading = self._xy(self.s_m, self.offset_m)
        if sidestep_m:
            heading += math.copysign(math.pi / 2, sidestep_m)
        if speed < 0:
            heading += math.pi
        return PedestrianPose(x, y, heading, speed, state)

    def _walk_in(self, dt_s: float, time_s: float) -> PedestrianPose:
        """A step of the walk along the sidewalk to the step-off point, at walking speed; reaching it
        starts the start delay (the pose is that of `time_s + dt_s`)."""
        self.s_m = min(self.kerb_s_m, self.s_m + self.params.walking_speed_mps * dt_s)
        state = "walking_in"
        if self.s_m >= self.kerb_s_m - 1e-9:
            self.s_m = self.kerb_s_m
            self.kerb_reached_s = time_s + dt_s
            self.crossing_from_s = self.kerb_reached_s + self.start_delay_s
            state = "waiting"
        self.speed_mps = self.params.walking_speed_mps if state == "walking_in" else 0.0
        self.state = state
        x, y, heading = self.position(self.s_m)
        return PedestrianPose(x, y, heading, self.speed_mps, state)

    def _track_ego_stopped(self, time_s: float, ego_speed_mps: float) -> None:
        """Since when the ego has stood still (None while it moves)."""
        if ego_speed_mps < self.params.stopped_speed_mps:
            if self._ego_stopped_since_s is None:
                self._ego_stopped_since_s = time_s
        else:
            self._ego_stopped_since_s = None

    def _respond(
        self,
        time_s: float,
        ego_xy: tuple[float, float],
        ego_yaw_rad: float,
        ego_speed_mps: float,
        ego_length_m: float,
        ego_width_m: float,
        sees_ego: Callable[[], bool] | None,
    ) -> tuple[float, str, float | None]:
        """(speed along the path, state, where a stepping-back pedestrian stops or None) by the
        pedestrian's response to the ego (module docstring)."""
        p = self.params
        speed = p.walking_speed_mps
        state = "walking"
        target_s: float | None = None  # where a stepping-back or yielding pedestrian stops
        conflict = self._conflict(ego_xy, ego_yaw_rad)
        if conflict is not None and p.risk != "unaware":
            s_conflict, d_ego = conflict
            half_w = ego_width_m / 2
            near_edge = s_conflict - (half_w + p.yield_clearance_m + p.radius_m)
            far_edge = s_conflict + half_w + p.radius_m
            ego_passed = d_ego < -(ego_length_m / 2 + p.radius_m)
            across = self.s_m > far_edge
            front_gap_m = max(d_ego - ego_length_m / 2 - p.radius_m, 0.0)
            moving = ego_speed_mps >= p.stopped_speed_mps
            time_to_path_s = front_gap_m / ego_speed_mps if moving else math.inf
            if ego_passed or across:
                self._aware_since_s, self._yielding, self._hastening = None, False, False
                self._seen_ego = False  # the next encounter needs its own look
                self._noticed_ego = self._kerb_yield = False
            else:
                threatened = moving and time_to_path_s <= p.awareness_ttc_s and self._sees(sees_ego)
                if self._yielding:
                    if self._accepts_gap(time_s, time_to_path_s, far_edge - self.s_m):
                        self._yielding, self._aware_since_s, self._kerb_yield = False, None, False
                elif threatened:
                    if self._aware_since_s is None:
                        self._aware_since_s = time_s
                        self._aware_at_kerb = self.s_m <= self.kerb_s_m + 1e-9
                    if time_s - self._aware_since_s >= p.reaction_time_s - 1e-9:
                        self._noticed_ego = True
                        if p.risk == "yield":
                            self._yielding = True
                            self._kerb_yield = p.yield_at_kerb and self._aware_at_kerb
                        else:
                            speed = min(p.walking_speed_mps * p.hasten_factor, p.max_speed_mps)
                            state, self._hastening = "hastening", True
                    else:
                        state = "reacting"
                elif self._hastening and moving:
                    # Once hastening, keep the pace until across or the ego has passed.
                    speed = min(p.walking_speed_mps * p.hasten_factor, p.max_speed_mps)
                    state = "hastening"
                else:
                    self._aware_since_s = None
                if self._yielding:
                    # At the kerb (yield_at_kerb) or `yield_clearance_m` short of the flank.
                    stop_s = min(self.kerb_s_m, near_edge) if self._kerb_yield else near_edge
                    if self.s_m >= s_conflict:
                        state = "clearing"  # past the centreline: out of the path forwards
                    elif self.s_m > stop_s:
                        speed, state, target_s = -p.step_back_speed_mps, "stepping_back", stop_s
                    else:
                        speed, state = 0.0, "yielding"
        return speed, state, target_s

    def _heeded(self, bodies: VehicleBodies, running: bool, step_m: float) -> VehicleBodies:
        """The bodies the body rule holds for (`body_rule_needs_notice`, module docstring): every standing
        one; a moving one once noticed: the ego once reacted to, another unless unaware or `running`.
        A body out of reach of a step of `step_m` (its circumscribed circle farther than the pedestrian's
        circle, the clearance and the step) is kept whatever: the rule cannot refuse a step for it, and
        leaving it in spares building new arrays in the common case."""
        p = self.params
        speeds = bodies.speed_mps
        if not p.body_rule_needs_notice or speeds is None:
            return bodies
        ego = bodies.ego_index
        x, y, _ = self._xy(self.s_m, self.offset_m)
        reach_add_m = p.radius_m + p.body_clearance_m + step_m
        half_diagonal = bodies.half_diagonal_m
        if half_diagonal is None:
            half_diagonal = 0.5 * np.hypot(bodies.length_m, bodies.width_m)
        if p.risk != "unaware" and not running:
            if self._noticed_ego or ego < 0 or speeds[ego] < p.stopped_speed_mps:
                return bodies  # every moving vehicle noticed
            gap_m = math.hypot(float(bodies.x_m[ego]) - x, float(bodies.y_m[ego]) - y)
            if gap_m > float(half_diagonal[ego]) + reach_add_m:
                return bodies
            ignored = np.zeros(len(speeds), dtype=bool)
            ignored[ego] = True
        else:  # a few vehicles: plain floats are faster than numpy on arrays this small
            stopped, noticed_ego = p.stopped_speed_mps, self._noticed_ego
            near_moving = [
                k
                for k, (speed, bx, by, half) in enumerate(
                    zip(speeds.tolist(), bodies.x_m.tolist(), bodies.y_m.tolist(), half_diagonal.tolist())
                )
                if speed >= stopped and not (noticed_ego and k == ego)
                and math.hypot(bx - x, by - y) <= half + reach_add_m
            ]  # fmt: skip
            if not near_moving:
                return bodies
            ignored = np.zeros(len(speeds), dtype=bool)
            ignored[near_moving] = True
        keep = ~ignored
        return VehicleBodies(
            bodies.x_m[keep],
            bodies.y_m[keep],
            bodies.yaw_rad[keep],
            bodies.length_m[keep],
            bodies.width_m[keep],
            np.asarray(half_diagonal)[keep],
            speeds[keep],
        )

    def _detour_step(self, bodies: VehicleBodies, time_s: float, dt_s: float, step_m: float) -> float:
        """The sidestep (left of the walking direction positive; 0: none) of a pedestrian whose forward step
        of `step_m` the body rule refused. Taken only once the same bodies have blocked them, standing (each
        centre within `stopped_speed_mps` x dt of where it was at the last blocked step), for
        `detour_wait_s`; towards the offset that passes the nearer end of those bodies (`_detour_offset`),
        at most `step_m` sideways, and only if the body rule allows that sidestep."""
        p = self.params
        x0, y0, heading = self._xy(self.s_m, self.offset_m)
        ahead = (x0 + step_m * math.cos(heading), y0 + step_m * math.sin(heading))
        blockers = np.flatnonzero(self._refused(bodies, (x0, y0), ahead, step_m))
        centres = np.column_stack([bodies.x_m[blockers], bodies.y_m[blockers]])
        previous, self._blocker_xy = self._blocker_xy, centres
        standing = previous is not None and len(previous) > 0 and len(centres) > 0
        if standing:
            assert previous is not None
            tolerance_m = p.stopped_speed_mps * dt_s + 1e-9
            shift = centres[:, None, :] - previous[None, :, :]
            moved_m = np.hypot(shift[..., 0], shift[..., 1]).min(axis=1)  # each to its nearest of before
            standing = bool(np.all(moved_m <= tolerance_m))
        if not standing or self._blocked_since_s is None:
            self._blocked_since_s, self._detour_to_m = time_s, None
            return 0.0
        if time_s - self._blocked_since_s < p.detour_wait_s - 1e-9:
            return 0.0
        if self._detour_to_m is None:
            self._detour_to_m = self._detour_offset(bodies, blockers, heading)
            if self._detour_to_m is None:
                return 0.0
        return self._sidestep(bodies, step_m)

    def _sidestep(self, bodies: VehicleBodies, step_m: float) -> float:
        """At most `step_m` sideways towards the detour's offset, if the body rule allows it; else 0."""
        assert self._detour_to_m is not None
        to_go = self._detour_to_m - self.offset_m
        if abs(to_go) < 1e-9:
            return 0.0
        sidestep = math.copysign(min(abs(to_go), step_m), to_go)
        x0, y0, _ = self._xy(self.s_m, self.offset_m)
        x1, y1, _ = self._xy(self.s_m, self.offset_m + sidestep)
        if bool(np.any(self._refused(bodies, (x0, y0), (x1, y1), abs(sidestep)))):
            return 0.0
        return sidestep

    def _detour_offset(self, bodies: VehicleBodies, blockers: np.ndarray, heading_rad: float) -> float | None:
        """The offset from the path (left positive) that passes the nearer end of the blocking bodies, the
        body circle twice `body_clearance_m` clear of their corners; of the two ends, the one nearer the
        pedestrian's current offset. None when neither is within `detour_max_offset_m`."""
        p = self.params
        x, y, _ = self.position(self.s_m)
        nx, ny = -math.sin(heading_rad), math.cos(heading_rad)
        lateral = []
        for k in blockers:
            c, s = math.cos(bodies.yaw_rad[k]), math.sin(bodies.yaw_rad[k])
            half_l, half_w = bodies.length_m[k] / 2, bodies.width_m[k] / 2
            for a, b in ((half_l, half_w), (half_l, -half_w), (-half_l, half_w), (-half_l, -half_w)):
                corner_x, corner_y = bodies.x_m[k] + a * c - b * s, bodies.y_m[k] + a * s + b * c
                lateral.append((corner_x - x) * nx + (corner_y - y) * ny)
        reach_m = p.radius_m + 2 * p.body_clearance_m
        ends = (max(lateral) + reach_m, min(lateral) - reach_m)
        options = [end for end in ends if abs(end) <= p.detour_max_offset_m]
        if not options:
            return None
        return min(options, key=lambda end: abs(end - self.offset_m))

    def _accepts_gap(self, time_s: float, time_to_path_s: float, to_clear_m: float) -> bool:
        """Gap acceptance (HCM critical headway): walk on only if the ego reaches the path later than the
        time needed to walk `to_clear_m` clear of it plus the start-up and clearance time. A standing ego
        (time_to_path_s inf) is an infinite gap once seen standing for a reaction time, else none."""
        p = self.params
        if math.isinf(time_to_path_s):
            stopped_since = self._ego_stopped_since_s
            if stopped_since is None or time_s - stopped_since < p.reaction_time_s - 1e-9:
                return False
        critical_s = max(to_clear_m, 0.0) / p.walking_speed_mps + p.gap_startup_clearance_s
        return time_to_path_s >= critical_s

    def _walks_into(self, bodies: VehicleBodies, s_from: float, s_to: float) -> bool:
        """Whether moving s_from -> s_to overlaps a vehicle footprint, or brings the body within
        `body_clearance_m` of one while heading towards it: the distance falls by more than
        sin(`body_graze_angle_deg`) of the step (walking along a body it stands against is allowed)."""
        x1, y1, _ = self._xy(s_to, self.offset_m)
        x0, y0, _ = self._xy(s_from, self.offset_m)
        half_diagonal = bodies.half_diagonal_m
        if half_diagonal is None:
            half_diagonal = 0.5 * np.hypot(bodies.length_m, bodies.width_m)
        graze_m = abs(s_to - s_from) * math.sin(math.radians(self.params.body_graze_angle_deg))
        # Compiled (this runs every step a pedestrian moves; the same arithmetic as
        # safety.geometry.rectangle_circle_distance_m, bit for bit), with the same cheap bound first: only
        # footprints whose circumscribed circle comes within the margin of the body can be too close.
        return bool(
            walks_into_body(
                *_float_arrays(bodies.x_m, bodies.y_m, bodies.yaw_rad, bodies.length_m, bodies.width_m),
                np.asarray(half_diagonal, dtype=float),
                x0,
                y0,
                x1,
                y1,
                float(self.params.radius_m),
                float(self.params.body_clearance_m),
                graze_m,
            )
        )

    def _refused(
        self, bodies: VehicleBodies, xy_from: tuple[float, float], xy_to: tuple[float, float], step_m: float
    ) -> np.ndarray:
        """Per body, whether the body rule of `_walks_into` refuses a step of length `step_m` from `xy_from`
        to `xy_to`, in any direction (a sidestep too)."""
        r, margin = self.params.radius_m, self.params.body_clearance_m
        box = (bodies.x_m, bodies.y_m, bodies.yaw_rad, bodies.length_m, bodies.width_m)
        before = rectangle_circle_distance_m(*box, xy_from[0], xy_from[1], r)
        after = rectangle_circle_distance_m(*box, xy_to[0], xy_to[1], r)
        graze_m = step_m * math.sin(math.radians(self.params.body_graze_angle_deg))
        return (after <= 0.0) | ((after < margin) & (after < before - graze_m))
