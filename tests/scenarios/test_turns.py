"""The turning scenarios' occlusion: right_turn's leader hides the pedestrian
waiting at the far end of the crosswalk at the start under SV, with the real sensor models in real SUMO,
and without it the same world shows them; both turning scenarios run under both conditions."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.geometry import Turn, load_turn
from pedsafe_sumo.scenarios.placements.turn import turn_leader
from pedsafe_sumo.scenarios.road_users import VEHICLE_CLASSES
from pedsafe_sumo.scenarios.specs import get_scenario


def _turn(exit_start_m: float) -> Turn:
    return Turn("right", 0, ("in", "out"), ((0.0, 0.0), (100.0, 0.0)), 50.0, "c", ((0, 0), (0, 1)),
                exit_lane_id="out_1", exit_start_m=exit_start_m)  # fmt: skip


def test_leader_geometry_by_hand():
    """Front 0.5 m onto the road turned into (which begins 22 m along the path), an SUV (4.8 m): its rear
    is 22 + 0.5 - 4.8 = 17.7 m along, 2.3 m before a conflict at 20 m; it has passed the pedestrian's
    0.3 m body after (2.3 + 0.3) / 5 = 0.52 s. A leader already past them leaves no wait."""
    spec = get_scenario("right_turn")
    assert spec.occluder_class == "suv"
    leader, clear_s = turn_leader(spec, _turn(22.0), 20.0, 5.0, (1, 2, 3), 0.5)
    assert leader.lane_id == "out_1" and leader.route == ("out",) and leader.front_pos_m == 0.5
    assert leader.speed_mps == 5.0 and leader.size == VEHICLE_CLASSES["suv"]
    assert clear_s == pytest.approx(2.6 / 5.0)
    _, clear_s = turn_leader(spec, _turn(30.0), 20.0, 5.0, (1, 2, 3), 0.5)
    assert clear_s == 0.0


def test_leader_fields_are_validated():
    spec = get_scenario("right_turn")
    with pytest.raises(ScenarioError, match="turn_leader only in a turning scenario"):
        get_scenario("crossing").with_overrides({"turn_leader": "1"})
    with pytest.raises(ScenarioError, match="turn_leader_front_max_m must be at most 5"):
        spec.with_overrides({"turn_leader_front_max_m": "1e12"})
    with pytest.raises(ScenarioError, match="turn_leader is 0 or 1"):
        spec.with_overrides({"turn_leader": "0.5"})


@pytest.fixture(scope="module")
def runner():
    from pedsafe_sumo.sim.episode import EpisodeRunner

    runner = EpisodeRunner(get_site("xueqing"), load_params(), ReferenceStack)
    yield runner
    runner.close()


@pytest.mark.slow
def test_right_turn_leader_hides_the_pedestrian_at_the_start_under_sv(runner):
    """In every episode of a seed sweep: at the start the leader's body is across the pedestrian's path
    (its rear before it, on SUMO's own positions), neither onboard sensor detects the pedestrian at the
    first step, and in the same world without the leader both do."""
    spec = get_scenario("right_turn")
    turn = load_turn(get_site("xueqing"), "right")
    hidden, shown = [], []
    for seed in range(6):
        setup = runner.draw_setup(spec, seed)
        (leader,) = setup.parked
        poses = {}

        def first_step(api, row, poses=poses):
            if not poses:
                poses["leader_0"] = (api.vehicle.getPosition("leader_0"), api.vehicle.getAngle("leader_0"))

        result = runner.run(spec, "sv", seed, setup=setup, on_step=first_step)
        (fx, fy), angle = poses["leader_0"]
        heading = math.radians(90.0 - angle)  # SUMO's angle: clockwise from north
        rear = (fx - leader.size.length_m * math.cos(heading), fy - leader.size.length_m * math.sin(heading))
        # Rear and front on either side of the pedestrian's path: the body is across it.
        (ax, ay), (bx, by) = setup.pedestrian.path_xy
        side = [np.sign((bx - ax) * (py - ay) - (by - ay) * (px - ax)) for px, py in (rear, (fx, fy))]
        assert side[0] != side[1], f"seed {seed}: the leader is not across the pedestrian's path"
        assert leader.lane_id == turn.exit_lane_id
        first = result.log.iloc[0]
        hidden.append(bool(first["detected_onboard_camera"] or first["detected_onboard_lidar"]))
        bare = runner.run(spec, "sv", seed, setup=dataclasses.replace(setup, parked=())).log.iloc[0]
        shown.append(bool(bare["detected_onboard_camera"] and bare["detected_onboard_lidar"]))
    assert not any(hidden), f"detected at the start under SV in seeds {np.flatnonzero(hidden).tolist()}"
    assert all(shown), "without the leader the onboard sensors must see the pedestrian at the start"


@pytest.fixture(scope="module")
def two_phase_runner():
    from pedsafe_sumo.sim.episode import EpisodeRunner

    runner = EpisodeRunner(get_site("xueqing_two_phase"), load_params(), ReferenceStack)
    yield runner
    runner.close()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["right_turn", "left_turn"])
def test_turning_scenarios_run_under_both_conditions(runner, two_phase_runner, name):
    """Real SUMO, both conditions, same world: the episode ends normally, the ego has green at the
    conflict, and the pedestrian stepped off on the walk signal (SUMO's state at that step). left_turn on
    the two-phase plan (Xueqing's cannot stage it)."""
    spec = get_scenario(name)
    runner = two_phase_runner if name == "left_turn" else runner
    for seed in range(2):
        worlds = []
        for condition in ("sv", "v2i"):
            result = runner.run(spec, condition, seed)
            outcome, log, setup = result.outcome, result.log, result.setup
            assert outcome["end_reason"] in ("both_cleared", "collision"), outcome["end_reason"]
            assert outcome["ego_signal"] == "green"
            step = int(np.searchsorted(log["time_s"].to_numpy(), setup.pedestrian.start_delay_s))
            assert result.signal_states[step][setup.signals.ped_link_index] in "Gg"
            worlds.append((setup.ego, setup.parked, setup.pedestrian))
        assert worlds[0] == worlds[1]


def test_xueqing_lets_no_other_approach_move_while_the_ego_turns_left():
    """Why left_turn has no occluder on Xueqing (docs/engine.md): in every phase of the real program in
    which the ego's left turn is green, every vehicle movement of the other approaches is red."""
    from pedsafe_sumo.scenarios.geometry import load_approach
    from pedsafe_sumo.scenarios.signals import load_junction_signals

    site = get_site("xueqing")
    approach, turn = load_approach(site), load_turn(site, "left")
    junction = load_junction_signals(site.file("net.xml"), approach.junction_id)
    ego_link = junction.vehicle_link(approach.lane_ids[turn.lane_index], turn.route[1])
    others = [
        link
        for (lane, _), link in junction.vehicle_links.items()
        if not lane.startswith(approach.edge_id + "_")
    ]
    assert others
    green_phases = [state for state in junction.program.states if state[ego_link] in "Gg"]
    assert green_phases
    for state in green_phases:
        assert all(state[link] == "r" for link in others)


def test_left_turn_is_hosted_on_the_two_phase_plan_and_refused_on_xueqing():
    """The hosting check reads the program: on Xueqing's split phasing no phase shows green to the oncoming
    through movement (S approach, median lane) with the ego's left (N approach, median lane); on the two-phase
    plan phase 1 does, and the SE corner pole sees where the pedestrian starts."""
    from pedsafe_sumo.scenarios.hosting import site_hosting
    from pedsafe_sumo.scenarios.specs import SCENARIOS

    spec = {"left_turn": SCENARIOS["left_turn"]}
    refused = site_hosting(get_site("xueqing"), spec, load_params())["left_turn"]
    assert refused is not None and "never shows green to the oncoming through movement" in refused
    assert site_hosting(get_site("xueqing_two_phase"), spec, load_params())["left_turn"] is None


def _in_footprint(api, vehicle_id: str, length_m: float, width_m: float, xy) -> float:
    """Distance from `xy` to the vehicle's footprint (0 inside), on SUMO's front position and angle."""
    fx, fy = api.vehicle.getPosition(vehicle_id)
    heading = math.radians(90.0 - api.vehicle.getAngle(vehicle_id))
    cx, cy = fx - length_m / 2 * math.cos(heading), fy - length_m / 2 * math.sin(heading)
    dx, dy = xy[0] - cx, xy[1] - cy
    lon = dx * math.cos(heading) + dy * math.sin(heading)
    lat = -dx * math.sin(heading) + dy * math.cos(heading)
    return math.hypot(max(abs(lon) - length_m / 2, 0.0), max(abs(lat) - width_m / 2, 0.0))


@pytest.mark.slow
def test_left_turn_on_the_two_phase_plan_permissive_green_walk_and_hidden_at_the_start(two_phase_runner):
    """left_turn on networks/xueqing_two_phase, 12 SV starts: SUMO shows the ego's left a permissive green
    ('g') and the oncoming vehicle's through movement green at the first step, the pedestrian's crosswalk
    the walk signal ('G') when they step off; the oncoming vehicle's body is across the line from the ego's
    centre (the roof LiDAR) to the pedestrian; at the first step neither onboard sensor detects the
    pedestrian in most starts, while in the same worlds without the oncoming vehicle one of them does."""
    runner = two_phase_runner
    spec = get_scenario("left_turn")
    hidden, shown = [], []
    for seed in range(12):
        setup = runner.draw_setup(spec, seed)
        (oncoming,) = setup.parked
        first = {}

        def at_start(api, row, first=first, setup=setup, oncoming=oncoming):
            if first:
                return
            state = api.trafficlight.getRedYellowGreenState(setup.signals.tls_id)
            first["ego"] = state[setup.signals.ego_link_index]
            first["oncoming"] = state[setup.signals.occluder_link_index]
            # The line from the ego's centre to the pedestrian passes through the oncoming vehicle's body.
            ex, ey = row["ego_x_m"], row["ego_y_m"]
            px, py = setup.pedestrian.path_xy[0]
            samples = [(ex + k / 200 * (px - ex), ey + k / 200 * (py - ey)) for k in range(201)]
            size = oncoming.size
            first["across"] = min(
                _in_footprint(api, "oncoming_0", size.length_m, size.width_m, xy) for xy in samples
            )

        short = dataclasses.replace(setup, time_limit_s=0.1)
        row = runner.run(spec, "sv", seed, setup=short, on_step=at_start).log.iloc[0]
        assert first["ego"] == "g" and first["oncoming"] in "Gg", (seed, first)
        assert first["across"] == 0.0, f"seed {seed}: the oncoming vehicle is not across the line of sight"
        hidden.append(not (row["detected_onboard_camera"] or row["detected_onboard_lidar"]))
        bare = runner.run(spec, "sv", seed, setup=dataclasses.replace(short, parked=())).log.iloc[0]
        shown.append(bool(bare["detected_onboard_camera"] or bare["detected_onboard_lidar"]))
        ped = cycle_state_at(setup, setup.pedestrian.start_delay_s)[setup.signals.ped_link_index]
        assert ped == "G", f"seed {seed}: the pedestrian steps off on {ped!r}"
    assert sum(hidden) > len(hidden) / 2, f"hidden at the start in {sum(hidden)} of {len(hidden)}"
    assert all(shown), "without the oncoming vehicle an onboard sensor must see the pedestrian at the start"


def cycle_state_at(setup, time_s: float) -> str:
    """The program's state `time_s` after the episode's start, walked from the net file's phases."""
    from pedsafe_sumo.scenarios.signals import load_junction_signals

    site = get_site("xueqing_two_phase")
    program = load_junction_signals(site.file("net.xml"), setup.signals.tls_id).program
    index, _ = program.phase_at(setup.signals.cycle_start_s + time_s)
    return program.states[index]
