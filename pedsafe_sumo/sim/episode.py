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

The loop (`drive`, sim/loop.py) is the hot path: measure a change to it with
benchmarks/profile_protocol.py --phases and benchmarks/bench_episode.py (BENCHMARKS.md).

Randomness: the episode seed is split (numpy SeedSequence) into a world stream, drawn identically
under SV and V2I, and a perception stream; SUMO gets the seed too.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from pedsafe_sumo.behaviour.pedestrian import (
    PedestrianWalker,
)
from pedsafe_sumo.control.agent import (
    Agent,
    check_sensor_names,
)
from pedsafe_sumo.control.stack_calls import close_quietly, setup_within, stack_label
from pedsafe_sumo.control.timeout import DEFAULT_AGENT_TIMEOUT_S, check_timeout_s, guard_step
from pedsafe_sumo.demand.sampling import traffic_distributions
from pedsafe_sumo.demand.vehicles import speed_limit_scale
from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.perception import (
    SensorSuite,
    V2ILink,
)
from pedsafe_sumo.safety.proximity import ProximityModel
from pedsafe_sumo.sampling.draws import Draws, draw_lognormal, draw_pedestrian_traits
from pedsafe_sumo.sampling.importance import Family
from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup
from pedsafe_sumo.scenarios.geometry import approach_unit_ids, refuge_walkingareas
from pedsafe_sumo.scenarios.oncoming import load_oncoming
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.specs import ScenarioSpec
from pedsafe_sumo.scenarios.staging import draw_episode, stage_signals
from pedsafe_sumo.sim.actuation import speed_change_limits_mps
from pedsafe_sumo.sim.connection import SumoSession
from pedsafe_sumo.sim.flush import step_if_moved_since
from pedsafe_sumo.sim.loop import StepHook, drive
from pedsafe_sumo.sim.observation import ObservationFeeds, granted_names, sensor_mounts
from pedsafe_sumo.sim.outcome import (
    EpisodeResult,
    judge_episode,
)
from pedsafe_sumo.sim.scene import (
    appearing_pose,
    in_scene_from_start,
)
from pedsafe_sumo.sim.staging import (
    EGO_ID,
    GuiView,
    SiteData,
    SumoStaging,
    background_arrivals,
    behaviour_params,
    draw_background,
    load_site_data,
    move_pedestrian,
    stop_line_lane_shape,
    subscribe_vehicles,
)

CONDITIONS = ("sv", "v2i")
DEFAULT_ALGORITHM = "pedsafe_sumo.control.reference:ReferenceStack"
STEP_LENGTH_S = 0.05
#: The parts of an episode's time the loop measures (EpisodeResult.timings_s).
TIMED_PARTS = ("sumo_s", "snapshot_s", "perception_s", "agent_s", "logging_s")


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
        if feeds is not None:
            feeds.subscribe_ego()
        pose = appearing_pose(walker)
        moved_at_s = math.nan
        if in_scene_from_start(ped):  # else the loop adds them to SUMO when they appear
            move_pedestrian(api, pose, ped.radius_m)
            moved_at_s = api.simulation.getTime()  # the move is pending until SUMO steps (sim/flush.py)
        # run_step under the per-step time limit: AgentTimeoutError ends the episode (status "timeout").
        run_step = guard_step(agent.run_step, self.agent_timeout_s).start()
        try:
            trace = drive(
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
