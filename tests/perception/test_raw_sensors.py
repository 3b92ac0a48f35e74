"""Raw sensor data of hand-built scenes, worked out by hand: LiDAR returns on a box at a known distance,
and the camera pixel where the pinhole projection puts a pedestrian."""

from __future__ import annotations

import math

import numpy as np
import pytest
from perception_scenes import world

from pedsafe_sumo.perception.raw import lidar_point_cloud, render_image
from pedsafe_sumo.perception.sensors import LidarSpec, SensorPose
from pedsafe_sumo.perception.surfaces import KIND_GROUND, KIND_VEHICLE

SENSOR_HEIGHT_M = 1.9
BOX_NEAR_X_M, BOX_LENGTH_M, BOX_HALF_WIDTH_M, BOX_HEIGHT_M = 10.0, 4.0, 1.0, 1.5
SPEC = LidarSpec(
    channels=32, elevation_min_deg=-25.0, elevation_max_deg=15.0, horizontal_resolution_deg=0.2,
    range_m=100.0, min_returns=5, cluster_tolerance_m=0.5, miss_probability=0.0,
)  # fmt: skip
POSE = SensorPose(np.array([0.0, 0.0, SENSOR_HEIGHT_M]), 0.0)
RED = (200, 30, 30)


def _box_scene():
    centre_x = BOX_NEAR_X_M + BOX_LENGTH_M / 2
    return world(
        vehicles=[("box", centre_x, 0.0, 0.0, BOX_LENGTH_M, 2 * BOX_HALF_WIDTH_M, BOX_HEIGHT_M, RED)]
    )


def test_the_beam_straight_ahead_returns_ground_before_the_box_then_its_face_then_ground_beyond():
    points, labels = lidar_point_cloud(_box_scene(), POSE, SPEC, labels=True)
    ahead = (np.abs(points[:, 1]) < 1e-9) & (points[:, 0] > 0)
    got = points[ahead]
    for k in range(SPEC.channels):
        el = math.radians(-25.0 + k * 40.0 / 31)
        # By hand: a downward beam reaches the ground at 1.9 / tan(-el); it meets the box's near face
        # (x = 10) at height 1.9 + 10 tan(el) if that is within [0, 1.5].
        z_face = SENSOR_HEIGHT_M + BOX_NEAR_X_M * math.tan(el)
        x_top = (BOX_HEIGHT_M - SENSOR_HEIGHT_M) / math.tan(el) if el < 0 else math.inf
        if 0.0 <= z_face <= BOX_HEIGHT_M:
            expected = (BOX_NEAR_X_M, z_face - SENSOR_HEIGHT_M)
        elif el < 0 and SENSOR_HEIGHT_M / math.tan(-el) < BOX_NEAR_X_M:
            expected = (SENSOR_HEIGHT_M / math.tan(-el), -SENSOR_HEIGHT_M)
        elif BOX_NEAR_X_M <= x_top <= BOX_NEAR_X_M + BOX_LENGTH_M:
            # Above the near face, but down to the roof (z = 1.5) before the box ends.
            expected = (x_top, BOX_HEIGHT_M - SENSOR_HEIGHT_M)
        elif el < 0 and SENSOR_HEIGHT_M / math.tan(-el) <= SPEC.range_m:
            expected = (SENSOR_HEIGHT_M / math.tan(-el), -SENSOR_HEIGHT_M)  # over the roof, ground beyond
        else:
            expected = None  # upward, or the ground beyond range: no return
        on_beam = np.isclose(np.arctan2(got[:, 2], got[:, 0]), el, atol=1e-9)
        if expected is None:
            assert not on_beam.any(), k
        else:
            assert on_beam.sum() == 1, k
            assert tuple(got[on_beam][0, [0, 2]]) == pytest.approx(expected, abs=1e-6), k
    assert set(np.unique(labels.kind)) <= {KIND_GROUND, KIND_VEHICLE}


def test_the_number_of_returns_on_the_box_is_the_count_of_beams_that_meet_its_near_face_or_roof():
    points, labels = lidar_point_cloud(_box_scene(), POSE, SPEC, labels=True)
    expected = 0
    for k_az in range(-40, 41):
        az = math.radians(0.2 * k_az)
        if abs(BOX_NEAR_X_M * math.tan(az)) > BOX_HALF_WIDTH_M:
            continue  # passes beside the box (and never reaches its sides, which start at x = 10)
        r = BOX_NEAR_X_M / math.cos(az)  # horizontal distance to the near face along this azimuth
        # Where the beam leaves the box's footprint: through the far face, or through a side.
        r_out = min(
            (BOX_NEAR_X_M + BOX_LENGTH_M) / math.cos(az), BOX_HALF_WIDTH_M / max(abs(math.sin(az)), 1e-12)
        )
        for k in range(SPEC.channels):
            el = math.radians(-25.0 + k * 40.0 / 31)
            z = SENSOR_HEIGHT_M + r * math.tan(el)
            z_out = SENSOR_HEIGHT_M + r_out * math.tan(el)
            if 0.0 <= z <= BOX_HEIGHT_M or (z > BOX_HEIGHT_M and z_out <= BOX_HEIGHT_M):
                expected += 1  # the near face, or the roof
    on_box = labels.kind == KIND_VEHICLE
    assert int(on_box.sum()) == expected
    assert np.all(labels.object_id[on_box] == "box")
    face = points[on_box][:, 2] < BOX_HEIGHT_M - SENSOR_HEIGHT_M - 1e-9
    assert points[on_box][face][:, 0] == pytest.approx(BOX_NEAR_X_M, abs=1e-6)
    assert points[on_box][~face][:, 2] == pytest.approx(BOX_HEIGHT_M - SENSOR_HEIGHT_M, abs=1e-6)


