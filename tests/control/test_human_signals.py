"""The careful human driver at signals and crosswalks, on hand-built observations with answers worked
out by hand: ITE's yellow rule with a 1.0 s perception-reaction time and 3.0 m/s^2, the red stop, the
start on green, yielding in a turn to a pedestrian on the crosswalk."""

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
)
from pedsafe_sumo.control.human import HumanDriverStack

DT = 0.05
LENGTH, WIDTH = 4.6, 1.8
#: ITE yellow change interval: perception-reaction 1.0 s, deceleration 10 ft/s^2 rounded down to 3.0
T_PR, A_COMF = 1.0, 3.0
#: UN R157 careful driver's hardest braking, 0.774 g
A_MAX = 0.774 * 9.80665


def driver(speed: float, seed: int = 7) -> HumanDriverStack:
    agent = HumanDriverStack()
    agent.setup({"initial_speed_mps": speed, "seed": seed})
    return agent


def drawn_reaction_time(seed: int) -> float:
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x68756D,)))
    return float(rng.lognormal(mean=math.log(0.9), sigma=math.log(1.2 / 0.9) / 0.6744897501960817))


def drive_to_signal(speed, line_m, states, end_s, latency_steps=0):
    """The ego's front starts `line_m` before a stop line on the x axis at `speed`. `states(t)` is the
    signal shown at time t. The feed gives it as SUMO's does: the state and the distance to the line
    while the front is before it, nothing once past. With `latency_steps` it arrives as over V2I: the
    state measured that many steps earlier, the distance now. The ego moves by the commanded speed.
    Returns (time, speed, front position, command) per step."""
    agent = driver(speed)
    front, rows = 0.0, []
    for k in range(int(round(end_s / DT))):
        t = k * DT
        light = None
        if front <= line_m:
            at = max(k - latency_steps, 0) * DT
            source = "v2i" if latency_steps and k >= latency_steps else "onboard_camera"
            at = at if source == "v2i" else t
            light = TrafficLightState("J", 0, states(at), line_m - front, math.nan, source, at)
        ego = EgoState(front - LENGTH / 2, 0.0, 0.0, speed, LENGTH, WIDTH)
        command = agent.run_step(Observation(ego, (), DT, traffic_light=light), t)
        rows.append((t, speed, front, command))
        speed = command.target_speed_mps
        front += speed * DT
    return rows


@pytest.mark.parametrize(
    ("speed", "distance", "decision"),
    [
        # v t + v^2 / (2 a) at t = 1.0 s, a = 3.0: 10 m/s -> 10 + 16.67 = 26.67 m; 15 m/s -> 15 + 37.5 =
        # 52.5 m; 5 m/s -> 5 + 4.17 = 9.17 m
        (10.0, 28.0, "stop"),
        (10.0, 25.0, "go"),
        (15.0, 55.0, "stop"),
        (15.0, 50.0, "go"),
        (5.0, 10.0, "stop"),
        (5.0, 9.0, "go"),
    ],
)
def test_yellow_onset_stops_when_the_comfortable_stop_after_the_reaction_fits(speed, distance, decision):
    rows = drive_to_signal(speed, distance, lambda t: "y" if t < 4.0 else "r", end_s=12.0)
    # The first second after the onset: the driver holds its speed (the state is being perceived).
    assert all(v == pytest.approx(speed) for t, v, _, _ in rows if t <= T_PR + 1e-9)
    if decision == "stop":
        final_speed, final_front = rows[-1][1], rows[-1][2]
        assert final_speed == pytest.approx(0.0, abs=1e-9)
        assert distance - 1.5 <= final_front <= distance  # stopped in the last 1.5 m before the line
        # the first braking step is the one at 1.0 s (or later, when the profile allows)
        first_brake = min(t for t, v, _, c in rows if c.target_speed_mps < v - 1e-9)
        assert first_brake >= T_PR - 1e-9
    else:
        # through at the same speed, past the line
        assert all(c.target_speed_mps == pytest.approx(speed) for _, _, _, c in rows)
        assert rows[-1][2] > distance


