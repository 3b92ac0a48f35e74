"""Which vehicles the onboard camera and LiDAR perceive, by the same line-of-sight rules as pedestrians.

Computed only for agents that ask for ``vehicles`` (see ``pedsafe_sumo.control.agent.WORLD_FEEDS``).

Camera: sample points on the vertical faces of each box that face the camera (``FACE_FRACTIONS``
along the face x ``FACE_FRACTIONS`` of the height); a sample is visible when it projects inside the
image and the first surface on the ray from the optical centre is the vehicle itself (or lies beyond
the sample). Detected when the visible share reaches the camera's ``min_visible_fraction`` and the
box's projected height (height x f / depth of its centre) its ``min_height_px``. Unlike pedestrians
there is no colour-contrast test (a vehicle is a large, structured object; stated assumption).

LiDAR: the beams of the regular grid within the box's angular window (all channels); detected when at
least ``min_returns`` first returns lie on the box within ``range_m``. No merging rule (a vehicle is
not absorbed into a neighbouring cluster the way a pedestrian beside a car is).
"""

from __future__ import annotations

import math

import numpy as np

from .raycast import cast_rays
from .sensors import CameraSpec, LidarSpec, SensorPose
from .surfaces import KIND_VEHICLE, NEAR_CLIP_M
from .world import WorldSnapshot

#: Where on each facing face the camera samples, as fractions of its width and of the box height.
FACE_FRACTIONS = (0.2, 0.5, 0.8)


def _corners(x, y, yaw, length, width):
    c, s = math.cos(yaw), math.sin(yaw)
    hl, hw = length / 2, width / 2
    local = ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))  # counter-clockwise
    return [(x + c * a - s * b, y + s * a + c * b) for a, b in local]


def camera_sees_vehicles(
    world: WorldSnapshot, pose: SensorPose, spec: CameraSpec, skip_vehicle: int
) -> np.ndarray:
    """(V,) bool: the vehicles the camera detects (the ego's own box, ``skip_vehicle``, never)."""
    veh = world.vehicles
    out = np.zeros(len(veh), dtype=bool)
    t_wc = pose.world_to_sensor
    rot, trans = t_wc[:3, :3], t_wc[:3, 3]
    k = spec.intrinsics
    f, cx, cy = k[0, 0], k[0, 2], k[1, 2]
    cam = np.asarray(pose.position_m, dtype=float)
    fr = np.asarray(FACE_FRACTIONS)
    points, owners, counts = [], [], []
    for i in range(len(veh)):
        if i == skip_vehicle:
            continue
        centre = rot @ np.array([veh.x_m[i], veh.y_m[i], veh.height_m[i] / 2]) + trans
        if centre[2] <= NEAR_CLIP_M or f * veh.height_m[i] / centre[2] < spec.min_height_px:
            continue
        corners = _corners(veh.x_m[i], veh.y_m[i], veh.yaw_rad[i], veh.length_m[i], veh.width_m[i])
        pts = []
        for a, b in zip(corners, corners[1:] + corners[:1]):
            # Outward normal of a counter-clockwise edge: (dy, -dx); the face faces the camera when the
            # camera lies on its outer side.
            nx, ny = b[1] - a[1], -(b[0] - a[0])
            if nx * (cam[0] - a[0]) + ny * (cam[1] - a[1]) <= 0:
                continue
            for u in fr:
                for h in fr:
                    pts.append((a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]), h * veh.height_m[i]))
        if pts:
            points.extend(pts)
            owners.append(i)
            counts.append(len(pts))
    if not points:
        return out
    surface_xyz = np.asarray(points)
    pc = surface_xyz @ rot.T + trans
    with np.errstate(divide="ignore", invalid="ignore"):
        u = f * pc[:, 0] / pc[:, 2] + cx
        v = f * pc[:, 1] / pc[:, 2] + cy
    in_image = (pc[:, 2] > NEAR_CLIP_M) & (u >= 0) & (u < spec.width_px) & (v >= 0) & (v < spec.height_px)
    vec = surface_xyz - cam
    dist = np.sqrt((vec * vec).sum(axis=1))
    counts_arr = np.asarray(counts, dtype=np.int64)
    hits = cast_rays(
        world,
        np.broadcast_to(cam, surface_xyz.shape),
        vec / dist[:, None],
        dist + 0.01,
        np.cumsum(counts_arr) - counts_arr,
        counts_arr,
        np.full(surface_xyz.shape[0], -1, dtype=np.int64),
        skip_vehicle,
    )
    owner = np.repeat(np.asarray(owners), counts_arr)
    own_hit = (hits.kind == KIND_VEHICLE) & (hits.index == owner)
    visible = in_image & (own_hit | (hits.t_m >= dist - 1e-6))
    share = np.bincount(np.repeat(np.arange(len(owners)), counts_arr), weights=visible) / counts_arr
    out[np.asarray(owners)[share >= spec.min_visible_fraction]] = True
    return out


