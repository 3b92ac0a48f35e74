"""First-hit ray casting against the world snapshot, vectorised over rays and candidate objects.

Rays come in *groups* (one group = one sensor looking at one pedestrian): every ray of a group is
tested only against the objects whose footprint overlaps the group's corridor (the 2D bounding box
of the group's ray segments), so the cost follows the rays that can matter rather than the size of
the site. Building walls are found through the grid of :class:`StaticOccluders`.

A ray is ``origin + t * direction`` with a unit direction in the world frame, ``t`` in metres from
0 to ``t_max``. Surfaces: the ground plane z = 0, vehicle boxes, pedestrian and tree cylinders,
prism walls (buildings, canopy blocks, hedges). A ray that starts inside a box or cylinder hits it
at t = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .world import WorldSnapshot

KIND_NONE = 0  #: nothing within t_max (sky, or beyond range)
KIND_GROUND = 1
KIND_VEHICLE = 2
KIND_PEDESTRIAN = 3
KIND_PRISM = 4  #: building / canopy / hedge wall; index = polygon index
KIND_CYLINDER = 5  #: tree trunk or crown; index = cylinder index


@dataclass(frozen=True)
class RayHits:
    """Per ray: distance ``t_m`` to the first hit (inf when none), its ``kind`` and object ``index``."""

    t_m: np.ndarray
    kind: np.ndarray
    index: np.ndarray


def _expand(gi: np.ndarray, oi: np.ndarray, gstart: np.ndarray, gcount: np.ndarray):
    """Candidate (group, object) pairs -> (ray, object) pairs for every ray of each group."""
    n = gcount[gi]
    total = int(n.sum())
    if total == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    rep = np.repeat(np.arange(gi.shape[0]), n)
    offs = np.arange(total) - np.repeat(np.cumsum(n) - n, n)
    return gstart[gi][rep] + offs, oi[rep]


def _slab(o, inv_d, lo, hi):
    a = (lo - o) * inv_d
    b = (hi - o) * inv_d
    return np.minimum(a, b), np.maximum(a, b)


def _circle_overlap(gbox: np.ndarray, x, y, radius) -> np.ndarray:
    """(G, N) bool: does the disc (x, y, radius) overlap each group's box [xmin, ymin, xmax, ymax]?"""
    return (
        (x[None, :] + radius[None, :] >= gbox[:, 0:1])
        & (x[None, :] - radius[None, :] <= gbox[:, 2:3])
        & (y[None, :] + radius[None, :] >= gbox[:, 1:2])
        & (y[None, :] - radius[None, :] <= gbox[:, 3:4])
    )


def _cylinder_t(ox, oy, oz, dx, dy, dz, cx, cy, r, z0, z1):
    fx = ox - cx
    fy = oy - cy
    a = dx * dx + dy * dy
    b = fx * dx + fy * dy
    c = fx * fx + fy * fy - r * r
    disc = b * b - a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        sq = np.sqrt(np.maximum(disc, 0.0))
        t0 = np.where(a > 1e-12, (-b - sq) / a, -np.inf)
        t1 = np.where(a > 1e-12, (-b + sq) / a, np.inf)
        hit2d = np.where(a > 1e-12, disc >= 0.0, c <= 0.0)
        inv = 1.0 / dz
        zn, zf = _slab(oz, inv, z0, z1)
    tn = np.maximum(t0, zn)
    tf = np.minimum(t1, zf)
    hit = hit2d & (tn <= tf) & (tf >= 0.0)
    return np.where(hit, np.maximum(tn, 0.0), np.inf)


