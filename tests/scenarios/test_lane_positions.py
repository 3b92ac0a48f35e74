"""Lane positions: the scenarios place their vehicles in SUMO's lane-length metres, which SUMO draws at
pos x (drawn length / lane length) along a lane's shape. Checked by hand on a built path, then against
SUMO itself: after the engine's own staging, where libsumo draws the occluders and where the ego's front
is when it reaches the staged conflict time at its initial speed (Xueqing's ego lane is 181.63 m long
and 181.16 m drawn: a drawn offset taken for a lane position put the ego 0.37-0.47 m off)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.scenarios.geometry import (
    lane_pos_to_offset_m,
    offset_to_lane_pos_m,
    path_pos_m,
    shape_length_m,
)
from pedsafe_sumo.scenarios.specs import get_scenario


def test_conversion_scales_by_drawn_over_lane_length():
    shape = ((0.0, 0.0), (60.0, 0.0), (60.0, 40.0))  # drawn 100 m
    assert shape_length_m(shape) == 100.0
    # A lane netconvert made 101 m long: SUMO draws lane position 50.5 m at 50 m along the shape.
    assert lane_pos_to_offset_m(shape, 101.0, 50.5) == pytest.approx(50.0)
    assert offset_to_lane_pos_m(shape, 101.0, 50.0) == pytest.approx(50.5)


def test_path_position_adds_the_lane_lengths_of_the_lanes_before():
    # Lane 1: drawn 10 m, 10.5 m long; lane 2 (a bend): drawn 4 m, 5 m long; lane 3 drawn 20 m, 20 m long.
    path = (
        (((0.0, 0.0), (10.0, 0.0)), 10.5),
        (((10.0, 0.0), (12.0, 0.0), (12.0, 2.0)), 5.0),
        (((12.0, 2.0), (12.0, 22.0)), 20.0),
    )
    assert path_pos_m(path, (5.0, 0.3)) == pytest.approx(5.25)
    # 3 m along lane 2 (the middle of its second leg) is 3 x 5/4 lane metres into it.
    assert path_pos_m(path, (12.2, 1.0)) == pytest.approx(10.5 + 3.75)
    assert path_pos_m(path, (11.9, 12.0)) == pytest.approx(10.5 + 5.0 + 10.0)


def _lines_cross(a, b, p, q):
    """Intersection of the infinite lines a-b and p-q."""
    d1 = (b[0] - a[0], b[1] - a[1])
    d2 = (q[0] - p[0], q[1] - p[1])
    denom = d1[0] * d2[1] - d1[1] * d2[0]
    t = ((p[0] - a[0]) * d2[1] - (p[1] - a[1]) * d2[0]) / denom
    return a[0] + t * d1[0], a[1] + t * d1[1]


def _kerb_lane_crossing(approach, path):
    """Where the pedestrian's straight path meets the kerb lane's drawn centreline (segment by segment)."""
    shape = approach.lane_shapes[0]
    for p, q in zip(shape[:-1], shape[1:]):
        x, y = _lines_cross(path[0], path[-1], p, q)
        along = ((x - p[0]) * (q[0] - p[0]) + (y - p[1]) * (q[1] - p[1])) / math.dist(p, q) ** 2
        if -1e-9 <= along <= 1 + 1e-9:
            return x, y
    raise AssertionError("the path does not cross the kerb lane")


def _rear(api, vehicle) -> tuple[float, float]:
    """Rear centre of a vehicle SUMO draws straight: its front minus its length along its heading."""
    x, y = api.vehicle.getPosition(vehicle.vehicle_id)
    heading = math.radians(90.0 - api.vehicle.getAngle(vehicle.vehicle_id))  # SUMO: clockwise from north
    return x - vehicle.size.length_m * math.cos(heading), y - vehicle.size.length_m * math.sin(heading)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["crossing", "jaywalking", "background_blending", "right_turn", "left_turn"])
def test_sumo_draws_the_staged_vehicles_at_the_intended_points(name):
    from pedsafe_sumo.control.reference import ReferenceStack
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.sim.episode import EpisodeRunner
    from pedsafe_sumo.sim.staging import place_on_junction

    spec = get_scenario(name).with_overrides({"background_traffic": 0})
    # left_turn needs a program that lets the oncoming vehicle move with the ego's left (not Xueqing's).
    site = get_site("xueqing_two_phase" if name == "left_turn" else "xueqing")
    runner = EpisodeRunner(site, load_params(), ReferenceStack)
    approach = runner.approach
    try:
        for seed in range(3):
            setup = runner.draw_setup(spec, seed)
            runner.session.run(runner.staging.sumo_args(seed))
            api = runner.session.api
            runner.staging.populate(api, setup, approach)
            api.simulation.step()  # inserts everything, as the engine does
            place_on_junction(api, setup)
            dt = api.simulation.getDeltaT()
            assert api.vehicle.getLanePosition("ego") == pytest.approx(setup.ego.front_pos_m, abs=1e-6)
            parked = {v.vehicle_id: v for v in setup.parked}
            path = setup.pedestrian.path_xy
            if name == "crossing":
                # The occluder's front 0.5 m before the stop line, the kerb lane's drawn end.
                (px, py), (qx, qy) = approach.lane_shapes[0][-2:]
                norm = math.hypot(qx - px, qy - py)
                intended = (qx - 0.5 * (qx - px) / norm, qy - 0.5 * (qy - py) / norm)
                assert math.dist(api.vehicle.getPosition("occluder_0"), intended) < 0.05
            elif name == "jaywalking":
                # The pedestrian's path runs through the middle of the gap between the two occluders.
                gap_front = api.vehicle.getPosition("occluder_1")
                gap_rear = _rear(api, parked["occluder_0"])
                middle = ((gap_front[0] + gap_rear[0]) / 2, (gap_front[1] + gap_rear[1]) / 2)
                assert math.dist(middle, _kerb_lane_crossing(approach, path)) < 0.05
            elif name == "background_blending":
                # The body circle touches the waiting vehicle's rear (blend gap 0): centre a radius away.
                rear = _rear(api, parked["waiting_0"])
                assert math.dist(rear, path[0]) == pytest.approx(setup.pedestrian.radius_m, abs=0.05)
            elif name == "left_turn":
                # The oncoming vehicle stands on the junction, its centre on the line from the ego's centre
                # (the roof LiDAR) to where the pedestrian waits, on SUMO's own positions.
                assert api.vehicle.getLaneID("oncoming_0").startswith(":")
                ego_rear, on_rear = _rear(api, setup.ego), _rear(api, parked["oncoming_0"])
                ego_front, on_front = api.vehicle.getPosition("ego"), api.vehicle.getPosition("oncoming_0")
                eye = ((ego_rear[0] + ego_front[0]) / 2, (ego_rear[1] + ego_front[1]) / 2)
                centre = ((on_rear[0] + on_front[0]) / 2, (on_rear[1] + on_front[1]) / 2)
                (ex, ey), (px, py) = eye, path[0]
                off_line = abs((px - ex) * (centre[1] - ey) - (py - ey) * (centre[0] - ex)) / math.dist(
                    eye, path[0]
                )
                assert off_line < 0.1, f"seed {seed}: the oncoming vehicle's centre is {off_line:.2f} m off"
            # The ego at its initial speed, nobody reacting: its front is at the staged conflict point
            # conflict_time_s after its insertion (interpolated between the two steps around it).
            api.vehicle.setSpeedMode("ego", 0)
            api.vehicle.setSpeed("ego", setup.ego.speed_mps)
            times, points = [0.0], [api.vehicle.getPosition("ego")]
            while times[-1] < setup.conflict_time_s:
                api.simulation.step()
                times.append(api.simulation.getTime() - dt)
                points.append(api.vehicle.getPosition("ego"))
            if len(times) > 1:
                w = (setup.conflict_time_s - times[-2]) / (times[-1] - times[-2])
                (ax, ay), (bx, by) = points[-2], points[-1]
                at_conflict = (ax + w * (bx - ax), ay + w * (by - ay))
            else:
                at_conflict = points[-1]
            off_m = math.dist(at_conflict, setup.conflict_xy)
            assert off_m < 0.05, f"seed {seed}: the ego's front is {off_m:.3f} m off the conflict point"
            runner.session.close()
    finally:
        runner.close()


def test_turn_lanes_follow_the_connection_through_the_internal_junction():
    """The turn's lanes join end to start (the lane after an internal junction is not skipped), and
    their drawn shapes make up the drawn turn path."""
    from pedsafe_sumo.scenarios.geometry import load_turn

    for direction in ("right", "left"):
        turn = load_turn(get_site("xueqing"), direction)
        for (shape_a, _), (shape_b, _) in zip(turn.lanes[:-1], turn.lanes[1:]):
            assert math.dist(shape_a[-1], shape_b[0]) < 1e-6
        drawn = sum(shape_length_m(shape) for shape, _ in turn.lanes)
        assert drawn == pytest.approx(shape_length_m(turn.path_xy), abs=1e-6)
        assert np.all(np.array([length for _, length in turn.lanes]) > 0)
