"""The safety-critical scenarios, as frozen data in one registry.

`--scenario NAME` is a lookup in SCENARIOS; `--set key=value` replaces fields of the spec (an unknown
key or a value out of range is an error). `draw_episode(spec, approach, seed, ...)` turns a spec and
a seed into one concrete initial world (EpisodeSetup): the same seed gives the same world, whatever
the condition (SV or V2I) it is then run under.

Staging (see scenarios/geometry.py and docs/engine.md): the occluder stands in the kerb lane of the
watched approach; the ego drives the lane next to it on the side the pedestrian crosses towards (the
pedestrian comes from the kerb-side sidewalk and crosses towards the median). Every staging is placed in
the junction's real signal program (scenarios/signals.py): the ego has green in every scenario.
- crossing: the pedestrian crosses on the crosswalk at the stop line against the red (red-light running
  by pedestrians, Zhu et al. 2021), stepping out in front of a black vehicle stopped at the stop line in
  the kerb lane (the head of a short queue), which hides them from the ego (the "multiple threat"
  crosswalk crash). The kerb lane carries the right turn: its head vehicle waits at the stop line on
  green, as right-turners do, for the pedestrians on the crosswalk of the road it turns into (the
  program gives that crosswalk its walk signal with the approach's green); the queue waits behind it;
- jaywalking: mid-block, 30-45 m before the crosswalk (no signal: ped_signal none), through the gap
  between vehicles queued or parked in the kerb lane; the ego cruises at a stable speed on green;
- background_blending: standing just behind the rear bumper of a vehicle waiting at the stop line in
  the kerb lane (a right-turner yielding, as in crossing), closer to it than the LiDAR can separate and
  dressed in its colour, so that seen from the ego the vehicle is right behind them, then crossing
  towards the median beside the crosswalk while it shows red.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import sumolib

from pedsafe_sumo.sampling.draws import Draws, as_draws
from pedsafe_sumo.scenarios.geometry import Approach, Turn, lane_pos_to_offset_m, path_pos_m
from pedsafe_sumo.scenarios.oncoming import OncomingPath, placement, sight_line_pos_m
from pedsafe_sumo.scenarios.signals import (
    NO_LINK,
    SIGNAL_STATES,
    JunctionSignals,
    SignalStagingError,
    draw_cycle_start_s,
)

#: Car body colours drawn for occluders and waiting vehicles (RGB 0-255): white, black, silver, grey,
#: red, blue - the common colours of the Beijing fleet.
CAR_COLOURS_RGB = (
    (235, 235, 235),
    (20, 20, 20),
    (192, 192, 192),
    (110, 110, 110),
    (170, 25, 30),
    (30, 60, 150),
)
#: Clothing colours for pedestrians who are not blending: saturated and dark/bright garments.
CLOTHING_COLOURS_RGB = (
    (200, 40, 40),
    (40, 80, 180),
    (40, 140, 60),
    (230, 200, 40),
    (240, 240, 240),
    (30, 30, 30),
)
OCCLUDER_BLACK_RGB = (20, 20, 20)
EGO_BLUE_RGB = (30, 110, 255)


#: Scenario fields that hold text; every other field is a number.
STRING_FIELDS = (
    "placement", "ego_speed_fit", "occluder_class", "roadside_units", "ego_signal", "ped_signal", "turn",
    "ped_start_corner", "ped_signal_hold", "waiting_vehicle_class", "approach",
)  # fmt: skip


class ScenarioError(ValueError):
    """Unknown scenario, unknown parameter, or a parameter out of range."""


@dataclass(frozen=True)
class VehicleSize:
    length_m: float
    width_m: float
    height_m: float


#: Body sizes of the vehicle classes in the scenes [m]. Height decides what a roof LiDAR (1.9 m) and a
#: 1.6 m camera see over: a 1.5 m car hides a pedestrian's legs only, an SUV or van hides them whole.
VEHICLE_CLASSES = {
    "car": VehicleSize(4.6, 1.8, 1.5),
    "suv": VehicleSize(4.8, 1.9, 1.75),
    "van": VehicleSize(5.0, 1.95, 2.0),
}
#: Shares of the classes among queued and waiting vehicles (assumption: Beijing urban fleet, where
#: SUVs and MPVs make up about a third of new passenger cars).
QUEUE_CLASS_WEIGHTS = {"car": 0.55, "suv": 0.35, "van": 0.10}


#: Upper bound of every numeric scenario field, with why: above it a value stages no meaningful scene,
#: or makes an episode (or the drawing of one) run for ever. `--set` beyond one is refused in one line.
SPEC_UPPER_BOUNDS: dict[str, tuple[float, str]] = {
    # |offset|: at 10 s the ego starts 100-200 m away at urban speeds, the length of the approach.
    "conflict_offset_max_s": (10.0, "the ego would start beyond the approach"),
    "ped_start_delay_s": (60.0, "twice the default episode length"),
    "midblock_distance_max_m": (200.0, "longer than the study site's approach (182 m)"),
    "parked_gap_max_m": (20.0, "a gap of four cars is no longer a gap between queued vehicles"),
    # 20 vehicles with their gaps fill 100-160 m: the whole approach; each is staged in SUMO.
    "queue_vehicles": (20.0, "20 queued vehicles fill the study site's 182 m approach"),
    "queue_gap_max_m": (20.0, "a queue with gaps of four cars is no queue"),
    "blend_gap_max_m": (5.0, "ten times the LiDAR cluster tolerance: no longer blending"),
    # The ego's vehicle type has maxSpeed 50 m/s (sim/episode.py): SUMO would cap anything above it.
    "ego_speed_max_mps": (50.0, "the ego's vehicle type is capped at 50 m/s (180 km/h)"),
    # 600 s at 0.05 s steps are 12,000 steps; the default is 30 s.
    "time_limit_s": (600.0, "20 times the default 30 s episode"),
    # The warm-up draws warmup + time limit seconds of demand on every entering lane.
    "background_warmup_s": (600.0, "vehicles that entered 10 minutes before have long left the site"),
    # The signal must hold its state this long after the staged conflict: a fixed-time cycle is rarely
    # longer than 180 s, so no start point in the cycle could satisfy a longer hold.
    "signal_hold_after_s": (180.0, "longer than a signal cycle: no start point in the cycle satisfies it"),
    # Beyond a car length onto the road turned into, the leader is no longer across the crosswalk.
    "turn_leader_front_max_m": (5.0, "a car length: the leader would have left the crosswalk"),
}


@dataclass(frozen=True)
class ScenarioSpec:
    name: str
    description: str
    #: "crosswalk", "midblock" or "behind_waiting_vehicle"
    placement: str
    #: Which lognormal speed fit the ego's initial speed comes from: "intersection" or "non_intersection".
    ego_speed_fit: str
    #: The ego's front reaches the pedestrian's path this long after the pedestrian reaches the centre
    #: of the ego's lane, if nobody reacts (uniform draw; negative: before) [s]. Like Euro NCAP's AEB
    #: pedestrian tests, every episode is on a collision course: within +-0.6 s a 1.4 m/s pedestrian is
    #: less than 0.9 m (half the car's width) from the lane centre when the car arrives. Wider windows
    #: add episodes that end safely whatever the AD stack does.
    conflict_offset_min_s: float = -0.6
    conflict_offset_max_s: float = 0.6
    #: Pedestrian waits this long before stepping off the kerb [s].
    ped_start_delay_s: float = 1.0
    #: Distance of the mid-block crossing line before the crosswalk (jaywalking) [m].
    midblock_distance_min_m: float = 30.0
    midblock_distance_max_m: float = 45.0
    #: Gap between the two queued/parked vehicles the jaywalker steps out between [m].
    parked_gap_min_m: float = 1.2
    parked_gap_max_m: float = 2.5
    #: Vehicles queued in the kerb lane behind the occluder (crossing) or upstream of the gap
    #: (jaywalking). One car stopped at the stop line hides the kerb from the next lane only once the
    #: ego is within ~19 m; a queue of three hides it from ~70 m (the sight line to the kerb crosses
    #: the kerb lane 40-70 % of the way there).
    queue_vehicles: float = 3
    #: Bumper-to-bumper gaps inside the queue [m].
    queue_gap_min_m: float = 1.5
    queue_gap_max_m: float = 3.0
    #: Gap between the blending pedestrian's body circle and the waiting vehicle's rear [m]. Background
    #: blending as the paper defines it (issue 13 item 3): the LiDAR cannot separate them. It merges
    #: them when a return on the body lies within the cluster tolerance (0.5 m) of one on the vehicle;
    #: the body's returns face the ego, the nearest to the vehicle at the silhouette's edges, 0.3 m (the
    #: body radius) plus the gap in front of the bumper, plus up to ~0.2 m where the 0.2 deg azimuth
    #: step misses the very edge at 30-40 m. So only a circle touching the bumper stays merged; the
    #: circle is deeper than a standing adult (chest depth about 0.25-0.3 m), so this is a person with
    #: their back about 0.15 m from it. Measured at the start, under SV: 0 of 30 detected by the LiDAR
    #: centred at gap 0, 8 of 30 at 0-0.1 m, 27 of 30 at the former 0.1-0.4 m (docs/engine.md).
    blend_gap_min_m: float = 0.0
    blend_gap_max_m: float = 0.0
    #: Ego initial speeds outside this range are clipped (the lognormal tails reach 1.5 and 25 m/s) [m/s].
    ego_speed_min_mps: float = 2.0
    ego_speed_max_mps: float = 20.0
    #: The episode ends at this time at the latest [s].
    time_limit_s: float = 30.0
    #: Class of the black occluder at the head of the queue (crossing), from VEHICLE_CLASSES.
    occluder_class: str = "suv"
    #: Background traffic from the demand model on every other entering lane (1 = on, 0 = off), with
    #: vehicles that would have entered up to `background_warmup_s` before the start already on the road.
    background_traffic: float = 1
    background_warmup_s: float = 60.0
    #: Roadside camera poles (POI ids of the site's rsu.add.xml, comma-separated) whose detections the
    #: V2I condition receives. As in the paper's scenario diagrams, each scenario has the pole that
    #: watches it: the corner pole for crossing and jaywalking; for background blending also the
    #: far-side pole, because from the corner the waiting vehicle hides the pedestrian behind it.
    roadside_units: str = "rsu_camera_0"
    #: The signal each road user has at the conflict (green, yellow, red or none), from the junction's
    #: program (scenarios/signals.py): the episode starts at a point of the cycle where the ego's and the
    #: pedestrian's signals show these from the start until `signal_hold_after_s` after the staged
    #: conflict. The ego has green in every scenario: a straight-through ego never meets red by accident.
    ego_signal: str = "green"
    #: crossing: the pedestrian crosses against the red (red-light running by pedestrians, the violation
    #: the paper cites, Zhu et al. 2021); none: no signal controls where they cross (mid-block).
    ped_signal: str = "red"
    #: How long after the staged conflict (the ego's front at the conflict point at its initial speed) the
    #: signal states must still hold [s]: the +-0.6 s conflict window plus a reaction (assumption).
    signal_hold_after_s: float = 2.0
    #: Turning scenarios (placement "turn"): "right" or "left", and the end of the crosswalk over the
    #: road turned into that the pedestrian starts from ("near": nearer the approach's stop line, the
    #: corner a right-turner turns around).
    turn: str = ""
    ped_start_corner: str = "near"
    #: How long the pedestrian's signal must show `ped_signal`: "conflict" from stepping off until after
    #: the conflict (crossing against the red all the way); "step_off" when they step off only (a
    #: pedestrian who started on the walk signal may still be on the crosswalk in the clearance
    #: interval that follows it, as the law allows).
    ped_signal_hold: str = "conflict"
    #: Class of the vehicle the blending pedestrian stands behind ("" draws it like a queued vehicle).
    waiting_vehicle_class: str = ""
    #: Turning scenarios: a vehicle of class `occluder_class` turning ahead of the ego on the same path
    #: and at the same speed (1), or none (0). At the start it is leaving the junction, its front this far
    #: onto the road turned into (uniform draw) [m] and its body across the crosswalk, between the
    #: pedestrian at its far end and the ego; the pedestrian steps off `ped_start_delay_s` after its rear
    #: has passed them (docs/engine.md, "Turning scenarios").
    turn_leader: float = 0
    turn_leader_front_min_m: float = 0.1
    turn_leader_front_max_m: float = 1.0
    #: Turning scenarios: a vehicle of class `occluder_class` coming the other way (the opposite approach's
    #: median lane, straight on, at the ego's speed) whose body is, at the start, across the line of sight
    #: from the ego's roof sensor to the pedestrian (1), or none (0). Its signal must show green from the
    #: start until `signal_hold_after_s` after the staged conflict, so a program that stops the opposing
    #: approach while the ego turns (split phasing, as on Xueqing) cannot stage it (scenarios/oncoming.py).
    oncoming_vehicle: float = 0
    #: The arm the ego comes in on (N, E, S or W; batch --approach): staging, poles and signals follow
    #: it. "" is the site's own approach, the one its first roadside pole watches.
    approach: str = ""

    @property
    def roadside_unit_ids(self) -> tuple[str, ...]:
        return tuple(part.strip() for part in self.roadside_units.split(","))

    def __post_init__(self) -> None:
        checks = [
            (self.placement in ("crosswalk", "midblock", "behind_waiting_vehicle", "turn"), "placement"),
            ((self.placement == "turn") == (self.turn in ("right", "left")), "turn is right or left (only)"),
            (self.ped_start_corner in ("near", "far"), "ped_start_corner is near or far"),
            (self.ped_signal_hold in ("conflict", "step_off"), "ped_signal_hold is conflict or step_off"),
            (
                self.waiting_vehicle_class in ("", *VEHICLE_CLASSES),
                f"waiting_vehicle_class in {sorted(VEHICLE_CLASSES)} or empty",
            ),
            (self.approach in ("", "N", "E", "S", "W"), "approach is N, E, S, W or empty"),
            (self.ego_speed_fit in ("intersection", "non_intersection"), "ego_speed_fit"),
            (self.occluder_class in VEHICLE_CLASSES, f"occluder_class in {sorted(VEHICLE_CLASSES)}"),
            (
                self.conflict_offset_min_s <= self.conflict_offset_max_s,
                "conflict_offset_min_s <= conflict_offset_max_s",
            ),
            (self.ped_start_delay_s >= 0, "ped_start_delay_s >= 0"),
            (
                0 < self.midblock_distance_min_m <= self.midblock_distance_max_m,
                "0 < midblock_distance_min_m <= max",
            ),
            (0 < self.parked_gap_min_m <= self.parked_gap_max_m, "0 < parked_gap_min_m <= parked_gap_max_m"),
            (
                self.queue_vehicles >= 1 and float(self.queue_vehicles).is_integer(),
                "queue_vehicles is a whole number >= 1",
            ),
            (0 < self.queue_gap_min_m <= self.queue_gap_max_m, "0 < queue_gap_min_m <= queue_gap_max_m"),
            (0 <= self.blend_gap_min_m <= self.blend_gap_max_m, "0 <= blend_gap_min_m <= blend_gap_max_m"),
            (
                0 < self.ego_speed_min_mps <= self.ego_speed_max_mps,
                "0 < ego_speed_min_mps <= ego_speed_max_mps",
            ),
            (self.time_limit_s > 0, "time_limit_s > 0"),
            (self.background_traffic in (0, 1), "background_traffic is 0 or 1"),
            (self.background_warmup_s >= 0, "background_warmup_s >= 0"),
            (all(self.roadside_unit_ids), "roadside_units is a comma-separated list of POI ids"),
            (self.ego_signal in SIGNAL_STATES, f"ego_signal in {SIGNAL_STATES}"),
            (self.ped_signal in SIGNAL_STATES, f"ped_signal in {SIGNAL_STATES}"),
            (self.signal_hold_after_s >= 0, "signal_hold_after_s >= 0"),
            (self.turn_leader in (0, 1), "turn_leader is 0 or 1"),
            (self.turn_leader == 0 or self.placement == "turn", "turn_leader only in a turning scenario"),
            (self.oncoming_vehicle in (0, 1), "oncoming_vehicle is 0 or 1"),
            (
                self.oncoming_vehicle == 0 or self.placement == "turn",
                "oncoming_vehicle only in a turning scenario",
            ),
            # libsumo 1.28 crashed (segmentation fault) in the first step of the next episode when one ended
            # before a step had followed the oncoming vehicle's move onto the junction (time limit 0.05 s).
            (
                self.oncoming_vehicle == 0 or self.time_limit_s >= 0.1,
                "time_limit_s >= 0.1 with an oncoming vehicle (two steps: libsumo crashed after one)",
            ),
            (
                0 < self.turn_leader_front_min_m <= self.turn_leader_front_max_m,
                "0 < turn_leader_front_min_m <= turn_leader_front_max_m",
            ),
        ]
        for ok, rule in checks:
            if not ok:
                raise ScenarioError(f"scenario '{self.name}': {rule} does not hold")
        bounds = [(key, getattr(self, key), bound, why) for key, (bound, why) in SPEC_UPPER_BOUNDS.items()]
        low, why = (
            -SPEC_UPPER_BOUNDS["conflict_offset_max_s"][0],
            SPEC_UPPER_BOUNDS["conflict_offset_max_s"][1],
        )
        if self.conflict_offset_min_s < low:
            raise ScenarioError(
                f"scenario '{self.name}': conflict_offset_min_s must be at least {low:g} ({why}), "
                f"got {self.conflict_offset_min_s:g}"
            )
        for key, value, bound, why in bounds:
            if value > bound:
                raise ScenarioError(
                    f"scenario '{self.name}': {key} must be at most {bound:g} ({why}), got {value:g}"
                )

    def with_overrides(self, overrides: Mapping[str, str | float]) -> ScenarioSpec:
        """A copy with fields replaced from --set key=value pairs (values parsed as numbers)."""
        names = {f.name for f in dataclasses.fields(self)} - {"name", "description"}
        changes: dict[str, Any] = {}
        for key, value in overrides.items():
            if key not in names:
                raise ScenarioError(f"unknown scenario parameter '{key}' (known: {', '.join(sorted(names))})")
            if key in STRING_FIELDS:
                changes[key] = str(value)
                continue
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise ScenarioError(f"scenario parameter '{key}' must be a number, got '{value}'") from None
            if not math.isfinite(number):
                raise ScenarioError(f"scenario parameter '{key}' must be finite, got '{value}'")
            changes[key] = number
        return dataclasses.replace(self, **changes)


SCENARIOS: dict[str, ScenarioSpec] = {
    spec.name: spec
    for spec in (
        ScenarioSpec(
            "crossing",
            "a pedestrian crossing against the red on the signalised crosswalk steps out in front of a "
            "black right-turner waiting on green in the kerb lane, which hides them from the ego (green)",
            placement="crosswalk",
            ego_speed_fit="intersection",
            ped_signal="red",
        ),
        ScenarioSpec(
            "jaywalking",
            "a pedestrian crosses mid-block, 30-45 m before the crosswalk, stepping out between vehicles "
            "queued in the kerb lane, while the ego cruises at a stable speed",
            placement="midblock",
            ego_speed_fit="non_intersection",
            ped_signal="none",
        ),
        ScenarioSpec(
            "background_blending",
            "a pedestrian dressed in the colour of a waiting vehicle crosses right behind its rear bumper, "
            "closer to it than the LiDAR cluster tolerance",
            placement="behind_waiting_vehicle",
            ego_speed_fit="intersection",
            ped_signal="red",
            roadside_units="rsu_camera_0,rsu_camera_1",
        ),
        ScenarioSpec(
            "right_turn",
            "the ego turns right on green from the kerb lane behind a vehicle turning ahead of it; a "
            "pedestrian waiting at the far end of the crosswalk of the road they turn into (the refuge "
            "between its carriageways) is hidden by that vehicle as it crosses in front of them, and steps "
            "off with the walk signal once it has passed",
            placement="turn",
            ego_speed_fit="intersection",
            turn="right",
            # From the far end: at the corner the ego turns around no vehicle the program lets move can
            # stand between them and the ego (docs/engine.md, "Turning scenarios").
            ped_start_corner="far",
            turn_leader=1,
            ped_signal="green",
            ped_signal_hold="step_off",
            # China's Road Traffic Safety Law Implementation Regulations, art. 46: at most 30 km/h when
            # turning.
            ego_speed_max_mps=8.33,
            # Staging bound, not a behaviour fit: the pedestrian steps off within the 11 s walk signal
            # that comes with the ego's green, so the ego (starting 3 m before the stop line) must reach
            # the crosswalk within it: at 2.0-2.5 m/s 19 of 1,500 draws could not be staged (protocol
            # paper-v2; paper-v1 had 2.0).
            ego_speed_min_mps=2.5,
            # The corner pole does not see where the pedestrian starts (the west crosswalk's north end);
            # the far-side pole does (network/hosting.py; protocol paper-v3).
            roadside_units="rsu_camera_0,rsu_camera_1",
        ),
        ScenarioSpec(
            "left_turn",
            "the ego turns left on a permissive green from the median lane; a pedestrian crosses the road "
            "it turns into with the walk signal, from the far corner, hidden at the start by a vehicle "
            "coming the other way on the same green; needs a program that lets the opposing approach move "
            "while the ego turns left (a two-phase plan: networks/xueqing_two_phase); Xueqing's split "
            "phasing cannot stage it",
            placement="turn",
            ego_speed_fit="intersection",
            turn="left",
            ped_start_corner="far",
            ped_signal="green",
            ped_signal_hold="step_off",
            # "Hidden by opposing traffic" (issue 13): an oncoming through vehicle, the class of the
            # crossing occluder (scenarios/oncoming.py, docs/engine.md).
            oncoming_vehicle=1,
            # The corner pole does not see where the pedestrian starts (the far end of the crosswalk
            # over the road the ego turns into); the corner pole of that road's approach, which watches
            # that crosswalk, does (network/hosting.py): rsu_camera_0@exit, rsu_camera_0_E from the N.
            roadside_units="rsu_camera_0,rsu_camera_0@exit",
            ego_speed_max_mps=8.33,
            # Staging bound, not a behaviour fit: the ego enters the junction on green and reaches the
            # far crosswalk (about 40 m of turn on Xueqing) within the approach's green (16 s with its
            # yellow-free part); slower left-turners cannot be staged there (issue 13, docs/engine.md).
            ego_speed_min_mps=3.5,
        ),
    )
}


def get_scenario(name: str) -> ScenarioSpec:
    try:
        return SCENARIOS[name]
    except KeyError:
        raise ScenarioError(f"unknown scenario '{name}' (known: {', '.join(SCENARIOS)})") from None


@dataclass(frozen=True)
class PedestrianSetup:
    path_xy: tuple[tuple[float, float], ...]
    start_delay_s: float
    age_years: float
    gender: str
    risk: str
    walking_speed_mps: float
    clothing_rgb: tuple[int, int, int]
    radius_m: float
    height_m: float
    #: People do not walk into a vehicle's body (pedsafe_sumo.behaviour.pedestrian); a test-track dummy
    #: on its platform (the Euro NCAP grid) does: it keeps its speed and path whatever is in its way.
    avoids_vehicle_bodies: bool = True


@dataclass(frozen=True)
class VehicleSetup:
    vehicle_id: str
    lane_id: str
    #: Position of the vehicle's FRONT on its lane (SUMO's convention) [m].
    front_pos_m: float
    speed_mps: float
    colour_rgb: tuple[int, int, int]
    size: VehicleSize
    #: Edges it drives at `speed_mps` (the turning scenarios' leader, on the road it turns into); empty:
    #: it stands on the approach (parked and queued vehicles), or it is the ego (EpisodeSetup.ego_route).
    route: tuple[str, ...] = ()
    #: A junction's internal lane and the position of the front on it where the vehicle stands at the start
    #: (the oncoming vehicle of left_turn): SUMO inserts on `lane_id`, the episode moves it there before the
    #: first step. "": it starts where it is inserted.
    internal_lane_id: str = ""
    internal_pos_m: float = 0.0
    #: > 0: the vehicle stands parked at the kerb beside `lane_id`, its centre this far to the right of
    #: the lane's centre (a one-lane approach: kerb_parking_offset_m); SUMO inserts it on the lane at
    #: `front_pos_m` and parks it in a parking space there (sim/kerb.py). 0: it stands in its lane.
    kerb_offset_m: float = 0.0


@dataclass(frozen=True)
class BackgroundVehicle:
    """A vehicle of the background traffic: enters at `depart_s` (>= 0) at `depart_pos_m` of its route's
    first edge, at its desired speed, and is then driven by SUMO."""

    vehicle_id: str
    route: tuple[str, ...]
    lane_index: int  # SUMO lane index on the first edge
    depart_s: float
    depart_pos_m: float
    desired_speed_mps: float
    speed_factor: float  # desired speed / speed limit of the entering lane
    colour_rgb: tuple[int, int, int]


@dataclass(frozen=True)
class EpisodeSetup:
    """One concrete initial world; identical under SV and V2I for the same seed."""

    scenario: str
    seed: int
    ego: VehicleSetup
    ego_route: tuple[str, ...]
    pedestrian: PedestrianSetup
    parked: tuple[VehicleSetup, ...]
    conflict_xy: tuple[float, float]
    conflict_offset_s: float
    time_limit_s: float
    background: tuple[BackgroundVehicle, ...] = ()
    #: Seconds from the start until the ego's front reaches `conflict_xy` at its initial speed (the
    #: staged conflict; the signal states are placed around it).
    conflict_time_s: float = math.nan
    #: The signalised crossing whose signal faces the pedestrian ("" when none does: mid-block).
    ped_crossing_id: str = ""
    #: Where the junction's signal program stands at the start (None: not staged, e.g. an old case).
    signals: SignalStaging | None = None
    #: The arm the ego comes in on (N, E, S, W; "" in cases written before approaches were recorded).
    approach: str = ""


@dataclass(frozen=True)
class SignalStaging:
    """The junction's traffic light at the start of an episode, and the links of its road users."""

    tls_id: str
    program_id: str
    #: Time of the program's cycle at the episode's t = 0 [s].
    cycle_start_s: float
    #: Link indices (SUMO's linkIndex) of the ego's connection and of the pedestrian's crossing
    #: (signals.NO_LINK when no signal controls where they cross).
    ego_link_index: int
    ped_link_index: int
    #: The right turn of the kerb lane, where the occluders wait (signals.NO_LINK when it has none).
    occluder_link_index: int = NO_LINK


