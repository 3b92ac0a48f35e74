"""The walk to the kerb, the yielder's wait at the kerb and the side strike, with hand-worked numbers.

Scene of test_pedestrian_behaviour.py: the ego (4.5 m x 1.8 m) at the origin heading +x at 10 m/s; the
pedestrian (radius 0.3 m, 1.5 m/s, 0.075 m a step of 0.05 s) crosses at x = 30 m from y = -6 to y = +6.
The ego's front needs 2.745 s to reach their body line: under the 3 s awareness threshold from the start.
"""

from __future__ import annotations

import numpy as np
import pytest

from pedsafe_sumo.behaviour.pedestrian import BehaviourParams, PedestrianWalker, VehicleBodies

PATH = [(30.0, -6.0), (30.0, 6.0)]
DT = 0.05


def advance(walker, k_from, k_to, ego_xy=(0.0, 0.0), ego_speed=10.0, **kwargs):
    """Steps k_from .. k_to - 1 (time k * DT) with the ego held at ego_xy and ego_speed."""
    pose = None
    for k in range(k_from, k_to):
        pose = walker.step(DT, k * DT, ego_xy, 0.0, ego_speed, **kwargs)
    return pose


def test_the_walk_to_the_kerb_goes_at_walking_speed_and_the_start_delay_runs_from_the_kerb():
    # 3 m of sidewalk before the kerb point (30, -6): 40 steps, whatever the threat (a hastener under it).
    walker = PedestrianWalker([(30.0, -9.0), *PATH], BehaviourParams("hasten", 1.5), 1.0, kerb_index=1)
    pose = advance(walker, 0, 20)
    assert walker.s_m == pytest.approx(1.5) and pose.state == "walking_in" and pose.speed_mps == 1.5
    pose = advance(walker, 20, 40)
    assert walker.s_m == pytest.approx(3.0) and pose.state == "waiting"
    assert walker.kerb_reached_s == pytest.approx(2.0) and walker.crossing_from_s == pytest.approx(3.0)
    # Waits the 1 s start delay there (steps of t = 2.0 .. 2.95), then walks: the step of t = 3.0 moves.
    pose = advance(walker, 40, 60)
    assert walker.s_m == pytest.approx(3.0) and pose.state == "waiting"
    advance(walker, 60, 61)
    assert walker.s_m == pytest.approx(3.075)
    # The conflict point lies on the crossing: 3 + 6 = 9 m along the path.
    assert walker._conflict((0.0, 0.0), 0.0)[0] == pytest.approx(9.0)


def test_a_yielder_who_notices_the_ego_at_the_kerb_waits_there():
    # Threatened from t = 0 while waiting out the 1 s start delay: noticed at t = 1.0, never steps off.
    walker = PedestrianWalker(PATH, BehaviourParams("yield", 1.5), start_delay_s=1.0)
    pose = advance(walker, 0, 60)
    assert walker.s_m == 0.0 and pose.state == "yielding"
    # Without the rule: walks from t = 1.0, notices then, reacts 1 s (1.5 m) and stands in the road.
    walker_in_road = PedestrianWalker(PATH, BehaviourParams("yield", 1.5, yield_at_kerb=False), 1.0)
    pose = advance(walker_in_road, 0, 60)
    assert walker_in_road.s_m == pytest.approx(1.5) and pose.state == "yielding"
    # Gap acceptance from the kerb: the ego stands from t = 3.0, seen standing 1 s at t = 4.0, then they
    # walk: 10 steps (t = 4.0 .. 4.45) of 0.075 m.
    pose = advance(walker, 60, 80, ego_speed=0.0)
    assert walker.s_m == 0.0 and pose.state == "yielding"
    pose = advance(walker, 80, 90, ego_speed=0.0)
    assert walker.s_m == pytest.approx(0.75) and pose.state == "walking"


def test_a_yielder_who_noticed_at_the_kerb_steps_back_onto_it():
    # No start delay: noticed at t = 0 on the kerb, 1.5 m into the road when the reaction time is over,
    # then back at 0.8 m/s (0.04 m a step): 1.5 / 0.04 = 37.5 steps, on the kerb by the step of t = 2.85.
    walker = PedestrianWalker(PATH, BehaviourParams("yield", 1.5))
    pose = advance(walker, 0, 21)
    assert walker.s_m == pytest.approx(1.5 - 0.04) and pose.state == "stepping_back"
    pose = advance(walker, 21, 60)
    assert walker.s_m == 0.0 and pose.state == "yielding"


def test_a_yielder_already_in_the_road_stops_where_the_reaction_finds_them():
    walker = PedestrianWalker(PATH, BehaviourParams("yield", 1.5))
    walker.s_m = 1.0  # stepped off before the ego came in sight: noticed in the road
    pose = advance(walker, 0, 60)
    assert walker.s_m == pytest.approx(2.5) and pose.state == "yielding"


