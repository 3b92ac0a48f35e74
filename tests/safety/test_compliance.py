"""Compliance columns on hand-built step logs whose answers are worked out by hand."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo.safety.compliance import episode_compliance, false_brake, standing_duration_s, stop_line_of

STEP_S = 0.05
# A 4 m x 1.8 m ego driving east along y = 0 at 10 m/s from x = 0 (0.5 m a step); its front is 2 m
# ahead of its centre. The stop line: the end of a lane drawn from (-100, 0) to (50, 0).
LINE = stop_line_of([(-100.0, 0.0), (50.0, 0.0)])


def drive(n=150, speed=10.0, ped=(30.0, 5.0), ped_v=(0.0, 0.0), braking=False, command=None):
    rows = []
    for k in range(n):
        rows.append(
            {
                "time_s": k * STEP_S,
                "ego_x_m": speed * k * STEP_S,
                "ego_y_m": 0.0,
                "ego_yaw_rad": 0.0,
                "ego_speed_mps": speed,
                "ego_length_m": 4.0,
                "ego_width_m": 1.8,
                "ped_x_m": ped[0],
                "ped_y_m": ped[1],
                "ped_vx_mps": ped_v[0],
                "ped_vy_mps": ped_v[1],
                "ped_radius_m": 0.3,
                "perceived": True,
                "command_speed_mps": speed if command is None else command,
                "braking": braking,
            }
        )
    return pd.DataFrame(rows)


def colours(n, yellow_from=None, red_from=None):
    out = []
    for k in range(n):
        if red_from is not None and k >= red_from:
            out.append("red")
        elif yellow_from is not None and k >= yellow_from:
            out.append("yellow")
        else:
            out.append("green")
    return out


def test_stop_line_is_the_lane_end_and_its_direction():
    assert LINE == ((50.0, 0.0), (1.0, 0.0))


def test_signal_when_the_front_crosses_the_line():
    # The front (x + 2) reaches 50 m at x = 48: step 96. Yellow from step 90 (front at 47 m).
    log = drive()
    n = len(log)
    assert episode_compliance(log, colours(n, 90), ["red"] * n, LINE)["stopline_signal"] == "yellow"
    assert episode_compliance(log, colours(n, 97), ["red"] * n, LINE)["stopline_signal"] == "green"
    assert episode_compliance(log, colours(n, 40, 96), ["red"] * n, LINE)["stopline_signal"] == "red"
    # Never crossed (30 steps: the front at 16.5 m at most), or no stop line: none.
    short = drive(n=30)
    assert episode_compliance(short, colours(30), ["red"] * 30, LINE)["stopline_signal"] == "none"
    assert episode_compliance(log, colours(n), ["red"] * n, None)["stopline_signal"] == "none"


@pytest.mark.parametrize(
    ("yellow_from", "could"),
    [
        # 10 m/s: 100 / (2 x 3) = 16.67 m to stop. Step 90: front at 47 m, 3 m from the line: no.
        (90, False),
        # Step 60: front at 32 m, 18 m from the line: yes. Step 64: front at 34 m, 16 m: no.
        (60, True),
        (64, False),
        # Step 20: front at 12 m, 38 m: yes.
        (20, True),
    ],
)
def test_could_stop_at_the_yellow_onset(yellow_from, could):
    log = drive()
    n = len(log)
    result = episode_compliance(log, colours(n, yellow_from), ["red"] * n, LINE)
    assert result["could_stop_at_yellow"] is could


def test_no_yellow_before_crossing_is_unknown():
    log = drive()
    n = len(log)
    assert episode_compliance(log, colours(n), ["red"] * n, LINE)["could_stop_at_yellow"] is None
    # Yellow only after the front crossed (step 96): unknown too.
    assert episode_compliance(log, colours(n, 100), ["red"] * n, LINE)["could_stop_at_yellow"] is None


def fb(log, ego_colours=None, ped_colours=None):
    n = len(log)
    return episode_compliance(log, ego_colours or ["green"] * n, ped_colours or ["red"] * n, None)[
        "false_brake"
    ]


def test_braking_for_someone_standing_beside_the_path_is_a_false_brake():
    # Standing 5 m left of the heading line: beyond 0.9 + 0.3 + 0.5 = 1.7 m.
    assert fb(drive(n=20, ped=(30.0, 5.0), braking=True)) is True
    # 1.6 m to the left: inside the corridor, braking is right.
    assert fb(drive(n=20, ped=(30.0, 1.6), braking=True)) is False
    # Walking (1.4 m/s): not standing.
    assert fb(drive(n=20, ped=(30.0, 5.0), ped_v=(0.0, -1.4), braking=True)) is False
    # Not braking.
    assert fb(drive(n=20, ped=(30.0, 5.0))) is False
    # Standing in its lane 10 m behind the ego's start (behind its rear at every step): outside its path.
    assert fb(drive(n=20, ped=(-10.0, 0.0), braking=True)) is True


def test_a_command_below_the_speed_is_braking_even_unflagged():
    # 1 m/s2 x 0.05 s = 0.05 m/s below the speed is braking; 0.04 is not.
    assert fb(drive(n=20, ped=(30.0, 5.0), command=10.0 - 0.06)) is True
    assert fb(drive(n=20, ped=(30.0, 5.0), command=10.0 - 0.04)) is False


def test_braking_for_a_signal_or_for_someone_on_walk_is_not_false():
    n = 20
    log = drive(n=n, ped=(30.0, 5.0), braking=True)
    # Yellow ahead (front before the line the whole time: no line given, so every step is before it).
    assert fb(log, ego_colours=["yellow"] * n) is False
    assert fb(log, ego_colours=["red"] * n) is False
    # The pedestrian has walk: yielding to someone about to cross.
    assert fb(log, ped_colours=["green"] * n) is False
    # Not perceived: the stack cannot have braked for them.
    unseen = log.assign(perceived=False)
    assert fb(unseen) is False


def test_an_empty_log_has_no_false_brake_and_no_crossing():
    empty = drive(n=1).iloc[:0]
    assert false_brake(empty, [], [], empty["time_s"].to_numpy() > 0) is False
    result = episode_compliance(empty, [], [], LINE)
    assert result == {"false_brake": False, "stopline_signal": "none", "could_stop_at_yellow": None}


def walks_then_stands(n, stop_step, brake_steps, ped_y_at_stop=5.0):
    """A pedestrian 30 m ahead walks towards the ego's path (south, 1.4 m/s) until step `stop_step - 1`
    and stands 5 m left of its heading line from `stop_step` on; the ego brakes at `brake_steps` only."""
    log = drive(n=n, ped=(30.0, ped_y_at_stop))
    walking = log.index < stop_step
    log.loc[walking, "ped_vy_mps"] = -1.4
    log.loc[walking, "ped_y_m"] = ped_y_at_stop + 1.4 * STEP_S * (stop_step - log.index[walking])
    log["braking"] = log.index.isin(brake_steps)
    return log


def test_standing_duration_counts_from_the_last_moving_step():
    time_s = np.arange(6) * STEP_S
    # Moves at steps 0 and 1, stands from step 2: 0, 0, 0.05, 0.10, 0.15, 0.20 (since step 1, 0.05 s).
    standing = np.array([False, False, True, True, True, True])
    present = np.ones(6, dtype=bool)
    assert standing_duration_s(time_s, standing, present) == pytest.approx([0, 0, 0.05, 0.10, 0.15, 0.20])
    # Standing from the first step: never seen moving, so stood "forever" at every step.
    assert np.all(np.isinf(standing_duration_s(time_s, np.ones(6, dtype=bool), present)))
    # Not in the scene at steps 0-2, standing once there: 0 while absent, then infinite.
    absent_first = np.array([False, False, False, True, True, True])
    got = standing_duration_s(time_s, np.ones(6, dtype=bool), absent_first)
    assert list(got[:3]) == [0, 0, 0] and np.all(np.isinf(got[3:]))
    # Walks at step 3 only (stands before and after it): 0 at step 3, then 0.05 and 0.10.
    walk_once = np.array([True, True, True, False, True, True])
    got = standing_duration_s(time_s, walk_once, present)
    assert np.all(np.isinf(got[:3])) and got[3:] == pytest.approx([0, 0.05, 0.10])


def test_braking_just_after_a_pedestrian_stopped_is_not_false():
    # Walked until step 39 (1.95 s), stands from step 40 (2.00 s). Braking at step 43 (2.15 s): they had
    # stood 2.15 - 1.95 = 0.20 s, under the 1 s a stop takes to be told: not a false brake.
    assert fb(walks_then_stands(n=120, stop_step=40, brake_steps=[43])) is False
    # Braking through steps 40-58 (up to 2.90 s: stood 0.95 s at most): still not.
    assert fb(walks_then_stands(n=120, stop_step=40, brake_steps=range(40, 59))) is False
    # Braking on at step 59 (2.95 s: stood 2.95 - 1.95 = 1.00 s): a false brake.
    assert fb(walks_then_stands(n=120, stop_step=40, brake_steps=range(40, 60))) is True


def test_braking_for_someone_who_stood_throughout_is_false():
    # Standing 5 m left of the heading line from the first step (t = 0), never seen moving: braking at
    # any step is a false brake, even the first (no stop to be told).
    log = drive(n=60, ped=(30.0, 5.0))
    for step in (0, 5, 30):
        log["braking"] = log.index == step
        assert fb(log) is True