def _extended_shape(approach: Approach, lane_index: int, beyond_m: float = 20.0):
    """The centreline the ego drives from the lane over the crosswalk into the junction: its straight-
    through path as SUMO draws it (the junction's internal lane need not continue the lane straight:
    0.12-0.15 m aside at Xueqing's crosswalk), or the lane continued straight where it has none."""
    lanes = approach.through_paths[lane_index] if approach.through_paths else ()
    if len(lanes) > 1:
        drawn = [tuple(p) for shape, _ in lanes for p in shape]
        return [p for k, p in enumerate(drawn) if k == 0 or math.dist(p, drawn[k - 1]) > 1e-6]
    shape = list(approach.lane_shapes[lane_index])
    (px, py), (qx, qy) = shape[-2], shape[-1]
    norm = math.hypot(qx - px, qy - py)
    shape.append((qx + beyond_m * (qx - px) / norm, qy + beyond_m * (qy - py) / norm))
    return shape


def _lane_pos_of(approach: Approach, lane_index: int, xy: tuple[float, float]) -> float:
    """SUMO distance (lane-length metres) from the start of the lane to the point of its straight-through
    path (the lane, the junction, the road beyond) nearest `xy`: where a front placed by it is drawn
    (see scenarios/geometry.py on lane positions)."""
    return path_pos_m(approach.through_paths[lane_index], xy)


