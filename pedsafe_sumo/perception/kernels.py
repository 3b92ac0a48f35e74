"""Compiled (numba) kernels of one perception frame: the three sensor rules and the V2I reception.

The same computations as the vectorised numpy reference (``sensors.plan_*``, :func:`raycast.cast_rays`,
``sensors.finish_*``; :func:`v2i.message_to_vehicle`), written as scalar loops over the rays of
:func:`raycast_kernels.cast_group` so that a frame costs a few microseconds instead of a few hundred
small numpy calls. Each expression keeps the reference's operation order, so the verdicts are the same;
only transcendental functions may differ from numpy's in the last bit.
``tests/perception/test_compiled_equivalence.py`` checks both paths against each other on random scenes.

Compiled on first use and cached on disk as :mod:`.raycast_kernels` says. Numba's cache is keyed on this
file alone: ``NEAR_CLIP_M`` and the ``KIND_*`` codes of :mod:`.surfaces` and the functions of
:mod:`.raycast_kernels` are frozen into the cached code, so after changing them touch this file too.
"""

from __future__ import annotations

import math

import numpy as np

from .raycast_kernels import _jit, cast_group, vehicle_tables
from .surfaces import KIND_CYLINDER, KIND_GROUND, KIND_PEDESTRIAN, KIND_PRISM, KIND_VEHICLE, NEAR_CLIP_M


@_jit
def _surface_lab(kind, idx, vlab, plab, poly_lab, cyl_lab, ground_lab, sky_lab, j):
    if kind == KIND_VEHICLE:
        return vlab[idx, j]
    if kind == KIND_PEDESTRIAN:
        return plab[idx, j]
    if kind == KIND_PRISM:
        return poly_lab[idx, j]
    if kind == KIND_CYLINDER:
        return cyl_lab[idx, j]
    if kind == KIND_GROUND:
        return ground_lab[j]
    return sky_lab[j]


