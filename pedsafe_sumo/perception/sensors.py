"""Sensor models: pinhole cameras (onboard and roadside) and a spinning LiDAR, as ray plans.

Each sensor works in two halves so that one frame casts all its rays in a single vectorised pass
(:func:`pedsafe_sumo.perception.raycast.cast_rays`):

* ``plan_*`` culls pedestrians that cannot be detected (behind the camera, out of the image, too
  small, beyond range) and emits the rays that decide the others;
* ``finish_*`` reads the hits of those rays and applies the detection rules.

Camera rule (per pedestrian): sample points on the side of the cylinder facing the camera
(``lateral_fractions`` x ``height_fractions``); a sample is visible when it projects inside the
image and nothing lies between it and the optical centre. Detected when the visible share is at
least ``min_visible_fraction``, the projected height (axis top to bottom, pixels) at least
``min_height_px``, and the median over visible samples of the CIE76 delta E (OpenCV sRGB -> CIELAB)
between clothing and the first surface behind the sample (the ray continued past the pedestrian up
to ``background_max_distance_m``: a vehicle, pedestrian, wall, tree, else the ground colour, else
the sky colour) is at least ``delta_e_threshold``, i.e. at least half of the visible samples reach it.

LiDAR rule: beams on a regular grid (``channels`` elevations evenly spaced from
``elevation_min_deg`` to ``elevation_max_deg``, azimuths every ``horizontal_resolution_deg`` from
the vehicle heading), first returns within ``range_m``. Only the beams in each pedestrian's angular
window, widened by the angle the cluster tolerance subtends, are cast. Returns on the ground are
removed (ground segmentation). Detected when at least ``min_returns`` returns lie on the pedestrian
and no return of a non-pedestrian object (vehicle, wall, tree) lies within ``cluster_tolerance_m``
of any of them: Euclidean clustering links by single linkage, so one close return merges the
pedestrian into the object behind. Returns of other pedestrians do not merge (a group of
pedestrians stays a pedestrian cluster).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .geometry import intrinsic_matrix, world_to_camera_transform
from .surfaces import (
    KIND_CYLINDER,
    KIND_GROUND,
    KIND_PEDESTRIAN,
    KIND_PRISM,
    KIND_VEHICLE,
    NEAR_CLIP_M,
    RayHits,
    rgb_to_lab,
)
from .world import Pedestrians, WorldSnapshot


@dataclass(frozen=True)
class CameraSpec:
    """A pinhole camera's intrinsics and detection rule (see module docstring)."""

    width_px: int
    height_px: int
    hfov_deg: float
    min_visible_fraction: float
    min_height_px: float
    delta_e_threshold: float
    background_max_distance_m: float
    lateral_fractions: tuple
    height_fractions: tuple
    miss_probability: float

    @functools.cached_property
    def intrinsics(self) -> np.ndarray:
        return intrinsic_matrix(self.width_px, self.height_px, self.hfov_deg)

    @functools.cached_property
    def sample_pattern(self) -> tuple:
        """(lateral (S,), depth (S,), height (S,)) fractions of the sample points, lateral-major."""
        lat = np.repeat(np.asarray(self.lateral_fractions, dtype=float), len(self.height_fractions))
        hf = np.tile(np.asarray(self.height_fractions, dtype=float), len(self.lateral_fractions))
        return lat, np.sqrt(np.clip(1.0 - lat**2, 0.0, 1.0)), hf

    @classmethod
    def from_params(cls, p: dict) -> CameraSpec:
        return cls(
            width_px=int(p["width_px"]),
            height_px=int(p["height_px"]),
            hfov_deg=float(p["hfov_deg"]),
            min_visible_fraction=float(p["min_visible_fraction"]),
            min_height_px=float(p["min_height_px"]),
            delta_e_threshold=float(p["delta_e_threshold"]),
            background_max_distance_m=float(p["background_max_distance_m"]),
            lateral_fractions=tuple(float(v) for v in p["sample_lateral_fractions"]),
            height_fractions=tuple(float(v) for v in p["sample_height_fractions"]),
            miss_probability=float(p["miss_probability"]),
        )