def draw_episode(
    spec: ScenarioSpec,
    approach: Approach,
    seed: int,
    pedestrian_traits: dict,
    ego_speed_mps: float,
    rng: np.random.Generator | Draws,
    turn: Turn | None = None,
    oncoming: OncomingPath | None = None,
) -> EpisodeSetup:
    """Place one episode of `spec` on the approach (for a turning scenario, on `turn`; with an oncoming
    vehicle, on the `oncoming` path).

    `pedestrian_traits` (age_years, gender, risk, walking_speed_mps) and `ego_speed_mps` come from the
    demand model's samplers, drawn from the same seeded `rng` before this is called; the draws here
    (offsets, gaps, colours) follow in a fixed order so the world is a function of the seed alone.
    `rng` may be a Draws (sampling/draws.py): the named draws then go through it, recorded (and under
    importance sampling drawn from its proposal); a bare Generator draws them all nominally.
    """
    draws = as_draws(rng)
    rng = draws.rng
    if spec.placement == "turn":
        if turn is None:
            raise ScenarioError(f"scenario '{spec.name}' needs the geometry of its {spec.turn} turn")
        return _draw_turn_episode(
            spec, approach, turn, seed, pedestrian_traits, ego_speed_mps, draws, oncoming
        )
    ego_size = VEHICLE_CLASSES["car"]
    # The occluders stand in the kerb lane; the pedestrian crosses from the kerb towards the median, so
    # the ego drives the lane next to the kerb lane on that side (lanes are listed kerb to median).
    # On a one-lane approach they stand parked at the kerb beside the lane instead, and the ego drives
    # the lane itself, next to them (kerb_offset_m); the draws are the same.
    kerb_lane = 0
    one_lane = len(approach.lane_ids) == 1
    ego_lane = 0 if one_lane else adjacent_lane(kerb_lane, +1, len(approach.lane_ids))
    kerb_lane_id = approach.lane_ids[kerb_lane]
    ego_speed_mps = float(np.clip(ego_speed_mps, spec.ego_speed_min_mps, spec.ego_speed_max_mps))
    radius_m = 0.3
    height_m = {"m": 1.72, "f": 1.60}.get(pedestrian_traits["gender"], 1.66)
    if pedestrian_traits["age_years"] < 19:
        height_m -= 0.05
    lane_w = approach.lane_width_m
    # Across the road: from the middle of the sidewalk to 1 m beyond the ego lane's far edge.
    kerb_offset_m = -(lane_w / 2 + approach.sidewalk_width_m / 2)
    far_offset_m = (len(approach.lane_ids) - 1) * lane_w + lane_w / 2 + 1.0
    conflict_offset_s = draws.uniform(
        "conflict_offset_s", spec.conflict_offset_min_s, spec.conflict_offset_max_s
    )
    stop_line_pos = approach.lane_lengths_m[kerb_lane]
    parked: list[VehicleSetup] = []
    clothing = CLOTHING_COLOURS_RGB[draws.index("clothing", len(CLOTHING_COLOURS_RGB))]
    class_names = list(QUEUE_CLASS_WEIGHTS)
    class_p = np.array([QUEUE_CLASS_WEIGHTS[c] for c in class_names])

    def random_vehicle(vehicle_id: str, front_pos: float, colour=None) -> VehicleSetup:
        size = VEHICLE_CLASSES[class_names[draws.choice(f"{vehicle_id}.class", class_p)]]
        if colour is None:
            colour = CAR_COLOURS_RGB[draws.index(f"{vehicle_id}.colour", len(CAR_COLOURS_RGB))]
        return VehicleSetup(vehicle_id, kerb_lane_id, front_pos, 0.0, colour, size)

    def queue_behind(first: VehicleSetup, start_index: int) -> None:
        """`queue_vehicles` vehicles queued upstream of `first`, bumper to bumper with small gaps."""
        rear = first.front_pos_m - first.size.length_m
        for k in range(int(spec.queue_vehicles)):
            vehicle_id = f"queued_{start_index + k}"
            front = rear - draws.uniform(f"{vehicle_id}.gap_m", spec.queue_gap_min_m, spec.queue_gap_max_m)
            vehicle = random_vehicle(vehicle_id, front)
            parked.append(vehicle)
            rear = front - vehicle.size.length_m

    if spec.placement == "crosswalk":
        path = approach.crosswalk_path
        # Extend from the crosswalk's kerb end back onto the sidewalk so the pedestrian starts off the road.
        (ax, ay), (bx, by) = path
        ux, uy = (bx - ax) / math.dist(path[0], path[1]), (by - ay) / math.dist(path[0], path[1])
        path = ((ax - ux * 1.0, ay - uy * 1.0), (bx + ux * 1.0, by + uy * 1.0))
        occluder = VehicleSetup(
            "occluder_0",
            kerb_lane_id,
            stop_line_pos - 0.5,
            0.0,
            OCCLUDER_BLACK_RGB,
            VEHICLE_CLASSES[spec.occluder_class],
        )
        parked.append(occluder)
        queue_behind(occluder, 1)
    elif spec.placement == "midblock":
        distance_m = draws.uniform(
            "midblock_distance_m", spec.midblock_distance_min_m, spec.midblock_distance_max_m
        )
        gap_m = draws.uniform("parked_gap_m", spec.parked_gap_min_m, spec.parked_gap_max_m)
        cross_pos = stop_line_pos - distance_m
        path = approach.across(kerb_lane, cross_pos, kerb_offset_m, far_offset_m)
        # Downstream vehicle: its rear gap/2 past the line; upstream: the queue, its head gap/2 before it.
        downstream = random_vehicle("occluder_0", 0.0)
        downstream = dataclasses.replace(
            downstream, front_pos_m=cross_pos + gap_m / 2 + downstream.size.length_m
        )
        upstream = random_vehicle("occluder_1", cross_pos - gap_m / 2)
        parked += [downstream, upstream]
        queue_behind(upstream, 2)
    else:  # behind_waiting_vehicle
        gap_m = draws.uniform("blend_gap_m", spec.blend_gap_min_m, spec.blend_gap_max_m)
        waiting = random_vehicle("waiting_0", stop_line_pos - 0.5)
        if spec.waiting_vehicle_class:
            waiting = dataclasses.replace(waiting, size=VEHICLE_CLASSES[spec.waiting_vehicle_class])
        cross_pos = waiting.front_pos_m - waiting.size.length_m - gap_m - radius_m
        # They already stand right behind the vehicle, centred on its rear: seen from the ego behind
        # them, the vehicle's rear surrounds them on both sides from the first frame. (On its kerb-side
        # half, the LiDAR found the vehicle's returns on one side only and separated them at the start
        # in 3 of 30 episodes even at gap 0; from the sidewalk both onboard sensors saw them before
        # they ever blended.)
        start_offset_m = 0.0
        if one_lane:
            # Behind the car parked at the kerb, centred on its rear as in the kerb lane.
            start_offset_m = -kerb_parking_offset_m(approach, waiting.size)
        path = approach.across(kerb_lane, cross_pos, start_offset_m, far_offset_m)
        parked.append(waiting)
        clothing = waiting.colour_rgb
    if one_lane:
        parked = [
            dataclasses.replace(v, kerb_offset_m=kerb_parking_offset_m(approach, v.size)) for v in parked
        ]

    # Where the pedestrian's path meets the centre of the ego's lane, and when they get there.
    conflict_xy = _crossing_with_lane(approach, ego_lane, path)
    walk_to_conflict_s = math.dist(path[0], conflict_xy) / pedestrian_traits["walking_speed_mps"]
    start_delay_s = spec.ped_start_delay_s
    ego_conflict_pos = _lane_pos_of(approach, ego_lane, conflict_xy)
    arrival_s = start_delay_s + walk_to_conflict_s + conflict_offset_s
    front_pos = ego_conflict_pos - ego_speed_mps * arrival_s
    if front_pos < ego_size.length_m:
        # Not enough road behind the conflict point: hold the pedestrian back instead.
        start_delay_s += (ego_size.length_m - front_pos) / ego_speed_mps
        front_pos = ego_size.length_m
    ego = VehicleSetup("ego", approach.lane_ids[ego_lane], front_pos, ego_speed_mps, EGO_BLUE_RGB, ego_size)
    conflict_time_s = (ego_conflict_pos - front_pos) / ego_speed_mps
    pedestrian = PedestrianSetup(
        path_xy=tuple((float(p[0]), float(p[1])) for p in path),
        start_delay_s=start_delay_s,
        age_years=float(pedestrian_traits["age_years"]),
        gender=str(pedestrian_traits["gender"]),
        risk=str(pedestrian_traits["risk"]),
        walking_speed_mps=float(pedestrian_traits["walking_speed_mps"]),
        clothing_rgb=(int(clothing[0]), int(clothing[1]), int(clothing[2])),
        radius_m=radius_m,
        height_m=height_m,
    )
    return EpisodeSetup(
        scenario=spec.name,
        seed=seed,
        ego=ego,
        ego_route=approach.through_route,
        pedestrian=pedestrian,
        parked=tuple(parked),
        conflict_xy=(float(conflict_xy[0]), float(conflict_xy[1])),
        conflict_offset_s=conflict_offset_s,
        time_limit_s=spec.time_limit_s,
        conflict_time_s=float(conflict_time_s),
        # Mid-block no signal faces the pedestrian; at the stop line (on the crosswalk or just beside
        # it, behind the waiting vehicle) the crosswalk's signal does.
        ped_crossing_id="" if spec.placement == "midblock" else approach.crosswalk_id,
    )


