"""Raw sensor data for AD stacks that run their own perception: the LiDAR point cloud and camera images.

Both come from the same first-hit ray cast as the detection rules (:func:`raycast.cast_rays`, the
compiled kernel) over the same world snapshot, so a raw return or pixel sees exactly the geometry the
detectors see: vehicle boxes, pedestrian cylinders, building/canopy/hedge prisms, tree cylinders and
the ground plane z = 0. Nothing here is computed unless an agent asks for it (see
``pedsafe_sumo.sim.observation``).

LiDAR (:func:`lidar_point_cloud`): the full beam grid of :class:`~.sensors.LidarSpec` (``channels``
elevations from ``elevation_min_deg`` to ``elevation_max_deg``; azimuths ``k * horizontal_resolution_deg``
counter-clockwise from the sensor's heading, k = 0 .. 360/res - 1), first return of each beam within
``range_m``, ground returns included. Points are in the sensor frame: x forward (the sensor's
heading), y left, z up, metres, origin at the sensor's optical centre (so the flat ground lies at
z = -mount height). Order: azimuth-major, channels ascending within an azimuth.

Camera (:func:`render_image`): one ray through the centre of every pixel (pixel (row i, column j)
has u = j + 0.5, v = i + 0.5 in the intrinsics of eq. 6, f = width / (2 tan(hfov/2)), c = (W/2, H/2)),
coloured flat with the colour of the first surface hit (vehicle colour, clothing colour, building or
tree colour, the ground colour; the sky colour when nothing lies within ``max_distance_m``). Depth is
the distance along the optical axis (camera z, metres; inf for sky).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .raycast import cast_rays
from .sensors import LidarSpec, SensorPose
from .surfaces import KIND_CYLINDER, KIND_GROUND, KIND_NONE, KIND_PEDESTRIAN, KIND_PRISM, KIND_VEHICLE
from .world import WorldSnapshot

#: Label codes of :class:`LidarLabels` (the ray cast's surface kinds).
LABEL_NAMES = {
    KIND_GROUND: "ground",
    KIND_VEHICLE: "vehicle",
    KIND_PEDESTRIAN: "pedestrian",
    KIND_PRISM: "building",
    KIND_CYLINDER: "tree",
}


@dataclass(frozen=True)
class LidarLabels:
    """Ground truth of each point of a cloud (same order): ``kind`` (N,) int8, a key of LABEL_NAMES, and
    ``object_id`` (N,) the vehicle or pedestrian id ("" for ground, buildings and trees)."""

    kind: np.ndarray
    object_id: np.ndarray


@dataclass(frozen=True)
class CameraImage:
    """A rendered frame: ``rgb`` (H, W, 3) uint8; ``depth_m`` (H, W) float32 along the optical axis
    (inf for sky) or None when not asked for."""

    rgb: np.ndarray
    depth_m: np.ndarray | None = None


def _beam_grid(spec: LidarSpec) -> tuple[np.ndarray, np.ndarray]:
    """Azimuths (A,) from the heading and elevations (C,) of the full beam grid, radians."""
    n_az = max(1, int(round(360.0 / spec.horizontal_resolution_deg)))
    azimuths = np.arange(n_az) * math.radians(spec.horizontal_resolution_deg)
    return azimuths, np.asarray(spec.elevations_rad, dtype=float)


def _top_m(world: WorldSnapshot) -> float:
    """Height of the highest surface in the snapshot [m]."""
    st = world.static
    tops = [0.0]
    for arr in (world.vehicles.height_m, world.pedestrians.height_m, st.z_top_m, st.cyl_z1_m):
        if len(arr):
            tops.append(float(np.max(arr)))
    return max(tops)


def _reach(origin_z: float, dz: np.ndarray, t_far: float, top_m: float) -> np.ndarray:
    """Per ray, the farthest distance worth testing: a downward ray meets the ground (every surface
    stands on it, so nothing is hit beyond), an upward one climbs above the highest surface, else
    ``t_far``. Shorter rays keep each group's search corridor narrow; the hits are the same."""
    with np.errstate(divide="ignore"):
        t_ground = np.where(dz < -1e-12, origin_z / -dz, np.inf)
        t_ceiling = np.where(dz > 1e-12, (max(top_m, origin_z) - origin_z) / dz, np.inf)
    return np.minimum(np.minimum(t_ground, t_ceiling), t_far)


def _cast_columns(world, origin, direction, t_max, n_rows, skip_vehicle, t_far):
    """Cast rays laid out in columns of ``n_rows`` consecutive rays. Each column is cut into runs of
    consecutive rays that are all short (ending on the ground or above everything) or all long, one
    group per run, so each group's search corridor stays narrow (no reordering of the rays)."""
    rays = t_max.shape[0]
    long_ray = t_max >= t_far
    first = np.zeros(rays, dtype=bool)
    first[::n_rows] = True
    first[1:] |= long_ray[1:] != long_ray[:-1]
    starts = np.flatnonzero(first)
    counts = np.diff(np.append(starts, rays))
    hits = cast_rays(
        world,
        origin,
        direction,
        t_max,
        starts,
        counts,
        np.full(rays, -1, dtype=np.int64),
        skip_vehicle,
    )
    return hits.t_m, hits.kind, hits.index


