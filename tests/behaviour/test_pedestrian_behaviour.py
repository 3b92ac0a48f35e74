"""Pedestrian behaviour by risk preference, with hand-worked numbers.

Scene: the ego (4.5 m x 1.8 m) at the origin heading +x at 10 m/s; the pedestrian (radius 0.3 m)
crosses at x = 30 m from y = -6 to y = +6 at 1.5 m/s. The conflict point is 6 m along the path. The
ego's front needs (30 - 2.25 - 0.3) / 10 = 2.745 s to reach the pedestrian's body line: under the
default awareness threshold of 3.0 s. A yielder stands with their body 1.0 m from the ego's flank:
centre at 6 - (0.9 + 1.0 + 0.3) = 3.8 m along the path; they are across once past 6 + 0.9 + 0.3 = 7.2 m.
"""

from __future__ import annotations

import numpy as np
import pytest

from pedsafe_sumo.behaviour.pedestrian import BehaviourParams, PedestrianWalker, VehicleBodies

PATH = [(30.0, -6.0), (30.0, 6.0)]
DT = 0.05


#: The yielder's rule in the road: with yield_at_kerb a yielder who notices the ego at the kerb (s = 0
#: here) waits there instead (tests/behaviour/test_kerb_and_side_strike.py).
IN_ROAD = {"yield_at_kerb": False}


def run(
    risk, seconds, ego_xy=(0.0, 0.0), ego_speed=10.0, reaction_time_s=1.0, start_s=0.0, params=None, **kwargs
):
    behaviour = BehaviourParams(risk, 1.5, reaction_time_s=reaction_time_s, **(params or {}))
    walker = PedestrianWalker(PATH, behaviour)
    walker.s_m = start_s
    pose = None
    for k in range(round(seconds / DT)):
        pose = walker.step(DT, k * DT, ego_xy, 0.0, ego_speed, **kwargs)
    return walker, pose


def advance(walker, k_from, k_to, ego_xy, ego_speed, **kwargs):
    """Steps k_from .. k_to - 1 (time k * DT) with the ego held at ego_xy and ego_speed."""
    pose = None
    for k in range(k_from, k_to):
        pose = walker.step(DT, k * DT, ego_xy, 0.0, ego_speed, **kwargs)
    return pose


def test_unaware_keeps_walking_speed():
    walker, pose = run("unaware", 2.0)
    assert walker.s_m == pytest.approx(3.0)  # 2 s at 1.5 m/s
    assert (pose.x_m, pose.y_m) == pytest.approx((30.0, -3.0))


def test_hasten_speeds_up_after_the_reaction_time():
    walker, pose = run("hasten", 2.0)
    # 1 s reacting at 1.5 m/s, then 1 s at 1.5 * 1.5 = 2.25 m/s: 1.5 + 2.25 = 3.75 m.
    assert walker.s_m == pytest.approx(3.75)
    assert pose.state == "hastening" and pose.speed_mps == pytest.approx(2.25)


def test_a_threat_that_passes_within_the_reaction_time_leaves_a_hastener_at_their_pace():
    walker = PedestrianWalker(PATH, BehaviourParams("hasten", 1.5))
    # 0.5 s threatened (2.745 s to the body line): reacting, walking 0.75 m.
    advance(walker, 0, 10, (0.0, 0.0), 10.0)
    # Then the ego slows to 5 m/s: 27.45 / 5 = 5.5 s > 3 s, no threat; 1 s more at 1.5 m/s, not 2.25.
    pose = advance(walker, 10, 30, (0.0, 0.0), 5.0)
    assert walker.s_m == pytest.approx(0.75 + 1.5) and pose.state == "walking"
    # Once hastening (after a full reaction time under threat), they keep the pace when the ego slows.
    walker, _ = run("hasten", 1.5)  # 1 s reacting (1.5 m) + 0.5 s at 2.25 m/s = 2.625 m
    pose = advance(walker, 30, 40, (0.0, 0.0), 5.0)  # 0.5 s more at 2.25 m/s
    assert walker.s_m == pytest.approx(2.625 + 1.125) and pose.state == "hastening"


