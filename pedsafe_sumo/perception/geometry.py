"""Frames, headings and the pinhole camera of the paper's eqs. 5-6, as pure functions over numpy arrays.

Conventions used throughout `pedsafe_sumo.perception`:

* World frame: the SUMO network frame, x east, y north, z up, metres. The ground is the plane z = 0.
* Heading: ``yaw_rad`` is counter-clockwise from +x (east), radians. SUMO reports angles in degrees
  clockwise from north; convert with :func:`sumo_angle_to_yaw_rad` / :func:`yaw_rad_to_sumo_angle`.
* Camera frame (OpenCV): x right, y down, z along the optical axis, metres. A camera pose is its
  optical centre in the world frame, the yaw of its optical axis (``yaw_rad``, as above) and its
  downward tilt ``pitch_down_rad`` (positive looks down). Roll is zero.
* A "world-to-camera transform" is the 4x4 homogeneous matrix T with P_cam = T @ P_world
  (the paper's R_I and R_V).
"""

from __future__ import annotations

import math

import numpy as np

from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre, yaw_rad_to_sumo_angle

__all__ = ["sumo_angle_to_yaw_rad", "sumo_front_to_centre", "yaw_rad_to_sumo_angle"]


def focal_length_px(width_px: float, hfov_deg: float) -> float:
    """Pinhole focal length f = width / (2 tan(fov/2)) in pixels (the erratum of the paper's eq. 6 in
    docs/design.md, 'Sources of numbers')."""
    if not 0.0 < hfov_deg < 180.0:
        raise ValueError(f"horizontal field of view must be in (0, 180) degrees, got {hfov_deg}")
    return width_px / (2.0 * math.tan(math.radians(hfov_deg) / 2.0))


def intrinsic_matrix(width_px: float, height_px: float, hfov_deg: float) -> np.ndarray:
    """K of eq. 6: fx = fy = f, cx = width/2, cy = height/2 (pixels)."""
    f = focal_length_px(width_px, hfov_deg)
    return np.array([[f, 0.0, width_px / 2.0], [0.0, f, height_px / 2.0], [0.0, 0.0, 1.0]])


def rotation_world_to_camera(yaw_rad: float, pitch_down_rad: float) -> np.ndarray:
    """3x3 rotation whose rows are the camera's x (right), y (down) and z (forward) axes in world frame."""
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    cp, sp = math.cos(pitch_down_rad), math.sin(pitch_down_rad)
    # right = (sin yaw, -cos yaw, 0); forward = (cp cos yaw, cp sin yaw, -sp); down = forward x right.
    return np.array([[sy, -cy, 0.0], [-sp * cy, -sp * sy, -cp], [cp * cy, cp * sy, -sp]])


def world_to_camera_transform(position_m, yaw_rad: float, pitch_down_rad: float) -> np.ndarray:
    """4x4 homogeneous world-to-camera transform (the paper's R_I, R_V): P_cam = T @ [x, y, z, 1]."""
    rot = rotation_world_to_camera(yaw_rad, pitch_down_rad)
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = -rot @ np.asarray(position_m, dtype=float)
    return out


def invert_transform(transform: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform (rotation transposed, translation rotated back)."""
    rot = transform[:3, :3]
    out = np.eye(4)
    out[:3, :3] = rot.T
    out[:3, 3] = -rot.T @ transform[:3, 3]
    return out


def to_homogeneous(points: np.ndarray) -> np.ndarray:
    """(K, 3) -> (K, 4) with a trailing 1."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    return np.hstack([points, np.ones((points.shape[0], 1))])


def transform_points(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 rigid transform to (K, 3) points; returns (K, 3)."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    return points @ transform[:3, :3].T + transform[:3, 3]


def roadside_to_vehicle_camera(points_roadside_m: np.ndarray, t_world_to_roadside, t_world_to_vehicle):
    """Paper eq. 5: P_V = R_V R_I^-1 P_I for (K, 3) points in the roadside camera frame -> vehicle camera."""
    chain = t_world_to_vehicle @ invert_transform(t_world_to_roadside)
    return transform_points(chain, points_roadside_m)


def project_points(intrinsics: np.ndarray, points_camera_m: np.ndarray):
    """Paper eq. 6: pixel (u, v) = K P / Z for (K, 3) camera-frame points.

    Returns (pixels (K, 2), in_front (K,) bool). Points with Z <= 0 get NaN pixels.
    """
    pts = np.atleast_2d(np.asarray(points_camera_m, dtype=float))
    z = pts[:, 2]
    in_front = z > 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        uvw = pts @ intrinsics.T
        pixels = uvw[:, :2] / uvw[:, 2:3]
    pixels[~in_front] = np.nan
    return pixels, in_front
