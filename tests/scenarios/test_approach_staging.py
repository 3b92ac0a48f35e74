"""Approach staging (ScenarioSpec.staging "approach", scenarios/placements/approach.py) on the real site
Xueqing: where the ego starts, when and where the pedestrian appears, walks in, crosses and walks on,
checked against SUMO's own network read with sumolib and against the timing formula by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sumolib

from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.sampling.draws import Draws
from pedsafe_sumo.scenarios.geometry import load_approach, load_turn
from pedsafe_sumo.scenarios.hosting import staging_problem
from pedsafe_sumo.scenarios.signals import load_junction_signals
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode, stage_signals, step_off_time_s
from pedsafe_sumo.scenarios.walkways import walk_in
from pedsafe_sumo.sumo_net import read_net

TRAITS = {"age_years": 35.0, "gender": "f", "risk": "unaware", "walking_speed_mps": 1.4}
STRAIGHT = ("crossing", "jaywalking", "background_blending")
#: The ego's car (road_users.VEHICLE_CLASSES["car"]) is 4.6 m long.
CAR_LENGTH_M = 4.6


@pytest.fixture(scope="module")
def site():
    return get_site("xueqing")


@pytest.fixture(scope="module")
def approach(site):
    return load_approach(site)


@pytest.fixture(scope="module")
def net(site):
    return read_net(str(site.file("net.xml")), withInternal=True)


def approach_spec(name, **overrides):
    return get_scenario(name).with_overrides({"staging": "approach", **overrides})


def draw(spec, approach, seed, speed=8.0, traits=TRAITS):
    """(the setup, the named draws made for it)."""
    draws = Draws(np.random.default_rng(seed))
    return draw_episode(spec, approach, seed, traits, speed, draws), draws.inputs


def _lane_pos(lane, xy) -> float:
    """SUMO lane position (lane-length metres) of the point of `lane`'s drawn shape nearest `xy`."""
    shape = lane.getShape()
    offset = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(xy, shape, perpendicular=False)
    drawn = sum(math.dist(p, q) for p, q in zip(shape[:-1], shape[1:]))
    return offset * lane.getLength() / drawn


def _polyline_m(points) -> float:
    return sum(math.dist(p, q) for p, q in zip(points[:-1], points[1:]))


@pytest.mark.parametrize("name", STRAIGHT)
def test_the_start_distance_is_drawn_and_is_the_distance_along_the_lane_to_the_conflict(name, approach, net):
    """From SUMO's lane shapes: the ego's front at the start is `ego_start_distance_m` before the conflict
    point along its lane (for crossing, the lane then the junction's internal lane to the crosswalk)."""
    spec = approach_spec(name)
    for seed in range(4):
        setup, inputs = draw(spec, approach, seed)
        lane = net.getLane(setup.ego.lane_id)
        conflict = setup.conflict_xy
        gap_m = sumolib.geomhelper.distancePointToPolygon(conflict, lane.getShape())
        if gap_m < 0.01:
            conflict_pos_m = _lane_pos(lane, conflict)
        else:
            # Beyond the stop line: along the straight connection's internal lane.
            (connection,) = [c for c in lane.getOutgoing() if c.getTo().getID() == setup.ego_route[1]]
            internal = net.getLane(connection.getViaLaneID())
            conflict_pos_m = lane.getLength() + _lane_pos(internal, conflict)
        assert setup.ego_start_distance_m == pytest.approx(conflict_pos_m - setup.ego.front_pos_m, abs=0.02)
        # The front is on the lane, the whole car behind it on the lane too.
        assert CAR_LENGTH_M - 1e-9 <= setup.ego.front_pos_m <= lane.getLength()
        drawn = inputs["ego_start_distance_m"]
        assert spec.ego_start_min_m <= drawn <= spec.ego_start_max_m
        if setup.ego_start_distance_m != pytest.approx(drawn):
            # Only where the road ends: the car's rear at the lane's start.
            assert setup.ego.front_pos_m == pytest.approx(CAR_LENGTH_M)