@_jit
def camera_kernel(
    cam_p, samples, rot, trans, cam_pos, skip_veh,
    vx, vy, vc, vs, vhl, vhw, vh, vrad, vlab,
    px, py, pr, ph, plab,
    trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny, mark,
    poly_lab, cyl_lab, ground_lab, sky_lab,
    out_f, out_b, row_f, row_b,
):  # fmt: skip
    """One pinhole camera (sensors.plan_camera + cast + sensors.finish_camera) for every pedestrian.

    cam_p: [f, cx, cy, width_px, height_px, min_visible_fraction, min_height_px, delta_e_threshold^2,
    background_max_distance_m]; samples (3, S): lateral, depth and height fractions; rot (3, 3) and
    trans (3,): world-to-camera; cam_pos (3,): optical centre. Writes visible fraction, height px,
    contrast fraction to out_f[row_f : row_f + 3] and the verdict to out_b[row_b]."""
    f, cx, cy, w_px, h_px = cam_p[0], cam_p[1], cam_p[2], cam_p[3], cam_p[4]
    min_vis, min_h, thr2, bg_max = cam_p[5], cam_p[6], cam_p[7], cam_p[8]
    n_s = samples.shape[1]
    m = px.shape[0]
    origin = np.empty((n_s, 3))
    direction = np.empty((n_s, 3))
    t_max = np.empty(n_s)
    dist = np.empty(n_s)
    in_image = np.empty(n_s, dtype=np.bool_)
    skip = np.empty(n_s, dtype=np.int64)
    t_hit = np.empty(n_s)
    kind = np.empty(n_s, dtype=np.int8)
    idx = np.empty(n_s, dtype=np.int64)
    for s in range(n_s):
        origin[s, 0] = cam_pos[0]
        origin[s, 1] = cam_pos[1]
        origin[s, 2] = cam_pos[2]
    for j in range(m):
        vis_frac = 0.0
        contrast = 0.0
        height_px = 0.0
        # Camera-frame axis bottom and top.
        b_x = px[j] * rot[0, 0] + py[j] * rot[0, 1] + trans[0]
        b_y = px[j] * rot[1, 0] + py[j] * rot[1, 1] + trans[1]
        b_z = px[j] * rot[2, 0] + py[j] * rot[2, 1] + trans[2]
        t_x = b_x + ph[j] * rot[0, 2]
        t_y = b_y + ph[j] * rot[1, 2]
        t_z = b_z + ph[j] * rot[2, 2]
        zmin = min(b_z, t_z)
        if zmin > NEAR_CLIP_M + pr[j]:
            ub = f * b_x / b_z + cx
            vb = f * b_y / b_z + cy
            ut = f * t_x / t_z + cx
            vt = f * t_y / t_z + cy
            half_w = f * pr[j] / zmin
            height_px = np.hypot(ub - ut, vb - vt)
            umin = min(ub, ut) - half_w
            umax = max(ub, ut) + half_w
            vmin = min(vb, vt)
            vmax = max(vb, vt)
            if umax >= 0 and umin < w_px and vmax >= 0 and vmin < h_px and height_px >= min_h:
                pcx, pcy, r, h = px[j], py[j], pr[j], ph[j]
                ux, uy = pcx - cam_pos[0], pcy - cam_pos[1]
                norm = max(np.hypot(ux, uy), 1e-9)
                ux, uy = ux / norm, uy / norm
                for s in range(n_s):
                    lat, dep, hf = samples[0, s], samples[1, s], samples[2, s]
                    qx = pcx + r * (-uy * lat - ux * dep)
                    qy = pcy + r * (ux * lat - uy * dep)
                    qz = h * hf
                    c0 = qx * rot[0, 0] + qy * rot[0, 1] + qz * rot[0, 2] + trans[0]
                    c1 = qx * rot[1, 0] + qy * rot[1, 1] + qz * rot[1, 2] + trans[1]
                    c2 = qx * rot[2, 0] + qy * rot[2, 1] + qz * rot[2, 2] + trans[2]
                    u = f * c0 / c2 + cx
                    v = f * c1 / c2 + cy
                    in_image[s] = c2 > NEAR_CLIP_M and u >= 0 and u < w_px and v >= 0 and v < h_px
                    ex = qx - cam_pos[0]
                    ey = qy - cam_pos[1]
                    ez = qz - cam_pos[2]
                    d = math.sqrt(ex * ex + ey * ey + ez * ez)
                    dist[s] = d
                    direction[s, 0] = ex / d
                    direction[s, 1] = ey / d
                    direction[s, 2] = ez / d
                    t_max[s] = d + bg_max
                    skip[s] = j
                cast_group(origin, direction, t_max, 0, n_s, skip, skip_veh,
                           vx, vy, vc, vs, vhl, vhw, vh, vrad, px, py, pr, ph,
                           trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m,
                           nx, ny, mark, t_hit, kind, idx)  # fmt: skip
                n_vis = 0
                n_strong = 0
                for s in range(n_s):
                    if in_image[s] and not (t_hit[s] < dist[s] - 1e-6):
                        n_vis += 1
                        d2 = 0.0
                        for c in range(3):
                            bg = _surface_lab(kind[s], idx[s], vlab, plab, poly_lab, cyl_lab, ground_lab,
                                              sky_lab, c)  # fmt: skip
                            diff = plab[j, c] - bg
                            d2 = d2 + diff * diff
                        if d2 >= thr2:
                            n_strong += 1
                vis_frac = n_vis / n_s
                contrast = n_strong / max(n_vis, 1)
        out_f[row_f, j] = vis_frac
        out_f[row_f + 1, j] = height_px
        out_f[row_f + 2, j] = contrast
        out_b[row_b, j] = vis_frac >= min_vis and height_px >= min_h and contrast >= 0.5


