"""One episode: a scenario under a condition, driven through SUMO by the AD stack under test.

The loop, at every step of `step_length_s` (default 0.05 s):
  1. read the world from SUMO's subscriptions (vehicles' front positions, angles, speeds);
  2. check the contact of the ego's footprint with the pedestrian's circle, and SUMO's own;
  3. build the world snapshot and run the sensors (perception layer);
  4. hand the AD stack what its condition grants (SV: onboard; V2I: onboard + roadside over the link);
  5. actuate the ego the TraCI way (speed mode 0, setSpeed to the stack's command);
  6. move the pedestrian by the behaviour model (person.moveToXY, so jaywalking leaves the crosswalks),
     which sees the vehicle bodies and casts its line of sight to the ego through the same geometry;
  7. log the step, and advance SUMO.
The episode ends on a collision (contact while the ego moves at `STATIONARY_SPEED_MPS` or faster; a
contact with a standing ego is logged and the episode goes on), once both road users have cleared the
conflict area (the ego's rear past the pedestrian's path, the pedestrian past the ego's far flank), when
the ego has left the network, or at the scenario's time limit.

Randomness: the episode seed is split (numpy SeedSequence) into a world stream, drawn identically
under SV and V2I, and a perception stream; SUMO gets the seed too.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import tempfile
import time
import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.behaviour.pedestrian import BehaviourParams, PedestrianPose, PedestrianWalker, VehicleBodies
from pedsafe_sumo.behaviour.sight import ego_in_sight
from pedsafe_sumo.control.agent import (
    Agent,
    Command,
    EgoState,
    Observation,
    PerceivedPedestrian,
    check_sensor_names,
)
from pedsafe_sumo.control.stack_calls import checked_speed_mps, close_quietly, setup_within, stack_label
from pedsafe_sumo.control.timeout import DEFAULT_AGENT_TIMEOUT_S, check_timeout_s, guard_step
from pedsafe_sumo.demand.sampling import traffic_distributions
from pedsafe_sumo.demand.site import load_site as load_demand_site
from pedsafe_sumo.demand.vehicles import generate_vehicles, route_ids, speed_limit_scale
from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.perception import (
    EgoPose,
    Pedestrians,
    SensorSuite,
    V2ILink,
    VehicleBoxes,
    WorldSnapshot,
    load_roadside_units,
    load_static_occluders,
    perceive,
)
from pedsafe_sumo.safety.collision import STATIONARY_SPEED_MPS
from pedsafe_sumo.safety.episode import episode_indexes
from pedsafe_sumo.safety.geometry_kernels import rectangle_circle_clearance_m
from pedsafe_sumo.safety.proximity import ProximityModel
from pedsafe_sumo.sampling.draws import Draws, draw_lognormal, draw_pedestrian_traits
from pedsafe_sumo.sampling.importance import Family
from pedsafe_sumo.scenarios.geometry import (
    approach_unit_ids,
    default_arm,
    load_approach,
    load_turn,
    refuge_walkingareas,
)
from pedsafe_sumo.scenarios.oncoming import load_oncoming
from pedsafe_sumo.scenarios.registry import (
    CAR_COLOURS_RGB,
    VEHICLE_CLASSES,
    BackgroundVehicle,
    EpisodeSetup,
    ScenarioSpec,
    SignalStaging,
    VehicleSetup,
    draw_episode,
    stage_signals,
)
from pedsafe_sumo.scenarios.signals import SignalStagingError, colour_of_link, load_junction_signals
from pedsafe_sumo.sim.actuation import plan_lateral, wants_lateral
from pedsafe_sumo.sim.connection import SumoSession
from pedsafe_sumo.sim.flush import step_if_moved_since
from pedsafe_sumo.sim.kerb import check_parked, kerb_parked, park_at_kerb, parking_xml, with_additional
from pedsafe_sumo.sim.observation import ObservationFeeds, granted_names, sensor_mounts
from pedsafe_sumo.sim.road_map import load_net_map
from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre

CONDITIONS = ("sv", "v2i")
DEFAULT_ALGORITHM = "pedsafe_sumo.control.reference:ReferenceStack"
STEP_LENGTH_S = 0.05
PED_ID = "ped"
#: The ego's SUMO deceleration [m/s2]: only SUMO's insertion check reads it (see _add_vehicle).
EGO_INSERTION_DECEL_MPS2 = 50.0
EGO_ID = "ego"
#: How far around the pedestrian SUMO searches for a lane to map them onto after each moveToXY [m].
#: SUMO's default (100 m) makes the call scan every lane and walking area of the junction each step
#: (~150 us of a ~560 us step); the pedestrian is never more than ~6.5 m from a sidewalk, crosswalk
#: or walking area, and the nearest one is the same either way: 180 episodes of all three scenarios
#: gave identical logs with 100 m and 10 m.
PED_MATCH_RADIUS_M = 10.0

#: The per-step log's columns, in order (pedsafe_sumo.safety.log's contract plus the command and
#: diagnostics): the loop appends one tuple of these per step.
LOG_COLUMNS = (
    "time_s",
    "ego_x_m",
    "ego_y_m",
    "ego_yaw_rad",
    "ego_speed_mps",
    "ego_length_m",
    "ego_width_m",
    "ped_x_m",
    "ped_y_m",
    "ped_vx_mps",
    "ped_vy_mps",
    "ped_radius_m",
    "detected_onboard_camera",
    "detected_onboard_lidar",
    "detected_roadside",
    "perceived",
    "roadside_raw",
    "clearance_m",
    "command_speed_mps",
    "braking",
    "ped_state",
    "sumo_collision",
    "command_refused",
)

#: A per-step observer for replay: `on_step(api, row)` gets SUMO's API handle, in the state of the step
#: just logged, and that step's log row (a dict of the log columns).
StepHook = Callable[[Any, dict[str, Any]], None]


@dataclass
class EpisodeResult:
    setup: EpisodeSetup
    condition: str
    #: One row per step (columns of pedsafe_sumo.safety.log plus the command and diagnostics).
    log: pd.DataFrame
    #: The DESIGN section 3 columns of this episode (one row of episodes.parquet).
    outcome: dict[str, Any]
    end_reason: str
    timings_s: dict[str, float] = field(default_factory=dict)
    #: SUMO's own record of the ego-pedestrian collision: {"time_s", "ego_speed_mps", "type"}, or {}.
    sumo_collision: dict[str, Any] = field(default_factory=dict)
    #: SUMO's link-state string of the junction's traffic light at every logged step ("" without one).
    signal_states: list[str] = field(default_factory=list)


#: The files of a site an episode reads (besides the sumo-gui view settings): the network, the
#: occluding buildings, the roadside unit and the site facts. No route file: the background traffic
#: is drawn from the demand model for each episode.
SITE_FILES_READ = ("net.xml", "poly.xml", "rsu.add.xml", "site.json")


@dataclass(frozen=True)
class SiteData:
    """What the episode loop derives from the site's files once per worker (load_site_data)."""

    approach: Any
    static: Any
    #: Every roadside camera pole of the site by id; a scenario names the ones its V2I receives.
    roadside_units: dict[str, Any]
    #: Background traffic enters on every entering lane except the scenario's own approach.
    background_lanes: list
    edge_lengths: dict[str, float]
    route_edges: dict[str, tuple[str, ...]]
    #: The main junction's traffic-light program and link indices (None when it has no traffic light).
    signals: Any = None
    #: The arm the approach comes from (N, E, S or W).
    arm: str = ""