def test_the_appearance_time_by_hand(approach):
    """Crossing, seed 3, ego at 8 m/s, pedestrian at 1.4 m/s: A = d / v - conflict offset - walk to the
    conflict - wait at the kerb - walk-in, with the drawn start distance and walk-in."""
    spec = approach_spec("crossing")
    setup, inputs = draw(spec, approach, 3)
    ped = setup.pedestrian
    step_off = ped.path_xy[ped.kerb_index]
    # The crosswalk's kerb end, 1 m back onto the sidewalk (placements/crosswalk.py).
    (ax, ay), (bx, by) = approach.crosswalk_path
    width = math.dist((ax, ay), (bx, by))
    assert step_off == pytest.approx((ax - (bx - ax) / width, ay - (by - ay) / width))
    walk_to_conflict_s = math.dist(step_off, setup.conflict_xy) / 1.4
    expected = (
        inputs["ego_start_distance_m"] / 8.0
        - inputs["conflict_offset_s"]
        - walk_to_conflict_s
        - spec.ped_start_delay_s
        - inputs["walk_in_s"]
    )
    assert expected >= spec.ped_appear_min_s  # an ordinary draw: no fallback
    assert ped.appear_time_s == pytest.approx(expected, abs=1e-6)
    assert setup.conflict_time_s == pytest.approx(inputs["ego_start_distance_m"] / 8.0)
    assert setup.time_limit_s == pytest.approx(expected + spec.time_limit_s)
    # The walk-in is the drawn time at their speed, and they step off after it and the wait.
    assert _polyline_m(ped.path_xy[: ped.kerb_index + 1]) == pytest.approx(inputs["walk_in_s"] * 1.4)
    assert step_off_time_s(ped) == pytest.approx(expected + inputs["walk_in_s"] + spec.ped_start_delay_s)


@pytest.mark.parametrize("name", STRAIGHT)
def test_ordinary_draws_appear_after_the_minimum(name, approach):
    spec = approach_spec(name)
    for seed in range(10):
        setup, _ = draw(spec, approach, seed)
        assert setup.pedestrian.appear_time_s >= spec.ped_appear_min_s - 1e-9
        assert setup.pedestrian.leaves_scene
        assert setup.pedestrian.kerb_index >= 1


@pytest.mark.parametrize("name", STRAIGHT)
def test_the_walk_in_is_on_a_sidewalk_and_the_walk_on_goes_beyond_the_crossing(name, approach, net):
    sidewalks = [
        lane
        for edge in net.getEdges(withInternal=False)
        for lane in edge.getLanes()
        if lane.allows("pedestrian") and not lane.allows("passenger")
    ]
    spec = approach_spec(name)
    for seed in range(6):
        setup, _ = draw(spec, approach, seed)
        ped = setup.pedestrian
        for point in ped.path_xy[: ped.kerb_index]:
            assert any(
                sumolib.geomhelper.distancePointToPolygon(point, lane.getShape()) < lane.getWidth() / 2
                for lane in sidewalks
            ), f"seed {seed}: walk-in point {point} is on no sidewalk"
        # The crossing of the straight placements is two points: the step-off point and its far end.
        far_end = ped.path_xy[ped.kerb_index + 1]
        assert _polyline_m(ped.path_xy[ped.kerb_index + 1 :]) >= spec.walk_on_m - 1e-6
        # Away from the road it crossed: farther from the conflict point than the far end is.
        assert math.dist(ped.path_xy[-1], setup.conflict_xy) > math.dist(far_end, setup.conflict_xy)


def test_the_walk_on_turns_along_the_far_sidewalk(approach, net):
    """Jaywalking across both carriageways: 25 m straight on reaches the northbound road's sidewalk
    (lane 1104710650#1_0, x about 217 m), and the pedestrian walks along it away from the junction
    (north, the junction lies south)."""
    setup, _ = draw(approach_spec("jaywalking", walk_on_m=25), approach, 0)
    ped = setup.pedestrian
    lane = net.getLane("1104710650#1_0")
    end = ped.path_xy[-1]
    assert sumolib.geomhelper.distancePointToPolygon(end, lane.getShape()) < 0.01
    assert end[1] > ped.path_xy[ped.kerb_index + 1][1] + 5.0


