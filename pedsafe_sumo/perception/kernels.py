"""Compiled (numba) kernels of one perception frame: ray casting and the three sensor rules.

The same computations as the vectorised numpy reference (:func:`raycast.cast_rays_numpy`,
``sensors.plan_*`` / ``sensors.finish_*``), written as scalar loops so that a frame costs a few
microseconds instead of a few hundred small numpy calls. Each expression keeps the reference's
operation order, and ties between surfaces at the same distance go to the same surface (the last of
vehicles, pedestrians, trees, walls, each in ascending index), so the verdicts are the same; only
transcendental functions may differ from numpy's in the last bit. ``tests/perception/
test_compiled_equivalence.py`` checks both paths against each other on random scenes.

Compiled on first use and cached on disk (``cache=True``: beside this file in ``__pycache__``, else
numba's user-wide cache directory, or ``NUMBA_CACHE_DIR``); where no cache location is writable the
kernels compile once per process instead. Numba's cache is keyed on this file: module constants used
here (``NEAR_CLIP_M``, the ``KIND_*`` codes of :mod:`.raycast`) are frozen into the cached code, so
change them here (or touch this file) rather than behind its back.
"""

from __future__ import annotations

import math
import warnings

import numba
import numpy as np

from .raycast import KIND_CYLINDER, KIND_GROUND, KIND_NONE, KIND_PEDESTRIAN, KIND_PRISM, KIND_VEHICLE
from .world import EDGE_GRID_CELL_M

NEAR_CLIP_M = 0.05  #: camera near plane (m): nothing is imaged closer than this
_INF = np.inf


_warned_no_cache = False


def _jit(fn):
    # error_model="numpy": division by zero gives inf/nan as in numpy (the slab tests rely on it).
    global _warned_no_cache
    try:
        return numba.njit(cache=True, error_model="numpy")(fn)
    except RuntimeError:  # no writable cache location: compile in every process instead
        if not _warned_no_cache:
            _warned_no_cache = True
            warnings.warn(
                "no writable numba cache directory (set NUMBA_CACHE_DIR): the perception kernels are "
                "compiled again in every process (about 10 s)",
                RuntimeWarning,
                stacklevel=2,
            )
        return numba.njit(error_model="numpy")(fn)


@_jit
def _nmin(a, b):
    """np.minimum on scalars: NaN propagates."""
    return a if (a <= b or a != a) else b


@_jit
def _nmax(a, b):
    """np.maximum on scalars: NaN propagates."""
    return a if (a >= b or a != a) else b


@_jit
def _box_t(ox, oy, oz, dx, dy, dz, bx, by, c, s, hl, hw, h):
    """Entry distance into an oriented box (slab test in the box frame), inf when missed."""
    rx = ox - bx
    ry = oy - by
    o1 = rx * c + ry * s
    inv1 = 1.0 / (dx * c + dy * s)
    a = (-hl - o1) * inv1
    b = (hl - o1) * inv1
    xn, xf = _nmin(a, b), _nmax(a, b)
    o2 = ry * c - rx * s
    inv2 = 1.0 / (dy * c - dx * s)
    a = (-hw - o2) * inv2
    b = (hw - o2) * inv2
    yn, yf = _nmin(a, b), _nmax(a, b)
    inv3 = 1.0 / dz
    a = (0.0 - oz) * inv3
    b = (h - oz) * inv3
    zn, zf = _nmin(a, b), _nmax(a, b)
    tn = _nmax(_nmax(xn, yn), zn)
    tf = _nmin(_nmin(xf, yf), zf)
    if tn <= tf and tf >= 0.0:
        return _nmax(tn, 0.0)
    return _INF