def _pedestrian(traits: dict, clothing, start_delay_s: float, path) -> PedestrianSetup:
    """The pedestrian of an episode (body sizes by gender and age, as in draw_episode)."""
    height_m = {"m": 1.72, "f": 1.60}.get(traits["gender"], 1.66)
    if traits["age_years"] < 19:
        height_m -= 0.05
    return PedestrianSetup(
        path_xy=tuple((float(p[0]), float(p[1])) for p in path),
        start_delay_s=start_delay_s,
        age_years=float(traits["age_years"]),
        gender=str(traits["gender"]),
        risk=str(traits["risk"]),
        walking_speed_mps=float(traits["walking_speed_mps"]),
        clothing_rgb=(int(clothing[0]), int(clothing[1]), int(clothing[2])),
        radius_m=0.3,
        height_m=height_m,
    )


#: SUMO inserts a vehicle before a minor (yielding) link only if it could stop before it: even with the
#: ego's hard insertion decel (sim/episode.py) it refused fronts within 2 m of the stop line at 2-8.3 m/s
#: (measured on Xueqing's right and left turns); 3 m leaves a margin.
TURN_START_BEFORE_STOP_LINE_M = 3.0


def _draw_turn_episode(
    spec: ScenarioSpec,
    approach: Approach,
    turn: Turn,
    seed: int,
    traits: dict,
    ego_speed_mps: float,
    rng: np.random.Generator | Draws,
    oncoming: OncomingPath | None = None,
) -> EpisodeSetup:
    """A turning ego and a pedestrian on the crosswalk over the road it turns into (right_turn,
    left_turn): the pedestrian walks from `ped_start_corner` with the walk signal (the signal staging
    gives it), the ego turns on its green and must yield to them."""
    draws = as_draws(rng)
    rng = draws.rng
    ego_size = VEHICLE_CLASSES["car"]
    ego_speed_mps = float(np.clip(ego_speed_mps, spec.ego_speed_min_mps, spec.ego_speed_max_mps))
    conflict_offset_s = draws.uniform(
        "conflict_offset_s", spec.conflict_offset_min_s, spec.conflict_offset_max_s
    )
    clothing = CLOTHING_COLOURS_RGB[draws.index("clothing", len(CLOTHING_COLOURS_RGB))]
    # Drawn after the draws above (and only when there is a leader), so the scenarios without one keep
    # their worlds seed for seed.
    leader_draws = _draw_turn_leader(spec, draws) if spec.turn_leader else None
    oncoming_colour = (
        CAR_COLOURS_RGB[draws.index("oncoming_0.colour", len(CAR_COLOURS_RGB))]
        if spec.oncoming_vehicle
        else None
    )
    near, far = turn.crosswalk_path
    start, end = (near, far) if spec.ped_start_corner == "near" else (far, near)
    # From 1 m back on the sidewalk to 1 m beyond the crosswalk's other end.
    length = math.dist(start, end)
    ux, uy = (end[0] - start[0]) / length, (end[1] - start[1]) / length
    path = ((start[0] - ux, start[1] - uy), (end[0] + ux, end[1] + uy))
    conflict_xy = _crossing_with_polyline(turn.path_xy, path)
    walk_to_conflict_s = math.dist(path[0], conflict_xy) / traits["walking_speed_mps"]
    start_delay_s = spec.ped_start_delay_s
    # In SUMO's lane-length metres along the turn, which the ego's speed covers.
    ego_conflict_pos = path_pos_m(turn.lanes, conflict_xy)
    leader = None
    if leader_draws is not None:
        leader, clear_s = _turn_leader(spec, turn, ego_conflict_pos, ego_speed_mps, *leader_draws)
        # They wait for it: they step off ped_start_delay_s after its rear has passed their body.
        start_delay_s += clear_s
    arrival_s = start_delay_s + walk_to_conflict_s + conflict_offset_s
    front_pos = ego_conflict_pos - ego_speed_mps * arrival_s
    # The ego starts on the approach lane with its whole body on it, TURN_START_BEFORE_STOP_LINE_M
    # before the stop line at the latest.
    latest_m = turn.approach_length_m - TURN_START_BEFORE_STOP_LINE_M
    if front_pos > latest_m:
        # The pedestrian would reach the conflict before the ego could come from the stop line: they
        # wait longer on the kerb instead.
        start_delay_s += (front_pos - latest_m) / ego_speed_mps
        front_pos = latest_m
    if front_pos < ego_size.length_m:
        start_delay_s += (ego_size.length_m - front_pos) / ego_speed_mps
        front_pos = ego_size.length_m
    ego = VehicleSetup(
        "ego", approach.lane_ids[turn.lane_index], front_pos, ego_speed_mps, EGO_BLUE_RGB, ego_size
    )
    others = [leader] if leader is not None else []
    if oncoming_colour is not None:
        if oncoming is None:
            raise ScenarioError(f"scenario '{spec.name}' needs the oncoming through movement of its approach")
        others.append(_oncoming_vehicle(spec, turn, ego, path[0], oncoming, oncoming_colour))
    return EpisodeSetup(
        scenario=spec.name,
        seed=seed,
        ego=ego,
        ego_route=turn.route,
        pedestrian=_pedestrian(traits, clothing, start_delay_s, path),
        parked=tuple(others),
        conflict_xy=(float(conflict_xy[0]), float(conflict_xy[1])),
        conflict_offset_s=conflict_offset_s,
        time_limit_s=spec.time_limit_s,
        conflict_time_s=float((ego_conflict_pos - front_pos) / ego_speed_mps),
        ped_crossing_id=turn.crosswalk_id,
    )


