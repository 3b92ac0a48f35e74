"""Which tracker the reference stack runs: the parameter file's choice, the older protocols' one."""

from __future__ import annotations

import pytest

from pedsafe_sumo import PROTOCOLS_DIR
from pedsafe_sumo.control.baseline import BaselineStack
from pedsafe_sumo.control.imm_tracker import ImmTracker
from pedsafe_sumo.control.kalman_tracker import KalmanTracker
from pedsafe_sumo.params import ParameterError, load_params, validate
from pedsafe_sumo.protocol import load_protocol


def test_the_parameter_file_chooses_the_imm_tracker():
    assert load_params(None)["algorithm"]["tracker_motion_model"] == "imm"


@pytest.mark.parametrize("name", ["paper-v7", "approach-v1", "approach-v2"])
def test_protocols_that_do_not_name_it_run_the_constant_velocity_tracker(name):
    path = PROTOCOLS_DIR / f"{name}.toml"
    if not path.is_file():
        pytest.skip(f"{name} not shipped")
    assert "tracker_motion_model" not in path.read_text()
    assert load_protocol(path).params()["algorithm"]["tracker_motion_model"] == "cv"


def test_the_stack_builds_the_tracker_it_is_told():
    for model, cls in (("imm", ImmTracker), ("cv", KalmanTracker)):
        agent = BaselineStack()
        agent.setup({"initial_speed_mps": 10.0, "tracker_motion_model": model})
        assert type(agent.tracker) is cls
    agent = BaselineStack()
    agent.setup({"initial_speed_mps": 10.0})  # a config from before the parameter
    assert type(agent.tracker) is KalmanTracker


def test_an_unknown_tracker_in_the_parameter_file_is_refused():
    params = load_params(None)
    params["algorithm"]["tracker_motion_model"] = "ca"
    with pytest.raises(ParameterError, match="tracker_motion_model must be one of cv, imm"):
        validate(params)
