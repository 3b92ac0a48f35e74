"""The examples/ a user copies, in real SUMO: a stack that clusters raw LiDAR points (no labels) and
brakes avoids most of the crossing collisions a never-braking stack has; the cautious stack stops at
a red light and keeps its gap (unit tests of its logic); a --perception plug-in runs in the batch."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from examples.cautious_stack import COMFORT_DECEL_MPS2, GAP_M, HEADWAY_S, STOP_SHORT_M, CautiousStack
from examples.tracking_stack import COAST_S, TrackingStack
from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.control.agent import (
    EgoState,
    Observation,
    PerceivedPedestrian,
    PerceivedVehicle,
    TrafficLightState,
    load_agent_class,
    stack_spec,
)
from pedsafe_sumo.control.reference import CLEAR_HOLD_S, ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params, with_overrides
from pedsafe_sumo.scenarios.specs import SCENARIOS
from pedsafe_sumo.sim.episode import EpisodeRunner

SITE = get_site("xueqing")
CLUSTERING = stack_spec(
    "pedsafe_sumo.control.reference:ReferenceStack", "examples.lidar_clustering:LidarClustering"
)
#: A coarser LiDAR than the default (0.4 degrees, 40 m instead of 0.2 degrees, 100 m) keeps the test at a
#: few seconds per episode; the clustering reads the points of whatever LiDAR it is given.
COARSE_LIDAR = {"perception": {"lidar": {"horizontal_resolution_deg": 0.4, "range_m": 40.0}}}


@pytest.mark.slow
def test_a_stack_clustering_raw_lidar_points_avoids_most_collisions_of_a_never_braking_stack():
    params = with_overrides(load_params(), COARSE_LIDAR)
    spec = SCENARIOS["crossing"]
    never = EpisodeRunner(SITE, params, load_agent_class("tests.sim.plugin_agents:NeverBrakes"))
    collided = [s for s in range(1, 7) if never.run(spec, "sv", s).outcome["collision"]]
    never.close()
    assert len(collided) >= 4  # the crossing scenario puts the pedestrian in the ego's path

    stack = load_agent_class(CLUSTERING)
    # Raw points only (no labels, no detections), and the route the reference stack's corridor follows.
    assert stack().sensors() == ["onboard_lidar_points", "route"]
    runner = EpisodeRunner(SITE, params, stack)
    results = [runner.run(spec, "sv", s) for s in collided[:4]]
    runner.close()
    still = sum(bool(r.outcome["collision"]) for r in results)
    assert still <= len(results) // 4
    for r in results:
        log = r.log
        # It stops for the pedestrian, not for the scenery far away: the ego drives on until it is
        # within a few metres of her (stop margin 2 m plus half its length), and does not stand still
        # from the start.
        gap_m = np.hypot(log.ego_x_m - log.ped_x_m, log.ego_y_m - log.ped_y_m)
        travelled_m = math.hypot(
            log.ego_x_m.iloc[-1] - log.ego_x_m.iloc[0], log.ego_y_m.iloc[-1] - log.ego_y_m.iloc[0]
        )
        assert gap_m.min() < 8.0 and travelled_m > 10.0


@pytest.mark.slow
def test_the_batch_runs_a_perception_plugin_and_records_it_with_the_algorithm(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--scenario", "crossing", "--condition", "sv",
         "--episodes", "1", "--workers", "1", "--out", str(out),
         "--perception", "examples.lidar_clustering:LidarClustering",
         "--set", "perception.lidar.horizontal_resolution_deg=0.4", "--set", "perception.lidar.range_m=40"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    run = json.loads((out / "run.json").read_text())
    assert run["algorithm"] == CLUSTERING
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert list(episodes.status) == ["ok"]


def _observation(state, distance_m, speed_mps=10.0, vehicles=()):
    light = TrafficLightState("J", 0, state, distance_m, math.nan, "onboard_camera", 0.0)
    ego = EgoState(0.0, 0.0, 0.0, speed_mps, 4.5, 1.8)
    return Observation(ego, (), 0.05, traffic_light=light, vehicles=tuple(vehicles))


def test_the_cautious_stack_brakes_to_stop_at_a_red_light_and_drives_on_green():
    stack = CautiousStack()
    stack.setup({"initial_speed_mps": 10.0})
    assert stack.run_step(_observation("G", 30.0), 0.0).target_speed_mps == pytest.approx(10.0)
    # 30 m ahead at 10 m/s: 3 m/s2 stops in 16.7 m, so it holds its speed for now.
    assert stack.run_step(_observation("r", 30.0), 0.05).target_speed_mps == pytest.approx(10.0)
    red = stack.run_step(_observation("r", 12.0), 0.1)
    # By hand: the speed from which 3 m/s2 stops in the room left (12 - 1 - 0.5 m) is sqrt(2 * 3 * 10.5)
    # = 7.9 m/s, below 10: brake, at most 6 m/s2 over the 0.05 s step.
    assert math.sqrt(2 * COMFORT_DECEL_MPS2 * (12.0 - STOP_SHORT_M - 0.5)) < 10.0 - 6.0 * 0.05
    assert red.target_speed_mps == pytest.approx(10.0 - 6.0 * 0.05)
    assert red.info["red_light"] and red.info["braking"]
    # A yellow too close to stop at 3 m/s2 (10 m/s needs 16.7 m) is driven through.
    assert "red_light" not in stack.run_step(_observation("y", 8.0), 0.15).info


def test_the_cautious_stack_keeps_its_gap_to_the_vehicle_ahead():
    stack = CautiousStack()
    stack.setup({"initial_speed_mps": 10.0})
    ahead = PerceivedVehicle("v", 15.0, 0.0, 0.0, 4.5, 1.8, "onboard_lidar")
    beside = PerceivedVehicle("w", 15.0, 3.5, 0.0, 4.5, 1.8, "onboard_lidar")  # the next lane
    command = stack.run_step(_observation("G", 200.0, vehicles=[ahead, beside]), 0.0)
    gap = 15.0 - 4.5 - GAP_M  # bumper to bumper less the standstill gap
    assert command.info["following"] == "v"
    # min(gap / headway, sqrt(2 a gap)), and never harder than its maximum braking in one step.
    wanted = min(gap / HEADWAY_S, math.sqrt(2 * 3.0 * gap))
    assert command.target_speed_mps == pytest.approx(max(wanted, 10.0 - 6.0 * 0.05))


def _walking_into_the_path(time_s: float, perceived: bool):
    """The ego at the origin heading east at 10 m/s; a pedestrian 30 m ahead, 6 m to its right at t = 0,
    walking north at 1.5 m/s into its path (the corridor's edge, 0.9 + 0.5 m off centre, at t = 3.07 s)."""
    ego = EgoState(0.0, 0.0, 0.0, 10.0, 4.5, 1.8)
    pedestrians = (PerceivedPedestrian("p", 30.0, -6.0 + 1.5 * time_s, "v2i"),) if perceived else ()
    return Observation(ego, pedestrians, 0.05)


def test_the_tracking_stack_keeps_braking_for_a_pedestrian_it_lost_where_the_reference_forgets():
    """Perceived for 0.6 s, then lost: the reference stack drives on 0.5 s after the loss; the tracking
    stack keeps her where she walks (by hand) and brakes until 2 s after the loss, then the 0.5 s hold."""
    stacks = {"reference": ReferenceStack(), "tracking": TrackingStack()}
    for stack in stacks.values():
        stack.setup({"initial_speed_mps": 10.0})
    lost_at_s = 0.65
    commands = {name: {} for name in stacks}
    for k in range(0, 81):
        time_s = round(k * 0.05, 2)
        for name, stack in stacks.items():
            commands[name][time_s] = stack.run_step(
                _walking_into_the_path(time_s, time_s < lost_at_s), time_s
            )
        if time_s == 1.6:
            (kept,) = stacks["tracking"].coasted(_walking_into_the_path(time_s, False), time_s)
            # Last seen at 0.6 s at y = -6 + 0.9, moving north at 1.5 m/s: 1.0 s later, 1.5 m further.
            assert (kept.x_m, kept.y_m) == pytest.approx((30.0, -5.1 + 1.5 * 1.0), abs=1e-6)
    braking = {
        name: {t for t, c in by_time.items() if c.info.get("braking")} for name, by_time in commands.items()
    }
    # Both brake from the reaction time (0.4 s) after the threat (from 0.05 s: the tracker's second point).
    assert {0.45, 0.6} <= braking["reference"] and {0.45, 0.6} <= braking["tracking"]
    last_seen_s = 0.6
    # The threat clears once more than the hold has passed without one (to within a step: the times are
    # floats), and the stack drives on. The reference: 0.5 s after the last sighting.
    step_s = 0.05 + 1e-9
    assert max(braking["reference"]) + 0.05 == pytest.approx(last_seen_s + CLEAR_HOLD_S, abs=step_s)
    assert commands["reference"][1.3].target_speed_mps == pytest.approx(10.0)
    # The tracking stack: she is kept for 2 s after the last sighting, then the same 0.5 s hold.
    assert max(braking["tracking"]) + 0.05 == pytest.approx(last_seen_s + COAST_S + CLEAR_HOLD_S, abs=step_s)
    assert commands["tracking"][1.3].target_speed_mps < 10.0
    assert commands["tracking"][3.3].target_speed_mps == pytest.approx(10.0)
