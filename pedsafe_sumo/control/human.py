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
- **Resuming**: once no threat has been seen for 0.5 s, back to the cruise speed at 2 m/s^2.

Its parameters are class attributes (a subclass changes them); it reads neither `reaction_time_s` nor
`max_decel_mps2` of the setup config, which the parameter file's [algorithm] section sets for the
reference stack.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pedsafe_sumo.control.agent import Agent, Command, Observation
from pedsafe_sumo.control.reference import (
    CLEAR_HOLD_S,
    HORIZON_S,
    LATERAL_MARGIN_M,
    RESUME_ACCEL_MPS2,
    STOP_MARGIN_M,
    TRACK_WINDOW_S,
    PlannedPathCache,
    Tracker,
    predict_threat,
    predict_threat_on_path,
)

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


def reaction_time_rng(seed: int, stream: int = REACTION_STREAM) -> np.random.Generator:
    """The generator of the driver's reaction time in the episode of `seed`."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(stream,)))


def draw_reaction_time_s(
    seed: int, median_s: float = REACTION_MEDIAN_S, sigma_ln: float = REACTION_SIGMA_LN
) -> float:
    """One driver's perception-reaction time [s]: lognormal, ln RT ~ N(ln median, sigma_ln^2)."""
    return float(reaction_time_rng(seed).lognormal(mean=math.log(median_s), sigma=sigma_ln))


class HumanDriverStack(Agent):
    """An attentive, non-impaired human driver: sees with the onboard camera, reacts after a drawn
    perception-reaction time, brakes with a jerk-limited ramp to 0.774 g."""

    #: The model's parameters (module constants above); a subclass changes them for a sensitivity run,
    #: e.g. Green (2000)'s about 1.5 s for surprise events: `reaction_median_s = 1.5`.
    reaction_median_s = REACTION_MEDIAN_S
    reaction_sigma_ln = REACTION_SIGMA_LN
    brake_max_decel_mps2 = MAX_DECEL_MPS2
    brake_ramp_s = BRAKE_RAMP_S

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
        self._threat_since_s: float | None = None
        self._last_threat_s: float | None = None
        self._last_gap_m = math.inf
        self._decel_mps2 = 0.0  # deceleration applied in the last step [m/s^2]
        self._paths = PlannedPathCache()

    def sensors(self) -> list[str]:
        """The driver's eyes (the onboard camera) and the route the driver means to drive."""
        return ["onboard_camera", "route"]

    def run_step(self, observation: Observation, time_s: float) -> Command:
        path = self._paths.of(observation)
        # eyes only: whatever else might arrive is not the driver's
        seen = [p for p in observation.pedestrians if p.source == "onboard_camera"]
        tracked = self.tracker.update(seen, time_s)
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
        if reacted:
            room_m = self._last_gap_m - self.stop_margin_m
            needed = speed * speed / (2 * room_m) if room_m > 0.1 else self.max_decel_mps2
            # the pedal goes down at the ramp's jerk and comes back at once when less is needed
            wanted = min(self.max_decel_mps2, max(needed, 0.0))
            self._decel_mps2 = min(wanted, self._decel_mps2 + self.jerk_mps3 * dt)
            target = max(0.0, speed - self._decel_mps2 * dt)
            info = {"braking": True, "decel_mps2": self._decel_mps2, "threat_gap_m": self._last_gap_m}
            return Command(target, info)
        self._decel_mps2 = 0.0
        if self._threat_since_s is not None:  # seen, still reacting: foot stays where it was
            return Command(
                speed, {"braking": False, "reacting": True, "reaction_time_s": self.reaction_time_s}
            )
        return Command(min(self.cruise_speed_mps, speed + self.resume_accel_mps2 * dt), {"braking": False})