def test_yield_stops_short_of_the_ego_flank():
    walker, pose = run("yield", 3.0, params=IN_ROAD)
    # 1 s reacting (1.5 m walked), then stands where they are: 1.5 m is short of the 3.8 m stand line.
    assert walker.s_m == pytest.approx(1.5)
    assert pose.state == "yielding" and pose.speed_mps == 0.0


def test_yield_inside_the_safe_distance_steps_back_to_it():
    walker, pose = run("yield", 0.5, reaction_time_s=0.0, start_s=5.5)
    # No reaction time: steps back at 0.8 m/s, 0.4 m in 0.5 s: 5.5 - 0.4 = 5.1 m, still stepping back.
    assert walker.s_m == pytest.approx(5.1)
    assert pose.state == "stepping_back" and pose.speed_mps == pytest.approx(-0.8)
    walker2, pose2 = run("yield", 3.0, reaction_time_s=0.0, start_s=5.5)
    # 5.5 - 3.8 = 1.7 m at 0.8 m/s: at the stand line after 2.125 s, and standing there at 3 s.
    assert walker2.s_m == pytest.approx(3.8) and pose2.state == "yielding"
    # Standing, the body edge is 6 - 3.8 - 0.3 = 1.9 m from the centreline: 1.0 m from the 0.9 m flank.


def test_yield_past_the_centreline_clears_forwards():
    walker, pose = run("yield", 0.2, reaction_time_s=0.0, start_s=6.5)
    # Past the centreline (6 m): out of the path forwards at walking speed, 4 steps of 0.075 m.
    assert walker.s_m == pytest.approx(6.8) and pose.state == "clearing"


def test_yielder_resumes_only_once_the_standing_ego_was_seen_standing_for_a_reaction_time():
    walker, pose = run("yield", 3.0, params=IN_ROAD)  # steps 0..59: standing at 1.5 m
    assert pose.state == "yielding"
    # The ego stands from step 60 (t = 3.0 s). Still waiting at t = 3.95 s (stood 0.95 s < 1 s) ...
    pose = advance(walker, 60, 80, (0.0, 0.0), 0.0)
    assert walker.s_m == pytest.approx(1.5) and pose.state == "yielding"
    # ... at t = 4.0 s it has stood 1 s: walks on, 10 steps (t = 4.0 .. 4.45) of 0.075 m.
    pose = advance(walker, 80, 90, (0.0, 0.0), 0.0)
    assert walker.s_m == pytest.approx(1.5 + 10 * 0.075) and pose.state == "walking"


def test_yielder_resumes_on_an_accepted_gap_to_a_moving_ego():
    # Standing at 1.5 m, to be across they walk 7.2 - 1.5 = 5.7 m at 1.5 m/s = 3.8 s; plus the 3 s start-up
    # and clearance time, the critical gap is 6.8 s. An ego at 1 m/s whose centre is d m before the path
    # reaches the body line in d - 2.55 s.
    walker, _ = run("yield", 3.0, params=IN_ROAD)
    pose = advance(walker, 60, 70, (21.0, 0.0), 1.0)  # d = 9: 6.45 s < 6.8 s, keeps standing
    assert walker.s_m == pytest.approx(1.5) and pose.state == "yielding"
    walker, _ = run("yield", 3.0, params=IN_ROAD)
    pose = advance(walker, 60, 61, (20.0, 0.0), 1.0)  # d = 10: 7.45 s >= 6.8 s, walks on
    assert walker.s_m == pytest.approx(1.575) and pose.state == "walking"


