"""Per-cell metrics (pedsafe_sumo.ncap.metrics) on hand-built step logs, worked by hand."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from pedsafe_sumo.ncap.metrics import cell_metrics, ttc_along_path_s
from pedsafe_sumo.ncap.protocol import load_protocol

STEP_S = 0.1


def log_of(rows: list[tuple[float, float, float]], **columns) -> pd.DataFrame:
    """A log of an ego driving east (yaw 0, 4 m long) at (x, speed, commanded speed) per step, and a dummy
    (radius 0.25 m) at x = 20 m walking north at 1.5 m/s across its path."""
    frame = pd.DataFrame(
        {
            "ego_x_m": [x for x, _, _ in rows],
            "ego_y_m": 0.0,
            "ego_yaw_rad": 0.0,
            "ego_speed_mps": [v for _, v, _ in rows],
            "command_speed_mps": [c for _, _, c in rows],
            "ego_length_m": 4.0,
            "ped_x_m": 20.0,
            "ped_y_m": -1.0,
            "ped_vx_mps": 0.0,
            "ped_vy_mps": 1.5,
            "ped_radius_m": 0.25,
        }
    )
    for name, values in columns.items():
        frame[name] = values
    return frame


# Steps: holding 10 m/s; then a command of 9.5 m/s at 10 m/s (5 m/s2 commanded: brake onset); the speed
# follows; a last drop of 0.8 m/s in one step (8 m/s2) before contact at 8.2 m/s.
BRAKING = [(0.0, 10.0, 10.0), (1.0, 10.0, 9.5), (1.95, 9.5, 9.0), (2.85, 9.0, 8.2), (3.67, 8.2, 8.2)]


def test_worked_braking_run():
    metrics = cell_metrics(log_of(BRAKING), STEP_S, 36.0, collided=True, brake_onset_decel_mps2=1.0)
    # Onset at step 1: gap = 20 - 1.0 - 4/2 - 0.25 = 16.75 m, closing 10 m/s (the dummy crosses): 1.675 s.
    assert metrics["brake_onset_ttc_s"] == pytest.approx(1.675)
    # Contact at 8.2 m/s = 29.52 km/h: 36 - 29.52 = 6.48 km/h less than the test speed.
    assert metrics["speed_reduction_kmh"] == pytest.approx(6.48)
    # Largest drop: 9.0 -> 8.2 m/s in 0.1 s.
    assert metrics["peak_decel_mps2"] == pytest.approx(8.0)
    assert math.isnan(metrics["warning_time_s"])


def test_onset_threshold_and_avoidance():
    # Commanded 0.5 m/s2 (10 -> 9.95 in 0.1 s) stays under 1 m/s2: no onset; the speeds never drop.
    gentle = [(0.0, 10.0, 9.95), (1.0, 10.0, 9.95)]
    metrics = cell_metrics(log_of(gentle), STEP_S, 36.0, collided=False, brake_onset_decel_mps2=1.0)
    assert math.isnan(metrics["brake_onset_ttc_s"])
    assert metrics["peak_decel_mps2"] == 0.0
    # Avoided: the whole test speed is taken off.
    assert metrics["speed_reduction_kmh"] == 36.0
    # The protocol's threshold is the one stated in protocol.toml.
    assert load_protocol().brake_onset_decel_mps2 == 1.0


def test_warning_time_when_the_log_has_warnings():
    log = log_of(BRAKING, warning=[False, False, True, True, True])
    metrics = cell_metrics(log, STEP_S, 36.0, collided=True, brake_onset_decel_mps2=1.0)
    # First warning at step 2: gap = 20 - 1.95 - 2.25 = 15.8 m at 9.5 m/s closing.
    assert metrics["warning_time_s"] == pytest.approx(15.8 / 9.5)


def test_ttc_of_a_dummy_walking_ahead_and_of_one_not_yet_in_the_scene():
    log = log_of([(0.0, 10.0, 10.0), (0.0, 10.0, 10.0)])
    log["ped_vx_mps"], log["ped_vy_mps"] = 1.5, 0.0
    log.loc[1, "ped_x_m"] = math.nan
    ttc = ttc_along_path_s(log)
    # 17.75 m gap closed at 10 - 1.5 = 8.5 m/s; a dummy absent from the scene has no TTC.
    assert ttc[0] == pytest.approx(17.75 / 8.5)
    assert ttc[1] == math.inf
