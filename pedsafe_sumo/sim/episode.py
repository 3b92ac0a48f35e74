"""One episode: a scenario under a condition, driven through SUMO by the AD stack under test.

`EpisodeRunner.run` draws the episode's world (or takes one), stages it in SUMO (sim/staging.py), sets up
the AD stack, steps the loop below and judges what it recorded (sim/outcome.py).

The loop, at every step of `step_length_s` (default 0.05 s):
  1. read the world from SUMO's subscriptions (vehicles' front positions, angles, speeds);
  2. check the contact of the ego's footprint with the pedestrian's circle, and SUMO's own;
  3. build the world snapshot and run the sensors (perception layer);
  4. hand the AD stack what its condition grants (SV: onboard; V2I: onboard + roadside over the link);
  5. actuate the ego the TraCI way (speed mode 0, setSpeed to the stack's command);
  6. move the pedestrian by the behaviour model (person.moveToXY, so jaywalking leaves the crosswalks),
     which sees the vehicle bodies and casts its line of sight to the ego through the same geometry;
     add them to SUMO when they appear (PedestrianSetup.appear_time_s), remove them when they leave;
  7. log the step, and advance SUMO.
While the pedestrian is not in the scene no sensor runs (step 3) and the row logs them absent.
The episode ends on a collision (contact while the ego moves at `STATIONARY_SPEED_MPS` or faster; a
contact with a standing ego is logged), once both road users have cleared the conflict area (the ego's rear
past the pedestrian's path, the pedestrian past the ego's far flank), when the ego has left the network, or
at the scenario's time limit.

The loop (`_drive`) is the hot path: it binds what it uses to local variables once per episode; measure
a change to it with benchmarks/bench_episode.py (BENCHMARKS.md).

Randomness: the episode seed is split (numpy SeedSequence) into a world stream, drawn identically
under SV and V2I, and a perception stream; SUMO gets the seed too.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.behaviour.pedestrian import (
    PedestrianPose,
    PedestrianWalker,
    VehicleBodies,
)
from pedsafe_sumo.behaviour.sight import ego_in_sight
from pedsafe_sumo.control.agent import (
    Agent,
    Command,
    EgoState,
    Observation,
    check_sensor_names,
)
from pedsafe_sumo.control.stack_calls import checked_speed_mps, close_quietly, setup_within, stack_label
from pedsafe_sumo.control.timeout import DEFAULT_AGENT_TIMEOUT_S, check_timeout_s, guard_step
from pedsafe_sumo.demand.sampling import traffic_distributions
from pedsafe_sumo.demand.vehicles import speed_limit_scale
from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.perception import (
    EgoPose,
    Pedestrians,
    SensorSuite,
    V2ILink,
    VehicleBoxes,
    WorldSnapshot,
    perceive,
)
from pedsafe_sumo.safety.geometry_kernels import rectangle_circle_clearance_m
from pedsafe_sumo.safety.proximity import ProximityModel
from pedsafe_sumo.sampling.draws import Draws, draw_lognormal, draw_pedestrian_traits
from pedsafe_sumo.sampling.importance import Family
from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup
from pedsafe_sumo.scenarios.geometry import approach_unit_ids, refuge_walkingareas
from pedsafe_sumo.scenarios.oncoming import load_oncoming
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.specs import ScenarioSpec
from pedsafe_sumo.scenarios.staging import draw_episode, stage_signals
from pedsafe_sumo.sim.actuation import plan_lateral, speed_change_limits_mps, wants_lateral
from pedsafe_sumo.sim.connection import SumoSession
from pedsafe_sumo.sim.flush import step_if_moved_since
from pedsafe_sumo.sim.observation import ObservationFeeds, granted_names, sensor_mounts
from pedsafe_sumo.sim.outcome import (
    LOG_COLUMNS,
    EpisodeResult,
    EpisodeTrace,
    judge_episode,
    sumo_collision_record,
)
from pedsafe_sumo.sim.road_map import load_net_map
from pedsafe_sumo.sim.scene import (
    appearing_pose,
    episode_end,
    in_scene_from_start,
    perceived_pedestrians,
    vehicle_bodies,
)
from pedsafe_sumo.sim.staging import (
    EGO_ID,
    PED_ID,
    GuiView,
    SiteData,
    SumoStaging,
    VehicleDims,
    background_arrivals,
    behaviour_params,
    draw_background,
    load_site_data,
    move_pedestrian,
    stop_line_lane_shape,
    subscribe_vehicles,
)
from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre

CONDITIONS = ("sv", "v2i")
DEFAULT_ALGORITHM = "pedsafe_sumo.control.reference:ReferenceStack"
STEP_LENGTH_S = 0.05
#: The parts of an episode's time the loop measures (EpisodeResult.timings_s).
TIMED_PARTS = ("sumo_s", "snapshot_s", "perception_s", "agent_s", "logging_s")


#: A per-step observer for replay: `on_step(api, row)` gets SUMO's API handle, in the state of the step
#: just logged, and that step's log row (a dict of the log columns).
StepHook = Callable[[Any, dict[str, Any]], None]


class EpisodeRunner:
    """Runs episodes on one site, reusing one SUMO instance (libsumo, or sumo-gui through traci)."""

    #: How the runner puts an episode's world into SUMO (a subclass may stage more: ncap.suite).
    staging_class: type[SumoStaging] = SumoStaging

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
        self._use_approach("")
        self.session = SumoSession(gui=gui)
        view = GuiView(gui_settings_file or site.file("view.xml"), tuple(gui_options)) if gui else None
        #: Whether the network has median refuges (walking areas no sidewalk reaches: add_pedestrian).
        refuges = bool(refuge_walkingareas(site))
        self.staging = self.staging_class(site, step_length_s, refuges, view)

    def _use_approach(self, arm: str) -> None:
        """Stage what follows on the approach from `arm` (a spec's `approach`; "": the site's own)."""
        if arm not in self._by_approach:
            self._by_approach[arm] = load_site_data(self.site, self.params, arm)
        data = self._by_approach[arm]
        self._site_data = data
        self.approach = data.approach
        self.arm = data.arm
        self.signals = data.signals

    def close(self) -> None:
        self.session.close()
        self.staging.close()

    def sensors_for(self, spec: ScenarioSpec) -> SensorSuite:
        """The onboard sensors and the roadside poles the scenario names (built once per set of poles)."""
        side = self.approach.keep_side  # the scenario's turn names the near- or far-side turn
        ids = approach_unit_ids(spec.roadside_unit_ids, spec.approach, self._site_arm, spec.turn, side)
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

    # ------------------------------------------------------------------ the episode's world
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
        turn = placement_of(spec).load_turn(self.site, spec, spec.approach or None)
        oncoming = load_oncoming(self.site, spec.approach or None) if spec.oncoming_vehicle else None
        setup = draw_episode(spec, self.approach, seed, traits, ego_speed_mps, draws, turn, oncoming)
        if spec.approach:
            setup = dataclasses.replace(setup, approach=spec.approach)
        setup = stage_signals(spec, setup, self.signals, draws, self.approach.keep_side)
        if spec.background_traffic:
            background = draw_background(
                spec, self._site_data, self.params["traffic"], traffic_seq, setup.time_limit_s
            )
            setup = dataclasses.replace(setup, background=background)
        return setup, draws

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
        timings = dict.fromkeys(TIMED_PARTS, 0.0)

        started = time.perf_counter()
        program = self.signals.program if self.signals else None
        start_s = self.staging.stage(self.session, setup, seed, self.approach, program)
        timings["sumo_s"] += time.perf_counter() - started
        api = self.session.api
        dims = subscribe_vehicles(api, setup)
        register_departed = background_arrivals(api, setup.background, dims)
        if register_departed is not None:
            register_departed()

        ped = setup.pedestrian
        behaviour = behaviour_params(self.params["pedestrians"], ped)
        walker = PedestrianWalker(
            ped.path_xy,
            behaviour,
            start_delay_s=ped.start_delay_s,
            kerb_index=ped.kerb_index,
            appear_time_s=ped.appear_time_s,
            leaves_scene=ped.leaves_scene,
        )
        agent, wanted = self._start_agent(setup, condition, seed)
        sensors = self.sensors_for(spec)
        link = V2ILink(sensors.v2i, np.random.default_rng(streams[3])) if "v2i" in wanted else None
        feeds = ObservationFeeds.for_agent(
            api, EGO_ID, wanted, condition, self.site.file("net.xml"), sensors, self.params["perception"]
        )
        pose = appearing_pose(walker)
        moved_at_s = math.nan
        if in_scene_from_start(ped):  # else the loop adds them to SUMO when they appear
            move_pedestrian(api, pose, ped.radius_m)
            moved_at_s = api.simulation.getTime()  # the move is pending until SUMO steps (sim/flush.py)
        # run_step under the per-step time limit: AgentTimeoutError ends the episode (status "timeout").
        run_step = guard_step(agent.run_step, self.agent_timeout_s).start()
        try:
            trace = _drive(
                pose,
                run_step,
                on_step,
                stack=stack_label(self.agent_class),  # names the stack in its invalid commands' messages
                api=api,
                setup=setup,
                v2i=condition == "v2i",
                walker=walker,
                start_s=start_s,
                dims=dims,
                register_departed=register_departed,
                sensors=sensors,
                perception_rng=np.random.default_rng(streams[1]),
                link=link,
                feeds=feeds,
                wanted=wanted,
                static=self.static,
                step_length_s=self.step_length_s,
                eye_height_m=self.params["pedestrians"]["eye_height_fraction"] * ped.height_m,
                net_file=str(self.site.file("net.xml")),
                timings=timings,
                add_pedestrian=partial(self.staging.add_pedestrian_now, api, self.approach),
                body_speeds=behaviour.body_rule_needs_notice,
                speed_change_limits_mps=speed_change_limits_mps(
                    self.params.get("vehicle"), self.step_length_s
                ),
            )
        finally:
            run_step.stop()
            step_if_moved_since(api, moved_at_s)  # no moveToXY left pending (sim/flush.py)
            if not run_step.timed_out:  # a stack cut off mid-step may still be running: leave it
                close_quietly(agent)  # while the episode fails, its first failure is the one reported
        lane_shape = stop_line_lane_shape(str(self.site.file("net.xml")), setup)
        return judge_episode(
            setup, condition, seed, trace, self.arm, self.injury_model, self.proximity_model, lane_shape
        )

    def _start_agent(self, setup: EpisodeSetup, condition: str, seed: int) -> tuple[Agent, set[str]]:
        """A new instance of the stack under test, set up for the episode, and the sensors it gets: those
        it asks for that the condition grants."""
        agent = self.agent_class()
        granted = {"onboard_camera", "onboard_lidar"} | ({"v2i"} if condition == "v2i" else set())
        granted |= granted_names(condition)  # raw data and world feeds, on request only
        check_sensor_names(agent.sensors(), type(agent).__name__)
        setup_within(  # under --agent-timeout, like run_step (control/stack_calls.py)
            agent,
            {
                # The parameter file's [algorithm] settings (a run.json may have none).
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
        return agent, set(agent.sensors()) & granted


def _drive(
    pose: PedestrianPose,
    run_step: Callable[[Observation, float], Command],
    on_step: StepHook | None,
    *,
    stack: str,
    api,
    setup: EpisodeSetup,
    v2i: bool,
    walker: PedestrianWalker,
    start_s: float,
    dims: dict[str, VehicleDims],
    register_departed: Callable[[], None] | None,
    sensors: SensorSuite,
    perception_rng: np.random.Generator,
    link: V2ILink | None,
    feeds: ObservationFeeds | None,
    wanted: set[str],
    static,
    step_length_s: float,
    eye_height_m: float,
    net_file: str,
    timings: dict[str, float],
    add_pedestrian: Callable[[], None] | None = None,
    body_speeds: bool = False,
    speed_change_limits_mps: tuple[float, float] | None = None,
) -> EpisodeTrace:
    """Step a staged episode from the pedestrian's first `pose` until it ends (module docstring).

    `v2i`: the condition is V2I (its detections reach the log); `start_s`: SUMO's time at the episode's
    t = 0 (sim/kerb.py); `dims`: the bodies of the vehicles the loop sees, by id (`register_departed`
    adds the background's as they enter); `net_file`: the network, read for lateral commands; `timings`
    gets the seconds of each part of the loop added; `add_pedestrian()` adds the pedestrian to SUMO when
    they appear (PedestrianSetup.appear_time_s > 0); `body_speeds`: the behaviour model gets the vehicles'
    speeds (its body rule depends on them).

    While the pedestrian is not in the scene (before appear_time_s, after leaving it) they are in neither
    SUMO nor the snapshot, no sensor runs (the AD stack gets no pedestrians; raw-data feeds see the scene
    without them) and the step's row has ped_state "absent" or "left", NaN position and velocity and an
    infinite clearance."""
    clock = time.perf_counter
    tc = api.constants
    var_position, var_angle, var_speed = tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED
    ped = setup.pedestrian
    ped_radius_m, time_limit_s = ped.radius_m, setup.time_limit_s
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
    # SUMO checks vehicle-person contact only on crossings and walking areas: the person's SUMO edge
    # at the closest approach decides whether its verdict counts (sim.outcome).
    closest_clearance_m = math.inf
    closest_edge = ""
    end_reason = "time_limit"
    in_scene = in_scene_from_start(ped)
    gone = False  # left the scene at the end of their path
    appear_s = ped.appear_time_s - 1e-9
    nobody = Pedestrians((), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 3)))
    nan = math.nan
    while True:
        # The world at time_s, from SUMO's subscriptions.
        t0 = clock()
        time_s = api.simulation.getTime()
        if start_s:
            time_s = round(time_s - start_s, 6)
        if register_departed is not None:
            register_departed()
        results = api.vehicle.getAllSubscriptionResults()
        if EGO_ID not in results:
            end_reason = "ego_left_network"
            break
        # Vectorised: SUMO's front-bumper positions and angles to footprint centres and yaw. Every
        # subscribed vehicle has its body in `dims`, so the subscription's ids are the snapshot's; the
        # filter runs only when the set changes.
        ids = tuple(results)
        if ids != body_ids:
            ids = tuple(vid for vid in results if vid in dims)
            if ids != body_ids:
                body_ids = ids
                lengths, widths, heights, half_diagonals, colours, ego_index = vehicle_bodies(ids, dims)
        front_xy = np.array([results[vid][var_position] for vid in ids])
        yaw = sumo_angle_to_yaw_rad([results[vid][var_angle] for vid in ids])
        centre_x, centre_y = sumo_front_to_centre(front_xy[:, 0], front_xy[:, 1], yaw, lengths)
        ego_x, ego_y, ego_yaw = float(centre_x[ego_index]), float(centre_y[ego_index]), float(yaw[ego_index])
        ego_speed = float(results[EGO_ID][var_speed])
        ego_length, ego_width = float(lengths[ego_index]), float(widths[ego_index])
        if not sumo_collision:
            sumo_record = sumo_collision_record(api, time_s)
            sumo_collision = bool(sumo_record)
        # Built directly from float arrays of matching lengths (what .build would check and convert).
        vehicles = VehicleBoxes(ids, centre_x, centre_y, yaw, lengths, widths, heights, colours)
        if in_scene:
            pedestrians = Pedestrians(
                ped_ids, np.array([pose.x_m]), np.array([pose.y_m]), ped_radii, ped_heights, ped_rgb
            )
        else:
            pedestrians = nobody
        snapshot = WorldSnapshot(time_s, vehicles, pedestrians, static)
        t1 = clock()
        timings["snapshot_s"] += t1 - t0

        # What the sensors report.
        ego_pose = EgoPose(ego_x, ego_y, ego_yaw, EGO_ID)
        # Nobody to perceive while the pedestrian is not in the scene: the sensors do not run.
        detections = perceive(snapshot, ego_pose, sensors, perception_rng, time_s, link) if in_scene else None
        extra = feeds.step(snapshot, ego_pose, ego_index, time_s) if feeds is not None else {}
        t2 = clock()
        timings["perception_s"] += t2 - t1

        # The AD stack's command, from what its condition grants.
        reported = perceived_pedestrians(detections, wanted) if detections is not None else []
        ego = EgoState(ego_x, ego_y, ego_yaw, ego_speed, ego_length, ego_width)
        command: Command = run_step(Observation(ego, tuple(reported), step_length_s, **extra), time_s)
        target_mps = checked_speed_mps(command, stack, time_s)  # or StackError (control/stack_calls.py)
        refused, steer = "", None
        if wants_lateral(command):  # a lane change or a path; refusals are logged
            net = load_net_map(net_file)
            refused, steer = plan_lateral(
                api, EGO_ID, command, net, (ego_x, ego_y), ego_length, target_mps, step_length_s
            )
        t3 = clock()
        timings["agent_s"] += t3 - t2

        # The step's log row. Compiled scalar form of safety.geometry.rectangle_circle_distance_m (the
        # same bits).
        if detections is None:  # nobody in the scene
            clearance_m = math.inf
            rows.append(
                (time_s, ego_x, ego_y, ego_yaw, ego_speed, ego_length, ego_width, nan, nan, nan, nan,
                 ped_radius_m, False, False, False, False, False, clearance_m, target_mps,
                 bool(command.info.get("braking", False)), "left" if gone else "absent", sumo_collision,
                 refused)
            )  # fmt: skip
        else:
            clearance_m = float(
                rectangle_circle_clearance_m(
                    ego_x, ego_y, ego_yaw, ego_length, ego_width, pose.x_m, pose.y_m, ped_radius_m
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
                    ped_radius_m,
                    PED_ID in detections.camera,
                    PED_ID in detections.lidar,
                    v2i and PED_ID in detections.v2i_received,
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

        ended = episode_end(time_s, clearance_m, ego, pose, walker, ped, time_limit_s)
        if ended is not None:
            end_reason = ended
            break

        # Actuate the ego, move the pedestrian, advance SUMO.
        t4 = clock()
        if speed_change_limits_mps is None:
            api.vehicle.setSpeed(EGO_ID, target_mps)
        else:  # what the ego can do in one step, whatever was commanded (the log keeps the command)
            down_mps, up_mps = speed_change_limits_mps
            api.vehicle.setSpeed(
                EGO_ID, max(0.0, min(max(target_mps, ego_speed - down_mps), ego_speed + up_mps))
            )
        if steer is not None:
            steer()
        if in_scene:
            speeds = np.array([results[vid][var_speed] for vid in ids]) if body_speeds else None
            bodies = VehicleBodies(
                centre_x, centre_y, yaw, lengths, widths, half_diagonals, speeds, ego_index
            )
            pose = walker.step(
                step_length_s,
                time_s,
                (ego_x, ego_y),
                ego_yaw,
                ego_speed,
                ego_length,
                ego_width,
                sees_ego=partial(ego_in_sight, snapshot, ego_index, (pose.x_m, pose.y_m, eye_height_m)),
                bodies=bodies,
            )
            if pose.state == "left":  # at the end of their path, out of the scene
                api.person.remove(PED_ID)
                in_scene, gone = False, True
            else:
                move_pedestrian(api, pose, ped_radius_m)
        elif not gone and time_s + step_length_s >= appear_s and add_pedestrian is not None:
            # In the scene from the next step on: into SUMO, at the start of their path.
            add_pedestrian()
            move_pedestrian(api, pose, ped_radius_m)
            in_scene = True
        api.simulation.step()
        timings["sumo_s"] += clock() - t4

    log = pd.DataFrame(rows, columns=list(LOG_COLUMNS)) if rows else pd.DataFrame()
    return EpisodeTrace(log, end_reason, signal_states, sumo_record, closest_edge, timings)
