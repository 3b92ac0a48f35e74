"""Exact rectangle-circle geometry (the ego's footprint and the pedestrian), checked against hand values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.safety.geometry import (
    first_polyline_crossing,
    rectangle_circle_contact_time_s,
    rectangle_circle_distance_m,
)


def dist(cx, cy, yaw=0.0, r=0.3):
    """A 4 m x 2 m rectangle centred on the origin against a circle at (cx, cy)."""
    return rectangle_circle_distance_m(0.0, 0.0, yaw, 4.0, 2.0, cx, cy, r)


def test_circle_ahead_of_the_front_face():
    # front face at x = 2: 3 - 2 - 0.3 = 0.7
    assert dist(3.0, 0.0) == pytest.approx(0.7)


def test_rotated_ninety_degrees_the_side_faces_the_circle():
    # long axis along y now; the circle at (3, 0) faces a side at half-width 1: 3 - 1 - 0.3 = 1.7
    assert dist(3.0, 0.0, yaw=math.pi / 2) == pytest.approx(1.7)


def test_nearest_point_is_a_corner():
    # corner (2, 1) to (5, 5) is (3, 4), length 5: 5 - 0.3 = 4.7
    assert dist(5.0, 5.0) == pytest.approx(4.7)


def test_rotated_forty_five_degrees_along_the_diagonal():
    # (3, 3) lies on the rotated long axis at 3 sqrt 2 = 4.2426 m: 4.2426 - 2 - 0.3 = 1.9426
    assert dist(3.0, 3.0, yaw=math.pi / 4) == pytest.approx(3 * math.sqrt(2) - 2.3)


def test_inside_is_negative_and_touching_is_zero():
    # centre at (0.5, 0) is inside, 1 m from the nearest (long) side: -1 - 0.3 = -1.3
    assert dist(0.5, 0.0) == pytest.approx(-1.3)
    # circle of radius 0.3 whose centre is 0.3 m ahead of the front face just touches
    assert dist(2.3, 0.0) == pytest.approx(0.0, abs=1e-12)


def test_translated_rectangle_and_arrays_broadcast():
    # rectangle centred on (10, -5): the circle at (13, -5) is 3 m ahead of the centre, as in the first test
    got = rectangle_circle_distance_m(10.0, -5.0, 0.0, 4.0, 2.0, np.array([13.0, 10.0]), -5.0, 0.3)
    assert got == pytest.approx([0.7, -1.3])


def test_contact_time_head_on_with_the_front_face():
    # centre from x = 10 towards the box at 2 m/s touches when x = 2 + 0.3: (10 - 2.3) / 2 = 3.85 s
    assert rectangle_circle_contact_time_s(10.0, 0.0, -2.0, 0.0, 2.0, 1.0, 0.3) == pytest.approx(3.85)


def test_contact_time_on_a_rounded_corner_is_exact():
    # path y = 1.2 passes 0.2 m above the corner (2, 1): it touches the corner disc of radius 0.3 when
    # (x - 2)^2 + 0.2^2 = 0.3^2, x = 2 + sqrt(0.05) = 2.22361, i.e. after (10 - 2.22361) / 1 = 7.77639 s,
    # before it would reach the slab x = 2 (8 s)
    got = rectangle_circle_contact_time_s(10.0, 1.2, -1.0, 0.0, 2.0, 1.0, 0.3)
    assert got == pytest.approx(10.0 - 2.0 - math.sqrt(0.05))


def test_contact_time_is_zero_when_touching_and_inf_when_missing():
    assert rectangle_circle_contact_time_s(2.1, 0.0, 5.0, 0.0, 2.0, 1.0, 0.3) == 0.0
    # path y = 1.4 passes 0.4 m from the corner: more than the radius
    assert rectangle_circle_contact_time_s(10.0, 1.4, -1.0, 0.0, 2.0, 1.0, 0.3) == math.inf
    # moving away, and standing still outside
    assert rectangle_circle_contact_time_s(10.0, 0.0, 1.0, 0.0, 2.0, 1.0, 0.3) == math.inf
    assert rectangle_circle_contact_time_s(10.0, 0.0, 0.0, 0.0, 2.0, 1.0, 0.3) == math.inf


def test_polylines_cross_where_hand_geometry_says():
    # A along y = 0 from x = -5 to 5; B along x = 1 from y = -5 to 5: they cross at (1, 0)
    assert first_polyline_crossing(
        [-5.0, 0.0, 5.0], [0.0, 0.0, 0.0], [1.0, 1.0], [-5.0, 5.0]
    ) == pytest.approx((1.0, 0.0))
    # parallel lines, and a path of one point, never cross
    assert first_polyline_crossing([-5.0, 5.0], [0.0, 0.0], [-5.0, 5.0], [1.0, 1.0]) is None
    assert first_polyline_crossing([-5.0, 5.0], [0.0, 0.0], [1.0], [0.0]) is None


def test_polylines_whose_boxes_are_apart_or_only_touch():
    # B lies wholly right of A's box: no crossing
    assert first_polyline_crossing([0.0, 1.0], [0.0, 0.0], [1.5, 1.5], [-1.0, 1.0]) is None
    # B's box touches A's at A's end point, where B passes through it: the crossing at the vertex
    assert first_polyline_crossing([0.0, 1.0], [0.0, 0.0], [1.0, 1.0], [-1.0, 1.0]) == pytest.approx(
        (1.0, 0.0)
    )
    # boxes apart in y only
    assert first_polyline_crossing([0.0, 2.0], [0.0, 0.0], [1.0, 1.0], [0.5, 3.0]) is None


def test_polyline_crossing_found_across_blocks():
    # A: 1001 points along y = 0 from x = 0 to 1000; B crosses it at x = 700.5, in A's third block of 256
    ax = np.arange(1001.0)
    got = first_polyline_crossing(ax, np.zeros_like(ax), [700.5, 700.5], [-1.0, 1.0], block=256)
    assert got == pytest.approx((700.5, 0.0))
