"""Conflicts after Amini et al. 2022: MD, TMD, CS, the risk model, the candidate test, the episode flag."""

from __future__ import annotations

import math

import numpy as np
import pytest
from safety_logs import make_log

from pedsafe_sumo.safety.conflict import (
    AMINI_2022,
    conflict_steps,
    conflict_without_collision,
    episode_conflict,
    minimum_distance,
    path_crossing_times_s,
)


def test_minimum_distance_on_a_collision_course():
    # dp = (20, -3), dv = (-10, 1.5): dp.dv = -200 - 4.5 = -204.5, |dv|^2 = 100 + 2.25 = 102.25,
    # t* = 204.5 / 102.25 = 2.0 s, dp + 2 dv = (0, 0): MD = 0
    md, tmd = minimum_distance(20.0, -3.0, -10.0, 1.5)
    assert tmd == pytest.approx(2.0) and md == pytest.approx(0.0, abs=1e-12)


def test_minimum_distance_passing_by():
    # dp = (10, 2), dv = (-5, 0): t* = 50 / 25 = 2 s, dp + 2 dv = (0, 2): MD = 2 m
    md, tmd = minimum_distance(10.0, 2.0, -5.0, 0.0)
    assert (md, tmd) == pytest.approx((2.0, 2.0))


def test_minimum_distance_now_when_separating_or_at_equal_velocity():
    # moving apart: -(dp.dv) = -50 < 0 -> t* = 0, MD = |dp| = 10; dv = 0 -> t* = 0, MD = |(3, 4)| = 5
    assert minimum_distance(10.0, 0.0, 5.0, 0.0) == pytest.approx((10.0, 0.0))
    assert minimum_distance(3.0, 4.0, 0.0, 0.0) == pytest.approx((5.0, 0.0))


def test_risk_model_at_md_1_tmd_1_cs_5():
    # 4.327 - 2.898 * 1 - 3.067 * 1 + 0.376 * 5 = 4.327 - 2.898 - 3.067 + 1.88 = 0.242
    # P = 1 / (1 + e^-0.242) = 1 / (1 + 0.785056) = 0.560207
    assert AMINI_2022.probability(1.0, 1.0, 5.0) == pytest.approx(0.560207, abs=1e-6)


def test_crossing_times_to_the_conflict_point():
    # ego at (-20, 0) with (10, 0), pedestrian at (0, -3) with (0, 1.5): both reach the origin, after
    # 20 / 10 = 2 s and 3 / 1.5 = 2 s
    s, u = path_crossing_times_s(-20.0, 0.0, 10.0, 0.0, 0.0, -3.0, 0.0, 1.5)
    assert (s, u) == pytest.approx((2.0, 2.0))
    # parallel paths, and a standing pedestrian, have no conflict point
    assert np.isnan(path_crossing_times_s(-20.0, 0.0, 10.0, 0.0, 0.0, 3.0, 1.0, 0.0)).all()
    assert np.isnan(path_crossing_times_s(-20.0, 0.0, 10.0, 0.0, 0.0, 3.0, 0.0, 0.0)).all()


def test_first_step_of_the_collision_course(collision_log):
    # step 0: MD = 0, TMD = 2, CS = 10: 4.327 - 0 - 3.067 * 2 + 0.376 * 10 = 4.327 - 6.134 + 3.76 = 1.953,
    # P = 1 / (1 + e^-1.953) = 1 / (1 + 0.135335 * 1.048122) = 1 / 1.141848 = 0.875773
    row = conflict_steps(collision_log).iloc[0]
    assert row["candidate"] and row["conflict"]
    assert (row["md_m"], row["tmd_s"], row["cs_mps"]) == pytest.approx((0.0, 2.0, 10.0), abs=1e-12)
    assert row["conflict_probability"] == pytest.approx(0.875773, abs=1e-6)


