"""The episode loop: one step after another of a staged episode until it ends (sim/episode.py runs it;
docs/engine.md, "The loop").

The hot path: it binds what it uses to local variables once per episode; measure a change to it with
benchmarks/profile_protocol.py --phases and benchmarks/bench_episode.py (BENCHMARKS.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from functools import partial
from itertools import chain
from operator import itemgetter
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.behaviour.pedestrian import PedestrianPose, PedestrianWalker, VehicleBodies
from pedsafe_sumo.behaviour.sight import ego_in_sight
from pedsafe_sumo.control.agent import Command, EgoState, Observation
from pedsafe_sumo.control.stack_calls import checked_speed_mps
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
from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup
from pedsafe_sumo.sim.actuation import plan_lateral, wants_lateral
from pedsafe_sumo.sim.observation import ObservationFeeds
from pedsafe_sumo.sim.outcome import LOG_COLUMNS, EpisodeTrace, sumo_collision_record
from pedsafe_sumo.sim.road_map import load_net_map
from pedsafe_sumo.sim.scene import episode_end, in_scene_from_start, perceived_pedestrians, vehicle_bodies
from pedsafe_sumo.sim.staging import EGO_ID, PED_ID, VehicleDims, move_pedestrian

#: A per-step observer for replay: `on_step(api, row)` gets SUMO's API handle, in the state of the step
#: just logged, and that step's log row (a dict of the log columns).
StepHook = Callable[[Any, dict[str, Any]], None]


def drive(
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
    position_of, angle_of, speed_of = itemgetter(var_position), itemgetter(var_angle), itemgetter(var_speed)
    ped = setup.pedestrian
    ped_radius_m, time_limit_s = ped.radius_m, setup.time_limit_s
    ped_ids = (PED_ID,)
    ped_radii = np.array([ped.radius_m], dtype=float)
    ped_heights = np.array([ped.height_m], dtype=float)
    ped_rgb = np.array([ped.clothing_rgb], dtype=float)
    # Body sizes and colours of the vehicles in the last snapshot: they change only when a vehicle
    # enters or leaves, so they are rebuilt then, not every step.
    body_ids: tuple[str, ...] = ()
    lengths = widths = heights = half_diagonals = half_lengths = np.zeros(0)
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
    # While nobody is in the scene and no feed is made from the snapshot, a step needs the ego alone: its
    # own subscription, no snapshot (the other vehicles matter to the sensors, the pedestrian model and
    # the snapshot's feeds only), no SUMO collision check (no person in SUMO to collide with).
    scene_feeds = feeds is not None and feeds.sees_scene
    ego_dims = dims[EGO_ID]
    ego_half_length = 0.5 * np.array([ego_dims[0]], dtype=float)
    while True:
        # The world at time_s, from SUMO's subscriptions.
        t0 = clock()
        time_s = api.simulation.getTime()
        if start_s:
            time_s = round(time_s - start_s, 6)
        if register_departed is not None:
            register_departed()
        if in_scene or scene_feeds:
            results = api.vehicle.getAllSubscriptionResults()
            if EGO_ID not in results:
                end_reason = "ego_left_network"
                break
            # Vectorised: SUMO's front-bumper positions and angles to footprint centres and yaw. Every
            # subscribed vehicle has its body in `dims`, so the subscription's ids are the snapshot's;
            # the filter runs only when the set changes.
            ids = tuple(results)
            if ids == body_ids:
                values = list(results.values())  # in the order of `ids`, without looking each one up
            else:
                ids = tuple(vid for vid in results if vid in dims)
                if ids != body_ids:
                    body_ids = ids
                    lengths, widths, heights, half_diagonals, colours, ego_index = vehicle_bodies(ids, dims)
                    half_lengths = 0.5 * lengths
                values = list(map(results.__getitem__, ids))
            n_vehicles = len(ids)
            front_xy = np.fromiter(chain.from_iterable(map(position_of, values)), float, 2 * n_vehicles)
            front_xy = front_xy.reshape(n_vehicles, 2)
            # units.sumo_angle_to_yaw_rad and units.sumo_front_to_centre: the same operations in the same
            # order (the same bits), without converting their arguments again.
            yaw = np.deg2rad(90.0 - np.fromiter(map(angle_of, values), float, n_vehicles))
            centre_x = front_xy[:, 0] - half_lengths * np.cos(yaw)
            centre_y = front_xy[:, 1] - half_lengths * np.sin(yaw)
            ego_x, ego_y = float(centre_x[ego_index]), float(centre_y[ego_index])
            ego_yaw = float(yaw[ego_index])
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
            detections = (
                perceive(snapshot, ego_pose, sensors, perception_rng, time_s, link) if in_scene else None
            )
            extra = (
                {} if feeds is None else feeds.step(snapshot, ego_pose, ego_index, time_s, results[EGO_ID])
            )
        else:
            ego_result = api.vehicle.getSubscriptionResults(EGO_ID)
            if not ego_result:
                end_reason = "ego_left_network"
                break
            # The ego's arrays of one element, the same operations as above: the same bits as its element
            # of the arrays of all the vehicles (numpy's elementwise functions).
            yaw = np.deg2rad(90.0 - np.array([ego_result[var_angle]], dtype=float))
            front_x, front_y = ego_result[var_position]
            centre_x = np.array([front_x], dtype=float) - ego_half_length * np.cos(yaw)
            centre_y = np.array([front_y], dtype=float) - ego_half_length * np.sin(yaw)
            ego_x, ego_y, ego_yaw = float(centre_x[0]), float(centre_y[0]), float(yaw[0])
            ego_speed = float(ego_result[var_speed])
            ego_length, ego_width = float(ego_dims[0]), float(ego_dims[1])
            t1 = clock()
            timings["snapshot_s"] += t1 - t0
            detections = None
            extra = (
                {}
                if feeds is None
                else feeds.step(None, EgoPose(ego_x, ego_y, ego_yaw, EGO_ID), 0, time_s, ego_result)
            )
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
            speeds = np.fromiter(map(speed_of, values), float, n_vehicles) if body_speeds else None
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