def load_site_data(site: Site, params: dict[str, Any], arm: str = "") -> SiteData:
    """Read the site's files (SITE_FILES_READ) into the loop's static world, staged on the approach from
    `arm` ("": the site's own); raises on a bad file."""
    approach = load_approach(site, arm or None)
    perception = params["perception"]
    static = load_static_occluders(site.file("poly.xml"), perception["occluders"])
    rsu = perception["roadside_camera"]
    units = load_roadside_units(
        site.file("rsu.add.xml"), rsu["default_height_m"], rsu["default_pitch_down_deg"]
    )
    demand_site = load_demand_site(site.name, net_file=site.file("net.xml"))
    background_lanes = [lane for lane in demand_site.entering_lanes if lane.edge_id != approach.edge_id]
    return SiteData(
        approach=approach,
        static=static,
        roadside_units={unit.id: unit for unit in units},
        background_lanes=background_lanes,
        edge_lengths={lane.edge_id: lane.length_m for lane in demand_site.entering_lanes},
        route_edges={rid: edges for edges, rid in route_ids(background_lanes).items()},
        signals=_junction_signals(site, approach.junction_id),
        arm=arm or default_arm(site),
    )


def _junction_signals(site: Site, junction_id: str):
    """The junction's signal program read from the site's network, or None when it has no traffic light."""
    try:
        return load_junction_signals(site.file("net.xml"), junction_id)
    except SignalStagingError as exc:
        if "has no traffic light" in str(exc):
            return None
        raise


def start_signals(api, staging: SignalStaging | None, program=None) -> None:
    """Put the junction's traffic light at the staged point of its cycle, at the episode's t = 0.

    SUMO must run the program the staging was drawn from (read from the same network): a program with
    other phases would give other signal states, so that is an error, not a silent difference.
    """
    if staging is None:
        return
    tls = staging.tls_id
    if api.trafficlight.getProgram(tls) != staging.program_id:
        api.trafficlight.setProgram(tls, staging.program_id)
    logic = next(
        (p for p in api.trafficlight.getAllProgramLogics(tls) if p.programID == staging.program_id), None
    )
    if logic is None:
        raise RuntimeError(f"SUMO has no program {staging.program_id} for traffic light {tls}")
    durations_s = [float(phase.duration) for phase in logic.phases]
    if program is not None and (
        tuple(durations_s) != program.durations_s or tuple(p.state for p in logic.phases) != program.states
    ):
        raise RuntimeError(
            f"SUMO runs another program {staging.program_id} for traffic light {tls} than the one the "
            "episode was staged in (read from the site's network)"
        )
    elapsed_s = staging.cycle_start_s % sum(durations_s)
    for index, duration_s in enumerate(durations_s):
        if elapsed_s < duration_s or index == len(durations_s) - 1:
            api.trafficlight.setPhase(tls, index)
            api.trafficlight.setPhaseDuration(tls, duration_s - elapsed_s)
            return
        elapsed_s -= duration_s


def conflict_step(log: pd.DataFrame, setup: EpisodeSetup) -> int:
    """Row of the log at the staged conflict: the first step at or after `setup.conflict_time_s` (the
    ego's front at the conflict point had nobody reacted), or the last step when the episode ended
    before it (a collision just before it). Not the closest approach: once an ego has stopped for the
    pedestrian their closest approach can come many seconds later, under the next phase."""
    times = log["time_s"].to_numpy()
    index = int(np.searchsorted(times, setup.conflict_time_s - 1e-9))
    return min(index, len(times) - 1)


def signals_at_conflict(log: pd.DataFrame, states: Sequence[str], setup: EpisodeSetup) -> tuple[str, str]:
    """(ego_signal, ped_signal) that SUMO showed at the staged conflict (conflict_step). `states` holds
    SUMO's link-state string of every logged step."""
    staging = setup.signals
    if staging is None or not len(log):
        return "none", "none"
    state = states[conflict_step(log, setup)]
    return colour_of_link(state, staging.ego_link_index), colour_of_link(state, staging.ped_link_index)


