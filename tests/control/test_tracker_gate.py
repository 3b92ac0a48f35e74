"""The trackers' validation gate: a position that cannot have come from a track's estimate, and is more
precise than it ("precise"; "reinitialise": any such position), starts the track afresh.

The gate's arithmetic is worked by hand on the constant-velocity filter's second position; the hand-over
from V2I positions to onboard ones, where an estimate lagging a pedestrian who has just stepped off meets
the first exact position a metre ahead, on synthetic positions whose truth is known.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.control.agent import PerceivedPedestrian
from pedsafe_sumo.control.baseline import BaselineStack
from pedsafe_sumo.control.imm_tracker import ImmTracker
from pedsafe_sumo.control.kalman_tracker import GATE_CHI2, KalmanTracker

STEP_S = 0.05
#: chi-square(2) at 99.9 % (tables: -2 ln 0.001 = 13.8155).
CHI2_999 = -2 * math.log(0.001)


def onboard(x, y=0.0):
    return PerceivedPedestrian("p", x, y, "onboard_camera")


def v2i(x, y=0.0):
    return PerceivedPedestrian("p", x, y, "v2i")


def second_position_gate_m() -> float:
    """Radius of the gate around a track started from one onboard position (0.01 m noise, velocity prior
    1.5 m/s per axis), 0.05 s later: S = 1e-4 + dt^2 1.5^2 + q dt^3 / 3 (predicted position variance,
    q = 0.01) + 1e-4 (the new position's noise); the gate is |z - x|^2 / S <= chi2."""
    s = 1e-4 + STEP_S**2 * 1.5**2 + 0.01 * STEP_S**3 / 3 + 1e-4
    return math.sqrt(CHI2_999 * s)


def test_the_gate_is_the_999_quantile_of_chi_square_with_two_degrees_of_freedom():
    assert GATE_CHI2 == pytest.approx(CHI2_999, abs=1e-3)


@pytest.mark.parametrize("precise_only", [False, True])
@pytest.mark.parametrize("tracker_class", [KalmanTracker, ImmTracker])
def test_a_position_just_inside_the_gate_is_folded_in_and_one_just_outside_starts_the_track_afresh(
    tracker_class, precise_only
):
    # The onboard position's variance (1e-4 m2) is far below the predicted one (about 0.0057 m2): under
    # "precise" too, one outside the gate restarts the track.
    radius = second_position_gate_m()  # 0.284 m
    assert radius == pytest.approx(0.2837, abs=1e-3)
    inside = tracker_class(gate_chi2=GATE_CHI2, gate_precise_only=precise_only)
    inside.update([onboard(0.0)], 0.0)
    track = inside.update([onboard(0.97 * radius)], STEP_S)[0]
    # Folded in: the velocity is taken up from the two positions (far from the prior's 0).
    assert track.vx_mps > 3.0
    outside = tracker_class(gate_chi2=GATE_CHI2, gate_precise_only=precise_only)
    outside.update([onboard(0.0)], 0.0)
    track = outside.update([onboard(1.03 * radius)], STEP_S)[0]
    # Started afresh: exactly at the new position, with the prior's zero velocity.
    assert (track.x_m, track.vx_mps) == (1.03 * radius, 0.0)
    # The IMM tracker's standing model is narrower still: the walking model's gate decides; without a
    # gate the same position is folded in.
    ungated = tracker_class()
    ungated.update([onboard(0.0)], 0.0)
    assert ungated.update([onboard(1.03 * radius)], STEP_S)[0].vx_mps > 3.0


def hand_over(tracker: ImmTracker, walk_mps: float, onboard_after_s: float, seed: int) -> list:
    """A person standing 10 s at x = 0 seen over V2I alone (the true position 0.1 s earlier plus 0.2 m noise
    per axis), who then walks along x at `walk_mps`; from `onboard_after_s` after the step-off the onboard
    sensors measure them exactly. The tracks of the first 1.5 s after the step-off, as (t after the
    step-off, true x, track)."""
    rng = np.random.default_rng(seed)
    start_s = 10.0
    out = []
    for k in range(1, int((start_s + 1.5) / STEP_S) + 1):
        t = round(k * STEP_S, 6)

        def true_x(at_s: float) -> float:
            return max(0.0, at_s - start_s) * walk_mps

        if t >= start_s + onboard_after_s - 1e-9:
            seen = [onboard(true_x(t))]
        else:
            seen = [v2i(true_x(t - 0.1) + rng.normal(0, 0.2), rng.normal(0, 0.2))]
        track = tracker.update(seen, t)[0]
        if t > start_s:
            out.append((t - start_s, true_x(t), track))
    return out


@pytest.mark.parametrize("precise_only", [False, True])
@pytest.mark.parametrize("seed", range(10))
def test_a_walker_handed_over_from_v2i_to_onboard_sensors_is_moving_within_two_steps(seed, precise_only):
    # 1.4 m/s (a usual walk), onboard positions from 0.6 s after the step-off: the V2I-built estimate
    # lags by then (the person is 0.84 m out; a V2I position is 0.14 m behind them and the filter takes
    # about a second to take up the start), the first onboard position is outside its gate, the track
    # restarts there and its second onboard position gives the velocity (1.4 m/s against the prior's
    # 1.5 m/s standard deviation: moving at 99.9 % from the second exact position).
    steps = hand_over(ImmTracker(gate_chi2=GATE_CHI2, gate_precise_only=precise_only), 1.4, 0.6, seed)
    after_onboard = [(dt, x, tr) for dt, x, tr in steps if dt >= 0.6 - 1e-9]
    moving_from = next(dt for dt, _, tr in after_onboard if tr.moving)
    assert moving_from <= 0.6 + 2 * STEP_S + 1e-9
    for dt, x, tr in after_onboard:
        if dt >= moving_from + 2 * STEP_S:
            assert tr.moving
            assert tr.x_m == pytest.approx(x, abs=0.02)
            assert tr.vx_mps == pytest.approx(1.4, abs=0.1)


def test_without_the_gate_the_same_walker_can_be_held_standing_while_measured_walking():
    # The failure the gate removes, at 2.35 m/s (a brisk crossing): the lagging estimate meets the first
    # exact position; without the gate the standing model explains it best, then both models' covariances
    # collapse onto the exact positions and the walker stays "standing" for the rest of the 1.5 s.
    held = 0
    for seed in range(10):
        steps = hand_over(ImmTracker(), 2.35, 0.65, seed)
        if not any(tr.moving for dt, _, tr in steps if dt >= 0.65 + 0.5):
            held += 1
    assert held >= 1


def v2i_start_tracks(tracker: ImmTracker, seed: int) -> list[tuple[float, float, float, float]]:
    """The track estimates over a stander's start seen over V2I alone: 5 s standing, then 1.4 m/s."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(1, 161):
        t = k * STEP_S
        x = 1.4 * max(t - 0.1 - 5.0, 0.0) + rng.normal(0, 0.2)
        (track,) = tracker.update([v2i(x, rng.normal(0, 0.2))], t)
        out.append((track.x_m, track.y_m, track.vx_mps, track.vy_mps))
    return out


@pytest.mark.parametrize("seed", range(10))
def test_under_precise_a_v2i_position_outside_the_gate_is_folded_in_as_without_a_gate(seed):
    # A V2I position's variance (0.04 m2) is above a converged track's predicted one (under 0.01 m2): under
    # "precise" it never restarts the track, whose estimates are then those of the ungated filter, step for
    # step; "reinitialise" restarts on the lagging estimate of the start in some of these draws.
    ungated = v2i_start_tracks(ImmTracker(), seed)
    assert v2i_start_tracks(ImmTracker(gate_chi2=GATE_CHI2, gate_precise_only=True), seed) == ungated


def test_reinitialise_restarts_on_v2i_positions_where_precise_does_not():
    restarted = sum(
        v2i_start_tracks(ImmTracker(gate_chi2=GATE_CHI2), seed) != v2i_start_tracks(ImmTracker(), seed)
        for seed in range(10)
    )
    assert restarted >= 1


@pytest.mark.parametrize("seed", range(5))
def test_a_person_standing_under_v2i_noise_is_never_told_moving_with_the_gate(seed):
    # A V2I position outside the gate happens about once in 1,000 steps (the gate's probability): the
    # track restarts with an unknown velocity, which the 99.9 % "moving" test does not take for motion.
    rng = np.random.default_rng(seed)
    tracker = ImmTracker(gate_chi2=GATE_CHI2)
    for k in range(1, 1201):  # 60 s
        track = tracker.update([v2i(rng.normal(0, 0.2), rng.normal(0, 0.2))], k * STEP_S)[0]
        assert not track.moving


def test_the_stack_takes_the_gate_from_its_config_and_refuses_an_unknown_one():
    stack = BaselineStack()
    stack.setup({"initial_speed_mps": 10.0, "tracker_motion_model": "imm", "tracker_gate": "reinitialise"})
    assert stack.tracker.gate_chi2 == GATE_CHI2 and not stack.tracker.gate_precise_only
    stack.setup({"initial_speed_mps": 10.0, "tracker_motion_model": "cv", "tracker_gate": "precise"})
    assert stack.tracker.gate_chi2 == GATE_CHI2 and stack.tracker.gate_precise_only
    stack.setup({"initial_speed_mps": 10.0})  # a config from before the key existed: no gate
    assert stack.tracker.gate_chi2 is None
    with pytest.raises(ValueError, match="tracker_gate"):
        stack.setup({"initial_speed_mps": 10.0, "tracker_gate": "sometimes"})
