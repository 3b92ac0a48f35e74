"""An episode's world put into SUMO: everything between the drawn EpisodeSetup and the loop's first step.

Once per runner and approach, `load_site_data` reads the site's files (SITE_FILES_READ) into a SiteData.
For each episode, `draw_background` draws the background traffic from the demand model and
`behaviour_params` sets up the drawn pedestrian's behaviour model. `SumoStaging.stage` then loads SUMO
with the episode's options, parks the kerb cars a step ahead (sim/kerb.py) or lets SUMO form the kerb
lane's queue before the episode's start (approach staging, sim/queue.py), adds the ego, the staged
vehicles, the background traffic and the pedestrian (`populate`), puts the traffic light at its staged
point of the cycle (`start_signals`), takes the inserting step and moves the vehicles that start on a
junction there (`place_on_junction`). `subscribe_vehicles` and `background_arrivals` give the loop SUMO's
positions of every vehicle it must see, and `move_pedestrian` is how the loop (and the runner, at t = 0)
puts the pedestrian where the behaviour model says.
"""

from __future__ import annotations

import math
import shutil
import tempfile
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pedsafe_sumo.behaviour.pedestrian import BehaviourParams
from pedsafe_sumo.demand.site import load_site as load_demand_site
from pedsafe_sumo.demand.vehicles import generate_vehicles, route_ids
from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.network.traffic_side import near_turn_letter
from pedsafe_sumo.perception import load_roadside_units, load_static_occluders
from pedsafe_sumo.safety.collision import STATIONARY_SPEED_MPS
from pedsafe_sumo.scenarios.episode_setup import (
    BackgroundVehicle,
    EpisodeSetup,
    PedestrianSetup,
    SignalStaging,
    VehicleSetup,
)
from pedsafe_sumo.scenarios.geometry import Approach, default_arm, load_approach
from pedsafe_sumo.scenarios.road_users import CAR_COLOURS_RGB, VEHICLE_CLASSES
from pedsafe_sumo.scenarios.signals import SignalStagingError, load_junction_signals
from pedsafe_sumo.scenarios.specs import ScenarioSpec
from pedsafe_sumo.sim.connection import SumoSession
from pedsafe_sumo.sim.kerb import check_parked, kerb_parked, park_at_kerb, parking_xml, with_additional
from pedsafe_sumo.sim.queue import form_queue, formed_queue
from pedsafe_sumo.sim.road_map import load_net_map

#: SUMO's ids of the episode's ego vehicle and pedestrian.
EGO_ID = "ego"
PED_ID = "ped"
#: The ego's SUMO deceleration [m/s2]: only SUMO's insertion check reads it (see add_vehicle).
EGO_INSERTION_DECEL_MPS2 = 50.0
#: How far around the pedestrian SUMO searches for a lane to map them onto after each moveToXY [m].
#: SUMO's default (100 m) makes the call scan every lane and walking area of the junction each step
#: (~150 us of a ~560 us step); the pedestrian is never more than ~6.5 m from a sidewalk, crosswalk
#: or walking area, and the nearest one is the same either way: 180 episodes of all three scenarios
#: gave identical logs with 100 m and 10 m.
PED_MATCH_RADIUS_M = 10.0

#: The files of a site an episode reads (besides the sumo-gui view settings): the network, the
#: occluding buildings, the roadside unit and the site facts. No route file: the background traffic
#: is drawn from the demand model for each episode.
SITE_FILES_READ = ("net.xml", "poly.xml", "rsu.add.xml", "site.json")

#: A staged vehicle's body for the loop's snapshot: (length_m, width_m, height_m, colour_rgb).
VehicleDims = tuple[float, float, float, tuple[int, int, int]]


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
    # No background vehicle enters on the approach (its chain of edges before a stub: scenarios/chained.py).
    approach_edges = set(approach.through_route[:-1])
    background_lanes = [lane for lane in demand_site.entering_lanes if lane.edge_id not in approach_edges]
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