@_jit
def _cylinder_t(ox, oy, oz, dx, dy, dz, cx, cy, r, z0, z1):
    """Entry distance into a vertical cylinder (circle plus z span), inf when missed."""
    fx = ox - cx
    fy = oy - cy
    a = dx * dx + dy * dy
    b = fx * dx + fy * dy
    c = fx * fx + fy * fy - r * r
    disc = b * b - a * c
    sq = math.sqrt(_nmax(disc, 0.0))
    if a <= 1e-12:
        t0 = -_INF
        t1 = _INF
        hit2d = c <= 0.0
    else:
        t0 = (-b - sq) / a
        t1 = (-b + sq) / a
        hit2d = disc >= 0.0
    inv = 1.0 / dz
    za = (z0 - oz) * inv
    zb = (z1 - oz) * inv
    tn = _nmax(t0, _nmin(za, zb))
    tf = _nmin(t1, _nmax(za, zb))
    if hit2d and tn <= tf and tf >= 0.0:
        return _nmax(tn, 0.0)
    return _INF


#: Safety margin (m) of the exact-test skips in cast_group: far above rounding errors, so a skip never
#: drops a hit (which would make the compiled cast differ from the reference).
REJECT_MARGIN_M = 1e-6


@_jit
def _misses_circle(fx, fy, dx, dy, a2, t_end, radius):
    """Does the 2D track f + (dx, dy) t, 0 <= t <= t_end, stay farther than radius + margin from the
    origin? (f: ray origin minus circle centre; a2 = dx^2 + dy^2 > 0.)"""
    tc = -(fx * dx + fy * dy) / a2
    if tc < 0.0:
        tc = 0.0
    elif tc > t_end:
        tc = t_end
    qx = fx + dx * tc
    qy = fy + dy * tc
    lim = radius + REJECT_MARGIN_M
    return qx * qx + qy * qy > lim * lim


@_jit
def _overlap(x, y, r, b0, b1, b2, b3):
    return x + r >= b0 and x - r <= b2 and y + r >= b1 and y - r <= b3


