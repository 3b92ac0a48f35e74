"""The baseline AD stack (`--algorithm reference`): a Kalman tracker with memory, a corridor planner that
brakes only for pedestrians in or predicted into its path, yielding at crosswalks, and signal compliance.

- Tracker (`tracker_motion_model`): "imm" (control/imm_tracker.py) an interacting multiple model filter
  per pedestrian, walking (constant velocity) and standing models; "cv" (control/kalman_tracker.py) the
  constant-velocity Kalman filter alone. Measurement noise: the sensors' stated noise (V2I 0.2 m, its
  0.1 s latency in the measurement model; onboard positions nearly exact); process noise: a stated
  acceleration spectral density; a track is predicted on for `track_memory_s` (2 s) after its last
  detection, then dropped; `tracker_gate` "precise": a position outside the track's 99.9 % validation gate
  and more precise than its predicted position starts it afresh ("reinitialise": any position outside).
- Pedestrians (control/baseline_planner.py): a track told moving (its velocity apart from standing at
  99.9 % under its covariance; under "imm" also the standing model the less probable) is moved ahead
  at that velocity for `horizon_s`, the corridor widened by one standard deviation of the predicted
  position; a standing track is a threat only where it stands inside the corridor.
- Crosswalks: a pedestrian on a crosswalk the path crosses who walks towards the corridor or stands
  in it, or one on it or at its kerb while it may show walk (the ego's own green is permissive,
  SUMO's 'g', for the crosswalk's signal; an unsignalised crosswalk), is a threat at the crosswalk,
  even standing, until they are across the corridor: the ego stops `stop_margin_m` short of it.
- Signals (`traffic_light` feed): stop for red; at a yellow's onset stop when v^2 / (2 a) at the
  comfortable deceleration fits before the stop line, else go on through.

Braking for a pedestrian starts after the reaction time, with the deceleration that stops the ego
`stop_margin_m` short, at most `max_decel_mps2`, as the paper-v7 stack (control/reference.py) does;
signal stops follow the comfortable deceleration. Every parameter and its source: docs/baseline_stack.md.
"""

from __future__ import annotations

import math
from typing import Any

from pedsafe_sumo.control.agent import KNOWN_SENSORS, Agent, Command, EgoState, Observation, RoadMap
from pedsafe_sumo.control.baseline_planner import (
    PERMISSIVE_GREEN,
    CrosswalkSpan,
    PathArrays,
    SignalPolicy,
    Threat,
    crosswalk_spans,
    distance_to_polygon_m,
    path_threat,
    speed_under_signal,
    straight_path,
)
from pedsafe_sumo.control.imm_tracker import ImmTracker
from pedsafe_sumo.control.kalman_tracker import (
    GATE_CHI2,
    TRACK_MEMORY_S,
    TRACKER_GATES,
    KalmanTracker,
    Track,
)
from pedsafe_sumo.control.reference import (
    CLEAR_HOLD_S,
    HORIZON_S,
    LATERAL_MARGIN_M,
    MAX_DECEL_MPS2,
    REACTION_TIME_S,
    RESUME_ACCEL_MPS2,
    STOP_MARGIN_M,
    planned_path,
)

#: The tracker's motion models (`tracker_motion_model` of [algorithm]): "cv" one constant-velocity Kalman
#: filter (control/kalman_tracker.py), "imm" walking and standing models (control/imm_tracker.py).
TRACKER_MOTION_MODELS = ("cv", "imm")
#: Comfortable deceleration for a signal stop [m/s2]: 10 ft/s2 (3.05 m/s2), the deceleration of ITE's
#: yellow change interval Y = t + v / (2a + 2Gg) (Institute of Transportation Engineers, "Determining
#: Vehicle Signal Change and Clearance Intervals", 1994; ITE Traffic Engineering Handbook), rounded down.
COMFORTABLE_DECEL_MPS2 = 3.0
#: The ego aims to stop this far before a stop line (where the comfortable deceleration allows) [m].
#: Assumption: the stop line's own width and a margin.
STOP_LINE_SHORT_M = 1.0
#: Standard deviations of the predicted position by which the corridor is widened for a moving track.
#: Assumption: one; two widened it past the adjacent lane's centre at the horizon under V2I noise.
SIGMA_FACTOR = 1.0
#: Time step of the pedestrian's predicted positions within the horizon [s] (0.14 m at 1.4 m/s).
PREDICTION_STEP_S = 0.1
#: A pedestrian within this distance of a crosswalk's polygon is at its kerb [m]. Assumption: one
#: stride and a half, where people wait to cross.
KERB_REACH_M = 1.5
#: Crosswalks are considered up to this far ahead of the ego's front even when the horizon at its
#: current speed is shorter (a slow or stopped ego at the line) [m]. Assumption.
CROSSWALK_LOOKAHEAD_M = 15.0


