"""Camera intrinsics, heading conversions and the paper's eqs. 5-6 against OpenCV."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from pedsafe_sumo.perception.geometry import (
    focal_length_px,
    intrinsic_matrix,
    invert_transform,
    project_points,
    roadside_to_vehicle_camera,
    sumo_angle_to_yaw_rad,
    sumo_front_to_centre,
    transform_points,
    world_to_camera_transform,
    yaw_rad_to_sumo_angle,
)


def test_focal_length_is_640px_for_1280px_at_90deg():
    # f = 1280 / (2 tan 45 deg) = 640 (the paper's tan(rad(fov)) without the /2 would give inf).
    assert focal_length_px(1280, 90.0) == pytest.approx(640.0)
    k = intrinsic_matrix(1280, 720, 90.0)
    assert k == pytest.approx(np.array([[640, 0, 640], [0, 640, 360], [0, 0, 1]]))


@pytest.mark.parametrize(("sumo_deg", "yaw_deg"), [(0, 90), (90, 0), (180, -90), (270, -180), (45, 45)])
def test_sumo_angle_conversion(sumo_deg, yaw_deg):
    assert math.degrees(float(sumo_angle_to_yaw_rad(sumo_deg))) == pytest.approx(yaw_deg)
    assert float(yaw_rad_to_sumo_angle(math.radians(yaw_deg))) == pytest.approx(sumo_deg % 360)


def test_sumo_front_to_centre():
    # SUMO reports the front bumper; a 4 m car heading north (yaw 90 deg) at (10, 20) is centred at (10, 18).
    x, y = sumo_front_to_centre(10.0, 20.0, math.pi / 2, 4.0)
    assert (float(x), float(y)) == pytest.approx((10.0, 18.0))


def test_camera_axes_for_a_camera_looking_north_pitched_down():
    # Looking north (yaw 90 deg), pitched 30 deg down from 6 m: a point 6 / tan 30 = 10.39 m north at
    # ground level lies on the optical axis, at depth sqrt(10.39^2 + 6^2) = 12 m.
    t = world_to_camera_transform([0.0, 0.0, 6.0], math.pi / 2, math.radians(30))
    p = transform_points(t, [[0.0, 6.0 / math.tan(math.radians(30)), 0.0]])[0]
    assert p == pytest.approx([0.0, 0.0, 12.0], abs=1e-9)
    # East of the pole is image right (+x), up is image -y.
    assert transform_points(t, [[1.0, 0.0, 6.0]])[0][0] == pytest.approx(1.0)
    assert transform_points(t, [[0.0, 0.0, 7.0]])[0][1] < 0


def _poses():
    t_i = world_to_camera_transform([22.0, -12.0, 6.0], math.radians(90), math.radians(30))
    t_v = world_to_camera_transform([1.5, 0.3, 1.6], math.radians(10), 0.0)
    return t_i, t_v


def test_eq5_round_trip_and_consistency_with_world():
    t_i, t_v = _poses()
    rng = np.random.default_rng(3)
    world = np.column_stack([rng.uniform(5, 40, 20), rng.uniform(-10, 10, 20), rng.uniform(0, 2, 20)])
    p_i = transform_points(t_i, world)
    p_v = roadside_to_vehicle_camera(p_i, t_i, t_v)  # P_V = R_V R_I^-1 P_I
    assert p_v == pytest.approx(transform_points(t_v, world), abs=1e-9)
    back = roadside_to_vehicle_camera(p_v, t_v, t_i)  # and back: P_I = R_I R_V^-1 P_V
    assert back == pytest.approx(p_i, abs=1e-9)
    assert invert_transform(t_i) @ t_i == pytest.approx(np.eye(4), abs=1e-12)


def test_eq6_projection_agrees_with_opencv_project_points():
    t_i, t_v = _poses()
    k = intrinsic_matrix(1280, 720, 90.0)
    world = np.array([[30.0, 0.0, 1.0], [20.0, 5.0, 0.0], [12.0, -3.0, 1.7], [40.0, 8.0, 0.5]])
    p_v = roadside_to_vehicle_camera(transform_points(t_i, world), t_i, t_v)
    ours, in_front = project_points(k, p_v)
    assert in_front.all()
    rvec, _ = cv2.Rodrigues(t_v[:3, :3])
    cv_px, _ = cv2.projectPoints(world.reshape(-1, 1, 3), rvec, t_v[:3, 3].copy(), k, np.zeros(5))
    assert ours == pytest.approx(cv_px.reshape(-1, 2), abs=1e-6)
    # Hand check of one pixel: the point 28.5 m straight ahead of a camera looking east at (1.5, 0, 1.6)
    # and 0.6 m below it lands at v = 360 + 640 * 0.6 / 28.5 = 373.47, u = 640.
    t_e = world_to_camera_transform([1.5, 0.0, 1.6], 0.0, 0.0)
    px, _ = project_points(k, transform_points(t_e, [[30.0, 0.0, 1.0]]))
    assert px[0] == pytest.approx([640.0, 360 + 640 * 0.6 / 28.5])


def test_points_behind_the_camera_have_no_pixel():
    k = intrinsic_matrix(1280, 720, 90.0)
    px, in_front = project_points(k, np.array([[0.0, 0.0, -5.0]]))
    assert not in_front[0] and np.isnan(px).all()