def test_red_stop_after_the_reaction_and_start_a_second_after_green():
    # Red from 60 m at 10 m/s: 10 x 1.0 + 100 / (2 x 7.59) = 16.6 m <= 60 m: stop. The comfortable
    # profile sqrt(6 (d - 1)) falls below 10 m/s at d - 1 = 16.67 m, so braking starts near 17.7 m.
    rows = drive_to_signal(10.0, 60.0, lambda t: "r" if t < 12.0 else "G", end_s=14.0)
    stopped = [r for r in rows if r[0] < 12.0 and r[1] == 0.0]
    assert stopped, "it stops at the red"
    assert 58.5 <= stopped[0][2] <= 60.0
    first_brake = min(t for t, v, _, c in rows if c.target_speed_mps < v - 1e-9)
    # the front is 60 - 17.67 = 42.3 m on at about 4.2 s at 10 m/s
    assert 4.0 <= first_brake <= 4.4
    # green at 12.0 s: stands until 13.0 s, then moves
    after = [(t, c.target_speed_mps) for t, _, _, c in rows if t >= 12.0]
    assert all(v == 0.0 for t, v in after if t < 13.0 - 1e-9)
    assert any(v > 0.0 for t, v in after if t >= 13.0 - 1e-9)


def test_a_red_too_close_to_stop_after_the_reaction_is_gone_through():
    # 15 m/s, red at 20 m: 15 x 1.0 + 225 / (2 x 7.59) = 29.8 m > 20 m: through.
    rows = drive_to_signal(15.0, 20.0, lambda t: "r", end_s=3.0)
    assert all(c.target_speed_mps == pytest.approx(15.0) for _, _, _, c in rows)
    assert rows[-1][2] > 20.0
    # acted on from 1.0 s (the red read at 0) until the front passes the line at 20 / 15 = 1.33 s
    committed = [t for t, _, _, c in rows if c.info.get("signal") == "committed"]
    assert committed and min(committed) == pytest.approx(T_PR) and max(committed) < 20.0 / 15.0


def test_the_signal_out_of_sight_is_not_obeyed_over_v2i():
    # V2I delivers the state from any distance; the driver reads a head only within 80 m. A red
    # 120 m ahead at 10 m/s: no reaction before the front is within 80 m (after 4.0 s).
    rows = drive_to_signal(10.0, 120.0, lambda t: "r", end_s=5.0, latency_steps=2)
    assert all(c.target_speed_mps == pytest.approx(10.0) for _, _, _, c in rows)


@pytest.mark.parametrize(("speed", "distance"), [(10.0, 28.0), (10.0, 25.0), (15.0, 55.0), (8.0, 60.0)])
def test_same_driver_under_sv_and_v2i(speed, distance):
    # The V2I state is 0.1 s late; the driver acts on each state 1.0 s after it was shown, with where
    # the ego was when it was measured: the same commands as reading it with its own eyes.
    def states(t):
        return "G" if t < 0.5 else ("y" if t < 3.5 else ("r" if t < 9.0 else "G"))

    sv = drive_to_signal(speed, distance, states, end_s=12.0)
    v2i = drive_to_signal(speed, distance, states, end_s=12.0, latency_steps=2)
    assert [r[3].target_speed_mps for r in sv] == [r[3].target_speed_mps for r in v2i]