def draw_background(
    spec: ScenarioSpec,
    data: SiteData,
    traffic_params: dict[str, Any],
    seed_seq: np.random.SeedSequence,
    duration_s: float,
) -> tuple[BackgroundVehicle, ...]:
    """Demand-model vehicles for [-warm-up, `duration_s`] on `data`'s background lanes (the episode's
    time limit: under approach staging the approach plus the scene); the early ones already down their
    first edge."""
    warmup_s = spec.background_warmup_s
    demand_seq, colour_seq = seed_seq.spawn(2)
    drawn = generate_vehicles(data.background_lanes, traffic_params, warmup_s + duration_s, demand_seq)
    colour_rng = np.random.default_rng(colour_seq)
    vehicles = []
    for vehicle in drawn:
        depart_s = vehicle.depart_s - warmup_s
        pos_m = 0.0
        if depart_s < 0:
            # Would have entered -depart_s ago: it is that far down its first edge at free speed
            # (or has left it, and then it does not matter to the scene).
            pos_m = vehicle.desired_speed_mps * -depart_s
            # Not within its stopping distance (4.5 m/s2, SUMO's default) of the edge end: SUMO
            # refuses to insert a vehicle that could not stop there for a red light.
            stopping_m = vehicle.desired_speed_mps**2 / (2 * 4.5) + 10.0
            if pos_m > data.edge_lengths[vehicle.lane.edge_id] - stopping_m:
                continue
            depart_s = 0.0
        route = data.route_edges[vehicle.route_id]
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


def behaviour_params(pedestrian_params: dict[str, Any], ped: PedestrianSetup) -> BehaviourParams:
    """The behaviour model's settings for the drawn pedestrian `ped` (params' [pedestrians] table)."""
    p = pedestrian_params
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
        yield_at_kerb=p["yield_at_kerb"],
        body_rule_needs_notice=p["body_rule_needs_notice"],
        stopped_speed_mps=STATIONARY_SPEED_MPS,
        radius_m=ped.radius_m,
        avoids_bodies=ped.avoids_vehicle_bodies,
    )


@dataclass(frozen=True)
class GuiView:
    """How sumo-gui shows the site: its view settings file and extra command-line options."""

    settings_file: Path
    options: tuple[str, ...] = ()


def sumo_args(site: Site, step_length_s: float, seed: int, gui: GuiView | None = None) -> list[str]:
    """SUMO's options for an episode on `site`; with `gui`, sumo-gui's too (buildings and poles drawn)."""
    args = [
        "-n",
        str(site.file("net.xml")),
        "--step-length",
        f"{step_length_s}",
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
    if gui is not None:
        args += [
            "-a",
            f"{site.file('poly.xml')},{site.file('rsu.add.xml')}",
            "--gui-settings-file",
            str(gui.settings_file),
            "--start",
            "true",
            # Close the window when the episode's TraCI connection closes.
            "--quit-on-end",
            "true",
            *gui.options,
        ]
    return args


def add_vehicle(
    api, vehicle: VehicleSetup, route_id: str, parked: bool, depart: str = "0", upstream: bool = False
) -> None:
    """Add a staged vehicle (the ego unless `parked`) with a vehicle type of its own: its size, colour and
    minGap, no driver imperfection. `upstream`: it enters at the start of its lane at the fastest safe
    speed, to be driven by SUMO (a vehicle of a formed queue, sim/queue.py), not at `front_pos_m`."""
    lane_index = int(vehicle.lane_id.rsplit("_", 1)[1])  # SUMO's index: the sidewalk is lane 0
    type_id = f"type_{vehicle.vehicle_id}"
    api.vehicletype.copy("DEFAULT_VEHTYPE", type_id)
    api.vehicletype.setLength(type_id, vehicle.size.length_m)
    api.vehicletype.setWidth(type_id, vehicle.size.width_m)
    api.vehicletype.setHeight(type_id, vehicle.size.height_m)
    api.vehicletype.setMinGap(type_id, vehicle.min_gap_m)
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
        departPos="0" if upstream else repr(float(vehicle.front_pos_m)),
        departSpeed="max" if upstream else repr(float(vehicle.speed_mps)),
    )


def add_pedestrian(api, sidewalk_edge: str, type_id: str, refuges: bool, depart_s: float = 0.0) -> None:
    """Add the scenario's pedestrian on `sidewalk_edge`, to be moved by the behaviour model (moveToXY).

    With the waiting stage alone, SUMO's first moveToXY gives the person a walking route of its current
    edge, and moving it on rebuilds that route to end on the walking area ahead. On a median refuge (a
    walking area no sidewalk reaches, `refuges`: the network has one) SUMO 1.28 then crashes
    (scenarios.geometry.refuge_walkingareas, docs/sites.md): the person first gets a walking route that
    ends on its sidewalk, which the rebuilt routes keep. Networks without refuges get the waiting stage
    alone.
    `depart_s`: SUMO's time at the episode's start (sim.kerb: one step when cars are parked at the kerb)."""
    api.person.add(PED_ID, sidewalk_edge, pos=1.0, depart=depart_s, typeID=type_id)
    if refuges:
        api.person.appendWalkingStage(PED_ID, [sidewalk_edge, sidewalk_edge], arrivalPos=1.0)
    api.person.appendWaitingStage(PED_ID, 100_000.0, "pedsafe: moved by the behaviour model")


