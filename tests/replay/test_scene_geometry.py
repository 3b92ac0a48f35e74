"""What the replay draws, as geometry with known answers: field-of-view wedges, a camera's reach, the
first-detection markers of a hand-built log, the framing of a screenshot."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo.perception.pipeline import Mount
from pedsafe_sumo.perception.sensors import CameraSpec
from pedsafe_sumo.perception.world import RoadsideUnit
from pedsafe_sumo.replay.scene import camera_range_m, first_detection_markers, screenshot_frame, wedge_xy


def test_wedge_spans_the_field_of_view_at_its_range():
    # Apex at (10, 5), looking north (yaw 90 deg), 60 deg wide, 20 m.
    shape = np.array(wedge_xy((10.0, 5.0), math.pi / 2, math.radians(60), 20.0, segments=6))
    assert tuple(shape[0]) == (10.0, 5.0) and tuple(shape[-1]) == (10.0, 5.0)
    arc = shape[1:-1] - (10.0, 5.0)
    assert np.hypot(arc[:, 0], arc[:, 1]) == pytest.approx(np.full(7, 20.0))
    # The arc runs from 30 deg right of north to 30 deg left of it: x = 20 sin(30 deg) = 10 m each side.
    assert arc[0] == pytest.approx((10.0, 20 * math.cos(math.radians(30))))
    assert arc[-1] == pytest.approx((-10.0, 20 * math.cos(math.radians(30))))
    assert arc[3] == pytest.approx((0.0, 20.0))


def test_camera_reach_is_where_the_pedestrian_shrinks_to_the_minimum_pixel_height():
    # 1280 px over 90 deg: f = 640 px; a 1.6 m pedestrian is 20 px tall at 640 * 1.6 / 20 = 51.2 m.
    camera = SimpleNamespace(width_px=1280, hfov_deg=90.0, min_height_px=20.0)
    assert camera_range_m(camera, 1.6) == pytest.approx(51.2)
    # The roadside camera of the parameter file: 1920 px, 90 deg: f = 960 px, 76.8 m.
    roadside = CameraSpec.from_params(
        {
            "hfov_deg": 90.0,
            "width_px": 1920,
            "height_px": 1080,
            "min_visible_fraction": 0.3,
            "min_height_px": 20.0,
            "delta_e_threshold": 15.0,
            "background_max_distance_m": 50.0,
            "sample_lateral_fractions": [0.0],
            "sample_height_fractions": [0.5],
            "miss_probability": 0.0,
        }
    )
    assert camera_range_m(roadside, 1.6) == pytest.approx(76.8)


def _log(**flags) -> pd.DataFrame:
    """Five steps, ego driving east from x=0 at 10 m/s, pedestrian standing at (40, 2)."""
    n = 5
    log = pd.DataFrame(
        {
            "time_s": 0.05 * (1 + np.arange(n)),
            "ego_x_m": 0.5 * np.arange(n),
            "ego_y_m": np.zeros(n),
            "ego_yaw_rad": np.zeros(n),
            "ego_length_m": np.full(n, 4.0),
            "ped_x_m": np.full(n, 40.0),
            "ped_y_m": np.full(n, 2.0),
        }
    )
    for name in ("detected_onboard_camera", "detected_onboard_lidar", "detected_roadside", "roadside_raw"):
        log[name] = flags.get(name, [False] * n)
    return log


SENSORS = SimpleNamespace(
    camera_mount=Mount(1.5, 0.0, 1.6),
    lidar_mount=Mount(0.0, 0.0, 1.9),
    roadside_units=(RoadsideUnit("rsu", 50.0, -20.0, 6.0, 0.0, 0.2),),
)


def test_markers_at_the_first_onboard_and_roadside_detections():
    log = _log(
        detected_onboard_lidar=[False, False, True, True, True],
        detected_onboard_camera=[False, False, False, True, True],
        roadside_raw=[False, True, True, True, True],
        detected_roadside=[False, False, False, True, True],
    )
    onboard, roadside = first_detection_markers(log, SENSORS, "v2i")
    # Step 2: the LiDAR (on the box centre) at x = 1.0 saw the pedestrian 39.05 m away.
    assert (onboard.kind, onboard.step_index, onboard.time_s) == ("onboard", 2, pytest.approx(0.15))
    assert onboard.sensor_xy == pytest.approx((1.0, 0.0)) and onboard.ped_xy == (40.0, 2.0)
    assert onboard.distance_m == pytest.approx(math.hypot(39.0, 2.0))
    assert "LiDAR" in onboard.label and "camera" not in onboard.label
    # Step 1: the roadside camera, from its pole; delivered over V2I at step 3 (t = 0.20 s).
    assert (roadside.kind, roadside.step_index) == ("roadside", 1)
    assert roadside.sensor_xy == (50.0, -20.0)
    assert "t=0.20 s" in roadside.label


def test_camera_first_marker_starts_its_sight_line_at_the_camera_mount():
    log = _log(detected_onboard_camera=[False, True, True, True, True])
    (onboard,) = first_detection_markers(log, SENSORS, "sv")
    assert onboard.sensor_xy == pytest.approx((0.5 + 1.5, 0.0))


def test_screenshot_frames_the_ego_front_and_the_pedestrian_around_their_midpoint():
    log = _log()
    centre, (width_m, height_m) = screenshot_frame(log, 4, minimum_width_m=30.0, aspect=1.25)
    # Ego centre x = 2.0, front 2 m further: 4.0; pedestrian at 40: 36 m apart, +20 m to spare.
    assert centre == pytest.approx(((4.0 + 40.0) / 2, 1.0))
    assert width_m == pytest.approx(56.0) and height_m == pytest.approx(56.0 / 1.25)
    _, (narrow_m, _) = screenshot_frame(log.assign(ped_x_m=6.0), 4, minimum_width_m=30.0, aspect=1.25)
    assert narrow_m == pytest.approx(30.0)
