"""A careful human driver: attentive, not impaired, eyes on the road, as a baseline beside the AD stack.

Model card: docs/human_driver.md. In short:

- **Perception**: the onboard camera only, standing for the driver's eyes (its field of view, range and
  occlusion rules, docs/perception.md); no LiDAR and no V2I, so the driver is the same under both
  conditions. The route feed gives the path the driver means to drive (a driver knows where they go).
- **Noticing a threat**: the reference stack's rule (control/reference.py): a perceived pedestrian,
  moved ahead at constant velocity, who enters the corridor of the planned path within 4 s.
- **Perception-reaction time**: one draw per episode from a lognormal fitted to the brake reaction
  times of drivers surprised by an unexpected braking signal (Johansson & Rumar 1971, Human Factors
  13(1):23-27: corrected median 0.9 s, 25 % of drivers slower than 1.2 s): ln RT ~ N(ln 0.9, 0.4265^2),
  0.4265 = ln(1.2 / 0.9) / 0.6745 (0.6745: the standard normal's 75th percentile). The draw comes from
  the episode seed of the setup config (its own numpy stream, REACTION_STREAM), so the same episode
  gives the same driver under SV and V2I.
- **Braking**: after the reaction time the deceleration rises linearly (jerk-limited) to at most
  0.774 g = 7.59 m/s^2 in 0.6 s, the emergency braking of the competent and careful human driver of UN
  Regulation No. 157 (ALKS), Annex 4, Appendix 3; it asks no more than the deceleration that stops the
  car 2 m short of the pedestrian (like the reference stack) and falls back at once when less is needed.
- **Memory**: a pedestrian the driver has seen and who goes out of sight (behind a vehicle, or lost
  against a background of their own colour) is kept in mind for MEMORY_S (2 s), moved on at the velocity
  last seen, and stays a threat while so predicted; a threat already noticed keeps its reaction under
  way through the gap rather than starting it over.
- **Resuming**: once no threat has been seen or remembered for 0.5 s, back to the cruise speed at
  2 m/s^2.
- **Crosswalks**: yields to a pedestrian it sees on a crosswalk its path crosses, until they are across
  its corridor, and to one at the crosswalk's kerb while the crosswalk may show walk (its own green is
  permissive, SUMO's 'g': a turn); the same reaction time and braking as any pedestrian threat. Source:
  Road Traffic Safety Law of the People's Republic of China, art. 47 (stop and yield to pedestrians
  passing on a crosswalk), the rule at the Xueqing site; the geometry is the reference stack's
  (control/baseline.py).
- **Signals**: the signal head as the onboard camera reads it (within its visibility distance); every
  signal change takes effect 1.0 s after it was shown (ITE's perception-reaction time for the yellow
  change interval). At a yellow's onset it stops when v t + v^2 / (2 a) <= the distance to the line
  (t = 1.0 s, a = 3.0 m/s^2), else goes through; a red seen first (no yellow before it) is stopped for
  when v t + v^2 / (2 x 0.774 g) fits; a stop follows the comfortable deceleration.

Its parameters are class attributes (a subclass changes them); it reads neither `reaction_time_s` nor
`max_decel_mps2` of the setup config, which the parameter file's [algorithm] section sets for the
reference stack. Under V2I the signal arrives over the link (0.1 s late): the driver takes from it only
what its eyes would have read at the time it was measured, so SV and V2I give the same driver.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from pedsafe_sumo.control.agent import Agent, Command, Observation, RoadMap, TrafficLightState
from pedsafe_sumo.control.baseline import (
    COMFORTABLE_DECEL_MPS2,
    CROSSWALK_LOOKAHEAD_M,
    KERB_REACH_M,
    STOP_LINE_SHORT_M,
)
from pedsafe_sumo.control.baseline_planner import (
    PERMISSIVE_GREEN,
    RED_STATES,
    YELLOW_STATES,
    CrosswalkSpan,
    PathArrays,
    crosswalk_spans,
    distance_to_polygon_m,
    speed_under_signal,
)
from pedsafe_sumo.control.reference import (
    CLEAR_HOLD_S,
    HORIZON_S,
    LATERAL_MARGIN_M,
    RESUME_ACCEL_MPS2,
    STOP_MARGIN_M,
    TRACK_WINDOW_S,
    PlannedPath,
    PlannedPathCache,
    Threat,
    TrackedPedestrian,
    Tracker,
    predict_threat,
    predict_threat_on_path,
)

#: How long a pedestrian seen and then out of sight is kept in mind [s]. Assumption: drivers keep the
#: position of a road user who has just left their view for seconds (Gugerty 1997, "Situation awareness
#: during driving: explicit and implicit knowledge in dynamic spatial memory", J. Exp. Psychol. Applied
#: 3(1):42-66: recall of recently seen cars' locations stays well above chance for several seconds);
#: 2 s is the reference stack's own track memory (control/kalman_tracker.py), so neither baseline
#: forgets a pedestrian sooner than the other.
MEMORY_S = 2.0
#: Lognormal perception-reaction time: median 0.9 s, 75th percentile 1.2 s (Johansson & Rumar 1971,
#: surprise condition); sigma of ln RT = ln(1.2 / 0.9) / 0.6745 = 0.28768 / 0.67449 = 0.42652.
REACTION_MEDIAN_S = 0.9
REACTION_SIGMA_LN = math.log(1.2 / 0.9) / 0.6744897501960817
#: Emergency braking of UN R157 Annex 4 Appendix 3's careful driver: 0.774 g reached in 0.6 s (its own
#: delay, 0.4 s risk perception + 0.75 s brake reaction, is replaced by the drawn reaction time; where
#: the figures were checked: docs/human_driver.md).
STANDARD_GRAVITY_MPS2 = 9.80665
MAX_DECEL_MPS2 = 0.774 * STANDARD_GRAVITY_MPS2
BRAKE_RAMP_S = 0.6
#: Spawn key of the reaction-time stream under the episode seed: far from the engine's own streams
#: (SeedSequence(seed).spawn(4) uses keys 0 to 3), so the draw is independent of the world's.
REACTION_STREAM = 0x68756D  # "hum"
#: Perception-reaction time to a signal change [s]: 1.0 s, the value of ITE's yellow change interval
#: Y = t + v / (2a + 2Gg) (Institute of Transportation Engineers, "Determining Vehicle Signal Change and
#: Clearance Intervals", 1994) that McGee et al. (NCHRP Report 731, "Guidelines for Timing Yellow and
#: All-Red Intervals at Signalized Intersections", 2012) keep: a signal change is an expected event,
#: so the surprise distribution above does not apply. Also the start-up delay on green (assumption:
#: the same figure).
SIGNAL_REACTION_S = 1.0
#: Distance within which the driver reads the signal head when the feed arrives over V2I [m]: the
#: default of the onboard camera's `perception.raw.signal_visibility_m` (80 m), which the SV feed applies
#: itself; the V2I feed carries the state from any distance.
SIGNAL_VISIBILITY_M = 80.0
#: Signal records kept to look back to the ego's distance from the line when a state was measured [s].
_SIGNAL_HISTORY_S = 3.0


def reaction_time_rng(seed: int, stream: int = REACTION_STREAM) -> np.random.Generator:
    """The generator of the driver's reaction time in the episode of `seed`."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(stream,)))


