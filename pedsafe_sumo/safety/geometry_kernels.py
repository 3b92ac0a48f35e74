"""Compiled (numba) scalar forms of :mod:`pedsafe_sumo.safety.geometry`'s rectangle-circle clearance, for
the per-step callers of the episode loop: the ego-pedestrian clearance of every step and the walker's
body test (:meth:`PedestrianWalker._walks_into`), where the numpy forms would make a dozen numpy calls on
scalars or on arrays of a few elements every step.

Bit-identical to the numpy functions: the same operations in the same order (``to_rectangle_frame``,
``box_signed_distance_m``, then minus the radius), and NaN propagates as in ``np.maximum``/``np.minimum``.
numba's ``np.cos``, ``np.sin`` and ``np.hypot`` call the C library, as numpy does on the CPUs this project
runs on (checked by ``tests/safety/test_geometry_kernels.py`` on random inputs, and by whole batches with
``tools/compare_runs_exact.py``); on a CPU with AVX512_SKX numpy has its own SIMD sin and cos, which may
differ in the last bit (as the perception kernels may, see :mod:`pedsafe_sumo.perception.kernels`).
Compiled on first use and cached on disk, as the
perception kernels (:func:`pedsafe_sumo.perception.raycast_kernels._jit`).
"""

from __future__ import annotations

import numpy as np

from pedsafe_sumo.perception.raycast_kernels import _jit, _nmax, _nmin


@_jit  # type: ignore[untyped-decorator]  # numba compiles it; the annotations are for readers
def rectangle_circle_clearance_m(
    rect_x_m: float,
    rect_y_m: float,
    rect_yaw_rad: float,
    rect_length_m: float,
    rect_width_m: float,
    x_m: float,
    y_m: float,
    radius_m: float,
) -> float:
    """:func:`geometry.rectangle_circle_distance_m` for one rectangle and one circle (floats)."""
    dx = x_m - rect_x_m
    dy = y_m - rect_y_m
    cos = np.cos(rect_yaw_rad)
    sin = np.sin(rect_yaw_rad)
    local_x = cos * dx + sin * dy
    local_y = -sin * dx + cos * dy
    qx = abs(local_x) - 0.5 * rect_length_m
    qy = abs(local_y) - 0.5 * rect_width_m
    outside = np.hypot(_nmax(qx, 0.0), _nmax(qy, 0.0))
    inside = _nmin(_nmax(qx, qy), 0.0)
    return outside + inside - radius_m


@_jit  # type: ignore[untyped-decorator]  # numba compiles it; the annotations are for readers
def walks_into_body(
    x_m: np.ndarray,
    y_m: np.ndarray,
    yaw_rad: np.ndarray,
    length_m: np.ndarray,
    width_m: np.ndarray,
    half_diagonal_m: np.ndarray,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    radius_m: float,
    margin_m: float,
    graze_m: float,
) -> bool:
    """The body test of :meth:`PedestrianWalker._walks_into` over the footprints (arrays): whether the
    circle moving (x0, y0) -> (x1, y1) ends overlapping a footprint, or within `margin_m` of one while its
    clearance falls by more than `graze_m`. Footprints whose circumscribed circle stays farther than the
    margin from the circle at (x1, y1) are skipped, as the numpy version's bound does."""
    reach_add = radius_m + margin_m
    for i in range(x_m.shape[0]):
        dx = x_m[i] - x1
        dy = y_m[i] - y1
        reach = half_diagonal_m[i] + reach_add
        if not (dx * dx + dy * dy <= reach * reach):
            continue
        box = (x_m[i], y_m[i], yaw_rad[i], length_m[i], width_m[i])
        before = rectangle_circle_clearance_m(*box, x0, y0, radius_m)
        after = rectangle_circle_clearance_m(*box, x1, y1, radius_m)
        if after <= 0.0 or (after < margin_m and after < before - graze_m):
            return True
    return False
