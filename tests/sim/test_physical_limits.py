"""The ego's physical limits ([vehicle] in the parameter file): whatever the AD stack commands, the speed
changes each step by at most max_decel_mps2 x step down and max_accel_mps2 x step up; the log keeps the
command as commanded. Without them (physical_limits false, as protocols written before them run) the ego
takes the command in one step."""

from __future__ import annotations

import numpy as np
import pytest

from pedsafe_sumo.control.agent import Agent, Command
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params, with_overrides
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim.episode import EpisodeRunner

STEP_S = 0.05


class StopsThenSprints(Agent):
    """Commands 0 m/s for the first second, then 30 m/s."""

    def run_step(self, observation, time_s):
        return Command(0.0 if time_s < 1.0 else 30.0)


def _log(params):
    runner = EpisodeRunner(get_site("xueqing"), params, StopsThenSprints)
    try:
        spec = get_scenario("jaywalking").with_overrides({"background_traffic": 0, "time_limit_s": 2.0})
        return runner.run(spec, "sv", 4).log
    finally:
        runner.close()


@pytest.mark.slow
def test_the_ego_brakes_and_accelerates_no_harder_than_a_car_can():
    params = load_params()
    decel, accel = params["vehicle"]["max_decel_mps2"], params["vehicle"]["max_accel_mps2"]
    log = _log(params)
    speed = log["ego_speed_mps"].to_numpy()
    change = np.diff(speed)
    braking = log["time_s"].to_numpy()[1:] <= 1.0
    v0 = speed[0]
    # By hand: from v0 the speed falls by 9 m/s2 x 0.05 s = 0.45 m/s a step until it reaches 0.
    expected = np.maximum(v0 - decel * STEP_S * np.arange(1, braking.sum() + 1), 0.0)
    np.testing.assert_allclose(speed[1 : braking.sum() + 1], expected, atol=1e-6)
    # Then up by at most 4 m/s2 x 0.05 s = 0.2 m/s a step, never the commanded jump to 30 m/s.
    assert change[~braking].max() <= accel * STEP_S + 1e-6
    assert change[~braking].max() >= accel * STEP_S - 1e-6
    # The log keeps what was commanded.
    assert set(np.round(log["command_speed_mps"], 6)) == {0.0, 30.0}


@pytest.mark.slow
def test_without_the_limits_the_ego_takes_the_command_in_one_step():
    log = _log(with_overrides(load_params(), {"vehicle.physical_limits": False}))
    speed = log["ego_speed_mps"].to_numpy()
    assert speed[0] > 1.0 and speed[1] == 0.0
    after = log["time_s"].to_numpy() > 1.0 + STEP_S
    assert np.allclose(speed[after], 30.0)