def _draw_turn_leader(spec: ScenarioSpec, draws: Draws) -> tuple[tuple, float]:
    """The leader's colour and how far its front is onto the road turned into, in that order of draws
    (recorded by name, as every draw of the world)."""
    colour = CAR_COLOURS_RGB[draws.index("leader_0.colour", len(CAR_COLOURS_RGB))]
    front_m = draws.uniform("leader_0.front_m", spec.turn_leader_front_min_m, spec.turn_leader_front_max_m)
    return colour, front_m


def _turn_leader(
    spec: ScenarioSpec, turn: Turn, conflict_pos_m: float, speed_mps: float, colour, front_m: float
) -> tuple[VehicleSetup, float]:
    """The vehicle turning ahead of the ego, on the ego's path at the ego's speed with its front `front_m`
    onto the road turned into, and the seconds until its rear has passed the pedestrian's body (0.3 m
    radius; 0 when it already has)."""
    size = VEHICLE_CLASSES[spec.occluder_class]
    rear_before_m = conflict_pos_m - (turn.exit_start_m + front_m - size.length_m)
    leader = VehicleSetup(
        "leader_0", turn.exit_lane_id, front_m, speed_mps, colour, size, route=(turn.route[1],)
    )
    return leader, max(0.0, rear_before_m + 0.3) / speed_mps