@dataclass(frozen=True)
class LidarSpec:
    channels: int
    elevation_min_deg: float
    elevation_max_deg: float
    horizontal_resolution_deg: float
    range_m: float
    min_returns: int
    cluster_tolerance_m: float
    miss_probability: float

    @functools.cached_property
    def elevations_rad(self) -> np.ndarray:
        return np.deg2rad(np.linspace(self.elevation_min_deg, self.elevation_max_deg, self.channels))

    @classmethod
    def from_params(cls, p: dict) -> LidarSpec:
        return cls(
            channels=int(p["channels"]),
            elevation_min_deg=float(p["elevation_min_deg"]),
            elevation_max_deg=float(p["elevation_max_deg"]),
            horizontal_resolution_deg=float(p["horizontal_resolution_deg"]),
            range_m=float(p["range_m"]),
            min_returns=int(p["min_returns"]),
            cluster_tolerance_m=float(p["cluster_tolerance_m"]),
            miss_probability=float(p["miss_probability"]),
        )


@dataclass(frozen=True)
class SensorPose:
    """A sensor's origin in the world frame (m), yaw (rad, CCW from east), downward pitch (rad)."""

    position_m: np.ndarray
    yaw_rad: float
    pitch_down_rad: float = 0.0

    @functools.cached_property
    def world_to_sensor(self) -> np.ndarray:
        """4x4 world-to-camera transform (OpenCV camera axes), the paper's R_I / R_V."""
        return world_to_camera_transform(self.position_m, self.yaw_rad, self.pitch_down_rad)


@dataclass
class RayPlan:
    """Rays one sensor wants cast, grouped per pedestrian (group g looks at pedestrian ``ped[g]``)."""

    ped: np.ndarray  # (G,) pedestrian index of each group
    origin: np.ndarray  # (R, 3)
    direction: np.ndarray  # (R, 3) unit
    t_max: np.ndarray  # (R,)
    skip_ped: np.ndarray  # (R,) pedestrian the ray ignores (-1 none)
    group_count: np.ndarray  # (G,)
    extra: dict


def _empty_plan(extra: dict) -> RayPlan:
    z = np.zeros((0, 3))
    e = np.zeros(0, dtype=np.int64)
    return RayPlan(e, z, z, np.zeros(0), e, e, extra)


# -------------------------------------------------------------------------------------------- camera


