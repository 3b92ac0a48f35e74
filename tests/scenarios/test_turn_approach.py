"""The turning scenarios under approach staging (placements/turn.py, TurnPlacement.stage_approach), on
Xueqing (right_turn) and its two-phase plan (left_turn): where the pedestrian walks in and steps off, where
the ego starts along its turning path, when the vehicle turning ahead of it and the oncoming vehicle pass,
and the signals, each against SUMO's network read with sumolib and the timing worked by hand; then a few
episodes in real SUMO."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sumolib

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.protocol import load_protocol
from pedsafe_sumo.sampling.draws import Draws
from pedsafe_sumo.scenarios.geometry import load_approach, load_turn
from pedsafe_sumo.scenarios.hosting import staging_problem
from pedsafe_sumo.scenarios.oncoming import load_oncoming
from pedsafe_sumo.scenarios.signals import colour_of, load_junction_signals
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode, stage_signals
from pedsafe_sumo.sumo_net import read_net

TRAITS = {"age_years": 35.0, "gender": "f", "risk": "unaware", "walking_speed_mps": 1.4}
#: road_users.VEHICLE_CLASSES: the ego's car and the SUV of the leader and the oncoming vehicle.
CAR_LENGTH_M = 4.6
SUV_LENGTH_M = 4.8
#: (scenario, site, the sidewalk lane that reaches the crosswalk end the pedestrian steps off from). From
#: the network: right_turn's crosswalk (over the west arm's westbound carriageway, 121510222#1) runs from
#: the north-west corner, 2.5 m from that carriageway's sidewalk 121510222#1_0, to the refuge between the
#: west arm's carriageways (5.1 m from it, farther from every other): the pedestrian comes from the
#: corner, the near end. left_turn's (over the east arm's eastbound carriageway, 121399196#1) runs from
#: the refuge (8.1 m from the nearest sidewalk) to the south-east corner, 2.5 m from 121399196#1_0: the far
#: end, as the spec says.
CASES = {
    "right_turn": ("xueqing", "121510222#1_0", "north"),
    "left_turn": ("xueqing_two_phase", "121399196#1_0", "south"),
}
#: The ego's speed where a test needs the drawn walk-in whole: left_turn's pedestrian waits the longer on
#: the kerb at 6 m/s (oncoming_moment "stop_line") and appears that much earlier, so that seed 1's walk-in
#: is shortened to keep ped_appear_min_s; at 4 m/s no seed of 0-9 is.
SPEED_MPS = {"right_turn": 6.0, "left_turn": 4.0}


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request):
    name = request.param
    site = get_site(CASES[name][0])
    spec = get_scenario(name).with_overrides({"staging": "approach"})
    approach = load_approach(site)
    turn = load_turn(site, spec.turn)
    oncoming = load_oncoming(site) if spec.oncoming_vehicle else None
    net = read_net(str(site.file("net.xml")), withInternal=True)
    return name, site, spec, approach, turn, oncoming, net


def draw(case, seed, speed=6.0, spec=None):
    name, site, fixed_spec, approach, turn, oncoming, net = case
    draws = Draws(np.random.default_rng(seed))
    setup = draw_episode(spec or fixed_spec, approach, seed, TRAITS, speed, draws, turn, oncoming)
    return setup, draws


# Lane paths from sumolib, apart from the package's geometry: each (lane id, drawn shape, SUMO length).
def sumo_path(net, from_lane_id: str, to_edge_id: str) -> list[tuple[str, list, float]]:
    """The lanes a vehicle drives from `from_lane_id` onto `to_edge_id`: the lane, the internal lanes of
    the connection (via lanes, followed through internal junctions), the lane reached."""
    lane = net.getLane(from_lane_id)
    (connection,) = [c for c in lane.getOutgoing() if c.getTo().getID() == to_edge_id][:1]
    lanes = [lane]
    via = connection.getViaLaneID()
    current = net.getLane(via) if via else connection.getToLane()
    while True:
        lanes.append(current)
        if not current.getID().startswith(":"):
            break
        following = current.getOutgoing()[0]
        current = net.getLane(following.getViaLaneID()) if following.getViaLaneID() else following.getToLane()
    return [(ln.getID(), [tuple(p) for p in ln.getShape()], ln.getLength()) for ln in lanes]


def _drawn_m(shape) -> float:
    return sum(math.dist(p, q) for p, q in zip(shape[:-1], shape[1:]))


def pos_along(path, xy) -> float:
    """SUMO metres from the start of `path` to its point nearest `xy`."""
    best = None
    done = 0.0
    for _, shape, length in path:
        offset = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(xy, shape, perpendicular=False)
        gap = math.dist(sumolib.geomhelper.positionAtShapeOffset(shape, offset), xy)
        if best is None or gap < best[0] - 1e-9:
            best = (gap, done + offset * length / _drawn_m(shape))
        done += length
    return best[1]


def point_along(path, pos_m) -> tuple[float, float]:
    done = 0.0
    for _, shape, length in path:
        if pos_m <= done + length:
            x, y = sumolib.geomhelper.positionAtShapeOffset(shape, (pos_m - done) * _drawn_m(shape) / length)[
                :2
            ]
            return x, y
        done += length
    raise AssertionError("beyond the path")


def walk_m(points) -> float:
    return sum(math.dist(p, q) for p, q in zip(points[:-1], points[1:]))


def test_the_pedestrian_walks_in_along_the_sidewalk_to_the_corner_end_of_the_crosswalk(case):
    """The step-off point is 1 m beyond the crosswalk's corner end (north end for right_turn, south end
    for left_turn, from the crossing's own shape), every walk-in point before it lies on the sidewalk that
    reaches that corner (within its half width of the lane's centreline), and the walk-in is the drawn
    time at their speed."""
    name, site, spec, approach, turn, _, net = case
    _, sidewalk_id, corner = CASES[name]
    shape = net.getEdge(turn.crosswalk_id).getLane(0).getShape()
    a, b = tuple(shape[0]), tuple(shape[-1])
    corner_end, other = (a, b) if (a[1] > b[1]) == (corner == "north") else (b, a)
    length = math.dist(corner_end, other)
    expected = (
        corner_end[0] + (corner_end[0] - other[0]) / length,
        corner_end[1] + (corner_end[1] - other[1]) / length,
    )
    sidewalk = net.getLane(sidewalk_id)
    for seed in range(6):
        setup, draws = draw(case, seed, speed=SPEED_MPS[name])
        ped = setup.pedestrian
        assert ped.kerb_index >= 1 and ped.leaves_scene
        assert ped.path_xy[ped.kerb_index] == pytest.approx(expected, abs=1e-6)
        for point in ped.path_xy[: ped.kerb_index]:
            gap = sumolib.geomhelper.distancePointToPolygon(point, sidewalk.getShape())
            assert gap < sidewalk.getWidth() / 2, f"seed {seed}: walk-in point {point} off {sidewalk_id}"
        # Walked towards the junction (the sidewalk of the road turned into runs away from it).
        assert math.dist(ped.path_xy[0], expected) > math.dist(ped.path_xy[ped.kerb_index - 1], expected)
        assert walk_m(ped.path_xy[: ped.kerb_index + 1]) == pytest.approx(draws.inputs["walk_in_s"] * 1.4)
        # They cross over the crosswalk to its other end and on beyond it.
        assert ped.path_xy[ped.kerb_index + 1] == pytest.approx(
            (other[0] - (corner_end[0] - other[0]) / length, other[1] - (corner_end[1] - other[1]) / length)
        )
        assert walk_m(ped.path_xy[ped.kerb_index + 1 :]) == pytest.approx(spec.walk_on_m, abs=1e-6)


def test_the_start_distance_along_the_turning_path_is_the_drawn_one(case):
    """From sumolib's lanes of the turn (approach lane, internal lanes, exit lane): the ego's front at the
    start is the drawn `ego_start_distance_m` before the conflict point along its path, on its lane at
    least 3 m before the stop line."""
    name, site, spec, approach, turn, _, net = case
    for seed in range(10):
        for speed in (4.0, 6.0, 8.0):  # within both scenarios' speed ranges
            setup, draws = draw(case, seed, speed)
            path = sumo_path(net, setup.ego.lane_id, setup.ego_route[1])
            conflict_m = pos_along(path, setup.conflict_xy)
            assert setup.ego_start_distance_m == pytest.approx(conflict_m - setup.ego.front_pos_m, abs=0.02)
            assert setup.ego_start_distance_m == pytest.approx(draws.inputs["ego_start_distance_m"])
            assert CAR_LENGTH_M <= setup.ego.front_pos_m <= path[0][2] - 3.0
            assert setup.conflict_time_s == pytest.approx(setup.ego_start_distance_m / speed)


def test_the_appearance_by_hand(case):
    """A = d / v - conflict offset - walk from the step-off point to the conflict - wait - walk-in, with
    the drawn values; no earlier than ped_appear_min_s in ordinary draws. The wait is ped_start_delay_s;
    with an oncoming vehicle (left_turn, oncoming_moment "stop_line") it is longer when the ego's front
    would be past the point 3 m before its stop line as they reach the kerb: 1 s + that excess / v."""
    name, site, spec, approach, turn, _, net = case
    speed = SPEED_MPS[name]
    for seed in range(10):
        setup, draws = draw(case, seed, speed=speed)
        ped = setup.pedestrian
        d = draws.inputs
        step_off = ped.path_xy[ped.kerb_index]
        walk_s = math.dist(step_off, setup.conflict_xy) / 1.4
        wait_s = spec.ped_start_delay_s
        if spec.oncoming_vehicle:
            path = sumo_path(net, setup.ego.lane_id, setup.ego_route[1])
            front_m = pos_along(path, setup.conflict_xy) - speed * (d["conflict_offset_s"] + walk_s + wait_s)
            wait_s += max(front_m - (path[0][2] - 3.0), 0.0) / speed
        expected = (
            d["ego_start_distance_m"] / speed - d["conflict_offset_s"] - walk_s - wait_s - d["walk_in_s"]
        )
        assert ped.appear_time_s == pytest.approx(expected, abs=1e-6)
        assert ped.appear_time_s >= spec.ped_appear_min_s
        assert ped.start_delay_s == pytest.approx(wait_s, abs=1e-9)
        assert setup.time_limit_s == pytest.approx(expected + spec.time_limit_s)


def _at_kerb_s(setup) -> float:
    """When the pedestrian reaches the kerb: their appearance and the walk-in."""
    ped = setup.pedestrian
    return ped.appear_time_s + walk_m(ped.path_xy[: ped.kerb_index + 1]) / ped.walking_speed_mps


def test_the_leader_passes_the_pedestrian_as_they_reach_the_kerb():
    """right_turn: the SUV turning ahead starts on the ego's lane at its speed; its rear passes the
    pedestrian's path by their radius (0.3 m past the conflict point along the turning path) when they
    reach the kerb, ped_start_delay_s before they step off, as in the fixed staging. By hand: the gap
    between the fronts is 0.3 + 4.8 + v (conflict offset + walk to the conflict + wait)."""
    site = get_site("xueqing")
    case = ("right_turn", site, get_scenario("right_turn").with_overrides({"staging": "approach"}),
            load_approach(site), load_turn(site, "right"), None,
            read_net(str(site.file("net.xml")), withInternal=True))  # fmt: skip
    net = case[-1]
    for seed in range(8):
        setup, draws = draw(case, seed, speed=5.0)
        (leader,) = setup.parked
        assert leader.vehicle_id == "leader_0" and leader.lane_id == setup.ego.lane_id
        assert leader.route == setup.ego_route and leader.speed_mps == 5.0
        step_off = setup.pedestrian.path_xy[setup.pedestrian.kerb_index]
        lead_s = draws.inputs["conflict_offset_s"] + math.dist(step_off, setup.conflict_xy) / 1.4 + 1.0
        assert leader.front_pos_m - setup.ego.front_pos_m == pytest.approx(0.3 + SUV_LENGTH_M + 5.0 * lead_s)
        path = sumo_path(net, setup.ego.lane_id, setup.ego_route[1])
        rear_m = leader.front_pos_m + 5.0 * _at_kerb_s(setup) - SUV_LENGTH_M
        assert rear_m == pytest.approx(pos_along(path, setup.conflict_xy) + 0.3, abs=1e-6)
        # Its green from its stop line on.
        assert leader.green_from_s == pytest.approx((path[0][2] - leader.front_pos_m) / 5.0)


def test_the_oncoming_vehicle_crosses_the_line_of_sight_as_they_reach_the_kerb():
    """left_turn on the two-phase plan: the oncoming SUV, driving at the ego's speed along the S approach's
    median lane straight on (the road before the 47 m approach included), has its centre on the line from
    the ego's box centre to the pedestrian's step-off point when they reach the kerb (the scene the fixed
    staging starts with); positions advanced along sumolib's lanes."""
    site = get_site("xueqing_two_phase")
    net = read_net(str(site.file("net.xml")), withInternal=True)
    case = ("left_turn", site, get_scenario("left_turn").with_overrides({"staging": "approach"}),
            load_approach(site), load_turn(site, "left"), load_oncoming(site), net)  # fmt: skip
    # The S approach's median lane, the road before it and the way straight on, from sumolib.
    before = net.getLane("1104710653#0_2")
    (into,) = [c for c in before.getOutgoing() if c.getToLane().getID() == "1104710653#1_2"]
    upstream = [("1104710653#0_2", [tuple(p) for p in before.getShape()], before.getLength())]
    upstream += [
        (ln.getID(), [tuple(p) for p in ln.getShape()], ln.getLength())
        for ln in [net.getLane(into.getViaLaneID())]
    ]
    route = upstream + sumo_path(net, "1104710653#1_2", "1104710650#1")
    starts = {lane_id: sum(length for _, _, length in route[:k]) for k, (lane_id, _, _) in enumerate(route)}
    stop_line_m = starts["1104710653#1_2"] + net.getLane("1104710653#1_2").getLength()
    for seed in range(10):
        for speed in (4.0, 6.0, 8.0):
            setup, _ = draw(case, seed, speed)
            (oncoming,) = setup.parked
            lane_id = oncoming.internal_lane_id or oncoming.lane_id
            pos = oncoming.internal_pos_m if oncoming.internal_lane_id else oncoming.front_pos_m
            front_m = starts[lane_id] + pos
            t_s = _at_kerb_s(setup)
            centre = point_along(route, front_m + speed * t_s - SUV_LENGTH_M / 2)
            ego_path = sumo_path(net, setup.ego.lane_id, setup.ego_route[1])
            eye = point_along(ego_path, setup.ego.front_pos_m + speed * t_s - CAR_LENGTH_M / 2)
            step_off = setup.pedestrian.path_xy[setup.pedestrian.kerb_index]
            gap = sumolib.geomhelper.distancePointToLine(centre, eye, step_off, perpendicular=True)
            assert gap is not None and gap < 0.05, f"seed {seed} at {speed} m/s: {gap}"
            assert oncoming.green_from_s == pytest.approx(max(stop_line_m - front_m, 0.0) / speed)


def test_signals_hold(case):
    """In the staged cycle: the ego's green from the pedestrian's appearance (or from the leader's stop
    line, when earlier) until signal_hold_after_s after the conflict, the pedestrian's walk when they
    step off, the oncoming vehicle's green from its stop line on."""
    name, site, spec, approach, turn, _, net = case
    junction = load_junction_signals(site.file("net.xml"), approach.junction_id)
    program = junction.program
    for seed in range(10):
        setup, draws = draw(case, seed, speed=5.0)
        staged = stage_signals(spec, setup, junction, draws)
        signals = staged.signals
        until_s = setup.conflict_time_s + spec.signal_hold_after_s

        def colour(link, time_s, signals=signals):
            return program.colour(link, (signals.cycle_start_s + time_s + 1e-6) % program.cycle_s)

        ego_from_s = staged.pedestrian.appear_time_s
        for vehicle in staged.parked:
            if vehicle.vehicle_id == "leader_0":
                # Down the ego's lane to its stop line at the ego's speed.
                ego_from_s = min(
                    ego_from_s, (net.getLane(vehicle.lane_id).getLength() - vehicle.front_pos_m) / 5.0
                )
            if vehicle.vehicle_id == "oncoming_0":
                entering = f"{vehicle.route[-2]}_2"
                link = junction.vehicle_link(entering, vehicle.route[-1])
                for time_s in np.arange(vehicle.green_from_s, until_s, 0.1):
                    assert colour(link, time_s) == "green", f"seed {seed}: oncoming at {time_s:.1f} s"
        for time_s in np.arange(ego_from_s, until_s, 0.1):
            assert colour(signals.ego_link_index, time_s) == "green", f"seed {seed}: ego at {time_s:.1f} s"
        step_off_s = _at_kerb_s(staged) + staged.pedestrian.start_delay_s
        assert colour(signals.ped_link_index, step_off_s) == "green"


def test_the_fixed_staging_draws_come_first(case):
    """The fixed staging's named draws are the first ones of the approach staging, value for value: its
    worlds are unchanged seed for seed."""
    name, site, spec, approach, turn, oncoming, net = case
    fixed = get_scenario(name)
    for seed in range(5):
        _, fixed_draws = draw(case, seed, spec=fixed)
        _, approach_draws = draw(case, seed)
        names = list(approach_draws.inputs)
        assert names[: len(fixed_draws.inputs)] == list(fixed_draws.inputs)
        assert names[len(fixed_draws.inputs) :] == ["ego_start_distance_m", "walk_in_s"]
        assert all(approach_draws.inputs[k] == v for k, v in fixed_draws.inputs.items())


def test_hosting(case):
    """Hosted under approach staging; refused in one line when the ego's lane cannot hold the minimum
    start before the conflict (the approach lane is 181.63 m long)."""
    name, site, spec, approach, turn, _, net = case
    assert staging_problem(site, spec, approach, turn, "N") is None
    far = spec.with_overrides({"ego_start_min_m": 300, "ego_start_max_m": 320})
    problem = staging_problem(site, far, approach, turn, "N")
    assert problem is not None and "\n" not in problem and "ego_start_min_m 300" in problem


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_a_few_episodes_in_sumo(name):
    """Real SUMO, 2 seeds under both conditions: the episodes end normally; SUMO inserts the ego and the
    leader / oncoming vehicle where staged; its signal states give the ego green at the pedestrian's
    appearance and the pedestrian walk when they step off."""
    from pedsafe_sumo.sim.episode import EpisodeRunner  # the engine: only for this test

    site = get_site(CASES[name][0])
    spec = get_scenario(name).with_overrides({"staging": "approach"})
    runner = EpisodeRunner(site, load_params(), ReferenceStack)
    try:
        for seed in range(2):
            for condition in ("sv", "v2i"):
                seen = {}
                setup = runner.draw_setup(spec, seed)
                other = setup.parked[0]

                at_kerb_s = _at_kerb_s(setup)

                def hook(api, row, seen=seen, setup=setup, other=other, at_kerb_s=at_kerb_s):
                    time_s = float(row["time_s"])
                    for key, when_s in (
                        ("before", at_kerb_s - 0.5),
                        ("at", at_kerb_s),
                        ("after", at_kerb_s + 0.5),
                    ):
                        if key not in seen and time_s >= when_s:
                            seen[key] = _body_and_line(api, other, setup, row)
                    if "first" not in seen:
                        seen["first"] = (
                            api.vehicle.getLanePosition("ego"),
                            api.vehicle.getLaneID(other.vehicle_id),
                        )
                    state = api.trafficlight.getRedYellowGreenState(setup.signals.tls_id)
                    if "appear" not in seen and time_s >= setup.pedestrian.appear_time_s:
                        seen["appear"] = state[setup.signals.ego_link_index]
                    step_off_s = _at_kerb_s(setup) + setup.pedestrian.start_delay_s
                    if "step_off" not in seen and time_s >= step_off_s:
                        seen["step_off"] = state[setup.signals.ped_link_index]

                result = runner.run(spec, condition, seed, setup=setup, on_step=hook)
                assert result.outcome["end_reason"] in ("both_cleared", "collision"), result.outcome
                ego_pos, other_lane = seen["first"]
                assert ego_pos == pytest.approx(setup.ego.front_pos_m, abs=0.01)
                assert other_lane == (other.internal_lane_id or other.lane_id)
                assert seen["appear"] in "Gg" and seen["step_off"] in "Gg"
                if other.vehicle_id == "leader_0":
                    # Across the pedestrian's path just before they reach the kerb, past it just after.
                    assert seen["before"]["across_path"] and not seen["after"]["across_path"]
                else:
                    # Across the line of sight from the ego's centre to them as they reach the kerb.
                    assert seen["at"]["sight_line_gap_m"] < 0.05
    finally:
        runner.close()


def _body_and_line(api, vehicle, setup, row) -> dict:
    """From SUMO's own position and angle of `vehicle`: whether its body is across the pedestrian's
    crossing (front and rear on either side of the line through the crosswalk's two ends on their path),
    and the distance from its footprint to the line of sight from the ego's centre (the log's) to the
    pedestrian's step-off point."""
    length_m, width_m = vehicle.size.length_m, vehicle.size.width_m
    fx, fy = api.vehicle.getPosition(vehicle.vehicle_id)
    heading = math.radians(90.0 - api.vehicle.getAngle(vehicle.vehicle_id))  # SUMO: clockwise from north
    rear = (fx - length_m * math.cos(heading), fy - length_m * math.sin(heading))
    ped = setup.pedestrian
    (ax, ay), (bx, by) = ped.path_xy[ped.kerb_index], ped.path_xy[ped.kerb_index + 1]
    side = [np.sign((bx - ax) * (py - ay) - (by - ay) * (px - ax)) for px, py in (rear, (fx, fy))]
    cx, cy = fx - length_m / 2 * math.cos(heading), fy - length_m / 2 * math.sin(heading)
    ex, ey = row["ego_x_m"], row["ego_y_m"]

    def outside_m(xy) -> float:
        dx, dy = xy[0] - cx, xy[1] - cy
        lon = dx * math.cos(heading) + dy * math.sin(heading)
        lat = -dx * math.sin(heading) + dy * math.cos(heading)
        return math.hypot(max(abs(lon) - length_m / 2, 0.0), max(abs(lat) - width_m / 2, 0.0))

    samples = [(ex + k / 400 * (ax - ex), ey + k / 400 * (ay - ey)) for k in range(401)]
    return {"across_path": side[0] != side[1], "sight_line_gap_m": min(outside_m(xy) for xy in samples)}


def test_a_slow_ego_s_leader_crosses_on_the_previous_phase_only_when_no_green_holds_it():
    """right_turn on Xueqing at 2.5 m/s (the spec's floor): every seed is placed in the signal program, and
    in every one the leader's stop line comes before the ego's green: no cycle time (searched every 0.1 s)
    gives the ego green from the leader's stop line to signal_hold_after_s after the conflict and the
    pedestrian walk when they step off (the walk shows in the first 11 s of the 16 s green only)."""
    site = get_site("xueqing")
    spec = get_scenario("right_turn").with_overrides({"staging": "approach"})
    approach = load_approach(site)
    case = ("right_turn", site, spec, approach, load_turn(site, "right"), None, None)
    junction = load_junction_signals(site.file("net.xml"), approach.junction_id)
    program = junction.program
    dropped = 0
    for seed in range(20):
        setup, draws = draw(case, seed, speed=2.5)
        staged = stage_signals(spec, setup, junction, draws)
        (leader,) = staged.parked
        ego_link, ped_link = staged.signals.ego_link_index, staged.signals.ped_link_index
        cycle_s = (staged.signals.cycle_start_s + leader.green_from_s + 1e-6) % program.cycle_s
        if program.colour(ego_link, cycle_s) == "green":
            continue
        dropped += 1
        until_s = staged.conflict_time_s + spec.signal_hold_after_s
        step_off_s = _at_kerb_s(staged) + staged.pedestrian.start_delay_s
        times = np.arange(leader.green_from_s, until_s, 0.1)
        for start_s in np.arange(0.0, program.cycle_s, 0.1):
            holds = all(program.colour(ego_link, (start_s + t) % program.cycle_s) == "green" for t in times)
            walk = program.colour(ped_link, (start_s + step_off_s) % program.cycle_s) == "green"
            assert not (holds and walk), f"seed {seed}: cycle start {start_s:.1f} s would hold the leader's"
    assert dropped == 20


#: Seeds of protocol approach-v2's right_turn episodes 12, 17, 31 and 58, whose pedestrian stepped off in
#: SUMO 1-3 steps after the planned moment, after their walk signal had ended, when the signal was held
#: only to the planned moment.
LATE_STEP_OFF_SEEDS = (3476010160, 2885966179, 3733510537, 3237545260)


@pytest.mark.slow
def test_the_pedestrian_steps_off_on_walk_though_sumo_steps_them_off_late():
    """Approach staging, ped_signal_hold "step_off": their signal shows walk from the planned step-off
    through the STEP_OFF_HOLD_S (0.5 s) after it, and at the step SUMO starts them moving from the kerb."""
    from pedsafe_sumo.sim.episode import EpisodeRunner  # the engine: only for this test

    protocol = load_protocol(REPO_ROOT / "protocols" / "approach-v2.toml")
    spec = protocol.specs()["right_turn"]
    assert spec.staging == "approach" and spec.ped_signal_hold == "step_off"
    runner = EpisodeRunner(get_site("xueqing"), protocol.params(), ReferenceStack)
    try:
        for seed in LATE_STEP_OFF_SEEDS:
            setup = runner.draw_setup(spec, seed)
            planned_s = _at_kerb_s(setup) + setup.pedestrian.start_delay_s
            colours: list[tuple[float, str, float]] = []

            def hook(api, row, colours=colours, setup=setup):
                state = api.trafficlight.getRedYellowGreenState(setup.signals.tls_id)
                colour = colour_of(state[setup.signals.ped_link_index])
                speed_mps = math.hypot(float(row["ped_vx_mps"]), float(row["ped_vy_mps"]))
                colours.append((float(row["time_s"]), colour, speed_mps))

            runner.run(spec, "sv", seed, setup=setup, on_step=hook)
            window = [(t, c) for t, c, _ in colours if planned_s - 1e-6 <= t <= planned_s + 0.5 - 1e-6]
            assert window and all(c == "green" for _, c in window), (seed, planned_s, window)
            moving = [(t, c) for t, c, v in colours if t >= planned_s - 1e-6 and v > 0.1]
            assert moving and moving[0][1] == "green", (seed, planned_s, moving[:3])
    finally:
        runner.close()
