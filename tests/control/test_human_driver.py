"""The careful human driver: a pedestrian appears in its path; braking starts after the drawn reaction
time and follows the published jerk-limited ramp."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.control.agent import Command, EgoState, Observation, PerceivedPedestrian, load_agent_class
from pedsafe_sumo.control.human import HumanDriverStack

DT = 0.05
SPEED = 14.0  # m/s, about 50 km/h
#: Johansson & Rumar 1971: median 0.9 s, 75th percentile 1.2 s; z(0.75) = 0.6744897501960817
MU, SIGMA = math.log(0.9), math.log(1.2 / 0.9) / 0.6744897501960817
#: UN R157 careful driver: 0.774 g in 0.6 s
A_MAX = 0.774 * 9.80665  # 7.590347 m/s^2
JERK = A_MAX / 0.6  # 12.650578 m/s^3


def drawn_reaction_time(seed: int) -> float:
    """The reaction time computed here, with numpy, from the seed and the documented stream key."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x68756D,)))
    return float(rng.lognormal(mean=MU, sigma=SIGMA))


def make_driver(seed: int, speed: float = SPEED) -> HumanDriverStack:
    driver = HumanDriverStack()
    # the [algorithm] section gives every stack the reference stack's keys: the driver must ignore them
    driver.setup({"initial_speed_mps": speed, "seed": seed, "reaction_time_s": 0.4, "max_decel_mps2": 6.0})
    return driver


def drive(driver, appear_s: float, distance_m: float, source: str = "onboard_camera", end_s: float = 4.0):
    """Ego on the x axis at SPEED; a pedestrian stands in its path `distance_m` ahead of the ego's
    centre from `appear_s` on. The ego moves by the commanded speed each step (the engine's rule)."""
    x, speed, steps = 0.0, SPEED, []
    ped_x = None
    for k in range(int(round(end_s / DT))):
        t = k * DT
        if t >= appear_s - 1e-9 and ped_x is None:
            ped_x = x + distance_m
        peds = () if ped_x is None else (PerceivedPedestrian("p", ped_x, 0.0, source),)
        ego = EgoState(x, 0.0, 0.0, speed, 4.5, 1.8)
        command = driver.run_step(Observation(ego, peds, DT), t)
        steps.append((t, speed, command))
        x += command.target_speed_mps * DT
        speed = command.target_speed_mps
    return steps


@pytest.mark.parametrize("seed", [3, 11, 2026])
def test_braking_starts_after_the_drawn_reaction_time(seed):
    reaction = drawn_reaction_time(seed)
    driver = make_driver(seed)
    assert driver.reaction_time_s == pytest.approx(reaction, abs=1e-12)
    appear = 1.0
    steps = drive(driver, appear, distance_m=80.0)
    braking = [t for t, _, c in steps if c.info.get("braking")]
    # the first step at or after appear + reaction (0.05 s steps)
    first_expected = appear + math.ceil(reaction / DT - 1e-9) * DT
    assert braking and braking[0] == pytest.approx(first_expected, abs=1e-9)
    # before it: cruise, then hold the speed while reacting (no braking, no speeding up)
    for t, _speed, command in steps:
        if t < braking[0] - 1e-9:
            assert command.target_speed_mps == pytest.approx(SPEED)


def test_deceleration_follows_the_jerk_limited_ramp():
    seed = 7
    reaction = drawn_reaction_time(seed)
    onset = 0.5 + math.ceil(reaction / DT - 1e-9) * DT
    # The pedestrian stands so close that, at the onset, stopping 2 m short needs more than 0.774 g:
    # at the onset the gap (front to pedestrian) is 9 m: 14^2 / (2 * (9 - 2)) = 14 m/s^2 > 7.59.
    # The ego covers SPEED * (onset - 0.5) before the onset; its front is 2.25 m ahead of its centre.
    distance = SPEED * (onset - 0.5) + 2.25 + 9.0
    steps = drive(make_driver(seed), 0.5, distance_m=distance, end_s=onset + 1.2)
    decels = [c.info["decel_mps2"] for t, _, c in steps if c.info.get("braking")]
    # step i of braking (i = 0, 1, ...): min(a_max, jerk * dt * (i + 1)): 0.632529, 1.265058, ...,
    # a_max = 7.590347 from step 11 on (12 steps of 0.05 s = the 0.6 s ramp)
    expected = [min(A_MAX, JERK * DT * (i + 1)) for i in range(len(decels))]
    assert len(decels) >= 15
    assert decels[:15] == pytest.approx(expected[:15], abs=1e-9)
    assert decels[0] == pytest.approx(0.632529, abs=1e-6) and decels[12] == pytest.approx(7.590347, abs=1e-6)
    # and the speed drops by the deceleration times the step
    speeds = [(s, c.target_speed_mps) for t, s, c in steps if c.info.get("braking")]
    for (before, after), decel in zip(speeds, decels):
        assert after == pytest.approx(max(0.0, before - decel * DT), abs=1e-12)


