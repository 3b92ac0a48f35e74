"""One perception frame: onboard camera, onboard LiDAR, roadside camera(s) and the V2I link.

``perceive`` is what the episode loop calls every simulation step::

    suite = SensorSuite.from_params(params["perception"], roadside_units)
    link = V2ILink(suite.v2i)                      # one per episode
    det = perceive(snapshot, ego, suite, rng, snapshot.time_s, link)
    det.sv.ids, det.v2i.ids                        # single-vehicle vs cooperative perception

All sensors are evaluated in every condition; the condition only chooses which union the AD stack
reads. Draw order per frame: onboard camera misses, LiDAR misses, roadside misses (each
``rng.random(M)``, only when its miss probability is > 0), then, when there is a link, per roadside
unit one loss draw and, unless lost, two noise draws per detected pedestrian, from the link's own
generator when it has one (recommended: then the onboard draws are the same with or without a
link, so SV and V2I episodes of one seed stay paired), else from ``rng``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import invert_transform
from .kernels import frame_kernel, v2i_to_vehicle
from .raycast import cast_rays_numpy
from .raycast_kernels import static_tables
from .sensors import (
    CameraResult,
    CameraSpec,
    LidarResult,
    LidarSpec,
    RayPlan,
    SensorPose,
    finish_camera,
    finish_lidar,
    plan_camera,
    plan_lidar,
)
from .surfaces import RayHits, rgb_to_lab
from .v2i import V2ILink, V2ISpec, message_to_vehicle
from .world import EgoPose, RoadsideUnit, WorldSnapshot


@dataclass(frozen=True)
class Mount:
    """Where a sensor sits on the ego: ``forward_m`` ahead of the box centre, ``left_m`` to the left,
    ``height_m`` above ground, optical axis yawed ``yaw_offset_rad`` (CCW) from the heading and
    tilted ``pitch_down_rad`` down."""

    forward_m: float
    left_m: float
    height_m: float
    yaw_offset_rad: float = 0.0
    pitch_down_rad: float = 0.0

    def pose(self, ego: EgoPose) -> SensorPose:
        c, s = math.cos(ego.yaw_rad), math.sin(ego.yaw_rad)
        pos = np.array(
            [
                ego.x_m + c * self.forward_m - s * self.left_m,
                ego.y_m + s * self.forward_m + c * self.left_m,
                self.height_m,
            ]
        )
        return SensorPose(pos, ego.yaw_rad + self.yaw_offset_rad, self.pitch_down_rad)

    @classmethod
    def from_params(cls, p: dict) -> Mount:
        return cls(
            float(p["forward_offset_m"]),
            float(p["left_offset_m"]),
            float(p["height_m"]),
            math.radians(float(p.get("yaw_offset_deg", 0.0))),
            math.radians(float(p.get("pitch_down_deg", 0.0))),
        )


@dataclass(frozen=True)
class SensorSuite:
    """Every sensor of one condition-independent setup, built from ``params["perception"]``."""

    camera: CameraSpec
    camera_mount: Mount
    lidar: LidarSpec
    lidar_mount: Mount
    roadside: CameraSpec
    roadside_units: tuple
    v2i: V2ISpec
    ground_rgb: tuple
    sky_rgb: tuple

    @classmethod
    def from_params(cls, perception: dict, roadside_units=()) -> SensorSuite:
        return cls(
            camera=CameraSpec.from_params(perception["camera"]),
            camera_mount=Mount.from_params(perception["camera"]),
            lidar=LidarSpec.from_params(perception["lidar"]),
            lidar_mount=Mount.from_params(perception["lidar"]),
            roadside=CameraSpec.from_params(perception["roadside_camera"]),
            roadside_units=tuple(roadside_units),
            v2i=V2ISpec.from_params(perception["v2i"]),
            ground_rgb=tuple(float(v) for v in perception["scene"]["ground_rgb"]),
            sky_rgb=tuple(float(v) for v in perception["scene"]["sky_rgb"]),
        )

    def roadside_pose(self, unit: RoadsideUnit) -> SensorPose:
        return SensorPose(np.array([unit.x_m, unit.y_m, unit.height_m]), unit.yaw_rad, unit.pitch_down_rad)

    @functools.cached_property
    def roadside_poses(self) -> tuple:
        return tuple(self.roadside_pose(u) for u in self.roadside_units)

    @functools.cached_property
    def _kernel_args(self) -> tuple:
        """The suite packed as :func:`kernels.frame_kernel` reads it (built once)."""

        def camera(spec: CameraSpec):
            k = spec.intrinsics
            p = [k[0, 0], k[0, 2], k[1, 2], spec.width_px, spec.height_px, spec.min_visible_fraction,
                 spec.min_height_px, spec.delta_e_threshold**2, spec.background_max_distance_m]  # fmt: skip
            return np.array(p, dtype=float), np.ascontiguousarray(np.array(spec.sample_pattern, dtype=float))

        def mount(m: Mount):
            return np.array([m.forward_m, m.left_m, m.height_m, m.yaw_offset_rad, m.pitch_down_rad])

        lid = self.lidar
        res = math.radians(lid.horizontal_resolution_deg)
        lid_p = np.array([lid.cluster_tolerance_m, lid.range_m, res, lid.min_returns, math.pi - res])
        poses = self.roadside_poses
        rsu_rot = np.array([p.world_to_sensor[:3, :3] for p in poses], dtype=float).reshape(-1, 3, 3)
        rsu_trans = np.array([p.world_to_sensor[:3, 3] for p in poses], dtype=float).reshape(-1, 3)
        rsu_pos = np.array([p.position_m for p in poses], dtype=float).reshape(-1, 3)
        return (
            *camera(self.camera),
            mount(self.camera_mount),
            lid_p,
            np.ascontiguousarray(lid.elevations_rad, dtype=float),
            mount(self.lidar_mount),
            *camera(self.roadside),
            rsu_rot,
            rsu_trans,
            rsu_pos,
        )

    @functools.cached_property
    def _kernel_lab(self) -> tuple:
        """CIELAB of the ground and sky colours."""
        lab = rgb_to_lab(np.array([self.ground_rgb, self.sky_rgb], dtype=float))
        return lab[0].copy(), lab[1].copy()


@dataclass(frozen=True)
class SensorDetections:
    """Pedestrians one source reports: ``ids``, world ground positions ``xy_m`` (K, 2) and their
    distance ``distance_m`` (K,) from the ego box centre at this frame."""

    ids: tuple
    xy_m: np.ndarray
    distance_m: np.ndarray

    @classmethod
    def empty(cls) -> SensorDetections:
        return cls((), np.zeros((0, 2)), np.zeros(0))

    def __contains__(self, ped_id) -> bool:
        return ped_id in self.ids

    def __len__(self) -> int:
        return len(self.ids)


_EMPTY = SensorDetections.empty()


@dataclass(frozen=True)
class Detections:
    """Everything perceived in one frame.

    ``camera``, ``lidar``: onboard; ``roadside``: what the roadside cameras saw this frame (at the
    pole, before the link); ``v2i_received``: roadside detections delivered to the ego this frame
    (stale by the latency, noisy); ``sv`` = camera OR lidar; ``v2i`` = sv OR v2i_received (onboard
    positions preferred). ``ego_camera_px``: pixels (eq. 6) of the received detections in the onboard
    camera, NaN when behind it. ``diagnostics``: per-sensor rule inputs for every pedestrian.
    """

    time_s: float
    camera: SensorDetections
    lidar: SensorDetections
    roadside: SensorDetections
    v2i_received: SensorDetections
    sv: SensorDetections
    v2i: SensorDetections
    ego_camera_px: np.ndarray
    diagnostics: dict = field(default_factory=dict, repr=False)

    def by_source(self) -> dict[str, SensorDetections]:
        """Detections under the AD interface's sensor names (``pedsafe_sumo.control.agent.KNOWN_SENSORS``):
        the condition grants ``"v2i"`` (roadside detections delivered this frame) or not."""
        return {"onboard_camera": self.camera, "onboard_lidar": self.lidar, "v2i": self.v2i_received}


class _Selector:
    """The pedestrians a boolean mask selects, as :class:`SensorDetections`, for one frame: positions
    and distances of all pedestrians are computed once, on the first non-empty selection, and a
    selection of everyone is that one object (shared, as ``_union`` shares its first argument)."""

    def __init__(self, peds, ego: EgoPose):
        self.peds = peds
        self.ego = ego
        self.everyone: SensorDetections | None = None

    def __call__(self, mask: np.ndarray) -> SensorDetections:
        # One pedestrian (every scenario's frames): the mask's one element is the count.
        n = int(mask[0]) if mask.shape[0] == 1 else int(np.count_nonzero(mask))
        if n == 0:
            return _EMPTY
        if self.everyone is None:
            peds, m = self.peds, len(self.peds)
            xy = np.empty((m, 2))
            xy[:, 0] = peds.x_m
            xy[:, 1] = peds.y_m
            dist = np.hypot(xy[:, 0] - self.ego.x_m, xy[:, 1] - self.ego.y_m)
            self.everyone = SensorDetections(tuple(peds.ids), xy, dist)
        if n == mask.shape[0]:
            return self.everyone
        idx = np.flatnonzero(mask)
        ids = self.everyone.ids
        return SensorDetections(
            tuple(ids[i] for i in idx), self.everyone.xy_m[idx], self.everyone.distance_m[idx]
        )


def _miss(detected: np.ndarray, probability: float, rng: np.random.Generator) -> np.ndarray:
    if probability <= 0.0 or detected.size == 0:
        return detected
    if detected.shape[0] == 1:
        # One pedestrian (every scenario's frames): a scalar draw is the same double of the same stream
        # as a draw of size 1 (numpy's next_double either way), without building an array (~4 us).
        return detected & (rng.random() >= probability)
    return detected & (rng.random(detected.shape[0]) >= probability)


def _union(first: SensorDetections, second: SensorDetections) -> SensorDetections:
    # Fast paths (the usual frames: nobody seen, or both sides the same selection): the same values
    # as the general case below, without building arrays.
    if first is second or not second.ids:
        return first
    if not first.ids:
        return second
    extra = [i for i, pid in enumerate(second.ids) if pid not in first.ids]
    if not extra:
        return first
    return SensorDetections(
        first.ids + tuple(second.ids[i] for i in extra),
        np.vstack([first.xy_m, second.xy_m[extra]]),
        np.concatenate([first.distance_m, second.distance_m[extra]]),
    )


def _cast_all(world: WorldSnapshot, plans: list[RayPlan], skip_vehicle, onboard=None):
    """Cast the rays of all plans in one pass (numpy reference); return each plan's slice of hits.

    ``skip_vehicle``: the ego's vehicle index (-1 none), ignored by the rays of the plans flagged in
    ``onboard`` (default: all plans)."""
    live = [p for p in plans if p.group_count.size]
    if not live:
        return [None] * len(plans)
    flags = [True] * len(plans) if onboard is None else list(onboard)
    counts = np.concatenate([p.group_count for p in live])
    group_skip = np.concatenate(
        [
            np.full(p.group_count.size, skip_vehicle if f else -1)
            for p, f in zip(plans, flags, strict=True)
            if p.group_count.size
        ]
    )
    starts = np.cumsum(counts) - counts
    hits = cast_rays_numpy(
        world,
        np.concatenate([p.origin for p in live]),
        np.concatenate([p.direction for p in live]),
        np.concatenate([p.t_max for p in live]),
        starts,
        counts,
        np.concatenate([p.skip_ped for p in live]),
        group_skip,
    )
    out: list[RayHits | None] = []
    pos = 0
    for p in plans:
        if not p.group_count.size:
            out.append(None)
            continue
        n = p.origin.shape[0]
        sl = slice(pos, pos + n)
        out.append(RayHits(hits.t_m[sl], hits.kind[sl], hits.index[sl]))
        pos += n
    return out


def _sensors_numpy(snapshot: WorldSnapshot, ego: EgoPose, sensors: SensorSuite, skip_vehicle: int):
    """Every sensor through the vectorised numpy reference: plans, one cast of all rays, rules."""
    peds = snapshot.pedestrians
    rsu_poses = sensors.roadside_poses
    plans = [
        plan_camera(sensors.camera, sensors.camera_mount.pose(ego), peds),
        plan_lidar(sensors.lidar, sensors.lidar_mount.pose(ego), peds),
    ]
    plans += [plan_camera(sensors.roadside, pose, peds) for pose in rsu_poses]
    hit_list = _cast_all(snapshot, plans, skip_vehicle, onboard=[True, True] + [False] * len(rsu_poses))

    def cam_result(spec, plan, hits) -> CameraResult:
        return finish_camera(spec, plan, hits or _NO_HITS, snapshot, sensors.ground_rgb, sensors.sky_rgb)

    cam = cam_result(sensors.camera, plans[0], hit_list[0])
    lid = finish_lidar(sensors.lidar, plans[1], hit_list[1] or _NO_HITS, snapshot)
    rsu = [cam_result(sensors.roadside, p, h) for p, h in zip(plans[2:], hit_list[2:], strict=True)]
    return cam, lid, rsu


_LAB_CACHE: dict = {}
_LAB_CACHE_SIZE = 512


def _lab_rows(rgb: np.ndarray) -> np.ndarray:
    """CIELAB of (K, 3) sRGB rows, remembered across frames (vehicles keep their colours). OpenCV
    converts each pixel on its own, so this equals the reference's one conversion of the snapshot."""
    key = rgb.tobytes()
    lab = _LAB_CACHE.get(key)
    if lab is None:
        if len(_LAB_CACHE) >= _LAB_CACHE_SIZE:
            _LAB_CACHE.clear()
        lab = np.ascontiguousarray(rgb_to_lab(rgb)).reshape(-1, 3)
        _LAB_CACHE[key] = lab
    return lab


