"""Fixtures of the perception tests (scene helpers live in perception_scenes.py)."""

from __future__ import annotations

import pytest

from pedsafe_sumo.params import load_params


@pytest.fixture
def params():
    return load_params()


@pytest.fixture
def suite(params):
    from perception_scenes import make_suite

    return make_suite(params)