def test_nobody_reacts_to_an_ego_they_cannot_see():
    looks = []

    def blind():
        looks.append(1)
        return False

    walker, pose = run("yield", 2.0, sees_ego=blind)
    # Never in sight: walks on at 1.5 m/s like the unaware, and looks every step (the ego threatens).
    assert walker.s_m == pytest.approx(3.0) and pose.state == "walking"
    assert len(looks) == 40
    # In sight: one look is enough; the line of sight is not cast again during the encounter.
    looks.clear()

    def sees():
        looks.append(1)
        return True

    walker, pose = run("yield", 2.0, sees_ego=sees, params=IN_ROAD)
    assert walker.s_m == pytest.approx(1.5) and pose.state == "yielding" and len(looks) == 1


def test_nobody_walks_into_a_standing_vehicle_body():
    # The audit's 0 km/h contact: an ego standing across the path. Its centre (30, 1.02), heading +x,
    # 4.5 m x 1.8 m: near flank at y = 0.12. With 0.1 m of body clearance the pedestrian's centre stops
    # at y <= 0.12 - 0.1 - 0.3 = -0.28, s <= 5.72 m: the last 0.075 m step that fits ends at 76 * 0.075
    # = 5.70 m. Whatever their risk preference. (Blocked from t = 3.80 s; at 5.5 s the 2 s they wait
    # before walking round a standing vehicle have not passed: test_blocked_by_a_standing_vehicle_...)
    ego = VehicleBodies(np.array([30.0]), np.array([1.02]), np.array([0.0]), np.array([4.5]), np.array([1.8]))
    for risk in ("unaware", "hasten", "yield"):
        walker, pose = run(risk, 5.5, ego_xy=(30.0, 1.02), ego_speed=0.0, bodies=ego)
        assert walker.s_m == pytest.approx(5.70), risk
        assert pose.state == "blocked" and pose.speed_mps == 0.0
    # Walking along a body without closing in on it is allowed: a 20 m bus parallel to the path, its
    # side 0.05 m from the pedestrian's body all along (the blending pedestrian behind a waiting car).
    beside = VehicleBodies(
        np.array([30.0 + 0.3 + 0.05 + 0.9]), np.array([0.0]), np.array([np.pi / 2]), np.array([20.0]),
        np.array([1.8]),
    )  # fmt: skip
    walker, pose = run("unaware", 2.0, ego_xy=(0.0, 0.0), ego_speed=10.0, bodies=beside)
    assert walker.s_m == pytest.approx(3.0) and pose.state == "walking"


def _clearance(pose, bodies):
    """Body edge to the nearest footprint, by hand: the circle's centre in each box's frame."""
    gaps = []
    for x, y, yaw, length, width in zip(
        bodies.x_m, bodies.y_m, bodies.yaw_rad, bodies.length_m, bodies.width_m
    ):
        dx, dy = pose.x_m - x, pose.y_m - y
        lon, lat = dx * np.cos(yaw) + dy * np.sin(yaw), -dx * np.sin(yaw) + dy * np.cos(yaw)
        out_x, out_y = max(abs(lon) - length / 2, 0.0), max(abs(lat) - width / 2, 0.0)
        gaps.append(np.hypot(out_x, out_y) - 0.3)
    return min(gaps)