def _oncoming_vehicle(
    spec: ScenarioSpec, turn: Turn, ego: VehicleSetup, ped_xy, oncoming: OncomingPath, colour
) -> VehicleSetup:
    """The oncoming through vehicle (class `occluder_class`, at the ego's speed), its centre where its path
    crosses the line of sight from the ego's box centre (where the roof LiDAR is) to the pedestrian at the
    start."""
    size = VEHICLE_CLASSES[spec.occluder_class]
    (shape, length_m) = turn.lanes[0]
    centre_offset_m = lane_pos_to_offset_m(shape, length_m, ego.front_pos_m) - ego.size.length_m / 2
    eye_xy = tuple(sumolib.geomhelper.positionAtShapeOffset(shape, centre_offset_m))
    crossing_m = sight_line_pos_m(oncoming, eye_xy, ped_xy)
    if crossing_m is None:
        raise ScenarioError(
            f"scenario '{spec.name}': the oncoming path ({oncoming.lanes[0].lane_id} straight on) does not "
            "cross the line of sight from the ego to the pedestrian"
        )
    lane_id, pos_m = placement(oncoming, crossing_m + size.length_m / 2)
    first, last = oncoming.lanes[0], oncoming.lanes[-1]
    if lane_id == first.lane_id:
        return VehicleSetup("oncoming_0", lane_id, pos_m, ego.speed_mps, colour, size, route=oncoming.route)
    if lane_id == last.lane_id:
        return VehicleSetup(
            "oncoming_0", lane_id, pos_m, ego.speed_mps, colour, size, route=(oncoming.route[1],)
        )
    # On the junction: inserted at the start of its approach lane (clear of the stop line), then moved.
    return VehicleSetup(
        "oncoming_0",
        first.lane_id,
        min(size.length_m + 1.0, first.length_m),
        ego.speed_mps,
        colour,
        size,
        route=oncoming.route,
        internal_lane_id=lane_id,
        internal_pos_m=pos_m,
    )


