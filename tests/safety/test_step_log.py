"""The per-step log contract: what the episode engine must write, and the SUMO conversions it needs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from safety_logs import make_log

from pedsafe_sumo.safety.log import (
    REQUIRED_COLUMNS,
    LogError,
    as_arrays,
    ego_velocity_mps,
    sensor_columns,
    sumo_angle_to_yaw_rad,
    sumo_front_to_centre,
)


def test_a_complete_log_validates_to_arrays():
    arrays = as_arrays(make_log([0.0, 0.1]))
    assert set(REQUIRED_COLUMNS) <= set(arrays)
    assert arrays["perceived"].dtype == bool and arrays["ego_x_m"].dtype == float


def test_a_dict_of_arrays_is_a_log_too():
    log = make_log([0.0, 0.1])
    assert set(as_arrays({c: log[c].to_numpy() for c in log.columns})) == set(log.columns)


@pytest.mark.parametrize("column", ["ped_radius_m", "perceived", "detected_roadside"])
def test_a_missing_column_is_named(column):
    with pytest.raises(LogError, match=f"lacks column.*{column}"):
        as_arrays(make_log([0.0, 0.1]).drop(columns=column))


def test_bad_values_are_rejected_with_the_column_named():
    with pytest.raises(LogError, match="ped_x_m holds a non-finite"):
        as_arrays(make_log([0.0, 0.1], ped_x_m=[1.0, math.nan]))
    with pytest.raises(LogError, match="ego_speed_mps must not be negative"):
        as_arrays(make_log([0.0, 0.1], ego_speed_mps=-1.0))
    with pytest.raises(LogError, match="time_s must strictly increase"):
        as_arrays(make_log([0.0, 0.0]))
    with pytest.raises(LogError, match="perceived must hold booleans"):
        as_arrays(make_log([0.0, 0.1], perceived=[0.5, 1.0]))
    with pytest.raises(LogError, match="empty"):
        as_arrays(make_log([]))


def test_plugin_sensor_columns_follow_the_standard_three():
    arrays = as_arrays(make_log([0.0], detected_radar=True, detected_acoustic=False))
    assert sensor_columns(arrays) == [
        "detected_onboard_camera",
        "detected_onboard_lidar",
        "detected_roadside",
        "detected_acoustic",
        "detected_radar",
    ]


def test_ego_velocity_follows_speed_and_yaw():
    # 10 m/s at yaw 90 deg (north): (10 cos 90, 10 sin 90) = (0, 10)
    vx, vy = ego_velocity_mps(as_arrays(make_log([0.0], ego_speed_mps=10.0, ego_yaw_rad=math.pi / 2)))
    assert vx[0] == pytest.approx(0.0, abs=1e-12) and vy[0] == pytest.approx(10.0)


def test_sumo_angle_is_clockwise_from_north():
    # SUMO 0 deg = north = +y = yaw 90 deg; SUMO 90 deg = east = +x = yaw 0; SUMO 180 = south = yaw -90 deg
    assert sumo_angle_to_yaw_rad(0.0) == pytest.approx(math.pi / 2)
    assert sumo_angle_to_yaw_rad(90.0) == pytest.approx(0.0)
    assert sumo_angle_to_yaw_rad(180.0) == pytest.approx(-math.pi / 2)


def test_sumo_front_bumper_moves_back_half_a_length():
    # front at (10, 5), 4 m long: heading east -> centre 2 m west (8, 5); heading north -> (10, 3)
    assert sumo_front_to_centre(10.0, 5.0, 0.0, 4.0) == pytest.approx((8.0, 5.0))
    assert sumo_front_to_centre(10.0, 5.0, math.pi / 2, 4.0) == pytest.approx((10.0, 3.0))
    assert np.allclose(sumo_front_to_centre(0.0, 0.0, math.pi, 4.0), (2.0, 0.0))
