"""Compiled (numba) form of the reference stack's projection of points onto its planned path
(:meth:`pedsafe_sumo.control.baseline_planner.PathArrays.project`), which runs once or twice a step for
every track: the numpy form makes about fifteen numpy calls on arrays of a few dozen elements.

Bit-identical to the numpy form: per point and segment the same operations in the same order (offsets,
distance along, clipped to the segment, lateral offset, ``np.hypot`` of the two), the nearest segment the
first of the smallest offsets as ``np.argmin`` takes it (a NaN first), its sign as ``np.sign`` with 0 taken
as left. numba's ``np.hypot`` calls the C library, as numpy does (see
:mod:`pedsafe_sumo.safety.geometry_kernels`; ``tests/control/test_path_projection.py`` checks both forms
on random paths and points). Compiled on first use and cached on disk, as the perception kernels
(:func:`pedsafe_sumo.perception.raycast_kernels._jit`).
"""

from __future__ import annotations

import numpy as np

from pedsafe_sumo.perception.raycast_kernels import _jit, _nmax, _nmin


@_jit  # numba compiles it; the annotations are for readers
def project_points(
    px: np.ndarray,
    py: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    ux: np.ndarray,
    uy: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    start: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Distance along the path and signed lateral offset of each point (px, py) against the segments
    (x, y, ux, uy: start and unit direction; low, high: the bounds of the distance along each; start:
    its distance from the path's start)."""
    n = px.shape[0]
    s_out = np.empty(n)
    lat_out = np.empty(n)
    for i in range(n):
        best = -1
        best_off = 0.0
        best_clipped = 0.0
        best_lat = 0.0
        for k in range(x.shape[0]):
            rx = px[i] - x[k]
            ry = py[i] - y[k]
            along = rx * ux[k] + ry * uy[k]
            clipped = _nmin(_nmax(along, low[k]), high[k])
            lat = rx * -uy[k] + ry * ux[k]
            off = np.hypot(along - clipped, lat)
            # np.argmin: the first NaN, else the first of the smallest.
            if best < 0 or (best_off == best_off and (off != off or off < best_off)):
                best, best_off, best_clipped, best_lat = k, off, clipped, lat
        s_out[i] = start[best] + best_clipped
        if best_lat != best_lat:
            side = best_lat
        elif best_lat < 0.0:
            side = -1.0
        else:
            side = 1.0
        lat_out[i] = side * best_off
    return s_out, lat_out


@_jit
def first_ahead(
    s_m: np.ndarray,
    times_s: np.ndarray,
    ego_s_m: float,
    speed_mps: float,
    front_offset_m: float,
    length_m: float,
) -> int:
    """The first predicted position (distance `s_m` along the path at `times_s`) the ego has not passed
    by then and whose gap from the ego's front is not below minus its length; -1 when none."""
    for i in range(s_m.shape[0]):
        ped_lon = s_m[i] - ego_s_m
        if ped_lon - speed_mps * times_s[i] < -front_offset_m:  # the ego has passed that point by then
            continue
        if ped_lon - front_offset_m < -length_m:
            continue
        return i
    return -1


@_jit
def first_in_corridor(
    s_m: np.ndarray,
    lat_m: np.ndarray,
    times_s: np.ndarray,
    start: int,
    sigmas_m: np.ndarray,
    sigma_factor: float,
    ego_s_m: float,
    speed_mps: float,
    front_offset_m: float,
    length_m: float,
    half_width_m: float,
) -> int:
    """From `start` (first_ahead) on, the first position as first_ahead takes them whose lateral offset
    is within the corridor's half width widened by `sigma_factor` times its standard deviation
    (`sigmas_m[i - start]`; none given: no widening); -1 when none."""
    for i in range(start, s_m.shape[0]):
        ped_lon = s_m[i] - ego_s_m
        if ped_lon - speed_mps * times_s[i] < -front_offset_m:
            continue
        if ped_lon - front_offset_m < -length_m:
            continue
        widen = sigma_factor * sigmas_m[i - start] if sigmas_m.shape[0] > 0 else 0.0
        if abs(lat_m[i]) <= half_width_m + widen:
            return i
    return -1


@_jit
def widening_rows(
    s_m: np.ndarray, times_s: np.ndarray, begin: int, starts_m: np.ndarray, ux: np.ndarray, uy: np.ndarray
) -> np.ndarray:
    """The rows h = (nx, ny, nx t, ny t) of the predicted positions from `begin` on, (n, 1, 4), n = the
    positions from `begin`: (nx, ny) the unit normal (-uy, ux) of the path's segment at distance `s_m`
    (the last segment starting at or before it, the first before the path's start; a NaN distance on the
    last, as np.searchsorted places NaN), t the time. Track.position_sigmas_of_rows takes them on."""
    n = s_m.shape[0] - begin
    last = starts_m.shape[0] - 1
    h = np.empty((n, 1, 4))
    for i in range(n):
        s = s_m[begin + i]
        if s != s:
            k = last
        else:
            k = 0
            while k < last and starts_m[k + 1] <= s:
                k += 1
        nx = -uy[k]
        ny = ux[k]
        t = times_s[begin + i]
        h[i, 0, 0] = nx
        h[i, 0, 1] = ny
        h[i, 0, 2] = nx * t
        h[i, 0, 3] = ny * t
    return h