def _first_crossing(polyline, path) -> tuple[float, float] | None:
    """First intersection of the pedestrian's straight path (two points) with a polyline, or None."""
    (ax, ay), (bx, by) = path
    for (px, py), (qx, qy) in zip(polyline[:-1], polyline[1:]):
        d1x, d1y, d2x, d2y = bx - ax, by - ay, qx - px, qy - py
        denom = d1x * d2y - d1y * d2x
        if abs(denom) < 1e-12:
            continue
        t = ((px - ax) * d2y - (py - ay) * d2x) / denom
        u = ((px - ax) * d1y - (py - ay) * d1x) / denom
        if 0 <= t <= 1 and 0 <= u <= 1:
            return ax + t * d1x, ay + t * d1y
    return None


def _crossing_with_polyline(polyline, path) -> tuple[float, float]:
    """First intersection of the pedestrian's straight path with a polyline (the ego's turn path)."""
    crossing = _first_crossing(polyline, path)
    if crossing is None:
        raise ScenarioError("the pedestrian's path does not cross the ego's turn")
    return crossing


def kerb_parking_offset_m(approach: Approach, size: VehicleSize) -> float:
    """How far to the right of the centre of a one-lane approach's lane a car parked at the kerb stands
    (its centre) [m]: on the sidewalk, its road-side flank on the kerb line (the lane's right edge).
    Standing in the lane, or across the kerb, it would overlap the ego driving the lane's centre: a 1.8 m
    car in a 3.2 m lane leaves 0.7 m to the kerb line, and every class is wider than that (docs/sites.md)."""
    return approach.lane_width_m / 2 + size.width_m / 2


