"""Pedestrian behaviour on an approaching vehicle, by risk preference (paper section IV-A).

A pedestrian walks a polyline path (a crosswalk, or a jaywalking line across the road) at their own
walking speed. Each step the model computes where the ego's path (a straight line along its heading)
crosses the pedestrian's path, and the ego's time to reach that conflict point. When that time falls
below `awareness_ttc_s`, a pedestrian who is not `unaware` reacts, after their reaction time:

- `unaware` keeps their speed (they have not noticed the vehicle);
- `hasten` speeds up (x `hasten_factor`, at most `max_speed_mps`) to pass before the vehicle;
- `yield` stops short of the ego's corridor, or steps back out of it if already inside.

Once the ego has passed the conflict point or stands still, everyone walks on at their own speed.
The model is pure: the episode loop feeds it the ego's pose and moves the SUMO person to the
returned position (traci person.moveToXY), so it works on and off the crosswalks alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

RISK_PREFERENCES = ("unaware", "hasten", "yield")


@dataclass(frozen=True)
class BehaviourParams:
    risk: str
    walking_speed_mps: float
    reaction_time_s: float = 1.0  # pedestrian perception-reaction time [s]
    awareness_ttc_s: float = 3.0  # reacts when the vehicle is this close in time to the conflict point [s]
    hasten_factor: float = 1.5  # speed multiplier when hastening [-]
    max_speed_mps: float = 2.5  # fastest a hastening pedestrian moves (a brisk run) [m/s]
    step_back_speed_mps: float = 0.8  # speed of stepping back out of the corridor [m/s]
    corridor_half_width_m: float = 1.4  # ego half width plus a margin: the strip a yielder keeps out of [m]

    def __post_init__(self) -> None:
        if self.risk not in RISK_PREFERENCES:
            raise ValueError(f"unknown risk preference '{self.risk}' (known: {', '.join(RISK_PREFERENCES)})")
        if self.walking_speed_mps <= 0:
            raise ValueError(f"walking speed must be positive, got {self.walking_speed_mps} m/s")


@dataclass(frozen=True)
class PedestrianPose:
    x_m: float
    y_m: float
    heading_rad: float  # direction of motion, counter-clockwise from +x
    speed_mps: float  # signed along the path: negative when stepping back
    state: str  # "walking", "reacting", "hastening", "yielding", "stepping_back", "finished"


def _conflict_point(path_xy: np.ndarray, ego_xy: tuple[float, float], ego_yaw_rad: float):
    """Distance along the pedestrian path where the ego's heading line crosses it, and the ego's
    signed distance to that point along its heading. None when the lines do not cross."""
    ex, ey = ego_xy
    dx, dy = math.cos(ego_yaw_rad), math.sin(ego_yaw_rad)
    walked = 0.0
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

    def __init__(self, path_xy, params: BehaviourParams, start_delay_s: float = 0.0) -> None:
        self.path_xy = np.asarray(path_xy, dtype=float)
        if self.path_xy.ndim != 2 or len(self.path_xy) < 2:
            raise ValueError("a pedestrian path needs at least two points")
        self.params = params
        seg = np.diff(self.path_xy, axis=0)
        self._seg_len = np.hypot(seg[:, 0], seg[:, 1])
        self._cum = np.concatenate([[0.0], np.cumsum(self._seg_len)])
        self.length_m = float(self._cum[-1])
        self.start_delay_s = start_delay_s
        self.s_m = 0.0  # distance walked along the path
        self.speed_mps = 0.0
        self._aware_since_s: float | None = None
        self.state = "waiting"

    def position(self, s_m: float) -> tuple[float, float, float]:
        s = min(max(s_m, 0.0), self.length_m)
        i = int(np.searchsorted(self._cum, s, side="right") - 1)
        i = min(i, len(self._seg_len) - 1)
        (ax, ay), (bx, by) = self.path_xy[i], self.path_xy[i + 1]
        u = (s - self._cum[i]) / self._seg_len[i] if self._seg_len[i] > 0 else 0.0
        return ax + u * (bx - ax), ay + u * (by - ay), math.atan2(by - ay, bx - ax)

    @property
    def finished(self) -> bool:
        return self.s_m >= self.length_m - 1e-9

    def step(
        self,
        dt_s: float,
        time_s: float,
        ego_xy: tuple[float, float],
        ego_yaw_rad: float,
        ego_speed_mps: float,
        ego_length_m: float = 4.5,
    ) -> PedestrianPose:
        p = self.params
        if time_s < self.start_delay_s:
            x, y, heading = self.position(self.s_m)
            return PedestrianPose(x, y, heading, 0.0, "waiting")
        if self.finished:
            x, y, heading = self.position(self.length_m)
            self.state = "finished"
            return PedestrianPose(x, y, heading, 0.0, "finished")

        speed = p.walking_speed_mps
        state = "walking"
        conflict = _conflict_point(self.path_xy, ego_xy, ego_yaw_rad)
        threatened = False
        if conflict is not None and p.risk != "unaware":
            s_conflict, d_ego = conflict
            ego_passed = d_ego < -ego_length_m / 2
            ego_stopped = ego_speed_mps < 0.1
            not_yet_across = self.s_m < s_conflict + p.corridor_half_width_m
            if not ego_passed and not ego_stopped and not_yet_across:
                ttc_s = max(d_ego, 0.0) / ego_speed_mps
                threatened = ttc_s <= p.awareness_ttc_s
            if threatened:
                if self._aware_since_s is None:
                    self._aware_since_s = time_s
                if time_s - self._aware_since_s < p.reaction_time_s - 1e-9:
                    state = "reacting"
                elif p.risk == "hasten":
                    speed, state = min(p.walking_speed_mps * p.hasten_factor, p.max_speed_mps), "hastening"
                else:  # yield: keep out of the ego's corridor
                    edge = s_conflict - p.corridor_half_width_m
                    if self.s_m > edge:
                        speed, state = -p.step_back_speed_mps, "stepping_back"
                    else:
                        speed, state = 0.0, "yielding"
            else:
                self._aware_since_s = None
        if state == "stepping_back":
            edge = conflict[0] - p.corridor_half_width_m
            self.s_m = max(edge, self.s_m + speed * dt_s, 0.0)
        elif state == "yielding":
            pass
        else:
            self.s_m = min(self.length_m, self.s_m + speed * dt_s)
        self.speed_mps = speed
        self.state = state
        x, y, heading = self.position(self.s_m)
        if speed < 0:
            heading += math.pi
        return PedestrianPose(x, y, heading, speed, state)