class BaselineStack(Agent):
    """Cruise; brake for pedestrians in or predicted into the path, yield at crosswalks, obey signals."""

    def setup(self, config: dict[str, Any]) -> None:
        self.cruise_speed_mps = float(config["initial_speed_mps"])
        self.reaction_time_s = float(config.get("reaction_time_s", REACTION_TIME_S))
        self.max_decel_mps2 = float(config.get("max_decel_mps2", MAX_DECEL_MPS2))
        self.horizon_s = float(config.get("horizon_s", HORIZON_S))
        self.lateral_margin_m = float(config.get("lateral_margin_m", LATERAL_MARGIN_M))
        self.stop_margin_m = float(config.get("stop_margin_m", STOP_MARGIN_M))
        self.resume_accel_mps2 = float(config.get("resume_accel_mps2", RESUME_ACCEL_MPS2))
        self.clear_hold_s = float(config.get("clear_hold_s", CLEAR_HOLD_S))
        comfortable = float(config.get("comfortable_decel_mps2", COMFORTABLE_DECEL_MPS2))
        self.signals = SignalPolicy(comfortable, self.max_decel_mps2, STOP_LINE_SHORT_M)
        memory_s = float(config.get("track_memory_s", TRACK_MEMORY_S))
        # A config without the key (a run.json written before the parameter existed) ran the
        # constant-velocity tracker.
        motion_model = str(config.get("tracker_motion_model", "cv"))
        if motion_model not in TRACKER_MOTION_MODELS:
            raise ValueError(f"tracker_motion_model must be one of {', '.join(TRACKER_MOTION_MODELS)}")
        # A config without the key ran without a validation gate.
        gate = str(config.get("tracker_gate", "none"))
        if gate not in TRACKER_GATES:
            raise ValueError(f"tracker_gate must be one of {', '.join(TRACKER_GATES)}")
        gate_chi2 = None if gate == "none" else GATE_CHI2
        precise = gate == "precise"
        self.tracker: KalmanTracker | ImmTracker = (
            ImmTracker(memory_s=memory_s, gate_chi2=gate_chi2, gate_precise_only=precise)
            if motion_model == "imm"
            else KalmanTracker(memory_s=memory_s, gate_chi2=gate_chi2, gate_precise_only=precise)
        )
        self._threat_since_s: float | None = None
        self._last_threat_s: float | None = None
        self._last_gap_m = math.inf
        self._path_key: tuple | None = None
        self._path: PathArrays | None = None
        self._spans: list[CrosswalkSpan] = []
        #: ped id -> side of the path (sign of the lateral offset) where the track was first seen.
        self._first_side: dict[str, float] = {}
        #: (tls id, state) of the last signal delivered: inside the junction (past the stop line) the
        #: feed names the next signal or none, and the state the ego entered on still tells whether the
        #: crosswalks it turns across may show walk.
        self._entered_on: tuple[str, str] | None = None

    def sensors(self) -> list[str]:
        """The three detection sources; the route its corridor follows; the crosswalks it yields at; the
        signal it obeys."""
        return [*KNOWN_SENSORS, "route", "road_map", "traffic_light"]

    def _path_of(self, observation: Observation) -> PathArrays:
        route = observation.route
        if route is None:
            return PathArrays.of(straight_path(observation.ego))
        key = (route.current_lane_id, route.edges)
        if key != self._path_key:
            path = planned_path(route)
            self._path_key = key
            self._path = PathArrays.of(path) if path is not None else None
            self._spans = self._crosswalks(self._path, observation.road_map, observation.ego)
        return self._path if self._path is not None else PathArrays.of(straight_path(observation.ego))

    def _crosswalks(
        self, path: PathArrays | None, road_map: RoadMap | None, ego: EgoState
    ) -> list[CrosswalkSpan]:
        if path is None or road_map is None:
            return []
        return crosswalk_spans(path, road_map, ego.width_m / 2 + self.lateral_margin_m)

    def _crosswalk_threat(
        self, track: Track, s_m: float, lat_m: float, ego_s_m: float, observation: Observation
    ) -> Threat | None:
        """Yielding: the pedestrian on a crosswalk ahead who walks towards the corridor or stands in it,
        or on it or at its kerb while it may show walk, until they are across the corridor."""
        ego = observation.ego
        half_width = ego.width_m / 2 + self.lateral_margin_m
        side = self._first_side.setdefault(track.ped_id, math.copysign(1.0, lat_m))
        across = math.copysign(1.0, lat_m) != side and abs(lat_m) > half_width
        if across:
            return None
        front_m = ego_s_m + ego.length_m / 2
        reach_m = max(ego.speed_mps * self.horizon_s, CROSSWALK_LOOKAHEAD_M)
        for span in self._spans:
            gap_m = span.enter_m - front_m
            if gap_m < 0 or gap_m > reach_m:
                continue
            # Too close to stop short of it even at the hardest braking: going on clears it sooner.
            if ego.speed_mps**2 / (2 * self.max_decel_mps2) > gap_m:
                continue
            distance = distance_to_polygon_m(track.x_m, track.y_m, span.crosswalk.polygon_xy_m)
            if distance > KERB_REACH_M:
                continue
            tls = span.crosswalk.tls_id
            walk = tls == "" or self._entered_on == (tls, PERMISSIVE_GREEN)
            # Walking towards the corridor: the lateral offset shrinks.
            towards = track.moving and self._lateral_speed(track, s_m, lat_m) < 0
            on_it = distance == 0.0
            if walk or (on_it and (towards or abs(lat_m) <= half_width)):
                return Threat(track.ped_id, gap_m, 0.0, "crosswalk")
        return None

    def _lateral_speed(self, track: Track, s_m: float, lat_m: float) -> float:
        """Rate of change of the pedestrian's distance from the path (negative: coming closer)."""
        assert self._path is not None
        nx, ny = self._path.normal_at(s_m) if self._spans else (0.0, 0.0)
        return (track.vx_mps * nx + track.vy_mps * ny) * math.copysign(1.0, lat_m)

    def run_step(self, observation: Observation, time_s: float) -> Command:
        ego = observation.ego
        light = observation.traffic_light
        if light is not None:
            self._entered_on = (light.tls_id, light.state)
        elif observation.route is None or not observation.route.current_lane_id.startswith(":"):
            self._entered_on = None  # past the junction, or no feed to tell
        path = self._path_of(observation)
        ego_s_m, first = path.ego_position_m(ego)
        half_width = ego.width_m / 2 + self.lateral_margin_m
        threats: list[Threat] = []
        for track in self.tracker.update(observation.pedestrians, time_s):
            found = path_threat(
                track, ego, path, first, ego_s_m, self.horizon_s, half_width, SIGMA_FACTOR, PREDICTION_STEP_S
            )
            if found is None and self._spans:
                s, lat = path.project(track.x_m, track.y_m, first)
                found = self._crosswalk_threat(track, float(s[0]), float(lat[0]), ego_s_m, observation)
            if found is not None:
                threats.append(found)
        speed = ego.speed_mps
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
        info: dict[str, Any] = {}
        # Brakes only while a threat is there now (a lost pedestrian stays one for the tracker's memory);
        # `clear_hold_s` keeps the reaction time from starting over when a threat flickers, not the brakes.
        braking = (
            bool(threats)
            and self._threat_since_s is not None
            and time_s - self._threat_since_s >= self.reaction_time_s - 1e-9
        )
        if braking:
            room_m = self._last_gap_m - self.stop_margin_m
            needed = speed * speed / (2 * room_m) if room_m > 0.1 else self.max_decel_mps2
            decel = min(self.max_decel_mps2, max(needed, 0.0))
            target = max(0.0, speed - decel * dt)
            info.update(brake_for="pedestrian", decel_mps2=float(decel), threat_gap_m=float(self._last_gap_m))
        elif self._threat_since_s is not None:  # reaction time running, or a threat just gone: hold speed
            target = speed
            info["reacting"] = True
        else:
            target = min(self.cruise_speed_mps, speed + self.resume_accel_mps2 * dt)
        signal = self.signals.demand(observation.traffic_light, speed, time_s)
        if signal.reason:
            info["signal"] = signal.reason
        if target > signal.speed_cap_mps:
            target = speed_under_signal(
                target, speed, signal.speed_cap_mps, signal.room_m, self.max_decel_mps2, dt
            )
            info.setdefault("brake_for", "signal")
        info["braking"] = bool(target < speed - 1e-9)
        return Command(float(target), info)