def populate(api, setup: EpisodeSetup, approach: Approach, refuges: bool, start_s: float = 0.0) -> None:
    """Add the episode's road users; `start_s` is SUMO's time at the episode's start (one step when
    cars are parked at the kerb: they were inserted before, sim/kerb.py)."""
    routes_added: set[str] = set()
    depart = repr(start_s) if start_s else "0"
    api.route.add("ego_route", list(setup.ego_route))
    api.route.add("kerb_route", [approach.edge_id])
    add_vehicle(api, setup.ego, "ego_route", parked=False, depart=depart)
    for vehicle in setup.parked:
        if vehicle.kerb_offset_m > 0 or vehicle.formed:  # in SUMO already (sim/kerb.py, sim/queue.py)
            continue
        route_id = "kerb_route"
        if vehicle.route:  # a vehicle that drives (the turning scenarios' leader)
            route_id = "route_" + vehicle.vehicle_id
            api.route.add(route_id, list(vehicle.route))
        add_vehicle(api, vehicle, route_id, parked=True, depart=depart)
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
        if route_id not in routes_added:
            api.route.add(route_id, list(bg.route))
            routes_added.add(route_id)
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
    if ped.appear_time_s <= 0.0:  # else the loop adds them when they appear (SumoStaging.add_pedestrian_now)
        add_pedestrian(api, approach.sidewalk_lane_id.rsplit("_", 1)[0], "ped_type", refuges, start_s)


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


def place_on_junction(api, setup: EpisodeSetup) -> None:
    """Move the vehicles that stand on a junction's internal lane at the start (left_turn's oncoming
    vehicle; an ego starting on the junction before its approach) there from where SUMO inserted them (it
    inserts on edges only)."""
    for vehicle in (setup.ego, *setup.parked):
        if vehicle.internal_lane_id and vehicle.vehicle_id in api.vehicle.getIDList():
            api.vehicle.moveTo(vehicle.vehicle_id, vehicle.internal_lane_id, vehicle.internal_pos_m)


def stop_line_lane_shape(net_file: str, setup: EpisodeSetup):
    """The drawn shape of the lane whose end is the stop line the ego's signal compliance is judged at
    (stopline_signal, could_stop_at_yellow): its approach lane at the junction, wherever it started (on
    the road before it under approach staging); () when the network has no such lane."""
    lane = load_net_map(net_file).lanes.get(setup.ego.stop_line_lane_id)
    return lane.shape_xy_m if lane is not None else ()


def move_pedestrian(api, pose, radius_m: float) -> None:
    """Put the pedestrian where the behaviour model says, free of SUMO's walking model (keepRoute=2).

    SUMO takes a person's position as the FRONT of their shape, a length x width box that extends
    `length` behind it along their angle (MSTransportable::getBoundingBox). Our pedestrian is a circle
    around the model's position, so SUMO gets the point `radius_m` ahead of it: SUMO's 2r x 2r box is
    then centred on our circle (with the position itself, the box would trail 0.6 m behind the circle
    and SUMO would see contacts at 0.2-0.3 m of our clearance, e.g. with yielders stepping back).
    """
    # units.yaw_rad_to_sumo_angle on one float, in math: the same bits (numpy's rad2deg and math.degrees
    # multiply by the same 180/pi, np.mod and % are both Python's modulo; 2 M angles checked), without
    # numpy's per-call cost on a scalar (~4 us per step: benchmarks/profile_protocol.py's person.moveToXY
    # phase 28.8 -> 24.7 us per step, measured one after the other at the same load).
    api.person.moveToXY(
        PED_ID,
        "",
        pose.x_m + radius_m * math.cos(pose.heading_rad),
        pose.y_m + radius_m * math.sin(pose.heading_rad),
        angle=(90.0 - math.degrees(pose.heading_rad)) % 360.0,
        keepRoute=2,
        matchThreshold=PED_MATCH_RADIUS_M,
    )


class KerbParkingFile:
    """The folder of the per-episode parking file of cars parked at the kerb (sim/kerb.py), made on
    first use and removed by close(), or when this object is collected or the process exits (batch
    workers end without closing their runner)."""

    def __init__(self) -> None:
        self._dir: Path | None = None
        self._cleanup: weakref.finalize | None = None

    def write(self, approach: Approach, vehicles: tuple[VehicleSetup, ...]) -> Path:
        """This episode's parking areas of the cars parked at the kerb, written for SUMO."""
        if self._dir is None:
            self._dir = Path(tempfile.mkdtemp(prefix="pedsafe_kerb_"))
            self._cleanup = weakref.finalize(self, shutil.rmtree, self._dir, True)
        path = self._dir / "kerb_parking.add.xml"
        path.write_text(parking_xml(approach, vehicles), encoding="utf-8")
        return path

    def close(self) -> None:
        if self._cleanup is not None:
            self._cleanup()
            self._dir = self._cleanup = None