# A right turn: east along e (y = 0) to x = 30, the internal lane to (35, -5), then south along f
# (x = 35). The crosswalk over f spans x 31..39, y -12..-8.
E_LANE = LaneCentreline("e_0", "e", 0, 3.2, 13.9, ((0.0, 0.0), (30.0, 0.0)), True)
TURN_LANE = LaneCentreline(":J_0_0", ":J_0", 0, 3.2, 13.9, ((30.0, 0.0), (35.0, -5.0)), True)
F_LANE = LaneCentreline("f_0", "f", 0, 3.2, 13.9, ((35.0, -5.0), (35.0, -60.0)), True)
ROUTE = RouteAhead(("e", "f"), (E_LANE, TURN_LANE, F_LANE), "e_0", 7.3)
CROSSWALK = Crosswalk(":J_c0", ((31.0, -12.0), (39.0, -12.0), (39.0, -8.0), (31.0, -8.0)), "J")
ROAD_MAP = RoadMap((CROSSWALK,), ())
#: Where the corridor (half width 0.9 + 0.5 m) meets the crosswalk: along f, the path's centre is
#: within 1.4 m of the polygon's edge y = -8 from y = -6.6, 1.6 m past f's start, which is 30 +
#: 5 sqrt(2) = 37.0711 m along the path: 38.6711 m, sampled every 0.25 m: 38.75 m. The ego's centre at
#: x = 5 (front at 7.3 m): the gap is 38.75 - 7.3 = 31.45 m.
GAP_M = 38.75 - 7.3


#: The driver has had its signal in sight for this long before the pedestrian appears [steps]: 1.2 s,
#: longer than the 1.0 s it takes to act on a state read.
LEAD = 24


def turning(agent, peds_xy, state, steps, speed=8.0):
    """The ego at x = 5 on e (its turn ahead) at `speed`, its signal showing `state`; after LEAD steps
    the pedestrian where peds_xy[k] puts them (k counted from their appearance). Returns the commands
    from the pedestrian's appearance on."""
    commands = []
    for k in range(-LEAD, steps):
        peds = (PerceivedPedestrian("p", *peds_xy(k), "onboard_camera"),) if k >= 0 else ()
        t = (k + LEAD) * DT
        light = TrafficLightState("J", 0, state, 30.0 - 7.3, math.nan, "onboard_camera", t)
        ego = EgoState(5.0, 0.0, 0.0, speed, LENGTH, WIDTH)
        obs = Observation(ego, peds, DT, route=ROUTE, road_map=ROAD_MAP, traffic_light=light)
        command = agent.run_step(obs, t)
        if k >= 0:
            commands.append(command)
    return commands


@pytest.mark.parametrize(
    ("ped_xy", "state", "yields"),
    [
        ((38.0, -10.0), "g", True),  # on the crosswalk, 3 m beside the corridor, standing: yield
        ((38.0, -10.0), "G", True),  # on it whatever the signal: a pedestrian passing on the crosswalk
        ((38.0, -13.0), "g", True),  # at its kerb (1 m off), the crosswalk may show walk: yield
        ((38.0, -13.0), "G", False),  # at its kerb, the turn is protected (no walk): no threat
        ((38.0, -16.0), "g", False),  # 4 m from the polygon: not at the kerb
    ],
)
def test_turning_the_driver_yields_to_a_pedestrian_on_the_crosswalk(ped_xy, state, yields):
    seed = 7
    reaction = drawn_reaction_time(seed)
    steps = int(math.ceil(reaction / DT)) + 3
    commands = turning(driver(8.0, seed), lambda k: ped_xy, state, steps)
    braking = [c.info.get("brake_for") == "pedestrian" for c in commands]
    assert braking[-1] is yields
    if yields:
        # after the drawn reaction time, not before, and short of the crosswalk
        first = braking.index(True)
        assert first * DT >= reaction - 1e-9 and (first - 1) * DT < reaction
        assert commands[-1].info["threat_gap_m"] == pytest.approx(GAP_M, abs=1e-6)


def test_a_pedestrian_across_the_corridor_is_no_longer_yielded_to():
    # First seen east of the path on the crosswalk (x = 38), then west of it beyond the corridor
    # (x = 33.2: 1.8 m from the centre x = 35 > 1.4 m): across, no threat; 0.5 s later the driver
    # speeds up again.
    agent = driver(8.0, seed=7)
    reaction = drawn_reaction_time(7)
    n = int(math.ceil(reaction / DT)) + 3
    commands = turning(agent, lambda k: (38.0, -10.0) if k < n else (33.2, -10.0), "g", n + 20)
    assert commands[n - 1].info.get("brake_for") == "pedestrian"
    assert "brake_for" not in commands[-1].info and commands[-1].target_speed_mps >= 8.0