@_jit
def cast_group(
    origin, direction, t_max, start, count, skip_ped, skip_veh,
    vx, vy, vc, vs, vhl, vhw, vh, vrad,
    px, py, pr, ph,
    trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny, mark,
    t_out, kind_out, idx_out,
):  # fmt: skip
    """First hits of the rays ``start : start + count`` (one group), written to the ``*_out`` arrays.

    Candidates: objects whose footprint overlaps the group's corridor (2D bounding box of its
    segments), walls through the uniform grid. ``mark`` (E,) int64 scratch, all < 0 on entry and on
    return."""
    end = start + count
    b0 = _INF
    b1 = _INF
    b2 = -_INF
    b3 = -_INF
    for k in range(start, end):
        ox, oy = origin[k, 0], origin[k, 1]
        ex = ox + direction[k, 0] * t_max[k]
        ey = oy + direction[k, 1] * t_max[k]
        b0 = min(b0, min(ox, ex))
        b1 = min(b1, min(oy, ey))
        b2 = max(b2, max(ox, ex))
        b3 = max(b3, max(oy, ey))

    n_v = vx.shape[0]
    vc_idx = np.empty(n_v, dtype=np.int64)
    nv = 0
    for i in range(n_v):
        if i != skip_veh and _overlap(vx[i], vy[i], vrad[i], b0, b1, b2, b3):
            vc_idx[nv] = i
            nv += 1
    n_p = px.shape[0]
    pc_idx = np.empty(n_p, dtype=np.int64)
    np_ = 0
    for i in range(n_p):
        if _overlap(px[i], py[i], pr[i], b0, b1, b2, b3):
            pc_idx[np_] = i
            np_ += 1
    n_c = trees.shape[0]
    cc_idx = np.empty(n_c, dtype=np.int64)
    nc = 0
    for i in range(n_c):
        if _overlap(trees[i, 0], trees[i, 1], trees[i, 2], b0, b1, b2, b3):
            cc_idx[nc] = i
            nc += 1
    # Walls: grid cells overlapping the corridor (one cell of margin), then the exact bbox test.
    n_e = walls.shape[0]
    ne = 0
    ec_idx = np.empty(n_e, dtype=np.int64)
    if n_e > 0:
        ix0 = max(int(math.floor((b0 - grid_x0) / cell_m)) - 1, 0)
        ix1 = min(int(math.floor((b2 - grid_x0) / cell_m)) + 1, nx - 1)
        iy0 = max(int(math.floor((b1 - grid_y0) / cell_m)) - 1, 0)
        iy1 = min(int(math.floor((b3 - grid_y0) / cell_m)) + 1, ny - 1)
        for ix in range(ix0, ix1 + 1):
            for iy in range(iy0, iy1 + 1):
                cell = ix * ny + iy
                for j in range(cell_start[cell], cell_start[cell + 1]):
                    e = cell_edges[j]
                    if mark[e] >= 0:
                        continue
                    mark[e] = 1
                    if ebox[e, 0] <= b2 and ebox[e, 2] >= b0 and ebox[e, 1] <= b3 and ebox[e, 3] >= b1:
                        ec_idx[ne] = e
                        ne += 1
        for j in range(ix0, ix1 + 1):
            for iy in range(iy0, iy1 + 1):
                cell = j * ny + iy
                for q in range(cell_start[cell], cell_start[cell + 1]):
                    mark[cell_edges[q]] = -1
    ec_sorted = np.sort(ec_idx[:ne])

    for k in range(start, end):
        ox, oy, oz = origin[k, 0], origin[k, 1], origin[k, 2]
        dx, dy, dz = direction[k, 0], direction[k, 1], direction[k, 2]
        best = t_max[k]
        kind = KIND_NONE
        idx = -1
        if dz < -1e-12:
            tg = -oz / dz
            if tg <= best:
                best = tg
                kind = KIND_GROUND
        # Running minimum with ties to the later candidate = the reference's "last entry at the minimum".
        # Objects whose footprint circle the ray's 2D track up to the current best distance misses (by
        # more than REJECT_MARGIN_M) cannot be hit at or before it and are skipped without the exact
        # test; what is tested is tested exactly as the reference does.
        a2 = dx * dx + dy * dy
        track = a2 > 1e-12
        for q in range(nv):
            i = vc_idx[q]
            if track and _misses_circle(ox - vx[i], oy - vy[i], dx, dy, a2, best, vrad[i]):
                continue
            t = _box_t(ox, oy, oz, dx, dy, dz, vx[i], vy[i], vc[i], vs[i], vhl[i], vhw[i], vh[i])
            if t <= best:
                best = t
                kind = KIND_VEHICLE
                idx = i
        sp = skip_ped[k]
        for q in range(np_):
            i = pc_idx[q]
            if i == sp:
                continue
            if track and _misses_circle(ox - px[i], oy - py[i], dx, dy, a2, best, pr[i]):
                continue
            t = _cylinder_t(ox, oy, oz, dx, dy, dz, px[i], py[i], pr[i], 0.0, ph[i])
            if t <= best:
                best = t
                kind = KIND_PEDESTRIAN
                idx = i
        for q in range(nc):
            i = cc_idx[q]
            if track and _misses_circle(ox - trees[i, 0], oy - trees[i, 1], dx, dy, a2, best, trees[i, 2]):
                continue
            t = _cylinder_t(ox, oy, oz, dx, dy, dz, trees[i, 0], trees[i, 1], trees[i, 2], trees[i, 3],
                            trees[i, 4])  # fmt: skip
            if t <= best:
                best = t
                kind = KIND_CYLINDER
                idx = i
        rx1 = ox + dx * best
        ry1 = oy + dy * best
        rx_lo, rx_hi = min(ox, rx1) - REJECT_MARGIN_M, max(ox, rx1) + REJECT_MARGIN_M
        ry_lo, ry_hi = min(oy, ry1) - REJECT_MARGIN_M, max(oy, ry1) + REJECT_MARGIN_M
        for q in range(ec_sorted.shape[0]):
            e = ec_sorted[q]
            if ebox[e, 0] > rx_hi or ebox[e, 2] < rx_lo or ebox[e, 1] > ry_hi or ebox[e, 3] < ry_lo:
                continue  # the wall's box and the ray's 2D track up to the best distance are apart
            ex_ = walls[e, 2]
            ey_ = walls[e, 3]
            wx = walls[e, 0] - ox
            wy = walls[e, 1] - oy
            inv = 1.0 / (dx * ey_ - dy * ex_)
            t = (wx * ey_ - wy * ex_) * inv
            u = (wx * dy - wy * dx) * inv
            z = oz + t * dz
            if u >= 0.0 and u <= 1.0 and t >= 0.0 and z >= walls[e, 4] and z <= walls[e, 5] and t <= best:
                best = t
                kind = KIND_PRISM
                idx = edge_poly[e]
        t_out[k] = _INF if kind == KIND_NONE else best
        kind_out[k] = kind
        idx_out[k] = idx


