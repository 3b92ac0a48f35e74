"""The examples/ a user copies, in real SUMO: a stack that clusters raw LiDAR points (no labels) and
brakes avoids most of the crossing collisions a never-braking stack has; the cautious stack stops at
a red light; both load through --algorithm / --perception."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.control.agent import load_agent_class, stack_spec
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params, with_overrides
from pedsafe_sumo.scenarios.registry import SCENARIOS
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
    assert stack().sensors() == ["onboard_lidar_points"]  # raw points only: no labels, no detections
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
