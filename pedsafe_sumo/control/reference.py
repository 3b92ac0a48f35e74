"""The reference AD stack: cruise, and brake for a perceived pedestrian whose path meets the ego's.

Behaviour (issue 5): cruise at the episode's initial speed. When a perceived pedestrian, moved ahead
at constant velocity, enters the ego's corridor (its width plus a margin, straight ahead along its
heading) within the prediction horizon, the stack brakes after its system reaction time, with the
deceleration that stops it short of the pedestrian, at most `max_decel_mps2`. Once no pedestrian has
threatened for `clear_hold_s`, it accelerates back to the cruise speed.

Its tracker estimates each pedestrian's velocity by a least-squares line through the positions of
the last `track_window_s` (a one-step difference of V2I positions with 0.2 m noise would be off by
several m/s). Signals and other vehicles are not its business: the scenarios put nothing else in its
path.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

from pedsafe_sumo.control.agent import Agent, Command, Observation

#: Defaults of the reference stack (issue 5); each can be overridden through the episode config (the
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

    def run_step(self, observation: Observation, time_s: float) -> Command:
        threats = [
            t
            for p in self.tracker.update(observation.pedestrians, time_s)
            if (t := predict_threat(observation, p, self.horizon_s, self.lateral_margin_m)) is not None
        ]
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
