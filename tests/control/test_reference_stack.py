"""The reference AD stack and the agent loader, with answers worked out by hand."""

from __future__ import annotations

import math

import pytest

from pedsafe_sumo.control.agent import (
    AlgorithmLoadError,
    Command,
    EgoState,
    Observation,
    PerceivedPedestrian,
    load_agent_class,
)
from pedsafe_sumo.control.reference import ReferenceStack, TrackedPedestrian, Tracker, predict_threat

EGO = EgoState(x_m=0.0, y_m=0.0, yaw_rad=0.0, speed_mps=10.0, length_m=4.5, width_m=1.8)


def ped(x, y, vx=0.0, vy=0.0):
    return TrackedPedestrian("p", x, y, vx, vy)


def seen(x, y):
    return PerceivedPedestrian("p", x, y, "onboard_camera")


def obs(*peds, speed=10.0):
    ego = EgoState(EGO.x_m, EGO.y_m, EGO.yaw_rad, speed, EGO.length_m, EGO.width_m)
    return Observation(ego, tuple(peds), step_length_s=0.05)


def test_tracker_recovers_a_constant_velocity_from_noisy_positions():
    # Walking +y at 1.5 m/s with +-0.2 m alternating noise; the least-squares slope over 0.5 s (11
    # samples) is 1.5 plus the slope of the noise pattern, small against the 0.2 / 0.05 = 4 m/s a
    # one-step difference would show.
    tracker = Tracker(window_s=0.5)
    for k in range(11):
        noise = 0.2 if k % 2 else -0.2
        (track,) = tracker.update([seen(30.0, -6.0 + 1.5 * 0.05 * k + noise)], 0.05 * k)
    assert track.vy_mps == pytest.approx(1.5, abs=0.6) and track.vx_mps == pytest.approx(0.0)
    # One sighting only: no motion estimate yet.
    (first,) = Tracker(0.5).update([seen(1.0, 2.0)], 0.0)
    assert (first.vx_mps, first.vy_mps) == (0.0, 0.0)


def test_pedestrian_standing_in_the_path_is_a_threat_at_its_gap():
    threat = predict_threat(obs(ped(30, 0)), ped(30, 0), horizon_s=4.0, lateral_margin_m=0.5)
    # Gap from the ego's front (2.25 m ahead of its centre) to the pedestrian: 30 - 2.25.
    assert threat.gap_m == pytest.approx(27.75) and threat.time_s == 0.0


def test_crossing_pedestrian_enters_the_corridor_when_expected():
    # Corridor half width 0.9 + 0.5 = 1.4 m; pedestrian 5 m to the right walking left at 1.5 m/s:
    # enters at (5 - 1.4) / 1.5 = 2.4 s. At 5 m/s the ego has covered 12 m by then, its front is at
    # 14.25 m, still short of the pedestrian at 20 m: a threat.
    p = ped(20, -5, vy=1.5)
    threat = predict_threat(obs(p, speed=5.0), p, horizon_s=4.0, lateral_margin_m=0.5)
    assert threat.time_s == pytest.approx(2.4)
    # At 10 m/s the ego is 24 m on by then, past the pedestrian: no threat.
    assert predict_threat(obs(p, speed=10.0), p, horizon_s=4.0, lateral_margin_m=0.5) is None
    # 8 m to the right: (8 - 1.4) / 1.5 = 4.4 s, beyond a 4 s horizon.
    far = ped(20, -8, vy=1.5)
    assert predict_threat(obs(far), far, horizon_s=4.0, lateral_margin_m=0.5) is None
    # Walking away from the path, or already behind the ego: no threat.
    away = ped(20, -2, vy=-1.5)
    assert predict_threat(obs(away), away, horizon_s=4.0, lateral_margin_m=0.5) is None
    behind = ped(-10, 0)
    assert predict_threat(obs(behind), behind, horizon_s=4.0, lateral_margin_m=0.5) is None


def test_brakes_only_after_the_reaction_time_then_with_the_stopping_deceleration():
    stack = ReferenceStack()
    stack.setup(
        {"initial_speed_mps": 10.0, "reaction_time_s": 0.4, "max_decel_mps2": 6.0, "stop_margin_m": 2.0}
    )
    p = seen(30, 0)
    # t = 0.0 .. 0.35: threat perceived, reaction time running: speed held at 10 m/s.
    for k in range(8):
        command = stack.run_step(obs(p), 0.05 * k)
        assert command.target_speed_mps == pytest.approx(10.0), k
    # t = 0.40: braking with v^2 / (2 (gap - margin)) = 100 / (2 * 25.75) = 1.9417 m/s2.
    command = stack.run_step(obs(p), 0.40)
    assert command.info["decel_mps2"] == pytest.approx(100 / 51.5)
    assert command.target_speed_mps == pytest.approx(10.0 - 0.05 * 100 / 51.5)


def test_braking_is_capped_at_the_maximum_deceleration_and_resumes_once_clear():
    stack = ReferenceStack()
    stack.setup({"initial_speed_mps": 12.0, "reaction_time_s": 0.0, "max_decel_mps2": 6.0})
    p = seen(6, 0)  # gap 3.75 m, room 1.75 m: needs 144 / 3.5 = 41 m/s2 -> capped at 6
    command = stack.run_step(obs(p, speed=12.0), 0.0)
    assert command.info["decel_mps2"] == 6.0
    assert command.target_speed_mps == pytest.approx(12.0 - 6.0 * 0.05)
    # Pedestrian gone: still braking during the 0.5 s hold, then accelerating at 2 m/s2.
    assert stack.run_step(obs(speed=5.0), 0.3).info["braking"] is True
    resumed = stack.run_step(obs(speed=5.0), 0.6)
    assert resumed.info["braking"] is False and resumed.target_speed_mps == pytest.approx(5.0 + 2.0 * 0.05)


class _Plugin:
    def setup(self, config):
        pass

    def sensors(self):
        return ["onboard_camera"]

    def run_step(self, observation, time_s):
        return Command(0.0)

    def close(self):
        pass


class _NoRunStep:
    def setup(self, config):
        pass

    def sensors(self):
        return []

    def close(self):
        pass


def test_loader_accepts_a_duck_typed_class_and_the_reference_stack():
    assert load_agent_class("pedsafe_sumo.control.reference:ReferenceStack") is ReferenceStack
    assert load_agent_class(f"{__name__}:_Plugin") is _Plugin


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("no_colon_here", "package.module:ClassName"),
        ("no_such_pkg.mod:Agent", "cannot import module 'no_such_pkg.mod'"),
        ("pedsafe_sumo.control.reference:Nope", "has no class 'Nope'"),
        (f"{__name__}:_NoRunStep", "missing run_step"),
    ],
)
def test_loader_rejects_broken_paths_with_one_line(spec, message):
    with pytest.raises(AlgorithmLoadError, match=message) as info:
        load_agent_class(spec)
    assert "\n" not in str(info.value)


def test_stopping_distance_check_by_hand():
    # Sanity of the braking law: from 10 m/s at 1.9417 m/s2 the ego stops in 100 / (2 * 1.9417) =
    # 25.75 m, i.e. exactly the stop margin (2 m) short of the pedestrian's gap (27.75 m).
    assert 100 / (2 * (100 / 51.5)) == pytest.approx(25.75)
    assert math.isclose(27.75 - 25.75, 2.0)
