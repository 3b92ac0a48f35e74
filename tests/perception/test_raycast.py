"""First-hit distances of single rays against each surface type, computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from perception_scenes import world

from pedsafe_sumo.perception import StaticOccluders
from pedsafe_sumo.perception.raycast import cast_rays
from pedsafe_sumo.perception.surfaces import (
    KIND_CYLINDER,
    KIND_GROUND,
    KIND_NONE,
    KIND_PEDESTRIAN,
    KIND_PRISM,
    KIND_VEHICLE,
)


def cast(snap, origins, dirs, t_max=100.0, skip=-1):
    o = np.asarray(origins, dtype=float).reshape(-1, 3)
    d = np.asarray(dirs, dtype=float).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    n = o.shape[0]
    return cast_rays(
        snap, o, d, np.full(n, t_max), np.arange(n), np.ones(n, dtype=np.int64), np.full(n, skip)
    )


def test_ray_hits_rotated_box_face():
    # A 4 x 2 x 1.5 m box at (10, 0) turned 90 deg: its 2 m width lies along x, so its near face is at x = 9.
    snap = world([("v", 10.0, 0.0, math.pi / 2, 4.0, 2.0, 1.5, (0, 0, 0))])
    hits = cast(snap, [[0, 0, 1.0]], [[1, 0, 0]])
    assert (hits.kind[0], hits.t_m[0]) == (KIND_VEHICLE, pytest.approx(9.0))
    # Over the roof: nothing (sky).
    hits = cast(snap, [[0, 0, 2.0]], [[1, 0, 0]])
    assert hits.kind[0] == KIND_NONE and np.isinf(hits.t_m[0])


def test_ray_hits_ground_and_cylinders():
    # From 2 m high at 45 deg down: ground at t = 2 sqrt 2.
    snap = world()
    hits = cast(snap, [[0, 0, 2.0]], [[1, 0, -1]])
    assert (hits.kind[0], hits.t_m[0]) == (KIND_GROUND, pytest.approx(2 * math.sqrt(2)))
    # A pedestrian cylinder r = 0.25 at (10, 0.15): the ray y = 0 enters at
    # x = 10 - sqrt(0.25^2 - 0.15^2) = 9.8.
    snap = world(peds=[("p", 10.0, 0.15, 0.25, 1.75, (1, 2, 3))])
    hits = cast(snap, [[0, 0, 1.0]], [[1, 0, 0]])
    assert (hits.kind[0], hits.t_m[0]) == (KIND_PEDESTRIAN, pytest.approx(9.8))
    assert cast(snap, [[0, 0, 1.0]], [[1, 0, 0]], skip=0).kind[0] == KIND_NONE  # skipped pedestrian
    # Tree crown cylinder 2.5..8 m: a rising ray from (0, 0, 1) at 45 deg enters the crown (r = 2 at x = 10)
    # through its bottom at z = 2.5, x = 1.5 ... no: x = 1.5 is outside the crown, so it enters the side at
    # x = 8, z = 9 > 8 -> passes above. A ray at 10 deg enters the side at x = 8, z = 1 + 8 tan 10 = 2.41 <
    # 2.5 -> under the crown, then through its bottom at x = 1.5 / tan 10 = 8.507.
    st = StaticOccluders.build(cylinders=[(10.0, 0.0, 2.0, 2.5, 8.0, (0, 90, 0))])
    snap = world(static=st)
    assert cast(snap, [[0, 0, 1.0]], [[1, 0, 1]]).kind[0] == KIND_NONE
    el = math.radians(10)
    hits = cast(snap, [[0, 0, 1.0]], [[math.cos(el), 0, math.sin(el)]])
    assert hits.kind[0] == KIND_CYLINDER
    assert hits.t_m[0] == pytest.approx((1.5 / math.tan(el)) / math.cos(el))


def test_ray_hits_building_wall_and_passes_over_low_wall():
    square = np.array([[5, -1], [7, -1], [7, 1], [5, 1]], dtype=float)
    st = StaticOccluders.build([("b", "building", square, 0.0, 3.0, (9, 9, 9))])
    snap = world(static=st)
    hits = cast(snap, [[0, 0, 1.0]], [[1, 0, 0]])
    assert (hits.kind[0], hits.index[0], hits.t_m[0]) == (KIND_PRISM, 0, pytest.approx(5.0))
    # Aimed 0.5 m over the roof at the far wall: z at x = 7 is 1 + 7 * 2.5 / 7 = 3.5 > 3 and at the near
    # wall 1 + 5 * 2.5 / 7 = 2.79 < 3 -> hits the near wall at x = 5.
    hits = cast(snap, [[0, 0, 1.0]], [[7, 0, 2.5]])
    assert hits.kind[0] == KIND_PRISM
    assert hits.t_m[0] == pytest.approx(5 * math.hypot(7, 2.5) / 7)
    # Clearly above: no hit.
    assert cast(snap, [[0, 0, 4.0]], [[1, 0, 0]]).kind[0] == KIND_NONE


def test_first_hit_wins_and_t_max_limits():
    st = StaticOccluders.build(
        [("b", "building", np.array([[20, -5], [22, -5], [22, 5], [20, 5]], float), 0, 9, (9, 9, 9))]
    )
    snap = world(
        [("v", 10.0, 0.0, 0.0, 4.0, 2.0, 1.5, (0, 0, 0))], [("p", 5.0, 0.0, 0.25, 1.75, (1, 1, 1))], st
    )
    hits = cast(snap, [[0, 0, 1.0]], [[1, 0, 0]])
    assert (hits.kind[0], hits.t_m[0]) == (KIND_PEDESTRIAN, pytest.approx(4.75))
    hits = cast(snap, [[0, 0, 1.0]], [[1, 0, 0]], skip=0)
    assert (hits.kind[0], hits.t_m[0]) == (KIND_VEHICLE, pytest.approx(8.0))
    hits = cast(snap, [[0, 0, 1.0]], [[1, 0, 0]], t_max=7.0, skip=0)
    assert hits.kind[0] == KIND_NONE