def plan_camera(spec: CameraSpec, pose: SensorPose, peds: Pedestrians) -> RayPlan:
    """Cull pedestrians and emit one ray per sample point of each remaining pedestrian."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return _plan_camera(spec, pose, peds)


def _plan_camera(spec: CameraSpec, pose: SensorPose, peds: Pedestrians) -> RayPlan:
    m = len(peds)
    height_px = np.zeros(m)
    extra = {"height_px": height_px, "candidates": np.zeros(0, dtype=np.int64)}
    if m == 0:
        return _empty_plan(extra)
    t_wc = pose.world_to_sensor
    rot, trans = t_wc[:3, :3], t_wc[:3, 3]
    k = spec.intrinsics
    f, cx, cy = k[0, 0], k[0, 2], k[1, 2]
    # Camera-frame coordinates of each pedestrian's axis bottom and top.
    base = peds.x_m[:, None] * rot[:, 0] + peds.y_m[:, None] * rot[:, 1] + trans
    top = base + peds.height_m[:, None] * rot[:, 2]
    zb, zt = base[:, 2], top[:, 2]
    front = np.minimum(zb, zt) > NEAR_CLIP_M + peds.radius_m
    if not front.any():
        return _empty_plan(extra)
    ub, vb = f * base[:, 0] / zb + cx, f * base[:, 1] / zb + cy
    ut, vt = f * top[:, 0] / zt + cx, f * top[:, 1] / zt + cy
    half_w = f * peds.radius_m / np.minimum(zb, zt)
    height_px[front] = np.hypot(ub - ut, vb - vt)[front]
    umin = np.minimum(ub, ut) - half_w
    umax = np.maximum(ub, ut) + half_w
    vmin = np.minimum(vb, vt)
    vmax = np.maximum(vb, vt)
    overlaps = (umax >= 0) & (umin < spec.width_px) & (vmax >= 0) & (vmin < spec.height_px)
    cand = np.nonzero(front & overlaps & (height_px >= spec.min_height_px))[0]
    extra["candidates"] = cand
    if cand.size == 0:
        return _empty_plan(extra)

    lat_s, depth, hf_s = spec.sample_pattern
    n_s = lat_s.size
    cam = pose.position_m
    pcx, pcy, r, h = peds.x_m[cand], peds.y_m[cand], peds.radius_m[cand], peds.height_m[cand]
    vx, vy = pcx - cam[0], pcy - cam[1]
    norm = np.maximum(np.hypot(vx, vy), 1e-9)
    vx, vy = vx / norm, vy / norm
    px = pcx[:, None] + r[:, None] * (-vy[:, None] * lat_s[None, :] - vx[:, None] * depth[None, :])
    py = pcy[:, None] + r[:, None] * (vx[:, None] * lat_s[None, :] - vy[:, None] * depth[None, :])
    pz = h[:, None] * hf_s[None, :]
    pts = np.empty((px.size, 3))  # (G*S, 3)
    pts[:, 0] = px.ravel()
    pts[:, 1] = py.ravel()
    pts[:, 2] = pz.ravel()
    pc = pts @ rot.T + trans
    u = f * pc[:, 0] / pc[:, 2] + cx
    v = f * pc[:, 1] / pc[:, 2] + cy
    in_image = (pc[:, 2] > NEAR_CLIP_M) & (u >= 0) & (u < spec.width_px) & (v >= 0) & (v < spec.height_px)
    vec = pts - cam
    dist = np.sqrt((vec * vec).sum(axis=1))
    direction = vec / dist[:, None]
    extra.update(dist=dist, in_image=in_image, n_samples=n_s)
    origin = np.empty_like(pts)
    origin[:] = cam
    return RayPlan(
        ped=cand,
        origin=origin,
        direction=direction,
        t_max=dist + spec.background_max_distance_m,
        skip_ped=np.repeat(cand, n_s),
        group_count=np.full(cand.size, n_s, dtype=np.int64),
        extra=extra,
    )


def delta_e_cie76(rgb_a: np.ndarray, rgb_b: np.ndarray) -> np.ndarray:
    """CIE76 colour difference (Euclidean distance in CIELAB) between (K, 3) sRGB colour rows."""
    a = np.asarray(rgb_a, dtype=float).reshape(-1, 3)
    lab = rgb_to_lab(np.vstack([a, np.asarray(rgb_b, dtype=float).reshape(-1, 3)]))
    return np.linalg.norm(lab[: a.shape[0]] - lab[a.shape[0] :], axis=1)


def _lab_tables(world: WorldSnapshot, ground_rgb, sky_rgb) -> dict:
    """CIELAB of every colour in the snapshot, per surface kind (static tables converted once)."""
    key = (tuple(ground_rgb), tuple(sky_rgb))
    cached = world.__dict__.get("_lab_tables")
    if cached is not None and cached[0] == key:
        return cached[1]
    st = world.static
    static_lab = st._grid.get("lab")
    if static_lab is None:
        static_lab = (rgb_to_lab(st.poly_rgb), rgb_to_lab(st.cyl_rgb))
        st._grid["lab"] = static_lab
    n_v = len(world.vehicles)
    dyn = rgb_to_lab(np.vstack([world.vehicles.rgb, world.pedestrians.rgb, [ground_rgb, sky_rgb]]))
    tables = {
        KIND_VEHICLE: dyn[:n_v],
        KIND_PEDESTRIAN: dyn[n_v:-2],
        KIND_PRISM: static_lab[0],
        KIND_CYLINDER: static_lab[1],
        KIND_GROUND: dyn[-2],
        "sky": dyn[-1],
    }
    object.__setattr__(world, "_lab_tables", (key, tables))  # converted once per snapshot
    return tables


def surface_lab(hits: RayHits, tables: dict) -> np.ndarray:
    """(R, 3) CIELAB colour of what each ray hit first (the sky colour when nothing)."""
    out = np.empty((hits.kind.shape[0], 3))
    out[:] = tables["sky"]
    for kind_code in (KIND_VEHICLE, KIND_PEDESTRIAN, KIND_PRISM, KIND_CYLINDER):
        sel = hits.kind == kind_code
        if sel.any():
            out[sel] = tables[kind_code][hits.index[sel]]
    out[hits.kind == KIND_GROUND] = tables[KIND_GROUND]
    return out


@dataclass(frozen=True)
class CameraResult:
    """Per pedestrian (all M of the snapshot): the rule's inputs and the verdict.

    ``contrast_fraction``: share of the visible samples whose delta E reaches the threshold (the
    median delta E reaches it exactly when this share is at least one half).
    """

    detected: np.ndarray
    visible_fraction: np.ndarray
    height_px: np.ndarray
    contrast_fraction: np.ndarray


def finish_camera(
    spec: CameraSpec, plan: RayPlan, hits: RayHits, world: WorldSnapshot, ground_rgb, sky_rgb
) -> CameraResult:
    m = len(world.pedestrians)
    vis_frac = np.zeros(m)
    contrast = np.zeros(m)
    cand = plan.extra["candidates"]
    if cand.size:
        n_s = plan.extra["n_samples"]
        visible = plan.extra["in_image"] & ~(hits.t_m < plan.extra["dist"] - 1e-6)
        n_vis = visible.reshape(cand.size, n_s).sum(axis=1)
        vis_frac[cand] = n_vis / n_s
        if visible.any():
            tables = _lab_tables(world, ground_rgb, sky_rgb)
            background = surface_lab(hits, tables)[visible]
            owner = np.repeat(np.arange(cand.size), n_s)[visible]
            clothing = tables[KIND_PEDESTRIAN][cand[owner]]
            diff = clothing - background
            strong = (diff * diff).sum(axis=1) >= spec.delta_e_threshold**2  # CIE76
            contrast[cand] = np.bincount(owner[strong], minlength=cand.size) / np.maximum(n_vis, 1)
    height_px = plan.extra["height_px"]
    detected = (vis_frac >= spec.min_visible_fraction) & (height_px >= spec.min_height_px) & (contrast >= 0.5)
    return CameraResult(detected, vis_frac, height_px, contrast)


# --------------------------------------------------------------------------------------------- LiDAR


def plan_lidar(spec: LidarSpec, pose: SensorPose, peds: Pedestrians) -> RayPlan:
    """Beams of the regular grid that fall in each in-range pedestrian's widened angular window."""
    m = len(peds)
    extra = {"candidates": np.zeros(0, dtype=np.int64)}
    if m == 0:
        return _empty_plan(extra)
    o = pose.position_m
    zs = float(o[2])
    tol = spec.cluster_tolerance_m
    dxy = np.hypot(peds.x_m - o[0], peds.y_m - o[1])
    r, h = peds.radius_m, peds.height_m
    in_range = (dxy - r <= spec.range_m) & (dxy > r)
    cand = np.nonzero(in_range)[0]
    if cand.size == 0:
        return _empty_plan(extra)
    d, r, h = dxy[cand], r[cand], h[cand]
    res = math.radians(spec.horizontal_resolution_deg)
    az_c = np.arctan2(peds.y_m[cand] - o[1], peds.x_m[cand] - o[0]) - pose.yaw_rad
    d_near = np.maximum(d - r - tol, 0.05)
    d_far = d + r + tol
    half = np.arcsin(np.minimum(r / d, 1.0)) + np.arctan2(tol, d_near)
    half = np.minimum(half, math.pi - res)
    k0 = np.ceil((az_c - half) / res).astype(np.int64)
    k1 = np.floor((az_c + half) / res).astype(np.int64)
    elev = spec.elevations_rad
    z_lo, z_hi = -zs, h + tol - zs  # nothing returns from below the ground
    e_near_lo, e_far_lo = np.arctan2(z_lo, d_near), np.arctan2(z_lo, d_far)
    e_near_hi, e_far_hi = np.arctan2(z_hi, d_near), np.arctan2(z_hi, d_far)
    c0 = np.searchsorted(elev, np.minimum(e_near_lo, e_far_lo), side="left")
    c1 = np.searchsorted(elev, np.maximum(e_near_hi, e_far_hi), side="right") - 1
    n_az = np.maximum(k1 - k0 + 1, 0)
    n_ch = np.maximum(c1 - c0 + 1, 0)
    count = n_az * n_ch
    keep = count > 0
    cand, k0, c0, n_ch, count, d_far, h = (
        cand[keep],
        k0[keep],
        c0[keep],
        n_ch[keep],
        count[keep],
        d_far[keep],
        h[keep],
    )
    extra["candidates"] = cand
    if cand.size == 0:
        return _empty_plan(extra)
    total = int(count.sum())
    gidx = np.repeat(np.arange(cand.size), count)
    local = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    az = (k0[gidx] + local // n_ch[gidx]) * res + pose.yaw_rad
    el = elev[c0[gidx] + local % n_ch[gidx]]
    ce = np.cos(el)
    direction = np.empty((total, 3))
    direction[:, 0] = ce * np.cos(az)
    direction[:, 1] = ce * np.sin(az)
    direction[:, 2] = np.sin(el)
    reach = np.hypot(d_far, np.maximum(h - zs, zs) + tol)
    t_max = np.minimum(spec.range_m, reach)[gidx]
    extra["group_of_ray"] = gidx
    origin = np.empty_like(direction)
    origin[:] = o
    return RayPlan(
        ped=cand,
        origin=origin,
        direction=direction,
        t_max=t_max,
        skip_ped=np.full(total, -1, dtype=np.int64),
        group_count=count.astype(np.int64),
        extra=extra,
    )


@dataclass(frozen=True)
class LidarResult:
    """Per pedestrian (all M): returns on them, whether they merged into another object, verdict."""

    detected: np.ndarray
    n_returns: np.ndarray
    merged: np.ndarray


def finish_lidar(spec: LidarSpec, plan: RayPlan, hits: RayHits, world: WorldSnapshot) -> LidarResult:
    m = len(world.pedestrians)
    n_ret = np.zeros(m, dtype=np.int64)
    merged = np.zeros(m, dtype=bool)
    cand = plan.ped
    if cand.size:
        tol = spec.cluster_tolerance_m
        gidx = plan.extra["group_of_ray"]
        own = cand[gidx]
        on_ped = (hits.kind == KIND_PEDESTRIAN) & (hits.index == own)
        n_ret[cand] = np.bincount(gidx[on_ped], minlength=cand.size)
        other = (hits.kind == KIND_VEHICLE) | (hits.kind == KIND_PRISM) | (hits.kind == KIND_CYLINDER)
        if np.any(other) and np.any(on_ped):
            peds = world.pedestrians
            q = plan.origin[other] + plan.direction[other] * hits.t_m[other][:, None]
            qg = gidx[other]
            qp = own[other]
            radial = np.maximum(
                np.hypot(q[:, 0] - peds.x_m[qp], q[:, 1] - peds.y_m[qp]) - peds.radius_m[qp], 0
            )
            vertical = np.maximum(np.maximum(-q[:, 2], q[:, 2] - peds.height_m[qp]), 0.0)
            near = np.hypot(radial, vertical) <= tol
            if np.any(near):
                q, qg = q[near], qg[near]
                p = plan.origin[on_ped] + plan.direction[on_ped] * hits.t_m[on_ped][:, None]
                pg = gidx[on_ped]
                d2 = ((q[:, None, :] - p[None, :, :]) ** 2).sum(axis=2)
                close = (d2 <= tol * tol) & (qg[:, None] == pg[None, :])
                hit_groups = np.unique(pg[np.nonzero(close.any(axis=0))[0]])
                merged[cand[hit_groups]] = True
    detected = (n_ret >= spec.min_returns) & ~merged
    return LidarResult(detected, n_ret, merged)
