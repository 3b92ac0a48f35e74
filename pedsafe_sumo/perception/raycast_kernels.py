"""Compiled (numba) ray casting: the kernel of :func:`raycast.cast_rays` and the pieces every compiled
sensor shares (the slab and cylinder tests, the per-group cast, the per-site tables).

The same computations as the vectorised numpy reference (:func:`raycast.cast_rays_numpy`), written as
scalar loops so that a cast costs a few microseconds instead of a few hundred small numpy calls. Each
expression keeps the reference's operation order, and ties between surfaces at the same distance go to
the same surface (the last of vehicles, pedestrians, trees, walls, each in ascending index), so the hits
are the same; only transcendental functions may differ from numpy's in the last bit.
``tests/perception/test_compiled_equivalence.py`` checks both paths against each other on random scenes.

Compiled on first use and cached on disk (``cache=True``) in the folder :mod:`.numba_cache` chooses
(``NUMBA_CACHE_DIR``, by default under the user's cache folder); where no cache location is writable the
kernels compile once per process instead. :func:`pedsafe_sumo.compiled_kernels.prepare_compiled_kernels`
compiles them all at once, saying so. Numba's cache is keyed on the file that defines a function
alone: the ``KIND_*`` codes of :mod:`.surfaces` used here are frozen into the cached code, and so are the
functions of this file into the cached sensor kernels of :mod:`.kernels` (and
:mod:`pedsafe_sumo.safety.geometry_kernels`). After changing this file or those constants, touch
``kernels.py`` too (and ``geometry_kernels.py`` after changing ``_nmin``/``_nmax``) so that numba compiles
them again.
"""

from __future__ import annotations

import math
import warnings

import numba
import numpy as np

from .numba_cache import use_kernel_cache
from .surfaces import (
    KIND_CYLINDER,
    KIND_GROUND,
    KIND_NONE,
    KIND_PEDESTRIAN,
    KIND_PRISM,
    KIND_VEHICLE,
    rgb_to_lab,
)
from .world import EDGE_GRID_CELL_M

_INF = np.inf

# Before the first @_jit below: numba picks a function's cache folder when the function is decorated.
KERNEL_CACHE_DIR = use_kernel_cache()
#: Every compiled kernel of the package (pedsafe_sumo.compiled_kernels checks their cache).
COMPILED_KERNELS: list[numba.core.dispatcher.Dispatcher] = []

_warned_no_cache = False


def _jit(fn):
    # error_model="numpy": division by zero gives inf/nan as in numpy (the slab tests rely on it).
    global _warned_no_cache
    try:
        kernel = numba.njit(cache=True, error_model="numpy")(fn)
        COMPILED_KERNELS.append(kernel)
        return kernel
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


def static_tables(st) -> tuple:
    """The per-site arrays the kernels read (walls, wall owners and boxes, the edge grid, trees and
    their CIELAB colours), built once and kept on the occluders."""
    tables = st._grid.get("kernel")
    if tables is None:
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
