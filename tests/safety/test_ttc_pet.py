"""Time to collision and post-encroachment time on hand-built encounters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from safety_logs import crossing_log, make_log

from pedsafe_sumo.safety.surrogates import min_ttc_s, pet_s, ttc_steps_s


def test_ttc_at_the_start_of_the_collision_course(collision_log):
    # relative to the ego, the pedestrian starts at (20, -3) and moves with (-10, 1.5). The front face grown
    # by the radius (x = 2.3) is reached after (20 - 2.3) / 10 = 1.77 s, when the pedestrian's lateral offset
    # is -3 + 1.5 * 1.77 = -0.345, within the half-width: TTC = 1.77 s, then 1.77 - t at later steps
    ttc = ttc_steps_s(collision_log)
    assert ttc[0] == pytest.approx(1.77)
    assert ttc[17] == pytest.approx(0.07)
    assert ttc[18] == 0.0  # the contact step
    assert min_ttc_s(collision_log, last_step=18) == 0.0


def test_min_ttc_of_a_braking_ego_and_a_standing_pedestrian():
    # pedestrian stands at (22.3, 0): front face to circle gap is 22.3 - x - 2 - 0.3 = 20 - x.
    # step 0: x = 0,  v = 10 -> 20 / 10 = 2 s;   step 1: x = 12, v = 8 -> 8 / 8 = 1 s
    # step 2: x = 16, v = 2  -> 4 / 2 = 2 s;     step 3: x = 18, v = 0 -> never: NaN. Minimum: 1 s
    log = make_log(
        [0.0, 1.0, 2.0, 3.0],
        ego_x_m=[0.0, 12.0, 16.0, 18.0],
        ego_speed_mps=[10.0, 8.0, 2.0, 0.0],
        ped_x_m=22.3,
        ped_y_m=0.0,
    )
    ttc = ttc_steps_s(log)
    assert ttc[:3] == pytest.approx([2.0, 1.0, 2.0]) and math.isnan(ttc[3])
    assert min_ttc_s(log) == pytest.approx(1.0)
    assert min_ttc_s(log, last_step=0) == pytest.approx(2.0)


def test_min_ttc_is_nan_when_never_on_a_collision_course(near_miss_log):
    assert math.isnan(min_ttc_s(near_miss_log))


def test_pet_ego_first_then_pedestrian():
    # conflict point: the origin. The ego (centre x = -20 + 10 t, 4 m long) covers it while |x| <= 2:
    # from 1.8 s to 2.2 s. The pedestrian starts at y = -4.8: its circle (radius 0.3) covers the origin while
    # |-4.8 + 1.5 t| <= 0.3, from 4.5 / 1.5 = 3.0 s to 5.1 / 1.5 = 3.4 s. PET = 3.0 - 2.2 = 0.8 s
    assert pet_s(crossing_log(-20.0, -4.8)) == pytest.approx(0.8)


def test_pet_pedestrian_first_then_ego(near_miss_log):
    # pedestrian covers the origin while |-3 + 1.5 t| <= 0.3: 1.8 s to 2.2 s; the ego (x = -31 + 10 t) while
    # |x| <= 2: 2.9 s to 3.3 s. PET = 2.9 - 2.2 = 0.7 s
    assert pet_s(near_miss_log) == pytest.approx(0.7)


def test_pet_is_zero_when_both_are_on_the_point_together(collision_log):
    # ego covers the origin 1.8-2.2 s, the pedestrian 1.8-2.2 s too (|-3 + 1.5 t| <= 0.3): they met there
    assert pet_s(collision_log) == 0.0


def test_pet_arrival_times_are_interpolated_between_steps():
    # steps 0.5 s apart, ego from x = -20.5: it covers the origin from (20.5 - 2) / 10 = 1.85 s to 2.25 s,
    # neither on a step; the pedestrian from y = -4.8 covers it from 3.0 s. PET = 3.0 - 2.25 = 0.75 s
    t = np.arange(11) * 0.5
    log = make_log(
        t, ego_x_m=-20.5 + 10 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=-4.8 + 1.5 * t, ped_vy_mps=1.5
    )
    assert pet_s(log) == pytest.approx(0.75)


def test_pet_is_nan_when_the_paths_never_cross():
    # the pedestrian walks along the kerb, parallel to the ego, and then turns back: no crossing
    t = np.arange(20) * 0.1
    log = make_log(t, ego_x_m=-20 + 10 * t, ego_speed_mps=10.0, ped_x_m=np.minimum(t, 1.0), ped_y_m=4.0)
    assert math.isnan(pet_s(log))


def test_pet_is_nan_when_the_pedestrian_stops_short_of_the_point():
    # the pedestrian walks to y = -1.5 and waits; the ego's path (y = 0) is never reached
    t = np.arange(50) * 0.1
    log = make_log(
        t, ego_x_m=-20 + 10 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=np.minimum(-3 + 1.5 * t, -1.5)
    )
    assert math.isnan(pet_s(log))
