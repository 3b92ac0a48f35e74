"""One episode's initial world as frozen data (EpisodeSetup): the ego, the pedestrian, the vehicles
standing or driving around them, the background traffic and the signal program's state at the start.
`staging.draw_episode` draws it from a scenario spec and a seed; the engine builds it in SUMO."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pedsafe_sumo.scenarios.road_users import VehicleSize
from pedsafe_sumo.scenarios.signals import NO_LINK


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
    #: The pedestrian enters the scene at this time [s]: before it they are nowhere (no sensor can report
    #: them). 0 in the fixed staging, where they stand at their step-off point from the start.
    appear_time_s: float = 0.0
    #: Index in `path_xy` of the step-off point, where they wait `start_delay_s` before crossing: the
    #: points before it are their walk on the sidewalk to it (approach staging; 0 in the fixed staging).
    kerb_index: int = 0
    #: At the end of `path_xy` they leave the scene (approach staging: they walk on off it) instead of
    #: standing there (fixed staging).
    leaves_scene: bool = False


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
    #: The ego starting before its approach (approach staging, on the road before it: placements/
    #: straight.py): the approach lane it drives to the junction's stop line on. "": `lane_id` is that lane.
    approach_lane_id: str = ""
    #: > 0: the vehicle stands parked at the kerb beside `lane_id`, its centre this far towards the kerb
    #: from the lane's centre (right of travel; left in left-hand traffic), on a one-lane approach
    #: (placements.straight.kerb_parking_offset_m); SUMO inserts it on the lane at `front_pos_m` and parks
    #: it in a parking space there (sim/kerb.py). 0: it stands in its lane.
    kerb_offset_m: float = 0.0
    #: SUMO forms it (approach staging, sim/queue.py): it enters its lane upstream before the episode's
    #: start and SUMO's car-following drives it up to a stop at the red stop line, or behind the vehicle
    #: before it in `parked` at `min_gap_m`; `front_pos_m` is where it must stand when the queue has
    #: formed (checked). False: SUMO adds it standing at `front_pos_m` at the start.
    formed: bool = False
    #: SUMO's minGap of the vehicle [m]: a formed vehicle stops this far behind the rear of the vehicle
    #: before it. 0.5 m for every staged vehicle that SUMO does not form (the staging's own gaps place it).
    min_gap_m: float = 0.5
    #: A vehicle that drives through the junction on its green (left_turn's oncoming vehicle; under
    #: approach staging right_turn's leader, which comes down the ego's lane): from when that green must
    #: show [s], the moment its front reaches the stop line (0: from the start; scenarios.staging.
    #: stage_signals).
    green_from_s: float = 0.0

    @property
    def stop_line_lane_id(self) -> str:
        """The lane it reaches the junction's stop line on (its approach lane)."""
        return self.approach_lane_id or self.lane_id


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
    #: Where the junction's signal program stands at the start (None: not staged, as in a case file
    #: that does not record it).
    signals: SignalStaging | None = None
    #: The arm the ego comes in on (N, E, S, W; "" in a case file that does not record it).
    approach: str = ""
    #: Distance along the ego's path from its front at the start to the conflict point [m] (NaN in a
    #: case file that does not record it).
    ego_start_distance_m: float = math.nan


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