def lidar_sees_vehicles(
    world: WorldSnapshot, pose: SensorPose, spec: LidarSpec, skip_vehicle: int
) -> np.ndarray:
    """(V,) bool: the vehicles with at least ``min_returns`` LiDAR returns on them."""
    veh = world.vehicles
    out = np.zeros(len(veh), dtype=bool)
    o = np.asarray(pose.position_m, dtype=float)
    res = math.radians(spec.horizontal_resolution_deg)
    elev = np.asarray(spec.elevations_rad, dtype=float)
    dirs, owners, counts = [], [], []
    for i in range(len(veh)):
        if i == skip_vehicle:
            continue
        corners = _corners(veh.x_m[i], veh.y_m[i], veh.yaw_rad[i], veh.length_m[i], veh.width_m[i])
        d_centre = math.hypot(veh.x_m[i] - o[0], veh.y_m[i] - o[1])
        half_diagonal = 0.5 * math.hypot(veh.length_m[i], veh.width_m[i])
        # Bounds of the horizontal distance from the sensor to any point of the box.
        d_min, d_max = max(d_centre - half_diagonal, 0.05), d_centre + half_diagonal
        if d_min > spec.range_m or d_centre < 1e-6:
            continue
        # Only the channels that can meet the box: between its bottom far away and its top close by
        channels = elev[
            (elev >= math.atan2(-o[2], d_max) - 1e-12)
            & (elev <= math.atan2(veh.height_m[i] - o[2], d_min) + 1e-12)
        ]
        if channels.size == 0:
            continue
        centre_az = math.atan2(veh.y_m[i] - o[1], veh.x_m[i] - o[0])
        rel = [
            (math.atan2(y - o[1], x - o[0]) - centre_az + math.pi) % (2 * math.pi) - math.pi
            for x, y in corners
        ]
        k0 = math.ceil((centre_az + min(rel) - pose.yaw_rad) / res)
        k1 = math.floor((centre_az + max(rel) - pose.yaw_rad) / res)
        if k1 < k0:
            continue
        az = np.repeat(np.arange(k0, k1 + 1) * res + pose.yaw_rad, channels.size)
        el = np.tile(channels, k1 - k0 + 1)
        d = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        dirs.append(d)
        owners.append(i)
        counts.append(d.shape[0])
    if not dirs:
        return out
    direction = np.vstack(dirs)
    counts_arr = np.asarray(counts, dtype=np.int64)
    with np.errstate(divide="ignore"):
        t_ground = np.where(direction[:, 2] < -1e-12, o[2] / -direction[:, 2], np.inf)
    hits = cast_rays(
        world,
        np.broadcast_to(o, direction.shape),
        direction,
        np.minimum(t_ground, spec.range_m),
        np.cumsum(counts_arr) - counts_arr,
        counts_arr,
        np.full(direction.shape[0], -1, dtype=np.int64),
        skip_vehicle,
    )
    owner = np.repeat(np.asarray(owners), counts_arr)
    on_it = (hits.kind == KIND_VEHICLE) & (hits.index == owner)
    n = np.bincount(np.repeat(np.arange(len(owners)), counts_arr), weights=on_it)
    out[np.asarray(owners)[n >= spec.min_returns]] = True
    return out