def test_blocked_by_a_standing_vehicle_the_pedestrian_walks_round_it_after_the_wait():
    # The standing ego across the path of the test above: blocked at s = 5.70 m (y = -0.30) by the step
    # of t = 3.80 s. After detour_wait_s = 2 s of the same standing body (t = 5.80 s) they step sideways
    # round its nearer end: its corners lie 2.25 m either side of the path (x = 27.75 and 32.25), so
    # either end is passed 2.25 + 0.3 + 2 x 0.1 = 2.75 m aside (within 3 m); on a tie, the left of the
    # walking direction (+y): -x, behind the car, at x = 27.25. 2.75 m of 0.075 m sidesteps: 37 steps,
    # t = 5.80-7.60 s (steps 116-152); then on along x = 27.25 (0.5 m from the rear: 0.2 m clear of the
    # body) to the end of the path, 12 - 5.70 = 6.30 m, 84 steps (153-236): at y = 6 at t = 11.80 s.
    ego = VehicleBodies(np.array([30.0]), np.array([1.02]), np.array([0.0]), np.array([4.5]), np.array([1.8]))
    walker = PedestrianWalker(PATH, BehaviourParams("unaware", 1.5))
    poses = {}
    for k in range(260):
        poses[k] = walker.step(DT, k * DT, (30.0, 1.02), 0.0, 0.0, bodies=ego)
        assert _clearance(poses[k], ego) >= 0.1 - 1e-9, k
    assert poses[75].state == "walking" and poses[76].state == "blocked"
    assert all(poses[k].state == "blocked" for k in range(76, 116))
    assert (poses[115].x_m, poses[115].y_m) == pytest.approx((30.0, -0.30))
    assert all(poses[k].state == "detouring" for k in range(116, 153))
    assert poses[116].x_m == pytest.approx(30.0 - 0.075) and poses[116].y_m == pytest.approx(-0.30)
    assert (poses[152].x_m, poses[152].y_m) == pytest.approx((27.25, -0.30))
    assert poses[153].state == "walking" and poses[153].y_m == pytest.approx(-0.225)
    assert poses[236].state == "walking" and poses[237].state == "finished"
    assert (poses[236].x_m, poses[236].y_m) == pytest.approx((27.25, 6.0))


def test_no_walking_round_a_moving_vehicle_or_beyond_the_largest_offset():
    # The same car creeping +x at 0.4 m/s (0.02 m a step, over the 0.1 m/s x 0.05 s = 0.005 m a standing
    # body may move): its body covers x = 30 until t = 6.05 s; they stay blocked behind it, not round it.
    walker = PedestrianWalker(PATH, BehaviourParams("unaware", 1.5))
    for k in range(120):
        ego_x = 30.0 + 0.02 * max(k - 76, 0)
        body = VehicleBodies(
            np.array([ego_x]), np.array([1.02]), np.array([0.0]), np.array([4.5]), np.array([1.8])
        )
        pose = walker.step(DT, k * DT, (ego_x, 1.02), 0.0, 0.4, bodies=body)
    assert pose.state == "blocked" and walker.offset_m == 0.0 and walker.s_m == pytest.approx(5.70)
    # A standing 12 m bus across the path: 6.55 m to either end, more than detour_max_offset_m (3 m).
    bus = VehicleBodies(
        np.array([30.0]), np.array([1.02]), np.array([0.0]), np.array([12.0]), np.array([1.8])
    )
    walker, pose = run("unaware", 15.0, ego_xy=(30.0, 1.02), ego_speed=0.0, bodies=bus)
    assert pose.state == "blocked" and walker.offset_m == 0.0 and walker.s_m == pytest.approx(5.70)
    # With 7 m allowed they go round it: 6 + 0.5 = 6.5 m aside, at x = 23.5, and on to the end.
    walker = PedestrianWalker(PATH, BehaviourParams("unaware", 1.5, detour_max_offset_m=7.0))
    for k in range(400):
        pose = walker.step(DT, k * DT, (30.0, 1.02), 0.0, 0.0, bodies=bus)
    assert pose.state == "finished" and (pose.x_m, pose.y_m) == pytest.approx((23.5, 6.0))


def _rear_at_angle(phi_deg):
    """A 4.5 m x 1.8 m car heading away from the path (+x, turned phi CCW), its rear edge through
    (30.31, 0): 0.01 m from the body of a pedestrian centred on it at (30, 0). Walking +y along the path,
    the body's distance to the rear's line is 0.31 cos(phi) - y sin(phi) - 0.3 until past its corner."""
    phi = np.radians(phi_deg)
    centre = np.array([30.31, 0.0]) + 2.25 * np.array([np.cos(phi), np.sin(phi)])
    return VehicleBodies(
        np.array([centre[0]]), np.array([centre[1]]), np.array([phi]), np.array([4.5]), np.array([1.8])
    )


