"""One episode's row of episodes.parquet from its log: the exact column set and golden values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from safety_logs import make_log

from pedsafe_sumo.safety import INDEX_COLUMNS, episode_indexes

# DESIGN section 3, the columns of episodes.parquet
DESIGN_COLUMNS = (
    "scenario condition episode seed ped_age ped_gender ped_risk ped_speed_mps ego_initial_speed_mps "
    "collision impact_speed_mps injury_probability conflict md_m tmd_s cs_mps conflict_probability "
    "min_ttc_s pet_s "
    "first_detection_distance_m first_detection_time_s detected_by sumo_collision status error "
    # the proximity measure's own columns
    "min_clearance_m ego_speed_at_min_clearance_mps drac_mps2 close_pass "
    "contact_stationary "
    # the second injury index (docs/safety_indexes.md)
    "injury_mais3f_probability"
).split()


def test_keys_are_exactly_the_index_columns_of_design():
    assert set(INDEX_COLUMNS) <= set(DESIGN_COLUMNS)
    assert set(INDEX_COLUMNS) == set(DESIGN_COLUMNS) - {
        "scenario", "condition", "episode", "seed", "ped_age", "ped_gender", "ped_risk", "ped_speed_mps",
        "ego_initial_speed_mps", "sumo_collision", "status", "error",
    }  # fmt: skip


def test_collision_episode(collision_log):
    log = collision_log.copy()
    log.loc[5:, "perceived"] = True  # first perceived at 0.5 s: ego at (-15, 0), pedestrian at (0, -2.25)
    log.loc[5:, "detected_onboard_camera"] = True
    row = episode_indexes(log, ped_age_years=30.0)
    assert list(row) == list(INDEX_COLUMNS)
    # contact at 1.8 s at 10 m/s = 36 km/h; age 30 -> 0.390193 (see test_injury)
    assert row["collision"] is True and row["impact_speed_mps"] == 10.0
    assert row["injury_probability"] == pytest.approx(0.390193, abs=1e-6)
    # riskiest step up to contact is the contact step (1.8 s): MD 0, TMD 2 - 1.8 = 0.2 s, CS 10 m/s,
    # 4.327 - 3.067 * 0.2 + 3.76 = 7.4736, P = 1 / (1 + e^-7.4736) = 1 / (1 + 0.000911882 * 0.622744)
    # = 1 / 1.000567862 = 0.999432
    assert row["conflict"] is True
    assert (row["md_m"], row["tmd_s"], row["cs_mps"]) == pytest.approx((0.0, 0.2, 10.0), abs=1e-9)
    assert row["conflict_probability"] == pytest.approx(0.999432, abs=1e-6)
    assert row["min_ttc_s"] == 0.0 and row["pet_s"] == 0.0
    # first detection distance: |(0 - (-15), -2.25 - 0)| = sqrt(225 + 5.0625) = sqrt(230.0625) = 15.16781
    assert row["first_detection_time_s"] == pytest.approx(0.5)
    assert row["first_detection_distance_m"] == pytest.approx(15.16781, abs=1e-5)
    assert row["detected_by"] == "onboard_camera"


def test_near_miss_episode(near_miss_log):
    row = episode_indexes(near_miss_log, ped_age_years=70.0, injury_model="rosen_sander2009")
    assert row["collision"] is False and math.isnan(row["impact_speed_mps"])
    assert row["injury_probability"] == 0.0
    assert row["conflict"] is True and row["conflict_probability"] == pytest.approx(0.514681, abs=1e-6)
    assert math.isnan(row["min_ttc_s"]) and row["pet_s"] == pytest.approx(0.7)
    assert math.isnan(row["first_detection_distance_m"]) and row["detected_by"] == ""


def test_steps_after_the_first_contact_are_ignored(collision_log):
    # after contact the logged pedestrian jumps far away (as if removed): nothing changes
    log = collision_log.copy()
    log.loc[19:, "ped_x_m"] = 500.0
    log.loc[19:, "ped_vy_mps"] = -30.0
    got, expected = episode_indexes(log, 30.0), episode_indexes(collision_log, 30.0)
    assert got.keys() == expected.keys()
    for key, value in expected.items():
        assert got[key] == value or (value != value and got[key] != got[key]), key  # NaN == NaN here


def test_unknown_injury_model_is_an_error(near_miss_log):
    known = "known models: monfort_mueller2025_mais3f, rosen_sander2009, saade2020"
    with pytest.raises(ValueError, match=known):
        episode_indexes(near_miss_log, 30.0, injury_model="bogus")


def test_values_have_parquet_friendly_types(near_miss_log):
    row = episode_indexes(near_miss_log, 30.0)
    flags = ("collision", "conflict", "close_pass", "contact_stationary")
    assert all(isinstance(row[c], bool) for c in flags)
    assert isinstance(row["detected_by"], str)
    others = set(INDEX_COLUMNS) - {*flags, "detected_by"}
    assert all(isinstance(row[c], float) and not isinstance(row[c], np.floating) for c in others)


def test_indexes_agree_with_each_other_on_random_encounters():
    # 200 straight-line encounters aimed at each other: both reach a common point at random times 1-4 s,
    # the pedestrian's path shifted by up to 5 m, random headings and speeds (ego 0-15 m/s, pedestrian
    # 0.3-2.5 m/s). A mix of collisions, near misses and harmless passings.
    rng = np.random.default_rng(2024)
    t = np.arange(60) * 0.1
    counts = {"collision": 0, "conflict_only": 0, "neither": 0}
    for _ in range(200):
        yaw, ped_heading = rng.uniform(-np.pi, np.pi, 2)
        speed, ped_speed = rng.uniform(0.0, 15.0), rng.uniform(0.3, 2.5)
        t_ego, t_ped = rng.uniform(1.0, 4.0, 2)
        shift = rng.uniform(-5.0, 5.0)
        ego_x0, ego_y0 = -speed * t_ego * np.cos(yaw), -speed * t_ego * np.sin(yaw)
        ped_x0 = -ped_speed * t_ped * np.cos(ped_heading) - shift * np.sin(ped_heading)
        ped_y0 = -ped_speed * t_ped * np.sin(ped_heading) + shift * np.cos(ped_heading)
        log = make_log(
            t,
            ego_x_m=ego_x0 + speed * np.cos(yaw) * t,
            ego_y_m=ego_y0 + speed * np.sin(yaw) * t,
            ego_yaw_rad=yaw,
            ego_speed_mps=speed,
            ped_x_m=ped_x0 + ped_speed * np.cos(ped_heading) * t,
            ped_y_m=ped_y0 + ped_speed * np.sin(ped_heading) * t,
            ped_vx_mps=ped_speed * np.cos(ped_heading),
            ped_vy_mps=ped_speed * np.sin(ped_heading),
        )
        row = episode_indexes(log, ped_age_years=rng.uniform(13, 90))
        # the reported step decides the flag
        assert row["conflict"] == (row["conflict_probability"] >= 0.425)
        # TTC reaches 0 exactly when the footprint and circle touch; a touch of a standing ego (below
        # 0.1 m/s) is a stationary contact, not a collision
        assert (row["min_ttc_s"] == 0.0) == (row["collision"] or row["contact_stationary"])
        assert not (row["collision"] and row["impact_speed_mps"] < 0.1)
        if row["collision"]:
            assert row["pet_s"] == 0.0 and 0.0 < row["injury_probability"] < 1.0
            counts["collision"] += 1
        else:
            assert row["injury_probability"] == 0.0 and math.isnan(row["impact_speed_mps"])
            assert math.isnan(row["pet_s"]) or row["pet_s"] > 0.0
            counts["conflict_only" if row["conflict"] else "neither"] += 1
    assert min(counts.values()) >= 5, counts  # conflicts without contact are the rarest
