"""The per-step log as the loop keeps it (one tuple per step): the replay hook gets each step as a dict
equal to the logged row, the columns and their types are the log contract's, and the ego's logged pose
is SUMO's own (front bumper and angle, converted here by hand), with background traffic entering and
leaving the snapshot."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.safety.log import BOOLEAN_COLUMNS, NUMERIC_COLUMNS
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sim.outcome import LOG_COLUMNS
from pedsafe_sumo.sim.staging import EGO_ID


@pytest.mark.slow
def test_hook_rows_equal_the_log_and_the_ego_pose_is_sumos():
    runner = EpisodeRunner(get_site("xueqing"), load_params(), ReferenceStack)
    seen: list[dict] = []
    sumo_pose: list[tuple[float, float, float, float]] = []
    vehicle_counts: list[int] = []

    def hook(api, row):
        seen.append(row)
        x, y = api.vehicle.getPosition(EGO_ID)
        angle_deg = api.vehicle.getAngle(EGO_ID)
        sumo_pose.append((x, y, angle_deg, api.vehicle.getLength(EGO_ID)))
        vehicle_counts.append(len(api.vehicle.getIDList()))

    try:
        result = runner.run(get_scenario("background_blending"), "v2i", 3, on_step=hook)
    finally:
        runner.close()
    log = result.log
    assert list(log.columns) == list(LOG_COLUMNS)
    assert len(seen) == len(log) > 20
    for i in (0, len(log) // 2, len(log) - 1):
        assert list(seen[i]) == list(LOG_COLUMNS)
        assert seen[i] == log.iloc[i].to_dict()
    for name in NUMERIC_COLUMNS:
        assert log[name].dtype == "float64", name
    for name in BOOLEAN_COLUMNS:
        assert log[name].dtype == bool, name
    assert pd.api.types.is_string_dtype(log["ped_state"]) and pd.api.types.is_string_dtype(
        log["command_refused"]
    )
    # SUMO gives the front bumper's middle and degrees clockwise from north; the log the footprint centre
    # and yaw counter-clockwise from east.
    for (x, y, angle_deg, length_m), (_, row) in zip(sumo_pose, log.iterrows(), strict=True):
        yaw = math.radians(90.0 - angle_deg)
        assert row["ego_yaw_rad"] == pytest.approx(yaw, abs=1e-9)
        assert row["ego_x_m"] == pytest.approx(x - 0.5 * length_m * math.cos(yaw), abs=1e-9)
        assert row["ego_y_m"] == pytest.approx(y - 0.5 * length_m * math.sin(yaw), abs=1e-9)
        assert row["ego_length_m"] == length_m
    # The background traffic changed the set of vehicles during the episode (the snapshot's ids were
    # rebuilt from the subscription at least once after the first step).
    assert len(set(vehicle_counts)) > 1