def _sensors_compiled(
    snapshot: WorldSnapshot,
    ego: EgoPose,
    sensors: SensorSuite,
    skip_vehicle: int,
    camera: bool = True,
    lidar: bool = True,
    roadside: bool = True,
):
    """Every sensor (or the ones flagged) through the compiled frame kernel; same results as
    :func:`_sensors_numpy` (sensors not run report nothing)."""
    veh, peds = snapshot.vehicles, snapshot.pedestrians
    cast, static_lab = static_tables(snapshot.static)
    out_f, n_ret, out_b = frame_kernel(
        float(ego.x_m), float(ego.y_m), float(ego.yaw_rad), skip_vehicle, camera, lidar, roadside,
        *sensors._kernel_args,
        veh.x_m, veh.y_m, veh.yaw_rad, veh.length_m, veh.width_m, veh.height_m, _lab_rows(veh.rgb),
        peds.x_m, peds.y_m, peds.radius_m, peds.height_m, _lab_rows(peds.rgb),
        *cast, *static_lab, *sensors._kernel_lab,
    )  # fmt: skip
    cam = CameraResult(out_b[0], out_f[0], out_f[1], out_f[2])
    lid = LidarResult(out_b[1], n_ret, out_b[2])
    rsu = [
        CameraResult(out_b[3 + u], out_f[3 + 3 * u], out_f[4 + 3 * u], out_f[5 + 3 * u])
        for u in range(len(sensors.roadside_units))
    ]
    return cam, lid, rsu