class SumoStaging:
    """Stages the episodes of one site in a SUMO session, in the order SUMO needs."""

    def __init__(self, site: Site, step_length_s: float, refuges: bool, gui: GuiView | None = None) -> None:
        """`refuges`: the network has median refuges (walking areas no sidewalk reaches: add_pedestrian);
        `gui`: sumo-gui's view (None headless)."""
        self.site = site
        self.step_length_s = step_length_s
        self.refuges = refuges
        self.gui = gui
        self._kerb_file = KerbParkingFile()

    def sumo_args(self, seed: int) -> list[str]:
        return sumo_args(self.site, self.step_length_s, seed, self.gui)

    def populate(self, api, setup: EpisodeSetup, approach: Approach, start_s: float = 0.0) -> None:
        """Add the episode's road users (module function `populate`); a subclass may add to the scene
        here, before the traffic light is started."""
        populate(api, setup, approach, self.refuges, start_s)

    def add_pedestrian_now(self, api, approach: Approach) -> None:
        """Add the episode's pedestrian (type "ped_type", made by `populate`) to SUMO now: the loop calls
        it when they appear, and moves them where the behaviour model puts them before SUMO steps."""
        sidewalk_edge = approach.sidewalk_lane_id.rsplit("_", 1)[0]
        add_pedestrian(api, sidewalk_edge, "ped_type", self.refuges, api.simulation.getTime())

    def stage(
        self, session: SumoSession, setup: EpisodeSetup, seed: int, approach: Approach, program=None
    ) -> float:
        """Load SUMO for episode `seed` and put `setup`'s world in place; return SUMO's time at the
        episode's t = 0. `program`: the junction's signal program the staging was drawn from."""
        kerb = kerb_parked(setup)
        args = self.sumo_args(seed)
        if kerb:
            args = with_additional(args, self._kerb_file.write(approach, kerb))
        session.run(args)
        api = session.api
        # Cars parked at the kerb go in a step ahead (SUMO parks a vehicle the step after inserting it):
        # the episode's clock starts then (sim/kerb.py). Without them SUMO's clock is the episode's.
        start_s = 0.0
        if kerb:
            park_at_kerb(
                api, kerb, lambda api_, vehicle, route_id: add_vehicle(api_, vehicle, route_id, True)
            )
            start_s = api.simulation.getTime()
        queue = formed_queue(setup)
        if queue:
            # Approach staging: SUMO forms the kerb lane's queue first (sim/queue.py); the episode's clock
            # starts once it stands.
            form_queue(
                api,
                queue,
                lambda api_, vehicle, route_id, depart: add_vehicle(
                    api_, vehicle, route_id, True, depart, upstream=True
                ),
                near_turn_letter(approach.keep_side),
            )
            start_s = api.simulation.getTime()
        self.populate(api, setup, approach, start_s)
        start_signals(api, setup.signals, program)
        api.simulation.step()  # inserts everything at t = 0
        place_on_junction(api, setup)
        check_parked(api, kerb)
        return start_s

    def close(self) -> None:
        self._kerb_file.close()


def subscribe_vehicles(api, setup: EpisodeSetup) -> dict[str, VehicleDims]:
    """Subscribe to the staged vehicles' positions, angles and speeds, hand their speed and lanes to
    TraCI (speed mode 0, lane-change mode 0), and return their bodies by id (RuntimeError for one SUMO
    did not insert)."""
    tc = api.constants
    dims: dict[str, VehicleDims] = {}
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
    return dims


def background_arrivals(
    api, background: Sequence[BackgroundVehicle], dims: dict[str, VehicleDims]
) -> Callable[[], None] | None:
    """The loop's per-step call that registers the background vehicles SUMO inserted in the last step
    (their speed factor, subscription and body in `dims`); None for an episode without background."""
    if not background:
        return None
    by_id = {v.vehicle_id: v for v in background}
    tc = api.constants
    car = VEHICLE_CLASSES["car"]

    def register_departed() -> None:
        for vid in api.simulation.getDepartedIDList():
            vehicle = by_id.get(vid)
            if vehicle is None:
                continue
            api.vehicle.setSpeedFactor(vid, vehicle.speed_factor)
            api.vehicle.subscribe(vid, [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED])
            dims[vid] = (car.length_m, car.width_m, car.height_m, vehicle.colour_rgb)

    return register_departed
