"""The careful human driver's braking against the stopping distance of UN Regulation No. 157's
competent and careful human driver (Annex 4, Appendix 3), worked by hand at 50 km/h."""

from __future__ import annotations

import pytest

from pedsafe_sumo.control.agent import EgoState, Observation, PerceivedPedestrian
from pedsafe_sumo.control.human import HumanDriverStack

DT = 0.05
V0 = 50 / 3.6  # 13.888889 m/s
G = 9.80665
A_MAX = 0.774 * G  # 7.590347 m/s^2
RAMP_S = 0.6
JERK = A_MAX / RAMP_S  # 12.650578 m/s^3
#: R157's careful driver starts braking 0.4 s (risk perception) + 0.75 s (brake reaction) after the risk.
R157_DELAY_S = 0.4 + 0.75

# By hand, from brake onset (continuous time):
#   during the ramp (0.6 s): V0 * 0.6 - JERK * 0.6^3 / 6 = 8.333333 - 0.455421 = 7.877913 m,
#   speed at its end: V0 - A_MAX * 0.6 / 2 = 13.888889 - 2.277104 = 11.611785 m/s,
#   then at A_MAX: 11.611785^2 / (2 * 7.590347) = 134.833545 / 15.180694 = 8.881909 m;
#   braking distance 7.877913 + 8.881909 = 16.759822 m.
# Before braking: V0 * 1.15 = 15.972222 m. Stopping distance from the risk: 32.732044 m.
BRAKING_DISTANCE_M = 16.759822
STOPPING_DISTANCE_M = 32.732044
#: The loop moves the ego by the commanded (end-of-step) speed, so its discrete distance trails the
#: continuous one by less than one step's travel at the initial speed.
STEP_TRAVEL_M = V0 * DT  # 0.694 m


def test_the_hand_worked_figures_are_consistent():
    ramp_m = V0 * RAMP_S - JERK * RAMP_S**3 / 6
    v_end = V0 - A_MAX * RAMP_S / 2
    assert ramp_m == pytest.approx(7.877913, abs=1e-6)
    assert v_end == pytest.approx(11.611785, abs=1e-6)
    assert ramp_m + v_end**2 / (2 * A_MAX) == pytest.approx(BRAKING_DISTANCE_M, abs=1e-6)
    assert V0 * R157_DELAY_S + BRAKING_DISTANCE_M == pytest.approx(STOPPING_DISTANCE_M, abs=1e-6)


def test_stopping_distance_at_50_kmh_with_the_r157_delay():
    driver = HumanDriverStack()
    driver.setup({"initial_speed_mps": V0, "seed": 1})
    driver.reaction_time_s = R157_DELAY_S  # R157's fixed delay instead of the drawn one
    appear_s = 0.5
    # A pedestrian standing in the path, 17.5 m ahead of the front when braking starts (the front is
    # 2.25 m ahead of the centre); a stop margin equal to that gap leaves no room, so the driver asks
    # for the most the ramp gives throughout.
    ped_x = V0 * (appear_s + R157_DELAY_S) + 2.25 + 17.5
    driver.stop_margin_m = 17.5
    x, speed = 0.0, V0
    x_appear = x_onset = None
    for k in range(int(round(6.0 / DT))):
        t = k * DT
        peds = (PerceivedPedestrian("p", ped_x, 0.0, "onboard_camera"),) if t >= appear_s - 1e-9 else ()
        if peds and x_appear is None:
            x_appear = x
        command = driver.run_step(Observation(EgoState(x, 0.0, 0.0, speed, 4.5, 1.8), peds, DT), t)
        if command.info.get("braking") and x_onset is None:
            x_onset = x
            assert t == pytest.approx(appear_s + R157_DELAY_S, abs=1e-9)
        x += command.target_speed_mps * DT
        speed = command.target_speed_mps
        if x_onset is not None and speed == 0.0:
            break
    assert speed == 0.0
    assert x_onset - x_appear == pytest.approx(V0 * R157_DELAY_S, abs=1e-9)  # 15.972 m held at V0
    assert BRAKING_DISTANCE_M - STEP_TRAVEL_M < x - x_onset <= BRAKING_DISTANCE_M
    assert STOPPING_DISTANCE_M - STEP_TRAVEL_M < x - x_appear <= STOPPING_DISTANCE_M
