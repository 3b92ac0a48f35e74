"""Injury models: hand-computed values, units, the registry, and monotonicity of every model."""

from __future__ import annotations

import numpy as np
import pytest

from pedsafe_sumo.safety.injury import (
    INJURY_MODELS,
    InjuryModel,
    episode_injury,
    injury_probability,
    register_injury_model,
)


def test_saade2020_at_36_kmh_age_30():
    # 10 m/s = 36 km/h. logit = -2.9893 + 0.0013 * 36^2 + 0.0286 * 30
    #                         = -2.9893 + 0.0013 * 1296 + 0.858 = -2.9893 + 1.6848 + 0.858 = -0.4465
    # e^0.4465 = e^0.4 * e^0.0465 = 1.491825 * 1.047598 = 1.562833; P = 1 / (1 + 1.562833) = 0.390193
    assert injury_probability(10.0, 30.0) == pytest.approx(0.390193, abs=1e-6)


def test_speed_is_converted_from_mps_to_kmh():
    # Had 10 m/s gone in as V = 10: logit = -2.9893 + 0.0013 * 100 + 0.858 = -2.0013,
    # P = 1 / (1 + e^2.0013) = 1 / (1 + 7.389056 * 1.001301) = 1 / 8.398670 = 0.119067 - a third of the truth.
    got = injury_probability(10.0, 30.0)
    assert got != pytest.approx(0.119067, abs=1e-3)
    assert injury_probability(10.0 / 3.6, 30.0) == pytest.approx(0.119067, abs=1e-6)


def test_rosen_sander2009_at_36_kmh_age_30():
    # logit = -9.1 + 0.095 * 36 + 0.040 * 30 = -9.1 + 3.42 + 1.2 = -4.48
    # e^4.48 = e^4 * e^0.48 = 54.59815 * 1.616074 = 88.23466; P = 1 / 89.23466 = 0.011206
    assert injury_probability(10.0, 30.0, model="rosen_sander2009") == pytest.approx(0.011206, abs=1e-6)


def test_unknown_model_names_the_known_ones():
    with pytest.raises(ValueError, match="unknown injury model 'euroncap'.*rosen_sander2009, saade2020"):
        injury_probability(10.0, 30.0, model="euroncap")


def test_negative_inputs_are_rejected():
    with pytest.raises(ValueError, match="impact speed must not be negative"):
        injury_probability(-1.0, 30.0)
    with pytest.raises(ValueError, match="age must not be negative"):
        injury_probability(1.0, -3.0)


@pytest.mark.parametrize("name", sorted(INJURY_MODELS))
def test_every_model_rises_with_speed_and_with_age(name):
    speeds = np.linspace(0.0, 25.0, 26)
    ages = np.linspace(12.0, 90.0, 27)
    by_speed = injury_probability(speeds, 40.0, model=name)
    by_age = injury_probability(15.0, ages, model=name)
    assert np.all(np.diff(by_speed) > 0) and np.all(np.diff(by_age) > 0)
    assert np.all((by_speed > 0) & (by_speed < 1))


def test_episode_injury_is_zero_without_a_collision():
    # eq. 4: P_I = p_collision * sigmoid(...), with p_collision = 0
    assert episode_injury(False, float("nan"), 30.0) == 0.0
    assert episode_injury(True, 10.0, 30.0) == pytest.approx(0.390193, abs=1e-6)
    with pytest.raises(ValueError, match="unknown injury model"):
        episode_injury(False, float("nan"), 30.0, model="nope")


def test_a_plugin_model_registers_once():
    model = InjuryModel("flat_half", "test model: always 1/2", lambda v_kmh, age: 0.0 * v_kmh)
    try:
        register_injury_model(model)
        assert injury_probability(12.0, 50.0, model="flat_half") == pytest.approx(0.5)
        with pytest.raises(ValueError, match="already registered"):
            register_injury_model(model)
    finally:
        INJURY_MODELS.pop("flat_half", None)