def test_the_sidewalk_shortens_the_walk_in(approach):
    """Background blending steps off about 160 m from where the sidewalk begins (its 181.63 m end at the
    junction): a walk-in of 60 s at 3.5 m/s (210 m) begins where the sidewalk begins, and the pedestrian
    appears later by what it lacks. The ego at 2 m/s starts far enough back for the whole walk."""
    spec = approach_spec(
        "background_blending", walk_in_min_s=60, walk_in_max_s=60, ego_start_min_m=170, ego_start_max_m=170
    )
    fast = {**TRAITS, "walking_speed_mps": 3.5}
    setup, inputs = draw(spec, approach, 1, speed=2.0, traits=fast)
    ped = setup.pedestrian
    assert ped.path_xy[0] == pytest.approx(approach.sidewalk_shape[0], abs=0.01)
    walk_in_m = _polyline_m(ped.path_xy[: ped.kerb_index + 1])
    assert walk_in_m < 185.0
    step_off = ped.path_xy[ped.kerb_index]
    expected = (
        170.0 / 2.0
        - inputs["conflict_offset_s"]
        - math.dist(step_off, setup.conflict_xy) / 3.5
        - spec.ped_start_delay_s
        - walk_in_m / 3.5
    )
    assert ped.appear_time_s == pytest.approx(expected, abs=1e-6)
    # Later than the whole 60 s walk-in would have had them appear.
    assert ped.appear_time_s > expected - (60.0 - walk_in_m / 3.5) + 5.0


def test_walk_in_by_hand():
    """An L-shaped sidewalk (0, 0) -> (0, 10) -> (10, 10); the step-off point 1 m beside (6, 10): 8 m of
    walk-in run from (0, 8) through the corner to (6, 10); 30 m run from the sidewalk's start."""
    shape = ((0.0, 0.0), (0.0, 10.0), (10.0, 10.0))
    step_off = (6.0, 9.0)
    assert _flat(walk_in(shape, step_off, 8.0)) == pytest.approx([0.0, 8.0, 0.0, 10.0, 6.0, 10.0])
    assert _flat(walk_in(shape, step_off, 30.0)) == pytest.approx([0.0, 0.0, 0.0, 10.0, 6.0, 10.0])
    # On the centreline: the walk-in ends at the point before it.
    assert _flat(walk_in(shape, (6.0, 10.0), 4.0)) == pytest.approx([2.0, 10.0])


def _flat(points) -> list[float]:
    return [c for point in points for c in point]


def test_the_fixed_staging_is_unchanged(approach):
    """No appearance, no walk-in, no walk-on, the spec's time limit; the start distance is what the ego
    covers until the staged conflict at its initial speed."""
    for name in STRAIGHT:
        spec = get_scenario(name)
        for seed in range(3):
            setup, inputs = draw(spec, approach, seed)
            ped = setup.pedestrian
            assert (ped.appear_time_s, ped.kerb_index, ped.leaves_scene) == (0.0, 0, False)
            assert len(ped.path_xy) == 2
            assert setup.time_limit_s == spec.time_limit_s
            assert "ego_start_distance_m" not in inputs and "walk_in_s" not in inputs
            assert setup.ego_start_distance_m == pytest.approx(setup.conflict_time_s * 8.0)
            # The collision course of the fixed staging: the pedestrian reaches the ego's lane
            # conflict_offset_s before the ego.
            walk_s = math.dist(ped.path_xy[0], setup.conflict_xy) / 1.4
            assert ped.start_delay_s + walk_s + setup.conflict_offset_s == pytest.approx(
                setup.conflict_time_s
            )


def test_the_fixed_staging_draws_the_same_world_with_or_without_the_approach_fields(approach):
    """The approach's ranges are drawn only under approach staging: changing them leaves a fixed
    staging's world as it was."""
    spec = get_scenario("jaywalking")
    other = spec.with_overrides({"ego_start_min_m": 150, "walk_in_max_s": 50, "walk_on_m": 3})
    assert draw(spec, approach, 5)[0] == draw(other, approach, 5)[0]