def test_it_sees_with_its_eyes_only():
    driver = make_driver(5)
    # the camera is its only detection source; the world feeds: route, crosswalks, the signal ahead
    assert driver.sensors() == ["onboard_camera", "route", "road_map", "traffic_light"]
    # a pedestrian reported by V2I or LiDAR only is not in the driver's world
    for source in ("v2i", "onboard_lidar"):
        steps = drive(make_driver(5), 0.5, distance_m=30.0, source=source, end_s=3.0)
        assert not any(c.info.get("braking") or c.info.get("reacting") for _, _, c in steps)


def test_the_reaction_times_have_the_published_quantiles():
    # 4000 drivers: median 0.9 s and 75th percentile 1.2 s within sampling error
    # (standard error of a lognormal's median here about 0.9 * 0.4265 * 1.2533 / sqrt(4000) = 0.0076 s)
    draws = np.array([make_driver(seed).reaction_time_s for seed in range(4000)])
    assert np.median(draws) == pytest.approx(0.9, abs=0.03)
    assert np.quantile(draws, 0.75) == pytest.approx(1.2, abs=0.05)


def test_same_seed_same_driver_other_seed_other_driver():
    assert make_driver(42).reaction_time_s == make_driver(42).reaction_time_s
    assert make_driver(42).reaction_time_s != make_driver(43).reaction_time_s


def test_loadable_by_its_spec():
    cls = load_agent_class("pedsafe_sumo.control.human:HumanDriverStack")
    assert cls is HumanDriverStack
    assert isinstance(make_driver(1).run_step(Observation(EgoState(0, 0, 0, 5.0, 4.5, 1.8)), 0.0), Command)


def _walk_then_hide(driver, hide_s: float, end_s: float, lateral_m: float = -6.0):
    """Ego on the x axis at SPEED; a pedestrian 60 m ahead walks towards its path (from y = lateral_m,
    1.4 m/s along +y), seen until `hide_s`, then out of sight. Returns (t, command) per step."""
    x, speed, steps = 0.0, SPEED, []
    ped_x, ped_y0 = 60.0, lateral_m
    for k in range(int(round(end_s / DT))):
        t = k * DT
        peds = (PerceivedPedestrian("p", ped_x, ped_y0 + 1.4 * t, "onboard_camera"),) if t < hide_s else ()
        command = driver.run_step(Observation(EgoState(x, 0.0, 0.0, speed, 4.5, 1.8), peds, DT), t)
        steps.append((t, command))
        x += command.target_speed_mps * DT
        speed = command.target_speed_mps
    return steps


def test_a_pedestrian_who_goes_out_of_sight_is_kept_in_mind_and_braked_for():
    # Seen for 0.2 s walking at 1.4 m/s from 6 m beside the lane: at 0.15 s they are 5.8 m from the lane
    # centre, 4.4 m from the corridor's edge (0.9 m half width + 0.5 m margin = 1.4 m): 3.1 s away at
    # 1.4 m/s, inside the 4 s horizon; the ego (front 57.75 m away at 14 m/s, 4.1 s) has not passed by
    # then: a threat from 0.05 s (the second position gives the velocity). Hidden from 0.2 s on, the
    # driver still brakes once the reaction time has run (seed 3: 0.85 s), though nobody is in sight.
    # Without the memory the threat would clear 0.5 s after 0.15 s, before the reaction completes.
    seed = 3
    reaction = drawn_reaction_time(seed)
    assert 0.15 + 0.5 < DT + reaction
    steps = _walk_then_hide(make_driver(seed), hide_s=0.2, end_s=2.5)
    braking = [t for t, c in steps if c.info.get("braking")]
    assert braking and braking[0] == pytest.approx(DT + math.ceil(reaction / DT - 1e-9) * DT, abs=1e-9)


def test_a_pedestrian_out_of_sight_for_longer_than_the_memory_is_forgotten():
    driver = make_driver(3)
    driver.memory_s = 0.2
    # hidden after 0.1 s: the threat (noticed at 0.05 s) is forgotten at 0.05 + 0.2 s, cleared 0.5 s
    # later (0.75 s); the reaction (0.85 s) never completes: the driver never brakes
    steps = _walk_then_hide(driver, hide_s=0.1, end_s=2.5)
    assert not [t for t, c in steps if c.info.get("braking")]
