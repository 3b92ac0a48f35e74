"""The compiled scalar clearance and body test give the numpy geometry's bits.

The references are safety.geometry's numpy functions, and the walker's body test written in numpy
(below): same inputs, every output compared bit for bit."""

from __future__ import annotations

import math

import numpy as np

from pedsafe_sumo.safety.geometry import rectangle_circle_distance_m
from pedsafe_sumo.safety.geometry_kernels import rectangle_circle_clearance_m, walks_into_body


def _walks_into_numpy(x, y, yaw, length, width, half_diagonal, x0, y0, x1, y1, r, margin, graze_m) -> bool:
    """PedestrianWalker._walks_into's body written in numpy, for the comparison."""
    dx, dy, reach = x - x1, y - y1, half_diagonal + (r + margin)
    near = dx * dx + dy * dy <= reach * reach
    if not near.any():
        return False
    box = (x[near], y[near], yaw[near], length[near], width[near])
    before = rectangle_circle_distance_m(*box, x0, y0, r)
    after = rectangle_circle_distance_m(*box, x1, y1, r)
    return bool(np.any((after <= 0.0) | ((after < margin) & (after < before - graze_m))))


def test_clearance_bits_equal_numpy_on_random_boxes():
    rng = np.random.default_rng(19)
    n = 20_000
    # Scenes at the junction's scale (coordinates ~200 m), touching, overlapping and far apart.
    cx, cy = rng.uniform(150, 250, n), rng.uniform(150, 250, n)
    yaw = rng.uniform(-2 * math.pi, 2 * math.pi, n)
    length, width = rng.uniform(3.5, 12.0, n), rng.uniform(1.6, 2.6, n)
    px, py = cx + rng.normal(0, 4, n), cy + rng.normal(0, 4, n)
    radius = rng.uniform(0.2, 0.35, n)
    expected = rectangle_circle_distance_m(cx, cy, yaw, length, width, px, py, radius)
    got = np.array(
        [
            rectangle_circle_clearance_m(*(float(a[i]) for a in (cx, cy, yaw, length, width, px, py, radius)))
            for i in range(n)
        ]
    )
    assert (expected <= 0).sum() > 1000 and (expected > 0).sum() > 1000  # both sides exercised
    # numba calls the C library's cos and sin; numpy does too, except on CPUs where it has its own SIMD
    # versions (AVX512_SKX), which may differ in the last bit: there the results agree to rounding only.
    libm = all(np.cos(v) == math.cos(v) and np.sin(v) == math.sin(v) for v in yaw)
    if libm:
        assert got.tobytes() == expected.tobytes()
    else:
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)


def test_clearance_of_a_hand_computed_case():
    # Box 4 x 2 at the origin heading +x; circle r 0.5 at (3, 2): corner (2, 1), distance sqrt(2) - 0.5.
    got = rectangle_circle_clearance_m(0.0, 0.0, 0.0, 4.0, 2.0, 3.0, 2.0, 0.5)
    assert got == math.sqrt(2.0) - 0.5
    # Inside: circle centre at the origin, nearest edge 1 m away: -1 - r.
    assert rectangle_circle_clearance_m(0.0, 0.0, 0.0, 4.0, 2.0, 0.0, 0.0, 0.5) == -1.5
    assert math.isnan(rectangle_circle_clearance_m(0.0, 0.0, math.nan, 4.0, 2.0, 3.0, 2.0, 0.5))


def test_walks_into_body_agrees_with_the_numpy_test():
    rng = np.random.default_rng(1919)
    trues = 0
    for _ in range(3000):
        k = int(rng.integers(1, 8))
        x, y = rng.uniform(-6, 6, k), rng.uniform(-6, 6, k)
        yaw = rng.uniform(-math.pi, math.pi, k)
        length, width = rng.uniform(3.5, 6.0, k), rng.uniform(1.6, 2.0, k)
        half_diagonal = 0.5 * np.hypot(length, width)
        x0, y0 = rng.uniform(-3, 3, 2)
        step = rng.normal(0, 0.08, 2)
        x1, y1 = x0 + step[0], y0 + step[1]
        margin = float(rng.choice([0.0, 0.1, 0.5]))
        graze_m = float(np.hypot(*step)) * math.sin(math.radians(5.0))
        args = (x, y, yaw, length, width, half_diagonal, float(x0), float(y0), float(x1), float(y1), 0.3)
        expected = _walks_into_numpy(*args, margin, graze_m)
        assert walks_into_body(*args, margin, graze_m) == expected
        trues += expected
    assert 100 < trues < 2900  # both answers exercised