def cast_rays(
    world: WorldSnapshot,
    origin: np.ndarray,
    direction: np.ndarray,
    t_max: np.ndarray,
    group_start: np.ndarray,
    group_count: np.ndarray,
    skip_pedestrian: np.ndarray,
    skip_vehicle=-1,
) -> RayHits:
    """First hit of each ray.

    origin, direction: (R, 3) world frame, unit directions; t_max: (R,) metres. Rays are sorted by
    group: group g owns rays ``group_start[g] : group_start[g] + group_count[g]`` (count >= 1).
    skip_pedestrian: (R,) pedestrian index each ray passes through (-1: none); skip_vehicle: index of
    a vehicle box ignored by every ray (the ego's own body), -1 for none, or a (G,) array of such
    indices, one per group (the ego hides nothing from its own sensors but does hide from the
    roadside camera).
    """
    n_rays = origin.shape[0]
    t_best = t_max.astype(float).copy()
    kind = np.zeros(n_rays, dtype=np.int8)
    index = np.full(n_rays, -1, dtype=np.int64)
    if n_rays == 0:
        return RayHits(np.full(0, np.inf), kind, index)
    ox, oy, oz = origin[:, 0], origin[:, 1], origin[:, 2]
    dx, dy, dz = direction[:, 0], direction[:, 1], direction[:, 2]

    # Ground plane z = 0.
    with np.errstate(divide="ignore", invalid="ignore"):
        tg = np.where(dz < -1e-12, -oz / dz, np.inf)
    g_hit = (tg >= 0.0) & (tg <= t_best)
    t_best = np.where(g_hit, tg, t_best)
    kind[g_hit] = KIND_GROUND

    # Corridor box of each group: 2D bounding box of its segments.
    ex = ox + dx * t_max
    ey = oy + dy * t_max
    gbox = np.empty((group_start.shape[0], 4))
    gbox[:, 0] = np.minimum.reduceat(np.minimum(ox, ex), group_start)
    gbox[:, 1] = np.minimum.reduceat(np.minimum(oy, ey), group_start)
    gbox[:, 2] = np.maximum.reduceat(np.maximum(ox, ex), group_start)
    gbox[:, 3] = np.maximum.reduceat(np.maximum(oy, ey), group_start)

    parts_t, parts_ray, parts_kind, parts_idx = [], [], [], []

    def collect(t, ray, kind_code, idx):
        ok = t <= t_best[ray]
        if np.any(ok):
            parts_t.append(t[ok])
            parts_ray.append(ray[ok])
            parts_kind.append(np.full(int(ok.sum()), kind_code, dtype=np.int8))
            parts_idx.append(idx[ok])

    # Vehicles: oriented boxes, slab test in each box frame.
    veh = world.vehicles
    if len(veh):
        half_diag = 0.5 * np.hypot(veh.length_m, veh.width_m)
        cand = _circle_overlap(gbox, veh.x_m, veh.y_m, half_diag)
        skip = np.broadcast_to(np.asarray(skip_vehicle, dtype=np.int64), (gbox.shape[0],))
        own = skip >= 0
        if own.any():
            cand[np.nonzero(own)[0], skip[own]] = False
        gi, vi = np.nonzero(cand)
        if gi.size:
            ray, vi = _expand(gi, vi, group_start, group_count)
            c = np.cos(veh.yaw_rad)[vi]
            s = np.sin(veh.yaw_rad)[vi]
            rx = ox[ray] - veh.x_m[vi]
            ry = oy[ray] - veh.y_m[vi]
            lx = rx * c + ry * s
            ly = ry * c - rx * s
            ldx = dx[ray] * c + dy[ray] * s
            ldy = dy[ray] * c - dx[ray] * s
            hl = 0.5 * veh.length_m[vi]
            hw = 0.5 * veh.width_m[vi]
            with np.errstate(divide="ignore", invalid="ignore"):
                xn, xf = _slab(lx, 1.0 / ldx, -hl, hl)
                yn, yf = _slab(ly, 1.0 / ldy, -hw, hw)
                zn, zf = _slab(oz[ray], 1.0 / dz[ray], 0.0, veh.height_m[vi])
            tn = np.maximum(np.maximum(xn, yn), zn)
            tf = np.minimum(np.minimum(xf, yf), zf)
            t = np.where((tn <= tf) & (tf >= 0.0), np.maximum(tn, 0.0), np.inf)
            collect(t, ray, KIND_VEHICLE, vi)

    # Pedestrians: upright cylinders.
    ped = world.pedestrians
    if len(ped):
        gi, pi = np.nonzero(_circle_overlap(gbox, ped.x_m, ped.y_m, ped.radius_m))
        if gi.size:
            ray, pi = _expand(gi, pi, group_start, group_count)
            keep = skip_pedestrian[ray] != pi
            ray, pi = ray[keep], pi[keep]
            t = _cylinder_t(
                ox[ray], oy[ray], oz[ray], dx[ray], dy[ray], dz[ray],
                ped.x_m[pi], ped.y_m[pi], ped.radius_m[pi], 0.0, ped.height_m[pi],
            )  # fmt: skip
            collect(t, ray, KIND_PEDESTRIAN, pi)

    st = world.static
    # Trees: trunk and crown cylinders.
    if st.n_cylinders:
        gi, ci = np.nonzero(_circle_overlap(gbox, st.cyl_x_m, st.cyl_y_m, st.cyl_radius_m))
        if gi.size:
            ray, ci = _expand(gi, ci, group_start, group_count)
            t = _cylinder_t(
                ox[ray], oy[ray], oz[ray], dx[ray], dy[ray], dz[ray],
                st.cyl_x_m[ci], st.cyl_y_m[ci], st.cyl_radius_m[ci], st.cyl_z0_m[ci], st.cyl_z1_m[ci],
            )  # fmt: skip
            collect(t, ray, KIND_CYLINDER, ci)

    # Prism walls: 2D segment intersection plus a height check at the crossing.
    if st.n_edges:
        gi, ei = st.edges_in_boxes(gbox)
        if gi.size:
            ray, ei = _expand(gi, ei, group_start, group_count)
            ex_ = st.bx[ei] - st.ax[ei]
            ey_ = st.by[ei] - st.ay[ei]
            wx = st.ax[ei] - ox[ray]
            wy = st.ay[ei] - oy[ray]
            rdx, rdy = dx[ray], dy[ray]
            den = rdx * ey_ - rdy * ex_
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (wx * ey_ - wy * ex_) / den
                u = (wx * rdy - wy * rdx) / den
            z = oz[ray] + t * dz[ray]
            hit = (u >= 0.0) & (u <= 1.0) & (t >= 0.0) & (z >= st.z_base_m[ei]) & (z <= st.z_top_m[ei])
            t = np.where(hit, t, np.inf)
            collect(t, ray, KIND_PRISM, st.edge_poly[ei])

    if parts_t:
        t_all = np.concatenate(parts_t)
        ray_all = np.concatenate(parts_ray)
        np.minimum.at(t_best, ray_all, t_all)
        win = t_all <= t_best[ray_all]
        kind[ray_all[win]] = np.concatenate(parts_kind)[win]
        index[ray_all[win]] = np.concatenate(parts_idx)[win]
    # Ground hits beaten by an object keep the object's kind above; rays with nothing keep KIND_NONE.
    t_out = np.where(kind == KIND_NONE, np.inf, t_best)
    return RayHits(t_out, kind, index)
