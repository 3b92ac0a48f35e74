"""The engine's rows without the pedestrian (before they appear, after they leave) in the indexes, and the
classification of a collision (sim.outcome.collision_type), on hand-built logs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo.safety.episode import INDEX_COLUMNS, NO_PEDESTRIAN_INDEXES, episode_indexes
from pedsafe_sumo.safety.proximity import SCOPE_EPISODE, default_proximity_model
from pedsafe_sumo.sim.outcome import collision_type, first_collision_step

DT = 0.05


def _log(n_absent_before=0, n_left_after=0):
    """The ego (4 m x 2 m) along y = 0 heading +x at 10 m/s from x = -20 at t = 0.05; a pedestrian standing
    at (10, 3) (their body 1.7 m from the ego's path line: clearance 3 - 1 - 0.3 = 1.7 m abeam), perceived
    from the 10th present step; `n_absent_before` rows before them and `n_left_after` after them have no
    pedestrian (NaN position and velocity, infinite clearance, nothing perceived)."""
    n = n_absent_before + 60 + n_left_after
    t = DT * np.arange(1, n + 1)
    ego_x = -20.0 + 10.0 * (t - DT)
    present = np.zeros(n, dtype=bool)
    present[n_absent_before : n_absent_before + 60] = True
    ped_x = np.where(present, 10.0, np.nan)
    ped_y = np.where(present, 3.0, np.nan)
    perceived = np.zeros(n, dtype=bool)
    perceived[n_absent_before + 9 : n_absent_before + 60] = True
    lon = np.abs(ped_x - ego_x) - 2.0
    clearance = np.where(present, np.hypot(np.maximum(lon, 0.0), 2.0) - 0.3, np.inf)
    state = np.where(present, "waiting", "absent")
    state[n_absent_before + 60 :] = "left"
    return pd.DataFrame(
        {
            "time_s": t, "ego_x_m": ego_x, "ego_y_m": 0.0, "ego_yaw_rad": 0.0, "ego_speed_mps": 10.0,
            "ego_length_m": 4.0, "ego_width_m": 2.0, "ped_x_m": ped_x, "ped_y_m": ped_y,
            "ped_vx_mps": np.where(present, 0.0, np.nan), "ped_vy_mps": np.where(present, 0.0, np.nan),
            "ped_radius_m": 0.3, "detected_onboard_camera": perceived, "detected_onboard_lidar": False,
            "detected_roadside": False, "perceived": perceived, "clearance_m": clearance, "ped_state": state,
        }
    )  # fmt: skip


def _same(a, b):
    return a == b or (isinstance(a, float) and math.isnan(a) and isinstance(b, float) and math.isnan(b))


def test_steps_without_the_pedestrian_change_no_index():
    log = _log(n_absent_before=30, n_left_after=25)
    # The minimum clearance over every step with the pedestrian (scope "episode"): the pedestrian here
    # stands beside the ego's path, which the interaction scope leaves out.
    every_step = dataclasses.replace(default_proximity_model(), scope=SCOPE_EPISODE)
    with_absent = episode_indexes(log, 40.0, proximity_model=every_step)
    present_only = episode_indexes(
        log[~log["ped_state"].isin(["absent", "left"])], 40.0, proximity_model=every_step
    )
    assert set(with_absent) == set(INDEX_COLUMNS)
    for name in INDEX_COLUMNS:
        assert _same(with_absent[name], present_only[name]), name
    # By hand: the pedestrian is there from t = 1.55 s to 4.50 s; the ego passes them (x = 10) at t = 3.05 s:
    # minimum clearance abeam, 3 - 1 - 0.3 = 1.7 m, at 10 m/s. First perceived at the 10th present step,
    # t = 2.0 s, with the ego's centre at x = -20 + 10 * 1.95 = -0.5: 10.5 m along, 3 m aside.
    assert with_absent["min_clearance_m"] == pytest.approx(1.7)
    assert with_absent["ego_speed_at_min_clearance_mps"] == 10.0
    assert with_absent["first_detection_time_s"] == pytest.approx(2.0)
    assert with_absent["first_detection_distance_m"] == pytest.approx(math.hypot(10.5, 3.0))
    assert not with_absent["collision"] and not with_absent["contact_stationary"]


def test_a_log_without_the_pedestrian_has_no_indexes():
    log = _log(n_absent_before=10)
    indexes = episode_indexes(log[log["ped_state"] == "absent"], 40.0)
    assert set(indexes) == set(NO_PEDESTRIAN_INDEXES)
    assert all(_same(indexes[k], v) for k, v in NO_PEDESTRIAN_INDEXES.items())
    assert math.isnan(indexes["min_clearance_m"]) and not indexes["collision"]


# ------------------------------------------------------------------------------------------ collision_type
def _contact(ped_xy, ped_v, yaws=(0.0, 0.0), speed=5.0):
    """Two rows: the ego (4 m x 2 m, centre at the origin at the second row) at `speed` along its yaw, the
    pedestrian (r 0.3) at `ped_xy` with velocity `ped_v` at the second row, in contact then."""
    (px, py), (vx, vy) = ped_xy, ped_v
    rows = {
        "time_s": [1.0, 1.05], "ego_x_m": [-speed * DT, 0.0], "ego_y_m": [0.0, 0.0],
        "ego_yaw_rad": list(yaws),
        "ego_speed_mps": [speed, speed], "ego_length_m": [4.0, 4.0], "ego_width_m": [2.0, 2.0],
        "ped_x_m": [px - vx * DT, px], "ped_y_m": [py - vy * DT, py], "ped_vx_mps": [vx, vx],
        "ped_vy_mps": [vy, vy], "ped_radius_m": [0.3, 0.3],
    }  # fmt: skip
    log = pd.DataFrame(rows)
    cos, sin = math.cos(yaws[1]), math.sin(yaws[1])
    lon, lat = cos * px + sin * py, -sin * px + cos * py
    out = math.hypot(max(abs(lon) - 2.0, 0.0), max(abs(lat) - 1.0, 0.0))
    gap = out + min(max(abs(lon) - 2.0, abs(lat) - 1.0), 0.0)
    log["clearance_m"] = [1.0, gap - 0.3]
    return log


def test_who_struck_whom():
    # Beside the middle of the right flank (y = -1.25: 0.05 m into it), walking +y (towards it) at 1.5 m/s.
    side = _contact((0.0, -1.25), (0.0, 1.5))
    assert first_collision_step(side) == 1 and collision_type(side, 1) == "pedestrian_strikes_side"
    # The same place, standing still, or walking away: the ego came onto them.
    assert collision_type(_contact((0.0, -1.25), (0.0, 0.0)), 1) == "ego_strikes_pedestrian"
    assert collision_type(_contact((0.0, -1.25), (0.0, -1.0)), 1) == "ego_strikes_pedestrian"
    # Ahead of the front face (x = 2 + 0.25), walking across it: the front strikes them.
    assert collision_type(_contact((2.25, 0.5), (0.0, 1.5)), 1) == "ego_strikes_pedestrian"
    # Beside the box but within the step's travel (5 m/s x 0.05 s = 0.25 m) of the front face's line:
    # the front corner came onto them; 0.3 m behind it, beside the flank.
    assert collision_type(_contact((1.8, -1.25), (0.0, 1.5)), 1) == "ego_strikes_pedestrian"
    assert collision_type(_contact((1.7, -1.25), (0.0, 1.5)), 1) == "pedestrian_strikes_side"
    # A turning ego (yaw rate +2 rad/s, turning left) sweeps its rear right side (lon -1.5) towards a
    # pedestrian on its right at 2 x 1.5 = 3 m/s: faster than their 1.5 m/s, the ego struck them.
    turning = _contact((-1.5, -1.25), (0.0, 1.5), yaws=(-0.1, 0.0))
    assert collision_type(turning, 1) == "ego_strikes_pedestrian"
    faster = _contact((-1.5, -1.25), (0.0, 4.0), yaws=(-0.1, 0.0))
    assert collision_type(faster, 1) == "pedestrian_strikes_side"
    assert collision_type(side, None) == "none"
