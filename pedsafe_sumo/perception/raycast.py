"""First-hit ray casting against the world snapshot.

:func:`cast_rays` runs the compiled kernel (:mod:`pedsafe_sumo.perception.raycast_kernels`);
:func:`cast_rays_numpy` is the vectorised numpy reference it is tested against (over rays and
candidate objects at once). Both give the same hits.

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

import numpy as np

from .raycast_kernels import cast_rays_kernel, static_tables
from .surfaces import (
    KIND_CYLINDER,
    KIND_GROUND,
    KIND_NONE,
    KIND_PEDESTRIAN,
    KIND_PRISM,
    KIND_VEHICLE,
    RayHits,
)
from .world import WorldSnapshot


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


def _cylinder_t(rr, cx, cy, r, z0, z1):
    """Entry distance of rays ``rr`` (K, 6: origin, unit direction) into vertical cylinders."""
    dx, dy = rr[:, 3], rr[:, 4]
    fx = rr[:, 0] - cx
    fy = rr[:, 1] - cy
    a = dx * dx + dy * dy
    b = fx * dx + fy * dy
    c = fx * fx + fy * fy - r * r
    disc = b * b - a * c
    sq = np.sqrt(np.maximum(disc, 0.0))
    vertical = a <= 1e-12
    t0 = np.where(vertical, -np.inf, (-b - sq) / a)
    t1 = np.where(vertical, np.inf, (-b + sq) / a)
    hit2d = np.where(vertical, c <= 0.0, disc >= 0.0)
    zn, zf = _slab(rr[:, 2], 1.0 / rr[:, 5], z0, z1)
    tn = np.maximum(t0, zn)
    tf = np.minimum(t1, zf)
    return np.where(hit2d & (tn <= tf) & (tf >= 0.0), np.maximum(tn, 0.0), np.inf)


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
    """First hit of each ray (compiled kernel; same arguments and results as :func:`cast_rays_numpy`)."""
    n_groups = np.asarray(group_start).shape[0]
    skip = np.ascontiguousarray(np.broadcast_to(np.asarray(skip_vehicle, dtype=np.int64), (n_groups,)))
    veh, ped = world.vehicles, world.pedestrians
    t, kind, index = cast_rays_kernel(
        np.ascontiguousarray(origin, dtype=float).reshape(-1, 3),
        np.ascontiguousarray(direction, dtype=float).reshape(-1, 3),
        np.ascontiguousarray(t_max, dtype=float),
        np.ascontiguousarray(group_start, dtype=np.int64),
        np.ascontiguousarray(group_count, dtype=np.int64),
        np.ascontiguousarray(skip_pedestrian, dtype=np.int64),
        skip,
        veh.x_m, veh.y_m, veh.yaw_rad, veh.length_m, veh.width_m, veh.height_m,
        ped.x_m, ped.y_m, ped.radius_m, ped.height_m,
        *static_tables(world.static)[0],
    )  # fmt: skip
    return RayHits(t, kind, index)


def cast_rays_numpy(
    world: WorldSnapshot,
    origin: np.ndarray,
    direction: np.ndarray,
    t_max: np.ndarray,
    group_start: np.ndarray,
    group_count: np.ndarray,
    skip_pedestrian: np.ndarray,
    skip_vehicle=-1,
) -> RayHits:
    """First hit of each ray: the vectorised numpy reference of the compiled :func:`cast_rays`.

    origin, direction: (R, 3) world frame, unit directions; t_max: (R,) metres. Rays are sorted by
    group: group g owns rays ``group_start[g] : group_start[g] + group_count[g]`` (count >= 1).
    skip_pedestrian: (R,) pedestrian index each ray passes through (-1: none); skip_vehicle: index of
    a vehicle box ignored by every ray (the ego's own body), -1 for none, or a (G,) array of such
    indices, one per group (the ego hides nothing from its own sensors but does hide from the
    roadside camera).
    """
    n_rays = origin.shape[0]
    kind = np.zeros(n_rays, dtype=np.int8)
    index = np.full(n_rays, -1, dtype=np.int64)
    if n_rays == 0:
        return RayHits(np.full(0, np.inf), kind, index)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return _cast(world, origin, direction, t_max, group_start, group_count, skip_pedestrian, skip_vehicle,
                     kind, index)  # fmt: skip


def _static_tables(st) -> dict:
    """Per-site arrays gathered by the wall and tree tests, built once and kept on the occluders."""
    tables = st._grid.get("cast")
    if tables is None:
        tables = {
            "walls": np.column_stack([st.ax, st.ay, st.bx - st.ax, st.by - st.ay, st.z_base_m, st.z_top_m]),
            "trees": np.column_stack([st.cyl_x_m, st.cyl_y_m, st.cyl_radius_m, st.cyl_z0_m, st.cyl_z1_m]),
        }
        st._grid["cast"] = tables
    return tables


def _cast(
    world, origin, direction, t_max, group_start, group_count, skip_pedestrian, skip_vehicle, kind, index
):
    rays = np.concatenate([origin, direction], axis=1)  # (R, 6): one gather per surface type
    t_best = t_max.astype(float)
    ox, oy, oz = origin[:, 0], origin[:, 1], origin[:, 2]
    dx, dy, dz = direction[:, 0], direction[:, 1], direction[:, 2]

    # Ground plane z = 0.
    tg = np.where(dz < -1e-12, -oz / dz, np.inf)
    g_hit = tg <= t_best
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
        if ok.any():
            parts_t.append(t[ok])
            parts_ray.append(ray[ok])
            parts_kind.append(np.full(int(ok.sum()), kind_code, dtype=np.int8))
            parts_idx.append(idx[ok])

    # Vehicles: oriented boxes, slab test in each box frame.
    veh = world.vehicles
    if len(veh):
        cand = _circle_overlap(gbox, veh.x_m, veh.y_m, 0.5 * np.hypot(veh.length_m, veh.width_m))
        skip = np.broadcast_to(np.asarray(skip_vehicle, dtype=np.int64), (gbox.shape[0],))
        own = skip >= 0
        if own.any():
            cand[np.nonzero(own)[0], skip[own]] = False
        gi, vi = np.nonzero(cand)
        if gi.size:
            ray, vi = _expand(gi, vi, group_start, group_count)
            yaw = veh.yaw_rad
            table = np.column_stack([veh.x_m, veh.y_m, np.cos(yaw), np.sin(yaw), 0.5 * veh.length_m,
                                     0.5 * veh.width_m, veh.height_m])[vi]  # fmt: skip
            rr = rays[ray]
            c, s, hl, hw = table[:, 2], table[:, 3], table[:, 4], table[:, 5]
            rx = rr[:, 0] - table[:, 0]
            ry = rr[:, 1] - table[:, 1]
            xn, xf = _slab(rx * c + ry * s, 1.0 / (rr[:, 3] * c + rr[:, 4] * s), -hl, hl)
            yn, yf = _slab(ry * c - rx * s, 1.0 / (rr[:, 4] * c - rr[:, 3] * s), -hw, hw)
            zn, zf = _slab(rr[:, 2], 1.0 / rr[:, 5], 0.0, table[:, 6])
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
            rr = rays[ray]
            t = _cylinder_t(rr, ped.x_m[pi], ped.y_m[pi], ped.radius_m[pi], 0.0, ped.height_m[pi])
            collect(t, ray, KIND_PEDESTRIAN, pi)

    st = world.static
    # Trees: trunk and crown cylinders.
    if st.n_cylinders:
        gi, ci = np.nonzero(_circle_overlap(gbox, st.cyl_x_m, st.cyl_y_m, st.cyl_radius_m))
        if gi.size:
            ray, ci = _expand(gi, ci, group_start, group_count)
            tt = _static_tables(st)["trees"][ci]
            t = _cylinder_t(rays[ray], tt[:, 0], tt[:, 1], tt[:, 2], tt[:, 3], tt[:, 4])
            collect(t, ray, KIND_CYLINDER, ci)

    # Prism walls: 2D segment intersection plus a height check at the crossing.
    if st.n_edges:
        gi, ei = st.edges_in_boxes(gbox)
        if gi.size:
            ray, ei = _expand(gi, ei, group_start, group_count)
            w = _static_tables(st)["walls"][ei]
            rr = rays[ray]
            ex_, ey_ = w[:, 2], w[:, 3]
            wx = w[:, 0] - rr[:, 0]
            wy = w[:, 1] - rr[:, 1]
            rdx, rdy = rr[:, 3], rr[:, 4]
            inv = 1.0 / (rdx * ey_ - rdy * ex_)
            t = (wx * ey_ - wy * ex_) * inv
            u = (wx * rdy - wy * rdx) * inv
            z = rr[:, 2] + t * rr[:, 5]
            hit = (u >= 0.0) & (u <= 1.0) & (t >= 0.0) & (z >= w[:, 4]) & (z <= w[:, 5])
            collect(np.where(hit, t, np.inf), ray, KIND_PRISM, st.edge_poly[ei])

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