def draw_reaction_time_s(
    seed: int, median_s: float = REACTION_MEDIAN_S, sigma_ln: float = REACTION_SIGMA_LN
) -> float:
    """One driver's perception-reaction time [s]: lognormal, ln RT ~ N(ln median, sigma_ln^2)."""
    return float(reaction_time_rng(seed).lognormal(mean=math.log(median_s), sigma=sigma_ln))


@dataclass(frozen=True)
class SeenSignal:
    """A signal state as the driver's eyes read it, and where the ego was then."""

    tls_id: str
    state: str
    measured_at_s: float
    distance_m: float  # ego's front to the stop line at measured_at_s [m]
    speed_mps: float  # ego's speed at measured_at_s


@dataclass(frozen=True)
class SignalResponse:
    """What the signal asks of the driver now: the speed allowed (inf: none), why, and the distance the
    ego is to stop within (inf: none)."""

    speed_cap_mps: float
    reason: str  # "", "red", "yellow_stop", "yellow_go", "committed"
    room_m: float = math.inf


class DriverSignals:
    """The careful driver at a signal. Each state read is acted on `reaction_s` after it was shown: at
    a yellow's onset the driver stops when v t + v^2 / (2 a) fits before the line (ITE's yellow-interval
    rule, v and the distance as at the onset), else goes through; at red seen first (no yellow before
    it) the driver stops when v t + v^2 / (2 a_max) fits, else goes through. A decision holds until the
    signal shows green again; stopping follows sqrt(2 a room) down to `stop_short_m` before the line."""

    def __init__(
        self,
        reaction_s: float,
        comfortable_decel_mps2: float,
        max_decel_mps2: float,
        stop_short_m: float,
        visibility_m: float,
    ) -> None:
        self.reaction_s = reaction_s
        self.comfortable_decel_mps2 = comfortable_decel_mps2
        self.max_decel_mps2 = max_decel_mps2
        self.stop_short_m = stop_short_m
        self.visibility_m = visibility_m
        #: step index -> (distance to the line of the signal delivered then [m], tls id, speed [m/s])
        self._own: dict[int, tuple[float, str, float]] = {}
        self._seen: deque[SeenSignal] = deque()
        self._acting: SeenSignal | None = None  # the latest state the driver has reacted to
        self._decided: dict[str, str] = {}  # tls id -> "stop" / "go"

    def observe(
        self, light: TrafficLightState | None, speed_mps: float, time_s: float, step_s: float
    ) -> None:
        """Record this step's delivery. The state is read as of its measurement time, with the ego's
        distance from the line then (the V2I state is `latency` old; the distance it carries is now)."""
        step = round(time_s / step_s)
        if light is not None and math.isfinite(light.distance_m):
            self._own[step] = (light.distance_m, light.tls_id, speed_mps)
        for old in [k for k in self._own if k < step - round(_SIGNAL_HISTORY_S / step_s)]:
            del self._own[old]
        if light is None:
            return
        then = self._own.get(round(light.measured_at_s / step_s))
        if then is None or then[1] != light.tls_id or not 0.0 <= then[0] <= self.visibility_m:
            return
        if self._seen and self._seen[-1].measured_at_s >= light.measured_at_s - 1e-9:
            return  # the same measurement delivered again
        self._seen.append(SeenSignal(light.tls_id, light.state, light.measured_at_s, then[0], then[2]))

    def acting_on(self, time_s: float) -> SeenSignal | None:
        """The latest state read at least `reaction_s` ago: the one the driver acts on now. A yellow or
        red met for the first time is decided here, with the speed and distance of its measurement."""
        while self._seen and self._seen[0].measured_at_s <= time_s - self.reaction_s + 1e-9:
            seen = self._seen.popleft()
            if seen.state not in YELLOW_STATES and seen.state not in RED_STATES:
                self._decided.pop(seen.tls_id, None)
            elif seen.tls_id not in self._decided:
                decel = self.comfortable_decel_mps2 if seen.state in YELLOW_STATES else self.max_decel_mps2
                needed_m = seen.speed_mps * self.reaction_s + seen.speed_mps**2 / (2 * decel)
                self._decided[seen.tls_id] = "stop" if needed_m <= seen.distance_m + 1e-9 else "go"
            self._acting = seen
        return self._acting

    def response(self, light: TrafficLightState | None, time_s: float) -> SignalResponse:
        """The demand of the state acted on, while the ego is before its stop line (the current
        delivery of the same signal tells where the line is now)."""
        acting = self.acting_on(time_s)
        if (
            acting is None
            or light is None
            or light.tls_id != acting.tls_id
            or not math.isfinite(light.distance_m)
            or light.distance_m < 0
        ):
            return SignalResponse(math.inf, "")
        yellow = acting.state in YELLOW_STATES
        if not yellow and acting.state not in RED_STATES:
            return SignalResponse(math.inf, "")
        if self._decided.get(acting.tls_id) == "go":
            return SignalResponse(math.inf, "yellow_go" if yellow else "committed")
        room_m = max(light.distance_m - self.stop_short_m, 0.0)
        cap = math.sqrt(2 * self.comfortable_decel_mps2 * room_m)
        return SignalResponse(cap, "yellow_stop" if yellow else "red", room_m)


