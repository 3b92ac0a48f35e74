"""Pedestrian behaviour by risk preference, with hand-worked numbers.

Scene: the ego at the origin heading +x at 10 m/s; the pedestrian crosses at x = 30 m from
y = -6 to y = +6 at 1.5 m/s. The conflict point is 6 m along the path, 30 m ahead of the ego:
time to conflict 30 / 10 = 3.0 s, at the default awareness threshold of 3.0 s.
"""

from __future__ import annotations

import pytest

from pedsafe_sumo.behaviour.pedestrian import BehaviourParams, PedestrianWalker

PATH = [(30.0, -6.0), (30.0, 6.0)]
DT = 0.05


def run(risk, seconds, ego_xy=(0.0, 0.0), ego_speed=10.0, reaction_time_s=1.0, start_s=0.0):
    walker = PedestrianWalker(PATH, BehaviourParams(risk, 1.5, reaction_time_s=reaction_time_s))
    walker.s_m = start_s
    pose = None
    for k in range(round(seconds / DT)):
        pose = walker.step(DT, k * DT, ego_xy, 0.0, ego_speed)
    return walker, pose


def test_unaware_keeps_walking_speed():
    walker, pose = run("unaware", 2.0)
    assert walker.s_m == pytest.approx(3.0)  # 2 s at 1.5 m/s
    assert (pose.x_m, pose.y_m) == pytest.approx((30.0, -3.0))


def test_hasten_speeds_up_after_the_reaction_time():
    walker, pose = run("hasten", 2.0)
    # 1 s reacting at 1.5 m/s, then 1 s at 1.5 * 1.5 = 2.25 m/s: 1.5 + 2.25 = 3.75 m.
    assert walker.s_m == pytest.approx(3.75)
    assert pose.state == "hastening" and pose.speed_mps == pytest.approx(2.25)


def test_yield_stops_short_of_the_corridor():
    walker, pose = run("yield", 3.0)
    # 1 s reacting (1.5 m walked), then stands: the corridor starts at 6 - 1.4 = 4.6 m.
    assert walker.s_m == pytest.approx(1.5)
    assert pose.state == "yielding" and pose.speed_mps == 0.0


def test_yield_inside_the_corridor_steps_back_to_its_edge():
    walker, pose = run("yield", 0.5, reaction_time_s=0.0, start_s=5.5)
    # No reaction time: steps back at 0.8 m/s, 0.4 m in 0.5 s: 5.5 - 0.4 = 5.1 m, still stepping back.
    assert walker.s_m == pytest.approx(5.1)
    assert pose.state == "stepping_back" and pose.speed_mps == pytest.approx(-0.8)
    walker2, pose2 = run("yield", 2.0, reaction_time_s=0.0, start_s=5.5)
    # After 2 s it reached the edge (4.6 m) at 1.125 s and stands there, yielding.
    assert walker2.s_m == pytest.approx(4.6) and pose2.state == "yielding"


def test_no_reaction_when_the_vehicle_is_far_passed_or_stopped():
    # 40 m away: 4 s to the conflict point > 3 s, nobody reacts.
    walker, _ = run("yield", 1.0, ego_xy=(-10.0, 0.0))
    assert walker.s_m == pytest.approx(1.5)
    # The ego's centre is 5 m past the path (more than half its 4.5 m length): walk on.
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
