"""Collision detection and impact speed on hand-built encounters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from safety_logs import make_log

from pedsafe_sumo.safety.collision import detect_collision


def test_crossing_encounter_collides_at_the_first_step_in_contact(collision_log):
    # ego centre x = -20 + 10 t, pedestrian y = -3 + 1.5 t. The front face (x_centre + 2) meets the
    # pedestrian's circle (centre x = 0, radius 0.3) when -20 + 10 t + 2 = -0.3, t = 1.77 s, and the
    # pedestrian is then at y = -3 + 1.5 * 1.77 = -0.345, within the half-width 1: first contact at 1.77 s.
    # Logged steps are 0.1 s apart: at 1.7 s the clearance is (0 - (-3 + 2)) - 0.3 = 0.7 m, at 1.8 s the
    # front face is at x = 0 and the clearance -0.3 m. So the first step in contact is 1.8 s (step 18).
    hit = detect_collision(collision_log)
    assert hit.collided and hit.step == 18
    assert hit.time_s == pytest.approx(1.8)
    assert hit.impact_speed_mps == pytest.approx(10.0)


def test_impact_speed_is_the_ego_speed_at_the_contact_step():
    # a braking ego, pedestrian standing at (5, 0): clearances 5 - 0 - 2 - 0.3 = 2.7, 5 - 2 - 2.3 = 0.7,
    # 5 - 3 - 2.3 = -0.3 -> contact at the third step, where the logged speed is 6 m/s
    log = make_log(
        [0.0, 0.2, 0.4], ego_x_m=[0.0, 2.0, 3.0], ego_speed_mps=[10.0, 8.0, 6.0], ped_x_m=5.0, ped_y_m=0.0
    )
    hit = detect_collision(log)
    assert (hit.collided, hit.step, hit.time_s, hit.impact_speed_mps) == (True, 2, 0.4, 6.0)


def test_near_miss_has_no_collision_even_at_millisecond_resolution(near_miss_log):
    # the pedestrian clears y = 1.3 (half-width + radius) at (3 + 1.3) / 1.5 = 2.867 s; the ego front is then
    # at -31 + 28.67 + 2 = -0.33 m, and the nearest corner (-0.33, 1) is sqrt(0.33^2 + 0.3^2) = 0.446 m > 0.3
    # from the circle's centre (0, 1.3): a miss, also between the logged steps
    assert not detect_collision(near_miss_log).collided
    t = np.arange(5001) * 0.001
    dense = make_log(
        t, ego_x_m=-31.0 + 10.0 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=-3.0 + 1.5 * t, ped_vy_mps=1.5
    )
    hit = detect_collision(dense)
    assert not hit.collided and math.isnan(hit.time_s) and math.isnan(hit.impact_speed_mps)


def test_contact_with_a_standing_ego_is_no_collision():
    # The audit's artefact: the ego stands (0.05 m/s, then 0) and the pedestrian walks into its flank.
    # Ego centre (0, 0), 4 m x 2 m: flank at y = 1. Pedestrian centre y = 1.6, 1.4, 1.2: clearances
    # 0.3, 0.1, -0.1 -> contact at the third step, where the ego's speed 0.0 is below 0.1 m/s.
    log = make_log([0.0, 0.1, 0.2], ego_speed_mps=[0.05, 0.0, 0.0], ped_x_m=0.0, ped_y_m=[1.6, 1.4, 1.2])
    hit = detect_collision(log)
    assert not hit.collided and hit.contact_stationary and hit.step is None
    assert math.isnan(hit.impact_speed_mps)


def test_a_standing_contact_then_the_ego_drives_on_is_a_collision_at_the_moving_step():
    # Contact from the second step on; the ego stands there (0.0 m/s) and then moves at 0.1 m/s (not
    # below the threshold) and 2 m/s: the collision is the step at 0.1 m/s, the contact before it stays
    # recorded as stationary.
    log = make_log(
        [0.0, 0.1, 0.2, 0.3], ego_speed_mps=[0.0, 0.0, 0.1, 2.0], ped_x_m=0.0, ped_y_m=[1.6, 1.2, 1.2, 1.2]
    )
    hit = detect_collision(log)
    assert (hit.collided, hit.step, hit.impact_speed_mps, hit.contact_stationary) == (True, 2, 0.1, True)


def test_no_collision_below_the_stationary_speed_whatever_the_log():
    # Any log: a collision always has an impact speed of at least 0.1 m/s.
    rng = np.random.default_rng(12)
    for _ in range(200):
        n = 20
        log = make_log(
            np.arange(n) * 0.1,
            ego_speed_mps=rng.choice([0.0, 0.05, 0.099, 0.1, 3.0], n),
            ped_x_m=rng.uniform(-3, 3, n),
            ped_y_m=rng.uniform(-2, 2, n),
        )
        hit = detect_collision(log)
        assert not hit.collided or hit.impact_speed_mps >= 0.1