def test_points_are_in_the_sensor_frame_whatever_the_heading():
    """The same scene turned by 90 degrees (box north of a sensor heading north) gives the same cloud."""
    turned = world(vehicles=[("box", 0.0, BOX_NEAR_X_M + 2.0, math.pi / 2, 4.0, 2.0, 1.5, RED)])
    straight, _ = lidar_point_cloud(_box_scene(), POSE, SPEC)
    rotated, _ = lidar_point_cloud(turned, SensorPose(POSE.position_m, math.pi / 2), SPEC)
    assert rotated.shape == straight.shape
    assert rotated == pytest.approx(straight, abs=1e-6)


def test_the_pedestrian_is_drawn_at_the_pixel_the_projection_predicts():
    # Camera at (1.5, 0, 1.6) looking east, 160 x 90 px, hfov 90: f = 80 px, c = (80, 45).
    cam = SensorPose(np.array([1.5, 0.0, 1.6]), 0.0)
    scene = world(peds=[("p", 20.0, 3.0, 0.3, 1.7, RED)])
    image = render_image(scene, cam, 160, 90, 90.0, (105, 105, 105), (170, 200, 235), 150.0, depth=True)
    assert image.rgb.shape == (90, 160, 3) and image.rgb.dtype == np.uint8
    # By hand: the axis at mid-height (20, 3, 0.85) is 18.5 m ahead, 3 m left and 0.75 m below the camera:
    # u = 80 - 80 * 3 / 18.5 = 67.03, v = 45 + 80 * 0.75 / 18.5 = 48.24 -> column 67, row 48.
    assert tuple(image.rgb[48, 67]) == RED
    # Its front surface is 0.3 m nearer than the axis (less at the edge of the disc).
    assert 18.5 - 0.3 - 1e-6 <= image.depth_m[48, 67] <= 18.5
    # Above the horizon (row < 45) and beside the pedestrian nothing lies within 150 m: sky.
    assert tuple(image.rgb[10, 67]) == (170, 200, 235) and math.isinf(image.depth_m[10, 67])
    # Row 60 of the centre column looks down (60.5 - 45) / 80: the ground 1.6 / 0.194 = 8.26 m ahead.
    assert tuple(image.rgb[60, 80]) == (105, 105, 105)
    assert image.depth_m[60, 80] == pytest.approx(1.6 * 80 / 15.5, rel=1e-5)
    # 20 columns to the right of the pedestrian (u = 87.5, 1.7 m right of the axis at 18.5 m): no one.
    assert tuple(image.rgb[48, 87]) == (105, 105, 105)


def _vehicle_scene(*extra):
    from perception_scenes import ego_box

    return world(vehicles=[ego_box(), *extra])


def test_a_car_ahead_is_perceived_and_a_car_hidden_behind_a_truck_is_not(suite):
    from perception_scenes import EGO

    from pedsafe_sumo.perception.vehicles import camera_sees_vehicles, lidar_sees_vehicles

    truck = ("truck", 12.0, 0.0, 0.0, 6.0, 2.5, 3.5, (230, 230, 230))
    hidden = ("hidden", 20.0, 0.0, 0.0, 4.5, 1.8, 1.5, RED)
    beside = ("beside", 20.0, 8.0, 0.0, 4.5, 1.8, 1.5, RED)  # 8 m to the left, in plain view
    far = ("far", 130.0, 0.0, 0.0, 4.5, 1.8, 1.5, RED)  # beyond the LiDAR's range; 7 px tall in the camera
    scene = _vehicle_scene(truck, hidden, beside, far)
    cam = camera_sees_vehicles(scene, suite.camera_mount.pose(EGO), suite.camera, 0)
    lid = lidar_sees_vehicles(scene, suite.lidar_mount.pose(EGO), suite.lidar, 0)
    names = ("ego", "truck", "hidden", "beside", "far")
    assert dict(zip(names, cam.tolist(), strict=True)) == {
        "ego": False, "truck": True, "hidden": False, "beside": True, "far": False,
    }  # fmt: skip
    assert dict(zip(names, lid.tolist(), strict=True)) == {
        "ego": False, "truck": True, "hidden": False, "beside": True, "far": False,
    }  # fmt: skip
    # Without the truck the car behind it is in plain view of both.
    open_scene = _vehicle_scene(hidden)
    assert camera_sees_vehicles(open_scene, suite.camera_mount.pose(EGO), suite.camera, 0).tolist() == [
        False,
        True,
    ]
    assert lidar_sees_vehicles(open_scene, suite.lidar_mount.pose(EGO), suite.lidar, 0).tolist() == [
        False,
        True,
    ]