def test_standing_against_a_bumper_the_pedestrian_walks_along_it_but_never_into_it():
    # The blending staging: a pedestrian centred behind a waiting car's rear, 0.01 m from it, their path
    # 0.3 deg off the rear's line. Per 0.075 m step the distance falls 0.075 sin(0.3 deg) = 0.00039 m, under
    # the graze allowance 0.075 sin(5 deg) = 0.0065 m; at the corner (0.9 m on) 0.0053 m are left, so they
    # walk on: 2 s at 1.5 m/s from s = 6 m. (Before the graze angle they stood "blocked" for the episode.)
    walker, pose = run(
        "unaware", 2.0, ego_xy=(0.0, 0.0), ego_speed=10.0, start_s=6.0, bodies=_rear_at_angle(0.3)
    )
    assert walker.s_m == pytest.approx(9.0) and pose.state == "walking"
    # 10 deg towards the car: the first step closes 0.075 sin(10 deg) = 0.013 m > 0.0065 m, inside the
    # 0.1 m clearance: refused.
    walker, pose = run(
        "unaware", 2.0, ego_xy=(0.0, 0.0), ego_speed=10.0, start_s=6.0, bodies=_rear_at_angle(10.0)
    )
    assert walker.s_m == pytest.approx(6.0) and pose.state == "blocked"
    # 4 deg: each step closes 0.075 sin(4 deg) = 0.0052 m, within the allowance, but never into the body:
    # 0.31 cos(4 deg) - 0.3 = 0.0092 m at s = 6, 0.0040 m after one step, -0.0012 m (overlap) after two.
    walker, pose = run(
        "unaware", 2.0, ego_xy=(0.0, 0.0), ego_speed=10.0, start_s=6.0, bodies=_rear_at_angle(4.0)
    )
    assert walker.s_m == pytest.approx(6.075) and pose.state == "blocked"


def test_no_reaction_when_the_vehicle_is_far_passed_or_stopped():
    # 40 m away: (40 - 2.55) / 10 = 3.745 s to the body line > 3 s, nobody reacts.
    walker, _ = run("yield", 1.0, ego_xy=(-10.0, 0.0))
    assert walker.s_m == pytest.approx(1.5)
    # The ego's centre is 5 m past the path (more than half its 4.5 m length plus the 0.3 m radius).
    walker, _ = run("yield", 1.0, ego_xy=(35.0, 0.0))
    assert walker.s_m == pytest.approx(1.5)
    # The ego stands still: walk on.
    walker, _ = run("yield", 1.0, ego_speed=0.0)
    assert walker.s_m == pytest.approx(1.5)


def test_walker_finishes_at_the_end_of_its_path():
    walker, pose = run("unaware", 10.0)  # 12 m path at 1.5 m/s: done after 8 s
    assert walker.finished and pose.state == "finished"
    assert (pose.x_m, pose.y_m) == pytest.approx(PATH[1])


def test_bad_parameters_are_rejected():
    with pytest.raises(ValueError, match="unknown risk preference 'reckless'"):
        BehaviourParams("reckless", 1.4)
    with pytest.raises(ValueError, match="walking speed must be positive"):
        BehaviourParams("unaware", -1.0)


def test_a_test_track_dummy_keeps_its_path_into_a_vehicle():
    # The Euro NCAP dummy (avoids_bodies False) walks on into the standing ego of the body test:
    # 10 s at 1.5 m/s would be 15 m, the path ends at 12 m.
    ego = VehicleBodies(np.array([30.0]), np.array([1.02]), np.array([0.0]), np.array([4.5]), np.array([1.8]))
    walker = PedestrianWalker(PATH, BehaviourParams("unaware", 1.5, avoids_bodies=False))
    for k in range(200):
        pose = walker.step(DT, k * DT, (30.0, 1.02), 0.0, 0.0, bodies=ego)
    assert walker.finished and pose.state == "finished"