def _move_pedestrian(api, pose, radius_m: float) -> None:
    """Put the pedestrian where the behaviour model says, free of SUMO's walking model (keepRoute=2).

    SUMO takes a person's position as the FRONT of their shape, a length x width box that extends
    `length` behind it along their angle (MSTransportable::getBoundingBox). Our pedestrian is a circle
    around the model's position, so SUMO gets the point `radius_m` ahead of it: SUMO's 2r x 2r box is
    then centred on our circle (with the position itself, the box trailed 0.6 m behind the circle and
    SUMO saw contacts at 0.2-0.3 m of our clearance, e.g. with yielders stepping back).
    """
    # units.yaw_rad_to_sumo_angle on one float, in math: the same bits (numpy's rad2deg and math.degrees
    # multiply by the same 180/pi, np.mod and % are both Python's modulo; 2 M angles checked), without
    # numpy's per-call cost on a scalar (~4 us per step on a quiet machine; BENCHMARKS.md, session 6).
    api.person.moveToXY(
        PED_ID,
        "",
        pose.x_m + radius_m * math.cos(pose.heading_rad),
        pose.y_m + radius_m * math.sin(pose.heading_rad),
        angle=(90.0 - math.degrees(pose.heading_rad)) % 360.0,
        keepRoute=2,
        matchThreshold=PED_MATCH_RADIUS_M,
    )


def add_pedestrian(api, sidewalk_edge: str, type_id: str, refuges: bool, depart_s: float = 0.0) -> None:
    """Add the scenario's pedestrian on `sidewalk_edge`, to be moved by the behaviour model (moveToXY).

    With the waiting stage alone, SUMO's first moveToXY gives the person a walking route of its current
    edge, and moving it on rebuilds that route to end on the walking area ahead. On a median refuge (a
    walking area no sidewalk reaches, `refuges`: the network has one) SUMO 1.28 then crashes
    (scenarios.geometry.refuge_walkingareas, docs/sites.md): the person first gets a walking route that
    ends on its sidewalk, which the rebuilt routes keep. Networks without refuges are staged as before.
    `depart_s`: SUMO's time at the episode's start (sim.kerb: one step when cars are parked at the kerb)."""
    api.person.add(PED_ID, sidewalk_edge, pos=1.0, depart=depart_s, typeID=type_id)
    if refuges:
        api.person.appendWalkingStage(PED_ID, [sidewalk_edge, sidewalk_edge], arrivalPos=1.0)
    api.person.appendWaitingStage(PED_ID, 100_000.0, "pedsafe: moved by the behaviour model")


def _is_crossing_or_walkingarea(edge_id: str) -> bool:
    """SUMO's netconvert names crossings ':<junction>_c<k>' and walking areas ':<junction>_w<k>'."""
    if not edge_id.startswith(":"):
        return False
    tail = edge_id.rsplit("_", 1)[-1]
    return len(tail) > 1 and tail[0] in "cw" and tail[1:].isdigit()