@pytest.mark.parametrize("name", STRAIGHT)
def test_the_same_seed_gives_the_same_setup(name, approach):
    spec = approach_spec(name)
    assert draw(spec, approach, 7)[0] == draw(spec, approach, 7)[0]
    assert draw(spec, approach, 7)[0] != draw(spec, approach, 8)[0]


def test_a_fast_ego_on_a_short_road_keeps_the_collision_course(approach):
    """Jaywalking at 20 m/s: the road holds at most about 140 m before the conflict (7 s), less than the
    pedestrian needs; the ego starts where the road begins and the pedestrian is already on their way at
    t = 0, so that they still reach the ego's lane conflict_offset_s before it."""
    spec = approach_spec("jaywalking")
    slow = {**TRAITS, "walking_speed_mps": 0.8}
    setup, _ = draw(spec, approach, 2, speed=20.0, traits=slow)
    ped = setup.pedestrian
    assert ped.appear_time_s == 0.0
    assert setup.ego.front_pos_m == pytest.approx(CAR_LENGTH_M)
    # When they reach the ego's lane: the rest of the walk-in, the rest of the wait, the rest of the
    # crossing (straight, from where they are at the kerb index) up to the conflict point.
    walk_m = _polyline_m(ped.path_xy[: ped.kerb_index + 1])
    to_conflict_m = math.dist(ped.path_xy[ped.kerb_index], setup.conflict_xy)
    reach_s = (walk_m + to_conflict_m) / 0.8 + ped.start_delay_s
    assert reach_s + setup.conflict_offset_s == pytest.approx(setup.conflict_time_s, abs=1e-6)


def test_signals_hold_from_the_appearance(site, approach):
    """Crossing under approach staging: the ego's signal is green from the pedestrian's appearance to 2 s
    after the conflict, the pedestrian's red from stepping off to then (sampled every 0.1 s)."""
    spec = approach_spec("crossing")
    signals = load_junction_signals(site.file("net.xml"), approach.junction_id)
    program = signals.program
    for seed in range(4):
        setup, _ = draw(spec, approach, seed)
        staged = stage_signals(spec, setup, signals, np.random.default_rng(seed))
        staging = staged.signals
        until_s = setup.conflict_time_s + spec.signal_hold_after_s
        for time_s in np.arange(setup.pedestrian.appear_time_s, until_s, 0.1):
            cycle_s = (staging.cycle_start_s + time_s + 1e-6) % program.cycle_s
            assert program.colour(staging.ego_link_index, cycle_s) == "green"
        for time_s in np.arange(step_off_time_s(setup.pedestrian), until_s, 0.1):
            cycle_s = (staging.cycle_start_s + time_s + 1e-6) % program.cycle_s
            assert program.colour(staging.ped_link_index, cycle_s) == "red"


def test_a_turn_under_approach_staging_is_staged(site, approach):
    """right_turn is hosted under approach staging and staged as the straight scenarios are (its own
    checks: tests/scenarios/test_turn_approach.py): the pedestrian appears after the minimum, walks in to
    their step-off point and leaves the scene."""
    spec = approach_spec("right_turn")
    turn = load_turn(site, "right")
    assert staging_problem(site, spec, approach, turn, "N") is None
    setup = draw_episode(spec, approach, 0, TRAITS, 5.0, np.random.default_rng(0), turn)
    ped = setup.pedestrian
    assert ped.appear_time_s >= spec.ped_appear_min_s and ped.kerb_index >= 1 and ped.leaves_scene
    assert spec.ego_start_min_m <= setup.ego_start_distance_m <= spec.ego_start_max_m