@_jit
def lidar_kernel(
    lid_p, elev, pos, yaw, skip_veh,
    vx, vy, vc, vs, vhl, vhw, vh, vrad,
    px, py, pr, ph,
    trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny, mark,
    n_ret_out, out_b, row_b,
):  # fmt: skip
    """The spinning LiDAR (sensors.plan_lidar + cast + sensors.finish_lidar) for every pedestrian.

    lid_p: [cluster_tolerance_m, range_m, horizontal resolution (rad), min_returns, pi - resolution];
    elev (C,) channel elevations (rad); pos (3,) the LiDAR origin; yaw its heading (rad). Writes the
    returns on each pedestrian to n_ret_out, the verdict to out_b[row_b] and "merged" to
    out_b[row_b + 1]."""
    tol, rng_m, res, min_ret, half_cap = lid_p[0], lid_p[1], lid_p[2], lid_p[3], lid_p[4]
    o0, o1, zs = pos[0], pos[1], pos[2]
    n_ch_all = elev.shape[0]
    m = px.shape[0]
    for j in range(m):
        n_ret_out[j] = 0
        out_b[row_b, j] = False
        out_b[row_b + 1, j] = False
        r, h = pr[j], ph[j]
        d = np.hypot(px[j] - o0, py[j] - o1)
        if not (d - r <= rng_m and d > r):
            continue
        az_c = np.arctan2(py[j] - o1, px[j] - o0) - yaw
        d_near = max(d - r - tol, 0.05)
        d_far = d + r + tol
        half = np.arcsin(min(r / d, 1.0)) + np.arctan2(tol, d_near)
        half = min(half, half_cap)
        k0 = int(math.ceil((az_c - half) / res))
        k1 = int(math.floor((az_c + half) / res))
        z_lo = -zs
        z_hi = h + tol - zs
        e_lo = min(np.arctan2(z_lo, d_near), np.arctan2(z_lo, d_far))
        e_hi = max(np.arctan2(z_hi, d_near), np.arctan2(z_hi, d_far))
        c0 = 0  # searchsorted side="left"
        while c0 < n_ch_all and elev[c0] < e_lo:
            c0 += 1
        c1 = 0  # searchsorted side="right", minus one
        while c1 < n_ch_all and elev[c1] <= e_hi:
            c1 += 1
        c1 -= 1
        n_az = max(k1 - k0 + 1, 0)
        n_ch = max(c1 - c0 + 1, 0)
        count = n_az * n_ch
        if count <= 0:
            continue
        reach = np.hypot(d_far, max(h - zs, zs) + tol)
        tmax = min(rng_m, reach)
        origin = np.empty((count, 3))
        direction = np.empty((count, 3))
        t_max = np.empty(count)
        skip = np.full(count, -1, dtype=np.int64)
        # The ray q is azimuth column q // n_ch and channel q % n_ch: each column's and each channel's
        # cos and sin are computed once (the same calls on the same arguments as per ray: same bits).
        cos_el = np.empty(n_ch)
        sin_el = np.empty(n_ch)
        for c in range(n_ch):
            cos_el[c] = np.cos(elev[c0 + c])
            sin_el[c] = np.sin(elev[c0 + c])
        q = 0
        for a in range(n_az):
            az = (k0 + a) * res + yaw
            cos_az = np.cos(az)
            sin_az = np.sin(az)
            for c in range(n_ch):
                direction[q, 0] = cos_el[c] * cos_az
                direction[q, 1] = cos_el[c] * sin_az
                direction[q, 2] = sin_el[c]
                origin[q, 0] = o0
                origin[q, 1] = o1
                origin[q, 2] = zs
                t_max[q] = tmax
                q += 1
        t_hit = np.empty(count)
        kind = np.empty(count, dtype=np.int8)
        idx = np.empty(count, dtype=np.int64)
        cast_group(origin, direction, t_max, 0, count, skip, skip_veh,
                   vx, vy, vc, vs, vhl, vhw, vh, vrad, px, py, pr, ph,
                   trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny,
                   mark, t_hit, kind, idx)  # fmt: skip
        n_on = 0
        for q in range(count):
            if kind[q] == KIND_PEDESTRIAN and idx[q] == j:
                n_on += 1
        merged = False
        if n_on > 0:
            # The returns on the pedestrian, computed once (the same expressions as per pair before).
            on_x = np.empty(n_on)
            on_y = np.empty(n_on)
            on_z = np.empty(n_on)
            n = 0
            for p in range(count):
                if kind[p] == KIND_PEDESTRIAN and idx[p] == j:
                    tp = t_hit[p]
                    on_x[n] = o0 + direction[p, 0] * tp
                    on_y[n] = o1 + direction[p, 1] * tp
                    on_z[n] = zs + direction[p, 2] * tp
                    n += 1
            for q in range(count):
                kq = kind[q]
                if not (kq == KIND_VEHICLE or kq == KIND_PRISM or kq == KIND_CYLINDER):
                    continue
                tq = t_hit[q]
                qx = o0 + direction[q, 0] * tq
                qy = o1 + direction[q, 1] * tq
                qz = zs + direction[q, 2] * tq
                radial = max(np.hypot(qx - px[j], qy - py[j]) - r, 0.0)
                vertical = max(max(-qz, qz - h), 0.0)
                if not (np.hypot(radial, vertical) <= tol):
                    continue
                for p in range(n_on):
                    ax = qx - on_x[p]
                    ay = qy - on_y[p]
                    az_ = qz - on_z[p]
                    if ax * ax + ay * ay + az_ * az_ <= tol * tol:
                        merged = True
                        break
                if merged:
                    break
        n_ret_out[j] = n_on
        out_b[row_b + 1, j] = merged
        out_b[row_b, j] = n_on >= min_ret and not merged


