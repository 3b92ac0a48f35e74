"""The baseline stack's Kalman tracker on positions whose truth is known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.control.agent import PerceivedPedestrian
from pedsafe_sumo.control.kalman_tracker import KalmanTracker

STEP_S = 0.05


def at(x, y, source="v2i"):
    return PerceivedPedestrian("p", x, y, source)


def test_a_standing_person_under_v2i_noise_has_a_speed_near_zero():
    # 200 steps (10 s) of a person standing at (30, 5) seen only over V2I, 0.2 m noise per axis.
    rng = np.random.default_rng(7)
    tracker = KalmanTracker()
    for k in range(200):
        nx, ny = rng.normal(0.0, 0.2, size=2)
        (track,) = tracker.update([at(30.0 + nx, 5.0 + ny)], k * STEP_S)
    assert math.hypot(track.vx_mps, track.vy_mps) < 0.2
    assert not track.moving
    # The position is the mean of many noisy ones: well within one noise sigma.
    assert math.hypot(track.x_m - 30.0, track.y_m - 5.0) < 0.2


@pytest.mark.parametrize("seed", range(5))
def test_standing_speed_stays_small_whatever_the_noise_draw(seed):
    rng = np.random.default_rng(100 + seed)
    tracker = KalmanTracker()
    speeds = []
    for k in range(200):
        nx, ny = rng.normal(0.0, 0.2, size=2)
        (track,) = tracker.update([at(nx, ny)], k * STEP_S)
        if k >= 100:
            speeds.append(math.hypot(track.vx_mps, track.vy_mps))
    # The last 5 s: never above 0.35 m/s (3.5 steady-state sigmas of ~0.1 m/s per axis).
    assert max(speeds) < 0.35


def test_a_walking_person_is_tracked_within_a_second():
    # Onboard positions (exact in this simulator) of a person walking +y at 1.4 m/s: after 1 s
    # (20 steps after the first sighting) the speed is within 0.1 m/s of 1.4.
    tracker = KalmanTracker()
    for k in range(21):
        (track,) = tracker.update([at(10.0, -5.0 + 1.4 * k * STEP_S, "onboard_lidar")], k * STEP_S)
    assert track.vy_mps == pytest.approx(1.4, abs=0.1)
    assert track.vx_mps == pytest.approx(0.0, abs=0.05)
    assert track.moving


def test_a_walking_person_under_v2i_noise_is_tracked_within_three_seconds():
    rng = np.random.default_rng(3)
    tracker = KalmanTracker()
    for k in range(61):
        nx, ny = rng.normal(0.0, 0.2, size=2)
        # V2I delivers the position of 0.1 s earlier.
        (track,) = tracker.update([at(nx, 1.4 * (k * STEP_S - 0.1) + ny)], k * STEP_S)
    assert track.vy_mps == pytest.approx(1.4, abs=0.3)
    assert track.moving


def test_v2i_latency_is_in_the_measurement_model():
    # Exact but 0.1 s old positions of a 1.4 m/s walker: taken as current, the estimate would lag by
    # 0.14 m; the filter's estimate at t is where the walker is at t.
    tracker = KalmanTracker(v2i_sigma_m=0.01)
    for k in range(41):
        t = k * STEP_S
        (track,) = tracker.update([at(1.4 * (t - 0.1), 0.0)], t)
    assert track.x_m == pytest.approx(1.4 * 40 * STEP_S, abs=0.03)


def test_a_lost_track_is_predicted_on_for_the_memory_then_dropped():
    tracker = KalmanTracker(memory_s=2.0)
    for k in range(21):
        tracker.update([at(0.0, 1.4 * k * STEP_S, "onboard_camera")], k * STEP_S)
    last_seen_s, last_y = 20 * STEP_S, 1.4 * 20 * STEP_S
    (kept,) = tracker.update([], last_seen_s + 1.9)
    assert kept.unseen_s == pytest.approx(1.9)
    # Moved on at about 1.4 m/s for 1.9 s (the velocity tracked when it was lost).
    assert kept.y_m == pytest.approx(last_y + 1.4 * 1.9, abs=0.2)
    assert tracker.update([], last_seen_s + 2.05) == []
