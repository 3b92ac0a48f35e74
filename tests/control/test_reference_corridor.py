"""The reference stack's threat corridor follows the ego's planned path (the route feed): hand-built
lanes of a right turn, with answers worked out by hand, and the straight corridor as the special case
of a straight path."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.control.agent import (
    EgoState,
    LaneCentreline,
    Observation,
    PerceivedPedestrian,
    RouteAhead,
)
from pedsafe_sumo.control.reference import (
    ReferenceStack,
    TrackedPedestrian,
    planned_path,
    predict_threat,
    predict_threat_on_path,
)

#: Right turn of a southbound ego: the approach lane down the y axis to the stop line at y = 0, a
#: quarter circle of radius 10 m about (-10, 0) (8 chords) into the exit lane westwards along y = -10.
RADIUS_M = 10.0
CHORDS = 8
ARC = tuple(
    (-10.0 + RADIUS_M * math.cos(a), RADIUS_M * math.sin(a))
    for a in np.linspace(0.0, -math.pi / 2, CHORDS + 1)
)


def lane(lane_id, edge_id, shape, drivable=True, index=1):
    return LaneCentreline(lane_id, edge_id, index, 3.2, 13.9, tuple(shape), drivable)


APPROACH = lane("in_1", "in", [(0.0, 50.0), (0.0, 0.0)])
SIDEWALK = lane("in_0", "in", [(2.6, 50.0), (2.6, 0.0)], drivable=False, index=0)
OTHER_LANE = lane("in_2", "in", [(-3.2, 50.0), (-3.2, 0.0)], index=2)
TURN = lane(":j_0_0", ":j_0", ARC)
# The left-lane's straight via, starting elsewhere (at the other lane's end): never joined to ours.
OTHER_VIA = lane(":j_1_0", ":j_1", [(-3.2, 0.0), (-3.2, -20.0)])
EXIT = lane("out_1", "out", [(-10.0, -10.0), (-60.0, -10.0)])
ROUTE = RouteAhead(("in", "out"), (SIDEWALK, APPROACH, OTHER_LANE, TURN, OTHER_VIA, EXIT), "in_1", 38.0)

#: The ego's centre 12 m before the stop line, heading south, at 5 m/s; 4.5 x 1.8 m: corridor half width
#: 0.9 + 0.5 = 1.4 m, front 2.25 m ahead of the centre.
EGO = EgoState(x_m=0.0, y_m=12.0, yaw_rad=-math.pi / 2, speed_mps=5.0, length_m=4.5, width_m=1.8)


def standing(x, y):
    return TrackedPedestrian("p", x, y, 0.0, 0.0)


def test_planned_path_chains_the_turn_not_the_other_lanes():
    path = planned_path(ROUTE)
    starts = [(s.x_m, s.y_m) for s in path.segments]
    assert starts[0] == (0.0, 50.0) and path.current_count == 1
    assert len(starts) == 1 + CHORDS + 1
    np.testing.assert_allclose(starts[1:-1], ARC[:-1], atol=1e-12)
    np.testing.assert_allclose(starts[-1], (-10.0, -10.0), atol=1e-12)
    # Along the path: 50 m of approach, then 8 chords of 2 r sin(pi/32) each.
    chord_m = 2 * RADIUS_M * math.sin(math.pi / 2 / CHORDS / 2)
    assert path.segments[-1].start_m == pytest.approx(50.0 + CHORDS * chord_m)


def test_pedestrian_on_the_turn_path_is_a_threat_on_the_straight_extension_not():
    path = planned_path(ROUTE)
    obs = Observation(EGO, route=ROUTE)
    chord_m = 2 * RADIUS_M * math.sin(math.pi / 2 / CHORDS / 2)
    # On the exit lane's centreline 5 m past the end of the turn (the crosswalk the ego turns across).
    on_turn = standing(-15.0, -10.0)
    threat = predict_threat_on_path(obs, on_turn, path, horizon_s=4.0, lateral_margin_m=0.5)
    # Gap along the path from the front: 12 m to the stop line, the arc's chords, 5 m, less 2.25 m.
    assert threat is not None and threat.time_s == 0.0
    assert threat.gap_m == pytest.approx(12.0 + CHORDS * chord_m + 5.0 - 2.25)
    # The straight corridor (along the ego's heading) misses them: 15 m to its right.
    assert predict_threat(obs, on_turn, 4.0, 0.5) is None
    # Straight on past the stop line, where the ego does not go: no threat on the path ...
    straight_on = standing(0.0, -12.0)
    assert predict_threat_on_path(obs, straight_on, path, horizon_s=4.0, lateral_margin_m=0.5) is None
    # ... though the straight corridor would brake for them (gap 12 + 12 - 2.25).
    assert predict_threat(obs, straight_on, 4.0, 0.5).gap_m == pytest.approx(21.75)


def test_pedestrian_walking_onto_the_turn_path_enters_when_expected():
    path = planned_path(ROUTE)
    # On the exit's crosswalk 3 m past the end of the turn, 4 m south of the exit lane's centre, walking
    # north at 1.4 m/s: enters the 1.4 m half width at (4 - 1.4) / 1.4 s.
    p = TrackedPedestrian("p", -13.0, -14.0, 0.0, 1.4)
    threat = predict_threat_on_path(Observation(EGO, route=ROUTE), p, path, 4.0, 0.5)
    assert threat.time_s == pytest.approx(2.6 / 1.4)


def test_on_a_straight_path_the_corridor_is_the_straight_one():
    """Random pedestrians around a straight route (approach, collinear internal lane, exit): same threats,
    gaps and times as the straight corridor along the ego's heading."""
    route = RouteAhead(
        ("in", "out"),
        (
            lane("in_1", "in", [(0.0, 80.0), (0.0, 0.0)]),
            lane(":j_2_0", ":j_2", [(0.0, 0.0), (0.0, -20.0)]),
            lane("out_1", "out", [(0.0, -20.0), (0.0, -120.0)]),
        ),
        "in_1",
        40.0,
    )
    path = planned_path(route)
    rng = np.random.default_rng(3)
    compared = threats = 0
    for _ in range(2000):
        ego = EgoState(0.0, float(rng.uniform(5, 70)), -math.pi / 2, float(rng.uniform(0, 15)), 4.5, 1.8)
        obs = Observation(ego, route=route)
        p = TrackedPedestrian("p", *rng.uniform((-12, -110), (12, 90)), *rng.uniform(-2.5, 2.5, 2))
        straight = predict_threat(obs, p, 4.0, 0.5)
        on_path = predict_threat_on_path(obs, p, path, 4.0, 0.5)
        compared += 1
        if straight is None:
            assert on_path is None, p
            continue
        threats += 1
        assert on_path.gap_m == pytest.approx(straight.gap_m, abs=1e-9)
        assert on_path.time_s == pytest.approx(straight.time_s, abs=1e-9)
    assert threats > 100  # the sample holds threats, not only misses


def test_stack_asks_for_the_route_and_brakes_for_the_pedestrian_on_its_turn():
    stack = ReferenceStack()
    stack.setup({"initial_speed_mps": 5.0, "reaction_time_s": 0.0})
    assert "route" in stack.sensors()
    seen = (PerceivedPedestrian("p", -15.0, -10.0, "onboard_camera"),)
    command = stack.run_step(Observation(EGO, seen, route=ROUTE), 0.0)
    assert command.info["braking"] is True
    # Without the route feed it falls back to the straight corridor, which misses them.
    fallback = ReferenceStack()
    fallback.setup({"initial_speed_mps": 5.0, "reaction_time_s": 0.0})
    assert fallback.run_step(Observation(EGO, seen), 0.0).info["braking"] is False
