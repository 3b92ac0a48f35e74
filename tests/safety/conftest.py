"""Fixtures: the two standard encounters of `safety_logs`."""

from __future__ import annotations

import pandas as pd
import pytest
from safety_logs import crossing_log


@pytest.fixture
def collision_log() -> pd.DataFrame:
    """Both centres reach the origin at t = 2 s (ego from x = -20 m, pedestrian from y = -3 m)."""
    return crossing_log(-20.0, -3.0)


@pytest.fixture
def near_miss_log() -> pd.DataFrame:
    """The pedestrian reaches the origin at 2.0 s, the ego centre at 3.1 s (from x = -31 m): no contact."""
    return crossing_log(-31.0, -3.0)