@_jit
def vehicle_tables(yaw, length, width):
    """Per vehicle: cos and sin of the heading, half length, half width, footprint circle radius."""
    n = yaw.shape[0]
    out = np.empty((5, n))
    for i in range(n):
        out[0, i] = np.cos(yaw[i])
        out[1, i] = np.sin(yaw[i])
        out[2, i] = 0.5 * length[i]
        out[3, i] = 0.5 * width[i]
        out[4, i] = 0.5 * np.hypot(length[i], width[i])
    return out


@_jit
def cast_rays_kernel(
    origin, direction, t_max, gstart, gcount, skip_ped, gskip_veh,
    vx, vy, vyaw, vlen, vwid, vh, px, py, pr, ph,
    trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny,
):  # fmt: skip
    """Every group of rays (the compiled :func:`raycast.cast_rays`): (t (R,), kind (R,), index (R,))."""
    n = origin.shape[0]
    t_out = np.empty(n)
    kind_out = np.zeros(n, dtype=np.int8)
    idx_out = np.full(n, -1, dtype=np.int64)
    vt = vehicle_tables(vyaw, vlen, vwid)
    mark = np.full(walls.shape[0], -1, dtype=np.int64)
    for g in range(gstart.shape[0]):
        cast_group(origin, direction, t_max, gstart[g], gcount[g], skip_ped, gskip_veh[g],
                   vx, vy, vt[0], vt[1], vt[2], vt[3], vh, vt[4], px, py, pr, ph,
                   trees, walls, edge_poly, ebox, cell_start, cell_edges, grid_x0, grid_y0, cell_m, nx, ny,
                   mark, t_out, kind_out, idx_out)  # fmt: skip
    return t_out, kind_out, idx_out


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


def static_tables(st) -> tuple:
    """The per-site arrays the kernels read (walls, wall owners and boxes, the edge grid, trees and
    their CIELAB colours), built once and kept on the occluders."""
    tables = st._grid.get("kernel")
    if tables is None:
        from .sensors import rgb_to_lab

        g = st._grid
        walls = np.ascontiguousarray(
            np.column_stack([st.ax, st.ay, st.bx - st.ax, st.by - st.ay, st.z_base_m, st.z_top_m])
        ).reshape(-1, 6)
        if st.n_edges:
            ebox = np.ascontiguousarray(np.column_stack([g["xmin"], g["ymin"], g["xmax"], g["ymax"]]))
            cell_start = np.ascontiguousarray(g["start"], dtype=np.int64)
            cell_edges = np.ascontiguousarray(g["edges"], dtype=np.int64)
            grid = (float(g["x0"]), float(g["y0"]), float(EDGE_GRID_CELL_M), int(g["nx"]), int(g["ny"]))
        else:
            ebox = np.zeros((0, 4))
            cell_start = np.zeros(1, dtype=np.int64)
            cell_edges = np.zeros(0, dtype=np.int64)
            grid = (0.0, 0.0, float(EDGE_GRID_CELL_M), 0, 0)
        trees = np.ascontiguousarray(
            np.column_stack([st.cyl_x_m, st.cyl_y_m, st.cyl_radius_m, st.cyl_z0_m, st.cyl_z1_m])
        ).reshape(-1, 5)
        edge_poly = np.ascontiguousarray(st.edge_poly, dtype=np.int64)
        cast = (trees, walls, edge_poly, ebox, cell_start, cell_edges, *grid)
        lab = (np.ascontiguousarray(rgb_to_lab(st.poly_rgb)).reshape(-1, 3),
               np.ascontiguousarray(rgb_to_lab(st.cyl_rgb)).reshape(-1, 3))  # fmt: skip
        tables = (cast, lab)
        st._grid["kernel"] = tables
    return tables


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
