"""research/experiments/is_pihat_shape.py: the braking margin against the stopping-distance condition, and the
speeds it computes from the proposable inputs against defaults.toml's own numbers (no SUMO)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pandas as pd
from scipy import special

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.specs import get_scenario

_spec = importlib.util.spec_from_file_location(
    "is_pihat_shape", REPO_ROOT / "research" / "experiments" / "is_pihat_shape.py"
)
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)


def test_braking_margin_by_hand() -> None:
    # 0.2 s offset + 2.3 m / 1.15 m/s = 2.2 s available; 0.4 s reaction + 10 / (2 * 6) s braking = 1.2333 s.
    margin = tool.braking_margin_s(np.array([0.2]), np.array([10.0]), np.array([1.15]), 0.4, 6.0, 2.3)
    assert np.isclose(margin[0], 2.2 - 0.4 - 10.0 / 12.0)


def test_negative_margin_is_a_stopping_distance_beyond_the_distance_left() -> None:
    rng = np.random.default_rng(3)
    offset, v, w = rng.uniform(-0.6, 0.6, 5000), rng.uniform(2, 20, 5000), rng.uniform(0.6, 3, 5000)
    margin = tool.braking_margin_s(offset, v, w, 0.4, 6.0, 2.3)
    # The ego's distance to the conflict point when the pedestrian is 2.3 m before it, against the
    # distance it needs to stop: reaction at speed, then v^2 / (2 a).
    distance_left_m = v * (offset + 2.3 / w)
    stopping_m = v * 0.4 + v * v / (2 * 6.0)
    assert np.array_equal(margin < 0, stopping_m > distance_left_m)


def test_speeds_follow_the_clip_and_the_age_groups_lognormal() -> None:
    params = load_params()
    spec = get_scenario("jaywalking")
    groups = list(params["pedestrians"]["age_groups"].values())
    z15 = float(special.ndtri(0.15))
    inputs = pd.DataFrame(
        {
            "ego_speed_log": [np.log(1e3), np.log(1e-3), np.log(8.0), np.log(8.0)],
            "ped_age_group": [0, 1, 2, 3],
            "ped_walking_speed_z": [z15, z15, z15, z15],
        }
    )
    v, w = tool.speeds_of(inputs, "jaywalking", params)
    assert np.allclose(v, [spec.ego_speed_max_mps, spec.ego_speed_min_mps, 8.0, 8.0])
    # z at the normal's 15th percentile gives each group's 15th-percentile walking speed of defaults.toml.
    assert np.allclose(w, [g["speed_p15_mps"] for g in groups], rtol=1e-6)