class EpisodeRunner:
    """Runs episodes on one site, reusing one SUMO instance (libsumo, or sumo-gui through traci)."""

    def __init__(
        self,
        site: Site,
        params: dict[str, Any],
        agent_class: type[Agent],
        gui: bool = False,
        step_length_s: float = STEP_LENGTH_S,
        injury_model: str = "saade2020",
        gui_settings_file: Path | None = None,
        gui_options: Sequence[str] = (),
        agent_timeout_s: float = DEFAULT_AGENT_TIMEOUT_S,
    ) -> None:
        """`gui_settings_file` replaces the site's sumo-gui view settings and `gui_options` are added to
        the sumo-gui command line (replay: window size, labels); both are ignored headless.
        `agent_timeout_s` limits each run_step call (pedsafe_sumo.control.timeout)."""
        self.agent_timeout_s = check_timeout_s(agent_timeout_s)
        self.site = site
        self.gui_settings_file = gui_settings_file or site.file("view.xml")
        self.gui_options = tuple(gui_options)
        self.params = params
        self.agent_class = agent_class
        self.step_length_s = step_length_s
        self.injury_model = injury_model
        self.proximity_model = ProximityModel.from_params(params)
        data = load_site_data(site, params)
        self.static = data.static
        self.roadside_units = data.roadside_units
        self._suites: dict[tuple[str, ...], SensorSuite] = {}
        #: The site's files staged on each approach a spec asked for ("": the site's own), read once.
        self._by_approach: dict[str, SiteData] = {"": data}
        self._site_arm = data.arm
        #: Whether the network has median refuges (walking areas no sidewalk reaches): see person.add.
        self._refuges = bool(refuge_walkingareas(site))
        #: Folder of the per-episode parking file of cars parked at the kerb (sim/kerb.py), made on first use.
        self._kerb_dir: Path | None = None
        self._use_approach("")
        self.session = SumoSession(gui=gui)

    def _use_approach(self, arm: str) -> None:
        """Stage what follows on the approach from `arm` (a spec's `approach`; "": the site's own)."""
        if arm not in self._by_approach:
            self._by_approach[arm] = load_site_data(self.site, self.params, arm)
        data = self._by_approach[arm]
        self.approach = data.approach
        self.arm = data.arm
        self.background_lanes = data.background_lanes
        self._edge_lengths = data.edge_lengths
        self._route_edges = data.route_edges
        self.signals = data.signals

    def close(self) -> None:
        self.session.close()
        if self._kerb_dir is not None:
            self._kerb_cleanup()
            self._kerb_dir = None

    def sensors_for(self, spec: ScenarioSpec) -> SensorSuite:
        """The onboard sensors and the roadside poles the scenario names (built once per set of poles)."""
        ids = approach_unit_ids(spec.roadside_unit_ids, spec.approach, self._site_arm, spec.turn)
        if ids not in self._suites:
            unknown = [i for i in ids if i not in self.roadside_units]
            if unknown:
                raise ValueError(
                    f"scenario '{spec.name}' names roadside unit(s) {', '.join(unknown)} that site "
                    f"{self.site.name} does not have (known: {', '.join(self.roadside_units)})"
                )
            units = [self.roadside_units[i] for i in ids]
            self._suites[ids] = SensorSuite.from_params(self.params["perception"], units)
        return self._suites[ids]

    # ------------------------------------------------------------------ setup
    def draw_setup(self, spec: ScenarioSpec, seed: int) -> EpisodeSetup:
        """The initial world of episode `seed`: a function of the seed alone (same under SV and V2I).

        The seed is split into three streams: the scenario's world, the perception noise (see run) and
        the background traffic, so that changing one never shifts the draws of another.
        """
        return self.draw_setup_sampled(spec, seed)[0]

    def draw_setup_sampled(
        self,
        spec: ScenarioSpec,
        seed: int,
        proposal: Mapping[str, Family] | None = None,
        defensive_share: float = 0.0,
    ) -> tuple[EpisodeSetup, Draws]:
        """draw_setup, with the world's random inputs drawn through a Draws (sampling/draws.py): under
        no proposal the same world, under an importance-sampling proposal the world and its weight."""
        self._use_approach(spec.approach)
        world_seq, _, traffic_seq = np.random.SeedSequence(seed).spawn(3)
        draws = Draws(np.random.default_rng(world_seq), proposal, defensive_share)
        traits = draw_pedestrian_traits(draws, self.params["pedestrians"])
        _, speed_nonintersection, speed_intersection = traffic_distributions(self.params["traffic"])
        fit = speed_intersection if spec.ego_speed_fit == "intersection" else speed_nonintersection
        # Drawn at the fits' speed limit, scaled to the approach's (speed_limit_scale, params/defaults.toml).
        ego_speed_mps = draw_lognormal(draws, "ego_speed_log", fit.log_mu, fit.log_sigma) * speed_limit_scale(
            self.approach.speed_limit_mps, self.params["traffic"]
        )
        turn = load_turn(self.site, spec.turn, spec.approach or None) if spec.placement == "turn" else None
        oncoming = load_oncoming(self.site, spec.approach or None) if spec.oncoming_vehicle else None
        setup = draw_episode(spec, self.approach, seed, traits, ego_speed_mps, draws, turn, oncoming)
        if spec.approach:
            setup = dataclasses.replace(setup, approach=spec.approach)
        setup = stage_signals(spec, setup, self.signals, draws)
        if spec.background_traffic:
            setup = dataclasses.replace(setup, background=self._background(spec, traffic_seq))
        return setup, draws

    def _background(
        self, spec: ScenarioSpec, seed_seq: np.random.SeedSequence
    ) -> tuple[BackgroundVehicle, ...]:
        """Demand-model vehicles for [-warm-up, time limit]; the early ones already down their first edge."""
        warmup_s = spec.background_warmup_s
        demand_seq, colour_seq = seed_seq.spawn(2)
        drawn = generate_vehicles(
            self.background_lanes, self.params["traffic"], warmup_s + spec.time_limit_s, demand_seq
        )
        colour_rng = np.random.default_rng(colour_seq)
        vehicles = []
        for vehicle in drawn:
            depart_s = vehicle.depart_s - warmup_s
            pos_m = 0.0
            if depart_s < 0:
                # Would have entered -depart_s ago: it is now that far down its first edge at free speed
                # (or has left it, and then it no longer matters to the scene).
                pos_m = vehicle.desired_speed_mps * -depart_s
                # Not within its stopping distance (4.5 m/s2, SUMO's default) of the edge end: SUMO
                # refuses to insert a vehicle that could not stop there for a red light.
                stopping_m = vehicle.desired_speed_mps**2 / (2 * 4.5) + 10.0
                if pos_m > self._edge_lengths[vehicle.lane.edge_id] - stopping_m:
                    continue
                depart_s = 0.0
            route = self._route_edges[vehicle.route_id]
            colour = CAR_COLOURS_RGB[int(colour_rng.integers(len(CAR_COLOURS_RGB)))]
            vehicles.append(
                BackgroundVehicle(
                    vehicle.vehicle_id,
                    route,
                    vehicle.lane.index,
                    round(depart_s, 2),
                    round(pos_m, 2),
                    vehicle.desired_speed_mps,
                    vehicle.desired_speed_mps / vehicle.lane.speed_limit_mps,
                    colour,
                )
            )
        return tuple(vehicles)

    def _sumo_args(self, seed: int) -> list[str]:
        args = [
            "-n",
            str(self.site.file("net.xml")),
            "--step-length",
            f"{self.step_length_s}",
            "--seed",
            str(seed % 2_147_483_647),
            "--no-step-log",
            "true",
            "--no-warnings",
            "true",
            "--time-to-teleport",
            "-1",
            "--pedestrian.model",
            "striping",
            # SUMO's own collision check, for the sumo_collision column: junctions and persons included.
            "--collision.check-junctions",
            "true",
            "--collision.action",
            "warn",
            "--collision.mingap-factor",
            "0",
        ]
        if self.session.gui:
            args += [
                "-a",
                f"{self.site.file('poly.xml')},{self.site.file('rsu.add.xml')}",
                "--gui-settings-file",
                str(self.gui_settings_file),
                "--start",
                "true",
                # Close the window when the episode's TraCI connection closes.
                "--quit-on-end",
                "true",
                *self.gui_options,
            ]
        return args

    def _kerb_parking_file(self, setup: EpisodeSetup, vehicles) -> Path:
        """This episode's parking areas of the cars parked at the kerb (sim/kerb.py), written for SUMO."""
        if self._kerb_dir is None:
            self._kerb_dir = Path(tempfile.mkdtemp(prefix="pedsafe_kerb_"))
            # Removed by close(), or when the runner is collected or the process exits (batch workers
            # end without closing their runner).
            self._kerb_cleanup = weakref.finalize(self, shutil.rmtree, self._kerb_dir, True)
        path = self._kerb_dir / "kerb_parking.add.xml"
        path.write_text(parking_xml(self.approach, vehicles), encoding="utf-8")
        return path

    def _add_vehicle(
        self, api, vehicle: VehicleSetup, route_id: str, parked: bool, depart: str = "0"
    ) -> None:
        lane_index = int(vehicle.lane_id.rsplit("_", 1)[1])  # SUMO's index: the sidewalk is lane 0
        type_id = f"type_{vehicle.vehicle_id}"
        api.vehicletype.copy("DEFAULT_VEHTYPE", type_id)
        api.vehicletype.setLength(type_id, vehicle.size.length_m)
        api.vehicletype.setWidth(type_id, vehicle.size.width_m)
        api.vehicletype.setHeight(type_id, vehicle.size.height_m)
        api.vehicletype.setMinGap(type_id, 0.5)
        api.vehicletype.setColor(type_id, (*vehicle.colour_rgb, 255))
        api.vehicletype.setImperfection(type_id, 0.0)
        if not parked:
            # The ego's speed is the AD stack's, not SUMO's: allow initial speeds above the limit.
            api.vehicletype.setSpeedFactor(type_id, 2.0)
            api.vehicletype.setMaxSpeed(type_id, 50.0)
            # SUMO inserts a vehicle before a minor link (a turn that must yield) only if it could stop
            # before it at its decel; the AD stack, not SUMO, brakes the ego (speed mode 0), so the
            # check must not refuse a turning ego close to the stop line. Followers keep judging it by
            # a passenger car's braking (apparent decel).
            api.vehicletype.setApparentDecel(type_id, api.vehicletype.getDecel(type_id))
            api.vehicletype.setDecel(type_id, EGO_INSERTION_DECEL_MPS2)
            api.vehicletype.setEmergencyDecel(type_id, EGO_INSERTION_DECEL_MPS2)
        api.vehicle.add(
            vehicle.vehicle_id,
            route_id,
            typeID=type_id,
            depart=depart,
            departLane=str(lane_index),
            departPos=repr(float(vehicle.front_pos_m)),
            departSpeed=repr(float(vehicle.speed_mps)),
        )

    def _populate(self, api, setup: EpisodeSetup, start_s: float = 0.0) -> None:
        """Add the episode's road users; `start_s` is SUMO's time at the episode's start (one step when
        cars are parked at the kerb: they were inserted before, sim/kerb.py)."""
        approach = self.approach
        self._routes_added: set[str] = set()
        depart = repr(start_s) if start_s else "0"
        api.route.add("ego_route", list(setup.ego_route))
        api.route.add("kerb_route", [approach.edge_id])
        self._add_vehicle(api, setup.ego, "ego_route", parked=False, depart=depart)
        for vehicle in setup.parked:
            if vehicle.kerb_offset_m > 0:
                continue
            route_id = "kerb_route"
            if vehicle.route:  # a vehicle that drives (the turning scenarios' leader)
                route_id = "route_" + vehicle.vehicle_id
                api.route.add(route_id, list(vehicle.route))
            self._add_vehicle(api, vehicle, route_id, parked=True, depart=depart)
        if setup.background:
            api.vehicletype.copy("DEFAULT_VEHTYPE", "background")
            size = VEHICLE_CLASSES["car"]
            api.vehicletype.setLength("background", size.length_m)
            api.vehicletype.setWidth("background", size.width_m)
            api.vehicletype.setHeight("background", size.height_m)
            api.vehicletype.setImperfection("background", 0.0)
            api.vehicletype.setMaxSpeed("background", 55.56)
        for bg in setup.background:
            route_id = "bg_" + "|".join(bg.route)
            if route_id not in self._routes_added:
                api.route.add(route_id, list(bg.route))
                self._routes_added.add(route_id)
            api.vehicle.add(
                bg.vehicle_id,
                route_id,
                typeID="background",
                depart=repr(bg.depart_s + start_s) if start_s else repr(bg.depart_s),
                departLane=str(bg.lane_index),
                departPos=repr(bg.depart_pos_m),
                # The fastest safe speed: a lognormal-tail desired speed (30+ m/s) just before a junction
                # would be refused by SUMO; the speed factor set on departure brings it up afterwards.
                departSpeed="max",
            )
            api.vehicle.setColor(bg.vehicle_id, (*bg.colour_rgb, 255))
        ped = setup.pedestrian
        api.vehicletype.copy("DEFAULT_PEDTYPE", "ped_type")
        api.vehicletype.setWidth("ped_type", 2 * ped.radius_m)
        api.vehicletype.setLength("ped_type", 2 * ped.radius_m)
        api.vehicletype.setHeight("ped_type", ped.height_m)
        api.vehicletype.setColor("ped_type", (*ped.clothing_rgb, 255))
        add_pedestrian(api, approach.sidewalk_lane_id.rsplit("_", 1)[0], "ped_type", self._refuges, start_s)

    # ------------------------------------------------------------------ run
    def run(
        self,
        spec: ScenarioSpec,
        condition: str,
        seed: int,
        setup: EpisodeSetup | None = None,
        on_step: StepHook | None = None,
    ) -> EpisodeResult:
        """Run one episode. `on_step`, when given, is called once per step right after the step is
        logged (the last step included), before SUMO advances; it must leave the simulation as it is
        (read state, colour, draw). An exception raised in it ends the episode and propagates, after
        the agent is closed. Without it the loop pays one `is None` test per step.
        """
        if condition not in CONDITIONS:
            raise ValueError(f"unknown condition '{condition}' (known: {', '.join(CONDITIONS)})")
        setup = setup or self.draw_setup(spec, seed)
        self._use_approach(setup.approach)
        # Streams of the episode seed: 0 world, 1 onboard/roadside misses, 2 background traffic, 3 the
        # V2I link (loss, noise): the link draws only under V2I, so it must not share the sensors' stream
        # or SV and V2I would see different onboard misses for the same seed.
        streams = np.random.SeedSequence(seed).spawn(4)
        perception_rng = np.random.default_rng(streams[1])
        timings = dict.fromkeys(("sumo_s", "snapshot_s", "perception_s", "agent_s", "logging_s"), 0.0)
        clock = time.perf_counter

        started = clock()
        kerb = kerb_parked(setup)
        args = self._sumo_args(seed)
        if kerb:
            args = with_additional(args, self._kerb_parking_file(setup, kerb))
        self.session.run(args)
        api = self.session.api
        tc = api.constants
        # Cars parked at the kerb go in a step ahead (SUMO parks a vehicle the step after inserting it):
        # the episode's clock starts then (sim/kerb.py). Without them SUMO's clock is the episode's.
        start_s = 0.0
        if kerb:
            park_at_kerb(
                api, kerb, lambda api_, vehicle, route_id: self._add_vehicle(api_, vehicle, route_id, True)
            )
            start_s = api.simulation.getTime()
        self._populate(api, setup, start_s)
        start_signals(api, setup.signals, self.signals.program if self.signals else None)
        api.simulation.step()  # inserts everything at t = 0
        self._place_on_junction(api, setup)
        check_parked(api, kerb)
        timings["sumo_s"] += clock() - started

        dims: dict[str, tuple[float, float, float, tuple[int, int, int]]] = {}
        for vehicle in (setup.ego, *setup.parked):
            if vehicle.vehicle_id not in api.vehicle.getIDList():
                raise RuntimeError(f"SUMO did not insert vehicle '{vehicle.vehicle_id}'")
            dims[vehicle.vehicle_id] = (
                vehicle.size.length_m,
                vehicle.size.width_m,
                vehicle.size.height_m,
                vehicle.colour_rgb,
            )
            api.vehicle.subscribe(vehicle.vehicle_id, [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED])
            api.vehicle.setSpeedMode(vehicle.vehicle_id, 0)
            api.vehicle.setSpeed(vehicle.vehicle_id, vehicle.speed_mps)
        for vehicle in setup.parked:
            api.vehicle.setLaneChangeMode(vehicle.vehicle_id, 0)
        api.vehicle.setLaneChangeMode(EGO_ID, 0)
        background = {v.vehicle_id: v for v in setup.background}
        car = VEHICLE_CLASSES["car"]

        def register_departed() -> None:
            """Background vehicles inserted in the last step: their speed factor, subscription, size."""
            for vid in api.simulation.getDepartedIDList():
                vehicle = background.get(vid)
                if vehicle is None:
                    continue
                api.vehicle.setSpeedFactor(vid, vehicle.speed_factor)
                api.vehicle.subscribe(vid, [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED])
                dims[vid] = (car.length_m, car.width_m, car.height_m, vehicle.colour_rgb)

        register_departed()

        ped = setup.pedestrian
        walker = PedestrianWalker(ped.path_xy, self._behaviour(ped), start_delay_s=ped.start_delay_s)
        agent = self.agent_class()
        granted = {"onboard_camera", "onboard_lidar"} | ({"v2i"} if condition == "v2i" else set())
        granted |= granted_names(condition)  # raw data and world feeds (issue 15), on request only
        check_sensor_names(agent.sensors(), type(agent).__name__)
        setup_within(  # under --agent-timeout, like run_step (control/stack_calls.py)
            agent,
            {
                # The parameter file's [algorithm] settings (older run.json files have none).
                **self.params.get("algorithm", {}),
                "initial_speed_mps": setup.ego.speed_mps,
                "condition": condition,
                "seed": seed,
                "step_length_s": self.step_length_s,
                "sensors": sorted(set(agent.sensors()) & granted),
                "sensor_mounts": sensor_mounts(self.params["perception"]),
            },
            self.agent_timeout_s,
        )
        wanted = set(agent.sensors()) & granted
        sensors = self.sensors_for(spec)
        link = V2ILink(sensors.v2i, np.random.default_rng(streams[3])) if "v2i" in wanted else None
        feeds = ObservationFeeds.for_agent(
            api, EGO_ID, wanted, condition, self.site.file("net.xml"), sensors, self.params["perception"]
        )
        ped_ids = (PED_ID,)
        ped_radii = np.array([ped.radius_m], dtype=float)
        ped_heights = np.array([ped.height_m], dtype=float)
        ped_rgb = np.array([ped.clothing_rgb], dtype=float)
        # Body sizes and colours of the vehicles in the last snapshot: they change only when a vehicle
        # enters or leaves, so they are rebuilt then, not every step.
        body_ids: tuple[str, ...] = ()
        lengths = widths = heights = half_diagonals = np.zeros(0)
        colours = np.zeros((0, 3))
        ego_index = -1

        rows: list[tuple] = []
        # SUMO's link states of the junction at every logged step (for the signals at the conflict).
        signal_states: list[str] = []
        tls_state = (
            (lambda tls=setup.signals.tls_id: api.trafficlight.getRedYellowGreenState(tls))
            if setup.signals is not None
            else (lambda: "")
        )
        sumo_collision = False
        sumo_record: dict[str, Any] = {}
        # SUMO checks vehicle-person contact only on crossings and walking areas: the person's SUMO
        # edge at the closest approach decides whether its verdict counts (sumo_collision null if not).
        closest_clearance_m = math.inf
        closest_edge = ""
        end_reason = "time_limit"
        start_x, start_y, start_heading = walker.position(0.0)
        pose = PedestrianPose(start_x, start_y, start_heading, 0.0, "waiting")
        eye_height_m = self.params["pedestrians"]["eye_height_fraction"] * ped.height_m
        _move_pedestrian(api, pose, ped.radius_m)
        moved_at_s = api.simulation.getTime()  # the move above is pending until SUMO steps (sim/flush.py)
        stack = stack_label(self.agent_class)  # names the stack in the messages of its invalid commands
        # run_step under the per-step time limit: AgentTimeoutError ends the episode (status "timeout").
        run_step = guard_step(agent.run_step, self.agent_timeout_s).start()
        try:
            while True:
                t0 = clock()
                time_s = api.simulation.getTime()
                if start_s:
                    time_s = round(time_s - start_s, 6)
                if background:
                    register_departed()
                results = api.vehicle.getAllSubscriptionResults()
                if EGO_ID not in results:
                    end_reason = "ego_left_network"
                    break
                # Vectorised: SUMO's front-bumper positions and angles to footprint centres and yaw.
                # Every subscribed vehicle has its body in `dims`, so the subscription's ids are the
                # snapshot's; the filter runs only when the set changes.
                ids = tuple(results)
                if ids != body_ids:
                    ids = tuple(vid for vid in results if vid in dims)
                if ids != body_ids:
                    body_ids = ids
                    sizes = np.array([dims[vid][:3] for vid in ids], dtype=float).reshape(-1, 3)
                    lengths, widths, heights = sizes[:, 0].copy(), sizes[:, 1].copy(), sizes[:, 2].copy()
                    half_diagonals = 0.5 * np.hypot(lengths, widths)
                    colours = np.array([dims[vid][3] for vid in ids], dtype=float).reshape(-1, 3)
                    ego_index = ids.index(EGO_ID)
                front_xy = np.array([results[vid][tc.VAR_POSITION] for vid in ids])
                yaw = sumo_angle_to_yaw_rad([results[vid][tc.VAR_ANGLE] for vid in ids])
                centre_x, centre_y = sumo_front_to_centre(front_xy[:, 0], front_xy[:, 1], yaw, lengths)
                ego_x, ego_y, ego_yaw = (
                    float(centre_x[ego_index]),
                    float(centre_y[ego_index]),
                    float(yaw[ego_index]),
                )
                ego_speed = float(results[EGO_ID][tc.VAR_SPEED])
                ego_length, ego_width = float(lengths[ego_index]), float(widths[ego_index])
                if not sumo_collision:
                    sumo_record = self._sumo_collision(api, time_s)
                    sumo_collision = bool(sumo_record)
                # Built directly from float arrays of matching lengths (what .build would check and
                # convert, every step).
                vehicles = VehicleBoxes(ids, centre_x, centre_y, yaw, lengths, widths, heights, colours)
                pedestrians = Pedestrians(
                    ped_ids, np.array([pose.x_m]), np.array([pose.y_m]), ped_radii, ped_heights, ped_rgb
                )
                snapshot = WorldSnapshot(time_s, vehicles, pedestrians, self.static)
                t1 = clock()
                timings["snapshot_s"] += t1 - t0

                ego_pose = EgoPose(ego_x, ego_y, ego_yaw, EGO_ID)
                detections = perceive(snapshot, ego_pose, sensors, perception_rng, time_s, link)
                extra = feeds.step(snapshot, ego_pose, ego_index, time_s) if feeds is not None else {}
                t2 = clock()
                timings["perception_s"] += t2 - t1

                reported: list[PerceivedPedestrian] = []
                sources = (
                    ("onboard_camera", detections.camera),
                    ("onboard_lidar", detections.lidar),
                    ("v2i", detections.v2i_received),
                )
                for source, found in sources:
                    if source not in wanted:
                        continue
                    for pid, xy in zip(found.ids, found.xy_m):
                        if all(p.ped_id != pid for p in reported):
                            reported.append(PerceivedPedestrian(pid, float(xy[0]), float(xy[1]), source))
                observation = Observation(
                    EgoState(ego_x, ego_y, ego_yaw, ego_speed, ego_length, ego_width),
                    tuple(reported),
                    self.step_length_s,
                    **extra,
                )
                command: Command = run_step(observation, time_s)
                target_mps = checked_speed_mps(command, stack, time_s)  # or StackError (stack_calls.py)
                refused, steer = "", None
                if wants_lateral(command):  # lane change or path (issue 15); refusals are logged
                    net = load_net_map(str(self.site.file("net.xml")))
                    refused, steer = plan_lateral(
                        api, EGO_ID, command, net, (ego_x, ego_y), ego_length, target_mps, self.step_length_s
                    )
                t3 = clock()
                timings["agent_s"] += t3 - t2

                # Compiled scalar form of safety.geometry.rectangle_circle_distance_m (the same bits).
                clearance_m = float(
                    rectangle_circle_clearance_m(
                        ego_x, ego_y, ego_yaw, ego_length, ego_width, pose.x_m, pose.y_m, ped.radius_m
                    )
                )
                if clearance_m < closest_clearance_m:
                    closest_clearance_m = clearance_m
                    closest_edge = api.person.getRoadID(PED_ID)
                # One tuple per step in LOG_COLUMNS' order (a dict per step cost more than the values).
                rows.append(
                    (
                        time_s,
                        ego_x,
                        ego_y,
                        ego_yaw,
                        ego_speed,
                        ego_length,
                        ego_width,
                        pose.x_m,
                        pose.y_m,
                        # The pose's heading is the direction of motion (flipped when stepping back).
                        abs(pose.speed_mps) * math.cos(pose.heading_rad),
                        abs(pose.speed_mps) * math.sin(pose.heading_rad),
                        ped.radius_m,
                        PED_ID in detections.camera,
                        PED_ID in detections.lidar,
                        condition == "v2i" and PED_ID in detections.v2i_received,
                        any(p.ped_id == PED_ID for p in reported),
                        PED_ID in detections.roadside,
                        clearance_m,
                        target_mps,
                        bool(command.info.get("braking", False)),
                        pose.state,
                        sumo_collision,
                        refused,
                    )
                )
                signal_states.append(tls_state())
                timings["logging_s"] += clock() - t3
                if on_step is not None:
                    on_step(api, dict(zip(LOG_COLUMNS, rows[-1], strict=True)))

                # End conditions, on the state at time_s. A contact with a standing ego is no
                # collision (safety.collision): the step is logged and the episode goes on.
                if clearance_m <= 0.0 and ego_speed >= STATIONARY_SPEED_MPS:
                    end_reason = "collision"
                    break
                cleared = walker.cleared((ego_x, ego_y), ego_yaw, ego_length, ego_width)
                if cleared is None:  # the ego's heading no longer crosses the path: the old test
                    lon = (pose.x_m - ego_x) * math.cos(ego_yaw) + (pose.y_m - ego_y) * math.sin(ego_yaw)
                    cleared = (lon < -(ego_length / 2 + ped.radius_m), walker.finished)
                if all(cleared) and time_s > ped.start_delay_s:
                    end_reason = "both_cleared"
                    break
                if time_s >= setup.time_limit_s:
                    end_reason = "time_limit"
                    break

                t4 = clock()
                api.vehicle.setSpeed(EGO_ID, target_mps)
                if steer is not None:
                    steer()
                bodies = VehicleBodies(centre_x, centre_y, yaw, lengths, widths, half_diagonals)
                pose = walker.step(
                    self.step_length_s,
                    time_s,
                    (ego_x, ego_y),
                    ego_yaw,
                    ego_speed,
                    ego_length,
                    ego_width,
                    sees_ego=partial(ego_in_sight, snapshot, ego_index, (pose.x_m, pose.y_m, eye_height_m)),
                    bodies=bodies,
                )
                _move_pedestrian(api, pose, ped.radius_m)
                api.simulation.step()
                timings["sumo_s"] += clock() - t4
        finally:
            run_step.stop()
            step_if_moved_since(api, moved_at_s)  # no moveToXY left pending (sim/flush.py)
            if not run_step.timed_out:  # a stack cut off mid-step may still be running: leave it
                close_quietly(agent)  # while the episode fails, its first failure is the one reported

        log = pd.DataFrame(rows, columns=list(LOG_COLUMNS)) if rows else pd.DataFrame()
        # SUMO's verdict counts where it looks: a pedestrian on a crossing or walking area at the
        # closest approach. Elsewhere (mid-block: a person moved across the road stays logically on
        # its sidewalk lane, where SUMO never checks against vehicles) it is unknown, not False.
        sumo_witness = sumo_collision if _is_crossing_or_walkingarea(closest_edge) else None
        indexes = episode_indexes(
            log, ped.age_years, injury_model=self.injury_model, proximity_model=self.proximity_model
        )
        ego_signal, ped_signal = signals_at_conflict(log, signal_states, setup)
        outcome = {
            "scenario": setup.scenario,
            "condition": condition,
            "seed": seed,
            "ped_age": ped.age_years,
            "ped_gender": ped.gender,
            "ped_risk": ped.risk,
            "ped_speed_mps": ped.walking_speed_mps,
            "ego_initial_speed_mps": setup.ego.speed_mps,
            **indexes,
            "sumo_collision": sumo_witness,
            "end_reason": end_reason,
            "ego_signal": ego_signal,
            "ped_signal": ped_signal,
            "approach": self.arm,
            "status": "ok",
            "error": "",
        }
        return EpisodeResult(setup, condition, log, outcome, end_reason, timings, sumo_record, signal_states)

    @staticmethod
    def _place_on_junction(api, setup: EpisodeSetup) -> None:
        """Move the vehicles that stand on a junction's internal lane at the start (left_turn's oncoming
        vehicle) there from where SUMO inserted them (it inserts on edges only)."""
        for vehicle in setup.parked:
            if vehicle.internal_lane_id and vehicle.vehicle_id in api.vehicle.getIDList():
                api.vehicle.moveTo(vehicle.vehicle_id, vehicle.internal_lane_id, vehicle.internal_pos_m)

    @staticmethod
    def _sumo_collision(api, time_s: float) -> dict[str, Any]:
        """SUMO's collision between the moving ego and the pedestrian in the last step, if it saw one.

        Same definition as ours: a contact while the ego is slower than STATIONARY_SPEED_MPS is none.
        """
        for collision in api.simulation.getCollisions():
            if {collision.collider, collision.victim} == {EGO_ID, PED_ID}:
                speed = collision.colliderSpeed if collision.collider == EGO_ID else collision.victimSpeed
                if speed >= STATIONARY_SPEED_MPS:
                    return {"time_s": time_s, "ego_speed_mps": float(speed), "type": collision.type}
        return {}

    def _behaviour(self, ped) -> BehaviourParams:
        p = self.params["pedestrians"]
        return BehaviourParams(
            risk=ped.risk,
            walking_speed_mps=ped.walking_speed_mps,
            reaction_time_s=p["reaction_time_s"],
            awareness_ttc_s=p["awareness_ttc_s"],
            hasten_factor=p["hasten_factor"],
            max_speed_mps=p["hasten_max_speed_mps"],
            step_back_speed_mps=p["step_back_speed_mps"],
            yield_clearance_m=p["yield_clearance_m"],
            body_clearance_m=p["body_clearance_m"],
            body_graze_angle_deg=p["body_graze_angle_deg"],
            gap_startup_clearance_s=p["gap_startup_clearance_s"],
            detour_wait_s=p["detour_wait_s"],
            detour_max_offset_m=p["detour_max_offset_m"],
            stopped_speed_mps=STATIONARY_SPEED_MPS,
            radius_m=ped.radius_m,
            avoids_bodies=ped.avoids_vehicle_bodies,
        )