@_jit
def rotation(yaw, pitch_down):
    """geometry.rotation_world_to_camera and the translation of world_to_camera_transform."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch_down), math.sin(pitch_down)
    rot = np.empty((3, 3))
    rot[0, 0], rot[0, 1], rot[0, 2] = sy, -cy, 0.0
    rot[1, 0], rot[1, 1], rot[1, 2] = -sp * cy, -sp * sy, -cp
    rot[2, 0], rot[2, 1], rot[2, 2] = cp * cy, cp * sy, -sp
    return rot


@_jit
def frame_kernel(
    ego_x, ego_y, ego_yaw, skip_veh, run_camera, run_lidar, run_roadside,
    cam_p, cam_samples, cam_mount, lid_p, elev, lid_mount, rsu_p, rsu_samples, rsu_rot, rsu_trans, rsu_pos,
    vx, vy, vyaw, vlen, vwid, vh, vlab,
    px, py, pr, ph, plab,
    trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny,
    poly_lab, cyl_lab, ground_lab, sky_lab,
):  # fmt: skip
    """One frame of every sensor. Mounts: [forward_m, left_m, height_m, yaw_offset_rad,
    pitch_down_rad]. Returns (out_f (3 + 3U, M): camera then each roadside unit's visible fraction,
    height px, contrast fraction; n_ret (M,) LiDAR returns; out_b (3 + U, M): camera verdict, LiDAR
    verdict, LiDAR merged, each roadside unit's verdict)."""
    m = px.shape[0]
    n_u = rsu_rot.shape[0]
    out_f = np.zeros((3 + 3 * n_u, m))
    out_b = np.zeros((3 + n_u, m), dtype=np.bool_)
    n_ret = np.zeros(m, dtype=np.int64)
    if m == 0:
        return out_f, n_ret, out_b
    vt = vehicle_tables(vyaw, vlen, vwid)
    vc, vs, vhl, vhw, vrad = vt[0], vt[1], vt[2], vt[3], vt[4]
    mark = np.full(walls.shape[0], -1, dtype=np.int64)
    c, s = math.cos(ego_yaw), math.sin(ego_yaw)
    if run_camera:
        pos = np.empty(3)
        pos[0] = ego_x + c * cam_mount[0] - s * cam_mount[1]
        pos[1] = ego_y + s * cam_mount[0] + c * cam_mount[1]
        pos[2] = cam_mount[2]
        rot = rotation(ego_yaw + cam_mount[3], cam_mount[4])
        trans = np.empty(3)
        for i in range(3):
            trans[i] = -rot[i, 0] * pos[0] + -rot[i, 1] * pos[1] + -rot[i, 2] * pos[2]
        camera_kernel(cam_p, cam_samples, rot, trans, pos, skip_veh,
                      vx, vy, vc, vs, vhl, vhw, vh, vrad, vlab, px, py, pr, ph, plab,
                      trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny,
                      mark, poly_lab, cyl_lab, ground_lab, sky_lab, out_f, out_b, 0, 0)  # fmt: skip
    if run_lidar:
        pos = np.empty(3)
        pos[0] = ego_x + c * lid_mount[0] - s * lid_mount[1]
        pos[1] = ego_y + s * lid_mount[0] + c * lid_mount[1]
        pos[2] = lid_mount[2]
        lidar_kernel(lid_p, elev, pos, ego_yaw + lid_mount[3], skip_veh,
                     vx, vy, vc, vs, vhl, vhw, vh, vrad, px, py, pr, ph,
                     trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny,
                     mark, n_ret, out_b, 1)  # fmt: skip
    if run_roadside:
        for u in range(n_u):
            camera_kernel(rsu_p, rsu_samples, rsu_rot[u], rsu_trans[u], rsu_pos[u], -1,
                          vx, vy, vc, vs, vhl, vhw, vh, vrad, vlab, px, py, pr, ph, plab,
                          trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m,
                          nx, ny, mark, poly_lab, cyl_lab, ground_lab, sky_lab, out_f, out_b, 3 + 3 * u,
                          3 + u)  # fmt: skip
    return out_f, n_ret, out_b


@_jit
def v2i_to_vehicle(points_roadside, roadside_to_world, ego_x, ego_y, ego_yaw, cam_mount, intrinsics):
    """Eqs. 5-6 for one V2I message (as :func:`v2i.message_to_vehicle`): roadside-camera points (K, 3)
    -> pixels (K, 2) in the ego camera (NaN behind it) and world ground positions (K, 2). The ego
    camera's pose comes from the ego pose and the mount [forward_m, left_m, height_m, yaw_offset_rad,
    pitch_down_rad]; roadside_to_world is the inverse of the message's world_to_roadside."""
    c, s = math.cos(ego_yaw), math.sin(ego_yaw)
    pos = np.empty(3)
    pos[0] = ego_x + c * cam_mount[0] - s * cam_mount[1]
    pos[1] = ego_y + s * cam_mount[0] + c * cam_mount[1]
    pos[2] = cam_mount[2]
    rot = rotation(ego_yaw + cam_mount[3], cam_mount[4])
    trans = np.empty(3)  # world_to_camera_transform: -rot @ pos
    for i in range(3):
        trans[i] = -rot[i, 0] * pos[0] + -rot[i, 1] * pos[1] + -rot[i, 2] * pos[2]
    back = np.empty(3)  # invert_transform: -rot.T @ trans
    for i in range(3):
        back[i] = -rot[0, i] * trans[0] + -rot[1, i] * trans[1] + -rot[2, i] * trans[2]
    chain = np.empty((3, 4))  # world_to_camera @ roadside_to_world (rows 0-2)
    for i in range(3):
        for j in range(4):
            v = rot[i, 0] * roadside_to_world[0, j] + rot[i, 1] * roadside_to_world[1, j]
            v = v + rot[i, 2] * roadside_to_world[2, j]
            if j == 3:
                v = v + trans[i]
            chain[i, j] = v
    k = points_roadside.shape[0]
    pixels = np.empty((k, 2))
    xy = np.empty((k, 2))
    pv = np.empty(3)
    for n in range(k):
        for i in range(3):
            pv[i] = (
                points_roadside[n, 0] * chain[i, 0]
                + points_roadside[n, 1] * chain[i, 1]
                + points_roadside[n, 2] * chain[i, 2]
                + chain[i, 3]
            )
        if pv[2] > 1e-9:
            w = intrinsics[2, 0] * pv[0] + intrinsics[2, 1] * pv[1] + intrinsics[2, 2] * pv[2]
            pixels[n, 0] = (
                intrinsics[0, 0] * pv[0] + intrinsics[0, 1] * pv[1] + intrinsics[0, 2] * pv[2]
            ) / w
            pixels[n, 1] = (
                intrinsics[1, 0] * pv[0] + intrinsics[1, 1] * pv[1] + intrinsics[1, 2] * pv[2]
            ) / w
        else:
            pixels[n, 0] = np.nan
            pixels[n, 1] = np.nan
        for i in range(2):
            xy[n, i] = rot[0, i] * pv[0] + rot[1, i] * pv[1] + rot[2, i] * pv[2] + back[i]
    return pixels, xy
