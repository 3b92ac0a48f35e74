"""research/experiments/is_local_roughness.py and is_model_reach.py: their
arithmetic against values worked by hand (no SUMO)."""

from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.sampling.importance import Beta, Normal

sys.path.insert(0, str(REPO_ROOT / "research" / "experiments"))


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, REPO_ROOT / "research" / "experiments" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


roughness = _load("is_local_roughness")
reach = _load("is_model_reach")


def test_a_moved_beta_input_is_reflected_into_its_range():
    family = Beta(1.0, 1.0, 30.0, 45.0)
    assert roughness.moved(40.0, family, 2.0) == pytest.approx(42.0)
    assert roughness.moved(44.0, family, 3.0) == pytest.approx(43.0)  # 47 -> 45 - 2
    assert roughness.moved(31.0, family, -4.0) == pytest.approx(33.0)  # 27 -> 30 + 3
    assert roughness.moved(1.0, Normal(0.0, 1.0), -5.0) == pytest.approx(-4.0)  # a normal is not bounded


def test_nominal_sd_of_the_families():
    assert roughness.nominal_sd(Normal(2.0, 0.5)) == 0.5
    assert roughness.nominal_sd(Beta(1.0, 1.0, -0.6, 0.6)) == pytest.approx(1.2 / math.sqrt(12.0))


def test_same_world_tolerates_a_last_bit_only():
    a = {"pedestrian": {"walking_speed_mps": 2.2913687603886315, "path_xy": ((1.0, 2.0),)}, "k": "x"}
    b = {"pedestrian": {"walking_speed_mps": 2.291368760388631, "path_xy": ((1.0, 2.0),)}, "k": "x"}
    assert roughness.same_world(a, b)
    b["pedestrian"]["walking_speed_mps"] = 2.2914
    assert not roughness.same_world(a, b)
    assert not roughness.same_world(a, {**a, "k": "y"})


def test_roughness_summary_by_hand():
    """Two collision episodes: one collides in 3 of 4 moves, the other in 4 of 4; with its own collision
    pi = 4/5 and 5/5, E[pi^-1/2 | Y=1] = (sqrt(5/4) + 1) / 2, ceiling (1 - P) / (P (that^2 - 1))."""
    rows = [{"episode": e, "delta": 0.0, "direction": 0, "collision": 1} for e in (1, 2)]
    rows += [{"episode": 1, "delta": 0.1, "direction": d, "collision": int(d != 0)} for d in range(4)]
    rows += [{"episode": 2, "delta": 0.1, "direction": d, "collision": 1} for d in range(4)]
    table = roughness.summarise(pd.DataFrame(rows), 0.05)
    inverse_root = (math.sqrt(5 / 4) + 1.0) / 2.0
    assert table.loc[0, "ceiling"] == pytest.approx(0.95 / (0.05 * (inverse_root**2 - 1.0)))
    assert table.loc[0, "moved runs that collide"] == pytest.approx(7 / 8)
    assert table.loc[0, "episodes that always collide"] == "1/2"


def test_model_reach_efficiencies_by_hand():
    """Four nominal rows, one collision, pi_hat = (0.5, 0.5, 0, 0): q/p = 0.1 + 0.9 sqrt(pi)/c with c =
    mean sqrt(pi) = sqrt(0.5)/2, so q/p = 1.9 on the first two rows; plain variance E[y / (q/p)] - P^2 =
    (1/1.9)/4 - 1/16; with the control variate E[(y - pi)^2 / (q/p)] - (P - E[pi])^2 = (0.25/1.9 +
    0.25/1.9)/4 - 0."""
    y = np.array([1.0, 0.0, 0.0, 0.0])
    pi = np.array([0.5, 0.5, 0.0, 0.0])
    plain, control = reach.efficiencies(pi, y, pi)
    p = 0.25
    assert plain == pytest.approx(p * (1 - p) / ((1 / 1.9) / 4 - p * p))
    assert control == pytest.approx(p * (1 - p) / ((0.25 / 1.9 + 0.25 / 1.9) / 4))
