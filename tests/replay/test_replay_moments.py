"""Which step a screenshot shows: the moments of hand-built logs with answers worked out by hand.

Every log: the ego 4 m long and 2 m wide, heading east (yaw 0) along y = 0; the pedestrian a standing
circle of 0.3 m. Straight ahead of the ego the clearance is ped_x - ego_x - 2 - 0.3 and the TTC
clearance / ego speed; beside the path (|ped_x - ego_x| <= 2) the clearance is |ped_y| - 1 - 0.3 and
the TTC undefined (standing still beside the path, they never touch). The first and last steps have
the pedestrian out of the scene (NaN position), as the engine logs them before they appear and after
they leave.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pandas as pd
import pytest

from pedsafe_sumo.replay.__main__ import moment_step
from pedsafe_sumo.replay.moments import find_moment
from pedsafe_sumo.replay.rundir import ReplayError

NAN = math.nan
DESCRIBE = "jaywalking episode 1, condition sv, seed 7"


def _log(steps: list[tuple[float, float, float, float, float]]) -> pd.DataFrame:
    """One row per (ego_x, ego_speed, ped_x, ped_y, clearance) at t = 0.05, 0.10, ..."""
    n = len(steps)
    ego_x, speed, ped_x, ped_y, clearance = (list(c) for c in zip(*steps, strict=True))
    return pd.DataFrame(
        {
            "time_s": [0.05 * (i + 1) for i in range(n)],
            "ego_x_m": ego_x,
            "ego_y_m": [0.0] * n,
            "ego_yaw_rad": [0.0] * n,
            "ego_speed_mps": speed,
            "ego_length_m": [4.0] * n,
            "ego_width_m": [2.0] * n,
            "ped_x_m": ped_x,
            "ped_y_m": ped_y,
            "ped_vx_mps": [0.0 if math.isfinite(x) else NAN for x in ped_x],
            "ped_vy_mps": [0.0 if math.isfinite(x) else NAN for x in ped_x],
            "ped_radius_m": [0.3] * n,
            "detected_onboard_camera": [False] * n,
            "detected_onboard_lidar": [False] * n,
            "detected_roadside": [False] * n,
            "perceived": [False] * n,
            "clearance_m": clearance,
        }
    )


def collision_log() -> pd.DataFrame:
    # Clearances 7.7, 2.7, then -0.3 (touching) at index 3.
    return _log(
        [
            (-20.0, 10.0, NAN, NAN, NAN),
            (0.0, 10.0, 10.0, 0.0, 7.7),
            (5.0, 10.0, 10.0, 0.0, 2.7),
            (8.0, 10.0, 10.0, 0.0, -0.3),
            (9.0, 10.0, 10.0, 0.0, -1.3),
            (9.0, 0.0, NAN, NAN, NAN),
        ]
    )


def near_miss_log() -> pd.DataFrame:
    # TTC 7.7/10 = 0.77 s, 5.7/10 = 0.57 s, 3.7/2 = 1.85 s, then the pedestrian beside the path at
    # y = 2 (clearance 2 - 1 - 0.3 = 0.7 m, no TTC). Least TTC at index 2, closest approach at index 4.
    return _log(
        [
            (-20.0, 10.0, NAN, NAN, NAN),
            (0.0, 10.0, 10.0, 0.0, 7.7),
            (2.0, 10.0, 10.0, 0.0, 5.7),
            (4.0, 2.0, 10.0, 0.0, 3.7),
            (9.0, 2.0, 10.0, 2.0, 0.7),
            (12.0, 2.0, NAN, NAN, NAN),
        ]
    )


def passing_log() -> pd.DataFrame:
    # Pedestrian standing at (0, 5), beside the path all along: no TTC. Clearances: dx = 8 - 2 = 6 lengthwise
    # and dy = 5 - 1 = 4 -> sqrt(36 + 16) - 0.3 = 6.911; dx = 1 -> sqrt(1 + 16) - 0.3 = 3.823; alongside
    # -> 3.7; dx = 1 -> 3.823. Closest approach at index 3 (ego at x = 0).
    return _log(
        [
            (-12.0, 10.0, NAN, NAN, NAN),
            (-8.0, 10.0, 0.0, 5.0, math.sqrt(52) - 0.3),
            (-3.0, 10.0, 0.0, 5.0, math.sqrt(17) - 0.3),
            (0.0, 10.0, 0.0, 5.0, 3.7),
            (3.0, 10.0, 0.0, 5.0, math.sqrt(17) - 0.3),
            (8.0, 10.0, NAN, NAN, NAN),
        ]
    )


def test_default_is_the_collision_when_there_is_one():
    moment = find_moment(collision_log(), None, DESCRIBE)
    assert (moment.name, moment.step_index) == ("collision", 3)
    assert moment.line() == "screenshot at the collision, t = 0.20 s: clearance -0.30 m, ego at 10.00 m/s"


def test_default_without_collision_is_the_least_ttc():
    moment = find_moment(near_miss_log(), None, DESCRIBE)
    assert (moment.name, moment.step_index) == ("least-ttc", 2)
    assert moment.line() == "screenshot at the least TTC, t = 0.15 s: TTC 0.57 s, clearance 5.70 m"


def test_default_without_collision_or_ttc_is_the_closest_approach():
    moment = find_moment(passing_log(), None, DESCRIBE)
    assert (moment.name, moment.step_index) == ("closest-approach", 3)
    assert moment.line() == "screenshot at the closest approach, t = 0.20 s: clearance 3.70 m"


def test_closest_approach_skips_the_steps_without_the_pedestrian():
    assert find_moment(near_miss_log(), "closest-approach", DESCRIBE).step_index == 4


def test_least_ttc_stops_at_the_collision():
    # After the first contact the TTC is 0 at every step; the least TTC is the collision step's 0.
    moment = find_moment(collision_log(), "least-ttc", DESCRIBE)
    assert moment.step_index == 3
    assert moment.detail.startswith("TTC 0.00 s")


def test_a_moment_the_episode_does_not_have_names_those_it_has():
    with pytest.raises(ReplayError) as caught:
        find_moment(near_miss_log(), "collision", DESCRIBE)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith("there is no collision in jaywalking episode 1")
    assert "least-ttc (t = 0.15 s)" in message and "closest-approach (t = 0.25 s)" in message
    assert "first-detection" not in message  # never perceived
    with pytest.raises(ReplayError, match="never on a collision course.*closest-approach"):
        find_moment(passing_log(), "least-ttc", DESCRIBE)


def test_moment_step_keeps_its_phrase():
    logged = SimpleNamespace(describe=lambda: DESCRIBE)
    assert moment_step(near_miss_log(), "least-ttc", logged) == (2, "the least TTC")