def perceive(
    snapshot: WorldSnapshot,
    ego: EgoPose,
    sensors: SensorSuite,
    rng: np.random.Generator,
    time_s: float | None = None,
    link: V2ILink | None = None,
) -> Detections:
    """Run every sensor on one snapshot (see module docstring). ``link`` carries the roadside
    detections to the ego; without one, ``v2i_received`` is empty and ``v2i`` equals ``sv``.

    The sensors run as compiled kernels (:mod:`pedsafe_sumo.perception.kernels`);
    :func:`perceive_reference` is the same frame through the vectorised numpy reference."""
    return _perceive(snapshot, ego, sensors, rng, time_s, link, compiled=True)


def perceive_reference(
    snapshot: WorldSnapshot,
    ego: EgoPose,
    sensors: SensorSuite,
    rng: np.random.Generator,
    time_s: float | None = None,
    link: V2ILink | None = None,
) -> Detections:
    """:func:`perceive` through the numpy reference implementation (plans, ``cast_rays_numpy``,
    rules of :mod:`~pedsafe_sumo.perception.sensors`); the tests check both give the same detections."""
    return _perceive(snapshot, ego, sensors, rng, time_s, link, compiled=False)


def _perceive(snapshot, ego, sensors, rng, time_s, link, compiled: bool) -> Detections:
    time_s = snapshot.time_s if time_s is None else float(time_s)
    peds = snapshot.pedestrians
    skip_vehicle = -1
    if ego.vehicle_id is not None:
        vids = snapshot.vehicles.ids
        if ego.vehicle_id in vids:
            skip_vehicle = vids.index(ego.vehicle_id)

    run_sensors = _sensors_compiled if compiled else _sensors_numpy
    cam, lid, rsu_results = run_sensors(snapshot, ego, sensors, skip_vehicle)

    cam_det = _miss(cam.detected, sensors.camera.miss_probability, rng)
    lid_det = _miss(lid.detected, sensors.lidar.miss_probability, rng)
    rsu_dets = [_miss(r.detected, sensors.roadside.miss_probability, rng) for r in rsu_results]
    if len(rsu_dets) == 1:
        rsu_any = rsu_dets[0]
    else:
        rsu_any = np.zeros(len(peds), dtype=bool)
        for d in rsu_dets:
            rsu_any |= d

    select = _Selector(peds, ego)
    camera = select(cam_det)
    lidar = select(lid_det)
    roadside = select(rsu_any)
    sv = _union(camera, lidar)

    received, pixels = _EMPTY, _NO_PIXELS
    if link is not None:
        link_rng = link.rng if link.rng is not None else rng
        for unit, pose, det in zip(sensors.roadside_units, sensors.roadside_poses, rsu_dets, strict=True):
            # One roadside unit: its detections are `roadside` (the same mask), already selected.
            sent = roadside if det is rsu_any else select(det)
            link.send(time_s, unit.id, pose.world_to_sensor, sent.ids, sent.xy_m, link_rng)
        received, pixels = _receive(link.receive(time_s), ego, sensors, compiled)
    return Detections(
        time_s=time_s,
        camera=camera,
        lidar=lidar,
        roadside=roadside,
        v2i_received=received,
        sv=sv,
        v2i=_union(sv, received),
        ego_camera_px=pixels,
        diagnostics={"camera": cam, "lidar": lid, "roadside": rsu_results},
    )