def test_hosting_refuses_a_road_too_short_for_any_start(site, approach):
    """Jaywalking crosses up to 45 m before the 181.63 m lane's stop line (a little more where the gap in
    the queue nearest the drawn distance lies beyond it): the ego's lane holds it (4.6 m) at most about
    132 m before the conflict, short of a 180 m minimum start."""
    assert staging_problem(site, approach_spec("jaywalking"), approach, None, "N") is None
    spec = approach_spec("jaywalking", ego_start_min_m=180, ego_start_max_m=200)
    problem = staging_problem(site, spec, approach, None, "N")
    assert problem is not None and "ego_start_min_m 180" in problem
    held_m = float(problem.split("at most ")[1].split(" m")[0])
    # At most the lane's length less the farthest mid-block distance and the car (the placement may
    # reach a little farther, to the queue gap nearest the drawn distance).
    assert 120.0 <= held_m <= 181.63 - 45.0 - CAR_LENGTH_M + 0.5


def test_a_scene_longer_than_the_green_starts_later_on_the_walk_in(site, approach):
    """Xueqing's southbound through green lasts 16 s of its 90 s cycle. A 10 s walk-in, the 1 s wait, the
    walk to the median lane (about 5.8 m at 1.0 m/s) and 2 s after the conflict do not fit in it (the ego
    at 3 m/s starts long enough before for the whole walk-in): the
    pedestrian appears 16 s before the end of the hold, further along the same walk-in, and steps off
    when they would have."""
    spec = approach_spec("crossing", walk_in_min_s=10, walk_in_max_s=10)
    slow = {**TRAITS, "walking_speed_mps": 1.0}
    signals = load_junction_signals(site.file("net.xml"), approach.junction_id)
    setup, _ = draw(spec, approach, 4, speed=3.0, traits=slow)
    staged = stage_signals(spec, setup, signals, np.random.default_rng(4))
    until_s = setup.conflict_time_s + spec.signal_hold_after_s
    assert until_s - setup.pedestrian.appear_time_s > 16.0
    ped = staged.pedestrian
    assert ped.appear_time_s == pytest.approx(until_s - 16.0, abs=0.01)
    assert step_off_time_s(ped) == pytest.approx(step_off_time_s(setup.pedestrian))
    assert staged.time_limit_s == pytest.approx(ped.appear_time_s + spec.time_limit_s)
    # Where they appear lies on the walk-in they would have walked.
    before = setup.pedestrian.path_xy[: setup.pedestrian.kerb_index + 1]
    gap_m = sumolib.geomhelper.distancePointToPolygon(ped.path_xy[0], list(before))
    assert gap_m < 1e-6
    assert ped.path_xy[ped.kerb_index :] == setup.pedestrian.path_xy[setup.pedestrian.kerb_index :]


def test_no_walk_on_ends_at_the_crossing(approach):
    setup, _ = draw(approach_spec("crossing", walk_on_m=0), approach, 0)
    ped = setup.pedestrian
    assert len(ped.path_xy) == ped.kerb_index + 2
    assert ped.leaves_scene


def test_a_fast_ego_starts_farther_back_to_keep_the_appearance(approach):
    """Jaywalking at 14 m/s from 100 m: the ego would arrive after about 7.1 s, before the pedestrian
    (walking 1.4 m/s, about 6 m to the median lane, 1 s at the kerb) could appear at 3 s even with no
    walk-in. The walk-in shrinks to the step from the sidewalk's centreline to the step-off point, and the
    ego starts 14 m/s x (3 s + offset + that step + walk + wait) before the conflict, so that the
    pedestrian appears at exactly 3 s."""
    spec = approach_spec("jaywalking", ego_start_min_m=100, ego_start_max_m=100)
    for seed in range(3):
        setup, inputs = draw(spec, approach, seed, speed=14.0)
        ped = setup.pedestrian
        step_off = ped.path_xy[ped.kerb_index]
        walk_in_m = _polyline_m(ped.path_xy[: ped.kerb_index + 1])
        # Nothing but the step from the sidewalk (3 m wide) to the step-off point.
        assert walk_in_m < 3.0
        walk_s = math.dist(step_off, setup.conflict_xy) / 1.4
        lead_s = inputs["conflict_offset_s"] + walk_s + spec.ped_start_delay_s + walk_in_m / 1.4
        assert setup.ego_start_distance_m == pytest.approx(14.0 * (3.0 + lead_s), abs=1e-6)
        assert ped.appear_time_s == pytest.approx(3.0, abs=1e-9)
