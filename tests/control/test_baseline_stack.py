"""The baseline stack on hand-built observations with answers worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.control.agent import (
    Crosswalk,
    EgoState,
    LaneCentreline,
    Observation,
    PerceivedPedestrian,
    RoadMap,
    RouteAhead,
    TrafficLightState,
    load_agent_class,
)
from pedsafe_sumo.control.baseline import BaselineStack
from pedsafe_sumo.control.baseline_planner import PathArrays, SignalPolicy, path_threat, straight_path
from pedsafe_sumo.control.kalman_tracker import Track
from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.control.stack_names import resolve_stack_name
from pedsafe_sumo.control.stack_source import is_shipped

STEP_S = 0.05
EGO = EgoState(x_m=0.0, y_m=0.0, yaw_rad=0.0, speed_mps=10.0, length_m=4.5, width_m=1.8)


def stack(cls=BaselineStack, speed=10.0):
    agent = cls()
    agent.setup({"initial_speed_mps": speed})
    return agent


def ego(speed=10.0, x=0.0):
    return EgoState(x, 0.0, 0.0, speed, EGO.length_m, EGO.width_m)


def run(agent, observations):
    return [agent.run_step(o, k * STEP_S) for k, o in enumerate(observations)]


def test_a_standing_person_beside_the_road_under_v2i_noise_is_no_reason_to_brake():
    # A person standing 3.2 m to the right of the ego's heading line (the next lane's centre), 30 m
    # ahead, seen only over V2I with 0.2 m noise, 200 steps; the ego's corridor is 0.9 + 0.5 = 1.4 m.
    rng = np.random.default_rng(11)
    positions = [(30.0 + nx, -3.2 + ny) for nx, ny in rng.normal(0.0, 0.2, size=(200, 2))]
    observations = [
        Observation(ego(), (PerceivedPedestrian("p", x, y, "v2i"),), STEP_S) for x, y in positions
    ]
    commands = run(stack(), observations)
    assert not any(c.info["braking"] for c in commands)
    assert all(c.target_speed_mps >= 10.0 - 1e-9 for c in commands)
    # The paper-v7 stack's least-squares velocity over 0.5 s sees the noise as motion and brakes.
    assert any(c.info["braking"] for c in run(stack(ReferenceStack), observations))


def track(x, y, vx=0.0, vy=0.0, sigma_v=0.05):
    cov = np.diag([0.01, 0.01, sigma_v**2, sigma_v**2])
    return Track("p", x, y, vx, vy, cov, 0.0)


def threat_of(t, speed=10.0):
    path = PathArrays.of(straight_path(ego(speed)))
    s, first = path.ego_position_m(ego(speed))
    return path_threat(t, ego(speed), path, first, s, 4.0, 1.4, 1.0, 0.1)


def test_standing_in_the_corridor_is_a_threat_outside_it_is_not():
    # Gap from the ego's front (2.25 m ahead of its centre) to the pedestrian: 30 - 2.25.
    inside = threat_of(track(30.0, 1.0))
    assert inside.gap_m == pytest.approx(27.75, abs=1e-6) and inside.time_s == 0.0
    assert threat_of(track(30.0, 1.6)) is None  # 1.6 > 1.4: outside, and standing


def test_a_crossing_walker_is_a_threat_when_predicted_into_the_corridor():
    # 5 m to the right walking left at 1.5 m/s: the corridor's edge (1.4 m) is reached after
    # (5 - 1.4) / 1.5 = 2.4 s, widened by one sigma of the predicted position (0.05 m/s x 2.4 s + ~0.1 m)
    # a little earlier; at 5 m/s the ego's front is at 2.25 + 12 = 14.25 m < 20 m then.
    found = threat_of(track(20.0, -5.0, vy=1.5), speed=5.0)
    assert found is not None and 2.1 <= found.time_s <= 2.4
    # Walking away from the path: no threat.
    assert threat_of(track(20.0, -5.0, vy=-1.5), speed=5.0) is None


# A straight lane east along y = 0 from x = 0 to 100; a crosswalk across it at x 40..44, y -8..8.
LANE = LaneCentreline("e_0", "e", 0, 3.2, 13.9, ((0.0, 0.0), (100.0, 0.0)), True)
ROUTE = RouteAhead(("e",), (LANE,), "e_0", 2.25)
CROSSWALK = Crosswalk(":J_c0", ((40.0, -8.0), (44.0, -8.0), (44.0, 8.0), (40.0, 8.0)), "J")
ROAD_MAP = RoadMap((CROSSWALK,), ())


def light(state, distance_m=35.0, at_s=0.0):
    return TrafficLightState("J", 0, state, distance_m, math.nan, "onboard_camera", at_s)


def at_crosswalk(agent, ped_xy, state, steps=12, speed=8.0):
    observations = [
        Observation(
            ego(speed, x=5.0),  # the crosswalk 31.5 m ahead of its front: within 4 s at 8 m/s
            (PerceivedPedestrian("p", *ped_xy, "onboard_camera"),),
            STEP_S,
            route=ROUTE,
            road_map=ROAD_MAP,
            traffic_light=light(state),
        )
        for _ in range(steps)
    ]
    return run(agent, observations)


@pytest.mark.parametrize(
    ("ped_xy", "state", "yields"),
    [
        ((42.0, -6.0), "g", True),  # on the crosswalk, 4.6 m beside the corridor, walk: yield
        ((42.0, -9.0), "g", True),  # at its kerb, 1 m off the polygon, walk: yield
        ((42.0, -9.0), "G", False),  # at its kerb, the ego has priority (no walk): no threat
        ((42.0, -6.0), "G", False),  # standing on it against the signal, outside the corridor
        ((42.0, -12.0), "g", False),  # 4 m from the polygon: not at the kerb
    ],
)
def test_yielding_at_a_crosswalk_the_path_crosses(ped_xy, state, yields):
    commands = at_crosswalk(stack(speed=8.0), ped_xy, state)
    # Braking starts once the reaction time (0.4 s: step 8) has run.
    assert commands[-1].info["braking"] is yields
    if yields:
        # Stopping short of where the corridor meets the crosswalk: the path's centre within 1.4 m of
        # the polygon from x = 38.6 (sampled every 0.25 m: 38.75), less the front at 5 + 2.25 m.
        assert commands[-1].info["threat_gap_m"] == pytest.approx(38.75 - 7.25, abs=1e-6)


def test_a_pedestrian_across_the_corridor_is_no_longer_yielded_to():
    agent = stack(speed=8.0)
    assert at_crosswalk(agent, (42.0, -6.0), "g", steps=12)[-1].info["braking"]
    # Now on the other side of the path, standing at the far kerb: crossed, no threat (after the
    # 0.5 s the last threat is held, the ego accelerates again).
    later = [
        agent.run_step(
            Observation(ego(8.0, x=5.0), (PerceivedPedestrian("p", 42.0, 9.0, "onboard_camera"),), STEP_S,
                        route=ROUTE, road_map=ROAD_MAP, traffic_light=light("g")),
            (12 + k) * STEP_S,
        )
        for k in range(15)
    ]  # fmt: skip
    assert not later[-1].info["braking"] and later[-1].target_speed_mps >= 8.0


@pytest.mark.parametrize(
    ("speed", "distance", "decision"),
    [
        # v^2 / (2 x 3.0): 10 m/s -> 16.67 m, 15 m/s -> 37.5 m, 5 m/s -> 4.17 m
        (10.0, 20.0, "stop"),
        (10.0, 16.0, "go"),
        (15.0, 40.0, "stop"),
        (15.0, 35.0, "go"),
        (5.0, 5.0, "stop"),
        (5.0, 4.0, "go"),
    ],
)
def test_yellow_onset_stops_when_the_comfortable_stop_fits(speed, distance, decision):
    demand = SignalPolicy(3.0, 6.0, 1.0).demand(light("y", distance), speed, 0.0)
    assert demand.reason == ("yellow_stop" if decision == "stop" else "yellow_go")
    # Stopping: the speed allowed is sqrt(2 a room), room the distance less 1 m.
    if decision == "stop":
        assert demand.speed_cap_mps == pytest.approx(math.sqrt(6.0 * (distance - 1.0)))
    else:
        assert demand.speed_cap_mps == math.inf


def test_yellow_decision_uses_where_and_how_fast_the_ego_was_when_the_state_was_sent():
    # V2I: the state arriving at t = 1.0 was measured at 0.9. The ego sped up 9 -> 9.5 -> 10 m/s and is
    # 14.5 m from the line now; at 0.9 it was 9.5 x 0.05 + 10 x 0.05 = 0.975 m further back (15.475 m)
    # at 9 m/s: 81 / 6 = 13.5 m <= 15.475 m: stop. Its current speed at its current distance would
    # have said go (100 / 6 = 16.67 m > 14.5 m).
    policy = SignalPolicy(3.0, 6.0, 1.0)
    policy.demand(light("G", 15.475, at_s=0.8), 9.0, 0.9)
    policy.demand(light("G", 15.0, at_s=0.85), 9.5, 0.95)
    assert policy.demand(light("y", 14.5, at_s=0.9), 10.0, 1.0).reason == "yellow_stop"
    assert SignalPolicy(3.0, 6.0, 1.0).demand(light("y", 14.5, at_s=1.0), 10.0, 1.0).reason == "yellow_go"


def test_the_stack_stops_before_the_line_at_red_and_goes_on_green():
    agent = stack(speed=10.0)
    x, speed, t = 0.0, 10.0, 0.0
    line_x = 40.0  # the stop line; the ego's front is at x + 2.25
    while t < 12.0:
        obs = Observation(ego(speed, x), (), STEP_S, traffic_light=light("r", line_x - (x + 2.25), t))
        speed = agent.run_step(obs, t).target_speed_mps
        x += speed * STEP_S
        t += STEP_S
    assert speed == pytest.approx(0.0, abs=0.05)
    assert line_x - 1.5 <= x + 2.25 <= line_x  # stopped within the last 1.5 m before the line
    obs = Observation(ego(speed, x), (), STEP_S, traffic_light=light("G", line_x - (x + 2.25), t))
    assert agent.run_step(obs, t).target_speed_mps > speed


def test_red_is_run_only_when_not_even_the_hardest_braking_stops_in_time():
    # 15 m/s at 10 m: 225 / 12 = 18.75 m at 6 m/s2 > 10 m.
    assert SignalPolicy(3.0, 6.0, 1.0).demand(light("r", 10.0), 15.0, 0.0).reason == "committed"
    assert SignalPolicy(3.0, 6.0, 1.0).demand(light("r", 20.0), 15.0, 0.0).reason == "red"


def test_shipped_stacks_load_by_short_name():
    assert load_agent_class("reference") is BaselineStack
    assert load_agent_class("paper-v7") is ReferenceStack
    assert load_agent_class("pedsafe_sumo.control.reference:ReferenceStack") is ReferenceStack
    assert resolve_stack_name("reference+x.y:Z") == "pedsafe_sumo.control.baseline:BaselineStack+x.y:Z"
    assert is_shipped("reference") and is_shipped("paper-v7") and not is_shipped("mypkg.stack:S")
    assert set(BaselineStack().sensors()) >= {"route", "road_map", "traffic_light", "v2i"}


def test_crosswalk_spans_are_worked_out_by_hand_and_kept_per_path_map_and_width():
    from pedsafe_sumo.control import baseline_planner

    # The ego at the origin heading +x: its straight path, which starts _STRAIGHT_REACH_M behind it; a 4 m
    # wide crosswalk across it from x = 20 to x = 24. With a half width of 1.4 m the corridor meets it from
    # x = 18.6 m to x = 25.4 m, the path sampled every _PATH_SAMPLE_M.
    path = PathArrays.of(straight_path(ego()))
    back = baseline_planner._STRAIGHT_REACH_M
    crosswalk = Crosswalk("c", ((20.0, -8.0), (24.0, -8.0), (24.0, 8.0), (20.0, 8.0)), "")
    road_map = RoadMap((crosswalk,), ())
    step = baseline_planner._PATH_SAMPLE_M
    (span,) = baseline_planner.crosswalk_spans(path, road_map, 1.4)
    assert span.enter_m == pytest.approx(math.ceil((back + 20.0 - 1.4) / step - 1e-9) * step)
    assert span.leave_m == pytest.approx(math.floor((back + 24.0 + 1.4) / step + 1e-9) * step)
    # asked again: the same spans, from the cache, in a list of its own
    again = baseline_planner.crosswalk_spans(path, road_map, 1.4)
    assert again == [span] and again is not baseline_planner.crosswalk_spans(path, road_map, 1.4)
    # another width, or another map, is worked out again
    (wide,) = baseline_planner.crosswalk_spans(path, road_map, 3.0)
    assert wide.enter_m == pytest.approx(math.ceil((back + 20.0 - 3.0) / step - 1e-9) * step)
    moved = RoadMap((Crosswalk("c", ((40.0, -8.0), (44.0, -8.0), (44.0, 8.0), (40.0, 8.0)), ""),), ())
    (far,) = baseline_planner.crosswalk_spans(path, moved, 1.4)
    assert far.enter_m == pytest.approx(math.ceil((back + 40.0 - 1.4) / step - 1e-9) * step)