def lidar_point_cloud(
    world: WorldSnapshot, pose: SensorPose, spec: LidarSpec, skip_vehicle: int = -1, labels: bool = False
) -> tuple[np.ndarray, LidarLabels | None]:
    """First returns of the full beam grid (see module docstring): (points (N, 3) float64 in the sensor
    frame, labels or None). ``skip_vehicle``: index of the ego's own box in ``world.vehicles`` (-1 none)."""
    azimuths, elevations = _beam_grid(spec)
    n_az, n_ch = azimuths.size, elevations.size
    # Directions in the sensor frame (x forward, y left, z up): azimuth-major, channels ascending.
    ce, se = np.cos(elevations), np.sin(elevations)
    local = np.empty((n_az, n_ch, 3))
    local[:, :, 0] = np.cos(azimuths)[:, None] * ce[None, :]
    local[:, :, 1] = np.sin(azimuths)[:, None] * ce[None, :]
    local[:, :, 2] = se[None, :]
    beams = local.reshape(-1, 3)
    c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
    direction = np.empty_like(beams)
    direction[:, 0] = c * beams[:, 0] - s * beams[:, 1]
    direction[:, 1] = s * beams[:, 0] + c * beams[:, 1]
    direction[:, 2] = beams[:, 2]
    o = np.asarray(pose.position_m, dtype=float)
    origin = np.broadcast_to(o, direction.shape)
    t_max = np.tile(_reach(float(o[2]), se, spec.range_m, _top_m(world)), n_az)
    t, kind, index = _cast_columns(world, origin, direction, t_max, n_ch, skip_vehicle, spec.range_m)
    hit = (kind != KIND_NONE) & (t <= spec.range_m)
    points = beams[hit] * t[hit][:, None]
    if not labels:
        return points, None
    return points, _labels(world, kind[hit], index[hit])


def _labels(world: WorldSnapshot, kind: np.ndarray, index: np.ndarray) -> LidarLabels:
    object_id = np.full(kind.shape[0], "", dtype=object)
    for code, ids in ((KIND_VEHICLE, world.vehicles.ids), (KIND_PEDESTRIAN, world.pedestrians.ids)):
        sel = np.flatnonzero(kind == code)
        if sel.size:
            object_id[sel] = np.asarray(ids, dtype=object)[index[sel]]
    return LidarLabels(kind.astype(np.int8), object_id)


def pixel_rays(width_px: int, height_px: int, hfov_deg: float, pose: SensorPose):
    """Unit world directions (W*H, 3) through the pixel centres, column-major (column j, then row i),
    and each direction's camera-z component (the factor from ray distance to depth)."""
    f = width_px / (2.0 * math.tan(math.radians(hfov_deg) / 2.0))
    u = np.arange(width_px) + 0.5
    v = np.arange(height_px) + 0.5
    cam = np.empty((width_px * height_px, 3))
    cam[:, 0] = np.repeat((u - width_px / 2.0) / f, height_px)
    cam[:, 1] = np.tile((v - height_px / 2.0) / f, width_px)
    cam[:, 2] = 1.0
    norm = np.sqrt((cam * cam).sum(axis=1))
    cam /= norm[:, None]
    rot = pose.world_to_sensor[:3, :3]  # rows: camera axes in the world frame
    return cam @ rot, cam[:, 2].copy()


def render_image(
    world: WorldSnapshot,
    pose: SensorPose,
    width_px: int,
    height_px: int,
    hfov_deg: float,
    ground_rgb,
    sky_rgb,
    max_distance_m: float,
    skip_vehicle: int = -1,
    depth: bool = False,
) -> CameraImage:
    """Flat-shaded render of the snapshot from a pinhole camera (see module docstring)."""
    direction, cos_axis = pixel_rays(width_px, height_px, hfov_deg, pose)
    o = np.asarray(pose.position_m, dtype=float)
    origin = np.broadcast_to(o, direction.shape)
    t_max = _reach(float(o[2]), direction[:, 2], max_distance_m, _top_m(world))
    t, kind, index = _cast_columns(world, origin, direction, t_max, height_px, skip_vehicle, max_distance_m)
    rgb = np.empty((kind.shape[0], 3))
    rgb[:] = sky_rgb
    rgb[kind == KIND_GROUND] = ground_rgb
    st = world.static
    for code, table in (
        (KIND_VEHICLE, world.vehicles.rgb),
        (KIND_PEDESTRIAN, world.pedestrians.rgb),
        (KIND_PRISM, st.poly_rgb),
        (KIND_CYLINDER, st.cyl_rgb),
    ):
        sel = kind == code
        if sel.any():
            rgb[sel] = np.asarray(table, dtype=float)[index[sel]]
    image = np.clip(np.rint(rgb), 0, 255).astype(np.uint8).reshape(width_px, height_px, 3).transpose(1, 0, 2)
    depth_m = None
    if depth:
        z = np.where(kind == KIND_NONE, np.inf, t * cos_axis)
        depth_m = z.astype(np.float32).reshape(width_px, height_px).T.copy()
    return CameraImage(np.ascontiguousarray(image), depth_m)