class HumanDriverStack(Agent):
    """An attentive, non-impaired human driver: sees with the onboard camera, reacts after a drawn
    perception-reaction time, brakes with a jerk-limited ramp to 0.774 g, yields at crosswalks, obeys
    the signals it reads."""

    #: The model's parameters (module constants above); a subclass changes them for a sensitivity run,
    #: e.g. Green (2000)'s about 1.5 s for surprise events: `reaction_median_s = 1.5`.
    reaction_median_s = REACTION_MEDIAN_S
    reaction_sigma_ln = REACTION_SIGMA_LN
    brake_max_decel_mps2 = MAX_DECEL_MPS2
    brake_ramp_s = BRAKE_RAMP_S
    signal_reaction_s = SIGNAL_REACTION_S
    comfortable_decel_mps2 = COMFORTABLE_DECEL_MPS2
    signal_visibility_m = SIGNAL_VISIBILITY_M
    memory_s = MEMORY_S

    def setup(self, config: dict[str, Any]) -> None:
        self.cruise_speed_mps = float(config["initial_speed_mps"])
        self.reaction_time_s = draw_reaction_time_s(
            int(config["seed"]), self.reaction_median_s, self.reaction_sigma_ln
        )
        self.max_decel_mps2 = float(self.brake_max_decel_mps2)
        self.jerk_mps3 = self.max_decel_mps2 / self.brake_ramp_s if self.brake_ramp_s > 0 else math.inf
        self.horizon_s = HORIZON_S
        self.lateral_margin_m = LATERAL_MARGIN_M
        self.stop_margin_m = STOP_MARGIN_M
        self.resume_accel_mps2 = RESUME_ACCEL_MPS2
        self.clear_hold_s = CLEAR_HOLD_S
        self.tracker = Tracker(TRACK_WINDOW_S)
        self.signals = DriverSignals(
            self.signal_reaction_s,
            self.comfortable_decel_mps2,
            self.max_decel_mps2,
            STOP_LINE_SHORT_M,
            self.signal_visibility_m,
        )
        self._threat_since_s: float | None = None
        self._last_threat_s: float | None = None
        self._last_gap_m = math.inf
        self._decel_mps2 = 0.0  # deceleration applied in the last step [m/s^2]
        #: pedestrian id -> (time last seen [s], their state then): what the driver keeps in mind
        self._last_seen: dict[str, tuple[float, TrackedPedestrian]] = {}
        self._paths = PlannedPathCache()
        self._spans_of: tuple[PlannedPath | None, list[CrosswalkSpan], PathArrays | None] = (None, [], None)
        #: ped id -> side of the path (sign of the lateral offset) where the driver first saw them.
        self._first_side: dict[str, float] = {}

    def sensors(self) -> list[str]:
        """The driver's eyes (the onboard camera), the route the driver means to drive, the crosswalks
        it knows to yield at, and the signal head ahead (read within the camera's visibility)."""
        return ["onboard_camera", "route", "road_map", "traffic_light"]

    def _spans(self, path: PlannedPath | None, road_map: RoadMap | None, half_width_m: float):
        """The crosswalks the corridor crosses, worked out once per planned path."""
        if path is None or road_map is None:
            return [], None
        if self._spans_of[0] is not path:
            arrays = PathArrays.of(path)
            self._spans_of = (path, crosswalk_spans(arrays, road_map, half_width_m), arrays)
        return self._spans_of[1], self._spans_of[2]

    def _crosswalk_threat(
        self,
        ped: TrackedPedestrian,
        spans: list[CrosswalkSpan],
        arrays: PathArrays,
        observation: Observation,
        walk_tls: tuple[str, str] | None,
    ) -> Threat | None:
        """Yielding: a pedestrian on a crosswalk ahead, or at its kerb while it may show walk, until
        they are across the corridor (art. 47: stop and yield to pedestrians passing on a crosswalk)."""
        ego = observation.ego
        half_width = ego.width_m / 2 + self.lateral_margin_m
        ego_s_m, first = arrays.ego_position_m(ego)
        _, lat = arrays.project(ped.x_m, ped.y_m, first)
        lat_m = float(lat[0])
        side = self._first_side.setdefault(ped.ped_id, math.copysign(1.0, lat_m))
        if math.copysign(1.0, lat_m) != side and abs(lat_m) > half_width:
            return None  # across the corridor
        front_m = ego_s_m + ego.length_m / 2
        reach_m = max(ego.speed_mps * self.horizon_s, CROSSWALK_LOOKAHEAD_M)
        for span in spans:
            gap_m = span.enter_m - front_m
            if gap_m < 0 or gap_m > reach_m:
                continue
            # Too close to stop short of it even at the hardest braking: going on clears it sooner.
            if ego.speed_mps**2 / (2 * self.max_decel_mps2) > gap_m:
                continue
            distance = distance_to_polygon_m(ped.x_m, ped.y_m, span.crosswalk.polygon_xy_m)
            tls = span.crosswalk.tls_id
            walk = tls == "" or walk_tls == (tls, PERMISSIVE_GREEN)
            if distance == 0.0 or (walk and distance <= KERB_REACH_M):
                return Threat(ped.ped_id, gap_m=gap_m, time_s=0.0)
        return None

    def _with_remembered(self, tracked: list[TrackedPedestrian], time_s: float) -> list[TrackedPedestrian]:
        """The pedestrians seen now, and those seen within memory_s and out of sight now, moved on at
        the velocity last seen."""
        for ped in tracked:
            self._last_seen[ped.ped_id] = (time_s, ped)
        seen_now = {ped.ped_id for ped in tracked}
        remembered = []
        for ped_id, (seen_s, ped) in list(self._last_seen.items()):
            if ped_id in seen_now:
                continue
            age_s = time_s - seen_s
            if age_s > self.memory_s + 1e-9:
                del self._last_seen[ped_id]
                continue
            remembered.append(
                TrackedPedestrian(
                    ped_id, ped.x_m + ped.vx_mps * age_s, ped.y_m + ped.vy_mps * age_s, ped.vx_mps, ped.vy_mps
                )
            )
        return [*tracked, *remembered]

    def run_step(self, observation: Observation, time_s: float) -> Command:
        path = self._paths.of(observation)
        ego = observation.ego
        speed = ego.speed_mps
        dt = observation.step_length_s
        light = observation.traffic_light
        self.signals.observe(light, speed, time_s, dt)
        signal = self.signals.response(light, time_s)
        acting = self.signals.acting_on(time_s)
        # The signal the ego entered the junction on tells whether the crosswalks it turns across may
        # show walk; it holds while the ego is on the junction's internal lanes.
        on_junction = observation.route is not None and observation.route.current_lane_id.startswith(":")
        before_line = light is not None and acting is not None and light.tls_id == acting.tls_id
        walk_tls = (
            (acting.tls_id, acting.state) if acting is not None and (before_line or on_junction) else None
        )
        # eyes only: whatever else might arrive is not the driver's
        seen = [p for p in observation.pedestrians if p.source == "onboard_camera"]
        tracked = self._with_remembered(self.tracker.update(seen, time_s), time_s)
        spans, arrays = self._spans(path, observation.road_map, ego.width_m / 2 + self.lateral_margin_m)
        threats = []
        for ped in tracked:
            if path is None:
                found = predict_threat(observation, ped, self.horizon_s, self.lateral_margin_m)
            else:
                found = predict_threat_on_path(observation, ped, path, self.horizon_s, self.lateral_margin_m)
            if found is None and spans and arrays is not None:
                found = self._crosswalk_threat(ped, spans, arrays, observation, walk_tls)
            if found is not None:
                threats.append(found)
        if threats:
            self._last_gap_m = min(t.gap_m for t in threats)
            self._last_threat_s = time_s
            if self._threat_since_s is None:
                self._threat_since_s = time_s
        elif self._last_threat_s is not None and time_s - self._last_threat_s > self.clear_hold_s:
            self._threat_since_s = self._last_threat_s = None
            self._last_gap_m = math.inf

        reacted = (
            self._threat_since_s is not None and time_s - self._threat_since_s >= self.reaction_time_s - 1e-9
        )
        info: dict[str, Any] = {}
        if reacted:
            room_m = self._last_gap_m - self.stop_margin_m
            needed = speed * speed / (2 * room_m) if room_m > 0.1 else self.max_decel_mps2
            # the pedal goes down at the ramp's jerk and comes back at once when less is needed
            wanted = min(self.max_decel_mps2, max(needed, 0.0))
            self._decel_mps2 = min(wanted, self._decel_mps2 + self.jerk_mps3 * dt)
            target = max(0.0, speed - self._decel_mps2 * dt)
            info.update(decel_mps2=self._decel_mps2, threat_gap_m=self._last_gap_m, brake_for="pedestrian")
        else:
            self._decel_mps2 = 0.0
            if self._threat_since_s is not None:  # seen, still reacting: foot stays where it was
                target = speed
                info.update(reacting=True, reaction_time_s=self.reaction_time_s)
            else:
                target = min(self.cruise_speed_mps, speed + self.resume_accel_mps2 * dt)
        if signal.reason:
            info["signal"] = signal.reason
        if target > signal.speed_cap_mps:
            target = speed_under_signal(
                target, speed, signal.speed_cap_mps, signal.room_m, self.max_decel_mps2, dt
            )
            info.setdefault("brake_for", "signal")
        info["braking"] = bool(reacted or target < speed - 1e-9)
        return Command(float(target), info)