def kerb_staging_problem(spec: ScenarioSpec, approach: Approach) -> str | None:
    """Why `spec` (crossing, jaywalking, background blending) cannot be staged with cars parked at the kerb
    of a one-lane approach, or None: the sidewalk must lie right beside the lane, hold the widest car the
    scenario draws, and the approach must hold the row of parked cars (SUMO inserts each on the lane before
    it parks: a car whose rear would stand before the lane's start cannot be inserted)."""
    queue_classes = (
        [VEHICLE_CLASSES[spec.waiting_vehicle_class]]
        if spec.placement == "behind_waiting_vehicle" and spec.waiting_vehicle_class
        else list(VEHICLE_CLASSES.values())
    )
    widest = max(queue_classes, key=lambda size: size.width_m)
    if spec.placement == "crosswalk":
        widest = max([widest, VEHICLE_CLASSES[spec.occluder_class]], key=lambda size: size.width_m)
    if not approach.sidewalk_beside_lane:
        return (
            f"approach {approach.edge_id} has one vehicle lane and another lane between it and the sidewalk: "
            "no kerb beside the lane for a parked car to hide the pedestrian"
        )
    if approach.sidewalk_width_m < widest.width_m:
        return (
            f"approach {approach.edge_id} has one vehicle lane and a {approach.sidewalk_width_m:g} m "
            f"sidewalk: no room at the kerb for a parked car {widest.width_m:g} m wide to hide the pedestrian"
        )
    longest_m = max(size.length_m for size in VEHICLE_CLASSES.values())
    queue_m = spec.queue_vehicles * (spec.queue_gap_max_m + longest_m)
    if spec.placement == "crosswalk":
        row_m = 0.5 + VEHICLE_CLASSES[spec.occluder_class].length_m + queue_m
    elif spec.placement == "midblock":
        row_m = spec.midblock_distance_max_m + spec.parked_gap_max_m / 2 + longest_m + queue_m
    else:
        row_m = 0.5 + max(size.length_m for size in queue_classes)
    if row_m > approach.lane_lengths_m[0]:
        return (
            f"approach {approach.edge_id} has one vehicle lane {approach.lane_lengths_m[0]:.1f} m long: the "
            f"cars parked at its kerb may need {row_m:.1f} m before the stop line"
        )
    return None


def adjacent_lane(occluder_lane: int, towards: int, n_lanes: int) -> int:
    """The lane next to `occluder_lane` in the direction the pedestrian crosses (+1: towards the
    median, lanes counted from the kerb), where the ego drives."""
    lane = occluder_lane + towards
    if not 0 <= lane < n_lanes:
        raise ScenarioError(
            f"the approach has {n_lanes} vehicle lane(s): no lane next to lane {occluder_lane} on the side "
            "the pedestrian crosses towards"
        )
    return lane


def _crossing_with_lane(approach: Approach, lane_index: int, path) -> tuple[float, float]:
    """Intersection of the pedestrian's straight path with the centreline of a lane."""
    crossing = _first_crossing(_extended_shape(approach, lane_index), path)
    if crossing is None:
        raise ValueError("the pedestrian's path does not cross the ego's lane")
    return crossing


def stage_signals(
    spec: ScenarioSpec,
    setup: EpisodeSetup,
    junction: JunctionSignals | None,
    rng: np.random.Generator | Draws,
) -> EpisodeSetup:
    """Place the episode in the junction's signal program: a start time in the cycle, drawn uniformly
    (one draw from `rng`) among those at which the ego's signal shows what `spec` requires from the
    start, and the pedestrian's from the moment they step off, until `signal_hold_after_s` after the
    staged conflict. SignalStagingError when the program has no such time (the message says which)."""
    if junction is None:
        # An unsignalised junction (another site): nobody has a signal, and episodes.parquet says so
        # (ego_signal and ped_signal "none").
        return setup
    ego_link = junction.vehicle_link(setup.ego.lane_id, setup.ego_route[1])
    ped_link = junction.crossing_link(setup.ped_crossing_id) if setup.ped_crossing_id else NO_LINK
    if (ped_link == NO_LINK) != (spec.ped_signal == "none"):
        where = f"crossing {setup.ped_crossing_id}" if setup.ped_crossing_id else "a mid-block crossing"
        raise SignalStagingError(
            f"scenario '{spec.name}': ped_signal {spec.ped_signal} does not fit {where} "
            f"({'signalised' if ped_link != NO_LINK else 'no signal'})"
        )
    until_s = setup.conflict_time_s + spec.signal_hold_after_s
    # The ego from the start (it sees its signal all the way to the stop line), the pedestrian from
    # stepping off the kerb, both until after the conflict.
    required: dict[int, str | tuple[str, float, float]] = {ego_link: (spec.ego_signal, 0.0, until_s)}
    if ped_link != NO_LINK:
        step_off_s = min(setup.pedestrian.start_delay_s, until_s)
        ped_until_s = until_s if spec.ped_signal_hold == "conflict" else step_off_s
        required[ped_link] = (spec.ped_signal, step_off_s, ped_until_s)
    # A vehicle coming the other way through the junction (left_turn's oncoming vehicle) has green too.
    oncoming_links = [
        junction.vehicle_link(v.lane_id, v.route[1])
        for v in setup.parked
        if v.vehicle_id.startswith("oncoming_") and len(v.route) == 2
    ]
    for link in oncoming_links:
        required[link] = ("green", 0.0, until_s)
    # The point in the cycle is one uniform draw on [0, 1), recorded (never proposed) as signal_cycle_u.
    source = as_draws(rng).uniform_source("signal_cycle_u")
    cycle_start_s = draw_cycle_start_s(junction.program, required, until_s, source)  # type: ignore[arg-type]
    staging = SignalStaging(
        tls_id=junction.program.tls_id,
        program_id=junction.program.program_id,
        cycle_start_s=round(cycle_start_s, 6),
        ego_link_index=ego_link,
        ped_link_index=ped_link,
        occluder_link_index=(
            oncoming_links[0]
            if oncoming_links
            else junction.turn_link(setup.parked[0].lane_id, "r")
            if setup.parked
            else NO_LINK
        ),
    )
    return dataclasses.replace(setup, signals=staging)
