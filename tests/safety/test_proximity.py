"""Proximity measures: minimum clearance, DRAC, close pass, on hand-built logs with numbers worked by hand."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from safety_logs import make_log

from pedsafe_sumo.params import ParameterError, load_params, with_overrides
from pedsafe_sumo.safety import episode_indexes
from pedsafe_sumo.safety.proximity import (
    ProximityModel,
    clearance_steps_m,
    drac_from_ttc_mps2,
    drac_mps2,
    drac_steps_mps2,
    episode_proximity,
    min_clearance_m,
)

#: Every step counts (scope "episode"): these tests are about the clearance itself; which steps count is
#: tested in test_proximity_scope.py.
DEFAULTS = ProximityModel(
    close_pass_clearance_m=1.5,
    close_pass_min_speed_mps=1.0,
    drac_threshold_mps2=3.4,
    interaction_margin_m=0.5,
    interaction_horizon_s=4.0,
    scope="episode",
)


def standing_pass_log(ped_y_m: float = 1.6, speed_mps: float = 8.0):
    """Ego 4 m x 2 m along +x on y = 0 from x = -20 m at `speed_mps`; a pedestrian (radius 0.3 m) standing
    at (0, ped_y_m). Steps of 0.1 s for 5 s."""
    t = np.arange(51) * 0.1
    return make_log(
        t,
        ego_x_m=-20.0 + speed_mps * t,
        ego_speed_mps=speed_mps,
        ped_x_m=0.0,
        ped_y_m=ped_y_m,
        ped_vy_mps=0.0,
    )


def test_standing_pedestrian_passed_at_0_3_m_is_a_close_pass():
    # Beside the car (|x_ped - x_ego| <= 2 m, the half length) the clearance is 1.6 - 1.0 (half width)
    # - 0.3 (radius) = 0.3 m. The ego's centre is within 2 m of x = 0 for -20 + 8 t in [-2, 2], i.e.
    # t in [2.25, 2.75]: the first such step is t = 2.3 s, at 8 m/s.
    log = standing_pass_log()
    result = episode_proximity(log, DEFAULTS)
    assert result.min_clearance_m == pytest.approx(0.3)
    assert result.step == 23
    assert result.ego_speed_at_min_clearance_mps == 8.0
    assert result.close_pass  # 0.3 m < 1.5 m at 8 m/s > 1 m/s
    # Never on a collision course (it passes beside), so no TTC and no DRAC.
    assert math.isnan(result.drac_mps2)


def test_the_conflict_model_misses_what_the_proximity_measure_catches():
    row = episode_indexes(standing_pass_log(), ped_age_years=30, proximity_model=DEFAULTS)
    # A standing pedestrian has no path: no Amini candidate, no TTC, no collision ...
    assert not row["collision"] and not row["conflict"] and math.isnan(row["min_ttc_s"])
    # ... but the close pass is in its own columns.
    assert row["close_pass"] and row["min_clearance_m"] == pytest.approx(0.3)
    assert row["ego_speed_at_min_clearance_mps"] == 8.0 and math.isnan(row["drac_mps2"])


def test_close_pass_thresholds_are_strict():
    # 0.9 m/s is not above the 1 m/s minimum: no close pass at any clearance
    assert not episode_proximity(standing_pass_log(speed_mps=0.9), DEFAULTS).close_pass
    # clearance 1.6 m (ped at y = 2.9) is not below the 1.5 m threshold; 1.4 m (y = 2.7) is
    assert not episode_proximity(standing_pass_log(ped_y_m=2.9), DEFAULTS).close_pass
    assert episode_proximity(standing_pass_log(ped_y_m=2.7), DEFAULTS).close_pass


def test_drac_of_a_standing_pedestrian_ahead():
    # Ego at 10 m/s from x = -20 m towards a pedestrian standing at the origin, 11 steps (t = 0..1 s).
    # Distance to contact at step k: d = -x_ego - 2 (half length) - 0.3 (radius) = 17.7 - 1.0 k;
    # DRAC = v^2 / (2 d) = 100 / (2 d): 2.824859 at t = 0, largest at t = 1 s: 100 / 15.4 = 6.493506.
    t = np.arange(11) * 0.1
    log = make_log(t, ego_x_m=-20.0 + 10.0 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=0.0)
    steps = drac_steps_mps2(log)
    assert steps[0] == pytest.approx(100 / (2 * 17.7))
    assert steps == pytest.approx(100 / (2 * (17.7 - 10.0 * t)))
    assert drac_mps2(log) == pytest.approx(6.493506, abs=1e-6)
    assert drac_mps2(log, last_step=0) == pytest.approx(2.824859, abs=1e-6)
    assert clearance_steps_m(log) == pytest.approx(17.7 - 10.0 * t)


def test_drac_is_undefined_in_contact_and_for_a_standing_ego():
    # v / (2 TTC): TTC NaN (never touching), TTC 0 (touching), v 0 (standing) -> NaN
    got = drac_from_ttc_mps2([8.0, 8.0, 8.0, 0.0], [2.0, math.nan, 0.0, 1.0])
    assert got[0] == pytest.approx(2.0)
    assert np.isnan(got[1:]).all()


def test_window_ends_at_the_first_contact():
    # Ego runs into a standing pedestrian and through it: the window stops at the first contact, where
    # the clearance is at most 0 (the run-through afterwards is ignored, and would be more negative).
    t = np.arange(31) * 0.1
    log = make_log(t, ego_x_m=-5.0 + 10.0 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=0.0)
    # contact when -x_ego - 2.3 <= 0: x_ego >= -2.3 -> first step t = 0.3 s (x = -2.0, clearance -0.3)
    row = episode_indexes(log, ped_age_years=30, proximity_model=DEFAULTS)
    assert row["collision"]
    assert row["min_clearance_m"] == pytest.approx(-0.3)
    assert row["ego_speed_at_min_clearance_mps"] == 10.0
    # largest DRAC before contact: t = 0.2 s, d = 5 - 2 - 2.3 = 0.7 m -> 100 / 1.4 = 71.428571
    assert row["drac_mps2"] == pytest.approx(100 / 1.4)
    # whole log: at t = 0.5 s the centres coincide, -1.0 (nearest side, the half width) - 0.3 = -1.3 m
    assert min_clearance_m(log) == (pytest.approx(-1.3), 10.0)


def test_a_log_without_detection_flags_is_enough():
    # e.g. trajectories from SUMO FCD output: only the kinematic columns
    log = standing_pass_log().drop(
        columns=["detected_onboard_camera", "detected_onboard_lidar", "detected_roadside", "perceived"]
    )
    assert episode_proximity(log, DEFAULTS).min_clearance_m == pytest.approx(0.3)


def test_thresholds_come_from_the_parameter_file():
    params = load_params()
    assert ProximityModel.from_params(params) == replace(DEFAULTS, scope="interaction")
    stricter = ProximityModel.from_params(with_overrides(params, {"safety.close_pass_clearance_m": 0.25}))
    assert not episode_proximity(standing_pass_log(), stricter).close_pass  # 0.3 m is not below 0.25 m
    with pytest.raises(ParameterError, match="close_pass_min_speed_mps"):
        with_overrides(params, {"safety.close_pass_min_speed_mps": -1.0})
