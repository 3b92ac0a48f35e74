"""First detection: time, distance and sensors at the first step the AD stack perceives the pedestrian."""

from __future__ import annotations

import math

import pytest
from safety_logs import make_log

from pedsafe_sumo.safety.detection import first_detection

T = [0.0, 0.1, 0.2, 0.3, 0.4]
EGO_X = [0.0, 1.0, 2.0, 3.0, 4.0]


def test_first_perceived_step_gives_time_distance_and_sensors():
    # perceived first at step 3 (t = 0.3 s): ego at (3, 0), pedestrian at (15, 5): dp = (12, 5), |dp| = 13 m.
    # The roadside camera saw it from step 1 (latency), the lidar from step 3, the camera never; at step 3
    # lidar and roadside are set: "onboard_lidar+roadside".
    log = make_log(
        T,
        ego_x_m=EGO_X,
        ped_x_m=15.0,
        ped_y_m=5.0,
        detected_roadside=[False, True, True, True, True],
        detected_onboard_lidar=[False, False, False, True, True],
        perceived=[False, False, False, True, True],
    )
    got = first_detection(log)
    assert got.step == 3 and got.time_s == pytest.approx(0.3)
    assert got.distance_m == pytest.approx(13.0)
    assert got.detected_by == "onboard_lidar+roadside"


def test_plugin_sensor_and_single_sensor_names():
    log = make_log(
        T, perceived=[False, True, True, True, True], detected_onboard_camera=True, detected_radar=True
    )
    assert first_detection(log).detected_by == "onboard_camera+radar"


def test_never_perceived_gives_nan_and_empty_sensor():
    got = first_detection(make_log(T, detected_onboard_camera=True))
    assert got.step is None and math.isnan(got.time_s) and math.isnan(got.distance_m)
    assert got.detected_by == ""