def test_near_miss_is_a_conflict_reported_at_its_riskiest_step(near_miss_log):
    # The pedestrian reaches the crossing point at T_p = 2.0 s, the ego centre at T_e = 3.1 s.
    # MD = |dp x dv| / |dv| = 15 |T_e - T_p| / sqrt(102.25) = 16.5 / 10.111874 = 1.631745 m at every step.
    # The absolute time of minimum distance minimises 100 (T_e - t)^2 + 2.25 (t - T_p)^2:
    # t = (200 T_e + 4.5 T_p) / 204.5 = T_p + 200 * 1.1 / 204.5 = T_p + 1.075795, so TMD falls as t grows
    # and p rises; the last candidate step is t = T_p = 2.0 s (after it the pedestrian has passed the point),
    # with TMD = 1.075795 s: 4.327 - 2.898 * 1.631745 - 3.067 * 1.075795 + 3.76
    #                      = 4.327 - 4.728797 - 3.299463 + 3.76 = 0.058740 -> P = 0.514681 >= 0.425.
    result = episode_conflict(near_miss_log)
    assert result.conflict and result.step == 20
    assert result.md_m == pytest.approx(1.631745, abs=1e-6)
    assert result.tmd_s == pytest.approx(1.075795, abs=1e-6)
    assert result.cs_mps == 10.0
    assert result.conflict_probability == pytest.approx(0.514681, abs=1e-6)


def test_ttc_difference_over_three_seconds_is_no_candidate():
    # pedestrian at the point after 2 s, ego after 60 / 10 = 6 s: |6 - 2| = 4 s > 3 s
    t = np.arange(11) * 0.1
    log = make_log(
        t, ego_x_m=-60 + 10 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=-3 + 1.5 * t, ped_vy_mps=1.5
    )
    steps = conflict_steps(log)
    assert steps["ttc_vehicle_s"].iloc[0] == pytest.approx(6.0) and steps["ttc_pedestrian_s"].iloc[0] == 2.0
    assert not steps["candidate"].any()
    result = episode_conflict(log)
    assert not result.conflict and result.step is None and math.isnan(result.conflict_probability)


def test_slow_ego_is_no_conflict_however_close():
    # CS = 0.9 m/s <= 1 m/s. Ego from x = -1.8 at 0.9 m/s and pedestrian from y = -3 at 1.5 m/s reach the
    # origin together after 2 s: MD = 0, TMD = 2, p = sigmoid(4.327 - 6.134 + 0.3384) = sigmoid(-1.4686)
    # = 0.187, and later steps come closer (TMD -> 0: p -> sigmoid(4.327 + 0.3384) = 0.9907)
    t = np.arange(21) * 0.1
    log = make_log(
        t, ego_x_m=-1.8 + 0.9 * t, ego_speed_mps=0.9, ped_x_m=0.0, ped_y_m=-3 + 1.5 * t, ped_vy_mps=1.5
    )
    steps = conflict_steps(log)
    assert steps["candidate"].all() and (steps["conflict_probability"] >= 0.425).any()
    assert not steps["conflict"].any() and not episode_conflict(log).conflict


@pytest.mark.parametrize("seed", range(5))
def test_no_conflict_when_the_paths_never_cross(seed):
    # pedestrian walking along the road (parallel to the ego's heading), anywhere, at any speed, either way
    rng = np.random.default_rng(seed)
    t = np.arange(40) * 0.1
    yaw = rng.uniform(-math.pi, math.pi)
    speed, ped_speed = rng.uniform(2.0, 15.0), rng.uniform(-2.0, 2.0)
    x0, y0 = rng.uniform(-30.0, 30.0, 2)
    log = make_log(
        t,
        ego_x_m=speed * math.cos(yaw) * t,
        ego_y_m=speed * math.sin(yaw) * t,
        ego_yaw_rad=yaw,
        ego_speed_mps=speed,
        ped_x_m=x0 + ped_speed * math.cos(yaw) * t,
        ped_y_m=y0 + ped_speed * math.sin(yaw) * t,
        ped_vx_mps=ped_speed * math.cos(yaw),
        ped_vy_mps=ped_speed * math.sin(yaw),
    )
    assert not conflict_steps(log)["candidate"].any()
    assert not episode_conflict(log).conflict


def test_conflict_point_behind_either_is_no_candidate():
    # the pedestrian walks away from the ego's path (from y = 1 towards +y): the crossing point is behind it
    t = np.arange(11) * 0.1
    log = make_log(
        t, ego_x_m=-10 + 10 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=1 + 1.5 * t, ped_vy_mps=1.5
    )
    assert (conflict_steps(log)["ttc_pedestrian_s"] < 0).all()
    assert not episode_conflict(log).conflict


def test_table_one_counts_a_conflict_only_without_a_collision():
    assert list(conflict_without_collision([True, True, False], [False, True, False])) == [True, False, False]