# ----------------------------------------------------------------------------- the side strike
# A car (4.5 m x 1.8 m) drives along y = 0 heading +x at 5 m/s; the pedestrian walks x = 0 from y = -5
# at 1.5 m/s. Their body reaches its near flank (y = -0.9) when the centre is at y = -1.2, s = 3.8 m,
# t = 2.533 s, as the car's centre passes x = 0: x_car(t) = 5 (t - 2.5333).
SIDE_PATH = [(0.0, -5.0), (0.0, 5.0)]
T_FLANK = 3.8 / 1.5


def _car(t, speed=5.0, ego_index=0):
    x = speed * (t - T_FLANK)
    bodies = VehicleBodies(
        np.array([x]), np.array([0.0]), np.array([0.0]), np.array([4.5]), np.array([1.8]), None,
        np.array([speed]), ego_index,
    )  # fmt: skip
    return (x, 0.0), bodies


def _walk_past_the_car(params, steps=80, ego_index=0):
    """Steps of the pedestrian beside the passing car; per step (time after it, s walked, state, the
    clearance to the car after the step worked out by hand: the centre's distance to the box less r)."""
    walker = PedestrianWalker(SIDE_PATH, params)
    out = []
    for k in range(steps):
        ego_xy, bodies = _car(k * DT, ego_index=ego_index)
        if ego_index < 0:  # another vehicle; the ego stands far away, no threat
            pose = walker.step(DT, k * DT, (-1000.0, 50.0), 0.0, 0.0, bodies=bodies)
        else:
            pose = walker.step(DT, k * DT, ego_xy, 0.0, 5.0, 4.5, 1.8, bodies=bodies)
        car_x, _ = _car((k + 1) * DT)[0]
        out_x = max(abs(pose.x_m - car_x) - 2.25, 0.0)
        out_y = max(abs(pose.y_m) - 0.9, 0.0)
        inside = min(max(abs(pose.x_m - car_x) - 2.25, abs(pose.y_m) - 0.9), 0.0)
        out.append(((k + 1) * DT, walker.s_m, pose.state, float(np.hypot(out_x, out_y) + inside - 0.3)))
    return out


def test_an_unaware_pedestrian_walks_into_the_side_of_a_moving_car():
    steps = _walk_past_the_car(BehaviourParams("unaware", 1.5))
    # Never held back: 0.075 m every step; the step of t = 2.50 ends at s = 3.825, 0.025 m into the flank,
    # the car's centre 0.08 m past x = 0 (its side, not its front, 2.25 m away).
    assert [s for _, s, _, _ in steps] == pytest.approx([0.075 * (k + 1) for k in range(80)])
    first = next(k for k, (_, _, _, gap) in enumerate(steps) if gap <= 0.0)
    assert steps[first][0] == pytest.approx(2.55) and steps[first][3] == pytest.approx(-0.025)
    # Under the rule of paper-v7 (body_rule_needs_notice off) they stop 0.1 m short, s <= 3.7: at 3.675.
    old = _walk_past_the_car(BehaviourParams("unaware", 1.5, body_rule_needs_notice=False))
    assert min(gap for *_, gap in old) >= 0.1 - 1e-9
    assert max(s for _, s, _, _ in old[:55]) == pytest.approx(3.675) and "blocked" in {
        st for _, _, st, _ in old
    }


def test_a_pedestrian_who_noticed_the_car_stops_short_of_its_side():
    # A hastener whose hastening is no faster (factor 1): the same walk, but the car (the ego) threatens
    # from t = 0 (its front 10.1 m from their body line: 2.0 s < 3 s); noticed at t = 1.0, so the body rule
    # holds for it: they stop at s = 3.675 (clearance 0.125 m), the next step would leave 0.05 m < 0.1 m.
    steps = _walk_past_the_car(BehaviourParams("hasten", 1.5, hasten_factor=1.0))
    assert min(gap for *_, gap in steps) >= 0.1 - 1e-9
    assert max(s for _, s, _, _ in steps[:55]) == pytest.approx(3.675)
    assert "blocked" in {state for _, _, state, _ in steps}


def test_other_moving_vehicles_stop_a_walker_but_not_the_unaware():
    # The car is not the ego (ego_index -1; the ego stands far away): a yielder, who is not distracted,
    # stops for it; an unaware pedestrian walks into it.
    walker_steps = _walk_past_the_car(BehaviourParams("yield", 1.5), ego_index=-1)
    assert min(gap for *_, gap in walker_steps) >= 0.1 - 1e-9
    unaware_steps = _walk_past_the_car(BehaviourParams("unaware", 1.5), ego_index=-1)
    assert min(gap for *_, gap in unaware_steps) < 0.0


def test_everyone_stops_for_a_standing_car():
    # The car stands across their way at x = 0 (speed 0): even the unaware stop 0.1 m short, s = 3.675.
    walker = PedestrianWalker(SIDE_PATH, BehaviourParams("unaware", 1.5))
    bodies = VehicleBodies(
        np.array([0.0]), np.array([0.0]), np.array([0.0]), np.array([4.5]), np.array([1.8]), None,
        np.array([0.0]), 0,
    )  # fmt: skip
    pose = None
    for k in range(80):
        pose = walker.step(DT, k * DT, (0.0, 0.0), 0.0, 0.0, bodies=bodies)
    assert walker.s_m == pytest.approx(3.675) and pose.state == "blocked"