_INVERSES: dict = {}


def _roadside_to_world(world_to_roadside: np.ndarray) -> np.ndarray:
    """``invert_transform`` of a roadside camera's transform, remembered (the poles do not move)."""
    key = world_to_roadside.tobytes()
    inv = _INVERSES.get(key)
    if inv is None:
        if len(_INVERSES) >= 64:
            _INVERSES.clear()
        inv = _INVERSES[key] = invert_transform(world_to_roadside)
    return inv


def _receive(messages, ego: EgoPose, sensors: SensorSuite, compiled: bool):
    """Delivered roadside detections in the ego's frame (eqs. 5-6), a later message (or another pole)
    superseding an earlier one for the same pedestrian. Returns (detections, pixels (K, 2)).

    ``compiled``: through :func:`kernels.v2i_to_vehicle` (with the roadside inverse remembered per
    pole), else :func:`message_to_vehicle` (numpy reference)."""
    messages = [m for m in messages if m.ped_ids]
    if not messages:
        return _EMPTY, _NO_PIXELS
    converted = []
    if compiled:
        mount = sensors._kernel_args[2]
        intrinsics = sensors.camera.intrinsics
        for msg in messages:
            px, xy = v2i_to_vehicle(
                msg.points_roadside_m, _roadside_to_world(msg.world_to_roadside), float(ego.x_m),
                float(ego.y_m), float(ego.yaw_rad), mount, intrinsics,
            )  # fmt: skip
            converted.append((msg.ped_ids, px, xy))
    else:
        world_to_cam = sensors.camera_mount.pose(ego).world_to_sensor
        for msg in messages:
            _, px, _, world_pts = message_to_vehicle(msg, world_to_cam, sensors.camera.intrinsics)
            converted.append((msg.ped_ids, px, np.ascontiguousarray(world_pts[:, :2])))
    ped_ids, px, xy = converted[0]
    if len(converted) == 1 and len(set(ped_ids)) == len(ped_ids):
        ids, pixels = ped_ids, px
    else:
        ids, xys, pxs = [], [], []  # type: ignore[var-annotated]  # lists of ids and (N, 2) arrays
        for ped_ids, px, world_xy in converted:
            for k, pid in enumerate(ped_ids):
                if pid in ids:
                    j = ids.index(pid)
                    xys[j], pxs[j] = world_xy[k], px[k]
                else:
                    ids.append(pid)
                    xys.append(world_xy[k])
                    pxs.append(px[k])
        xy, pixels = np.asarray(xys), np.asarray(pxs)
    return SensorDetections(tuple(ids), xy, np.hypot(xy[:, 0] - ego.x_m, xy[:, 1] - ego.y_m)), pixels


class PerceptionSystem:
    """Per-episode convenience: a sensor suite plus its own V2I link (with its own generator when
    ``link_rng`` is given, see :class:`V2ILink`)."""

    def __init__(self, sensors: SensorSuite, link_rng: np.random.Generator | None = None):
        self.sensors = sensors
        self.link = V2ILink(sensors.v2i, link_rng)

    def perceive(
        self, snapshot: WorldSnapshot, ego: EgoPose, rng: np.random.Generator, time_s: float | None = None
    ) -> Detections:
        return perceive(snapshot, ego, self.sensors, rng, time_s, self.link)


def _no_hits():
    return RayHits(np.zeros(0), np.zeros(0, dtype=np.int8), np.zeros(0, dtype=np.int64))


_NO_HITS = _no_hits()
_NO_PIXELS = np.zeros((0, 2))
