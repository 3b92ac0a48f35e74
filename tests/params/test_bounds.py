"""Every number a user can set has a sane upper bound: a scenario field or a parameter set
far out of range is refused with one line naming the key, the bound and the reason; the defaults are
inside every bound."""

from __future__ import annotations

import dataclasses
import re

import pytest

from pedsafe_sumo.params import ParameterError, load_params, with_overrides
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.specs import SCENARIOS, SPEC_UPPER_BOUNDS

FAR_OUT = 1e12


def numeric_leaves(table, prefix=""):
    """Dotted keys of every number (not bool) in the parameter tree."""
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from numeric_leaves(value, dotted + ".")
        elif isinstance(value, int | float) and not isinstance(value, bool):
            yield dotted


PARAM_KEYS = sorted(numeric_leaves(load_params()))
SPEC_FIELDS = sorted(
    f.name
    for f in dataclasses.fields(SCENARIOS["crossing"])
    if isinstance(getattr(SCENARIOS["crossing"], f.name), int | float)
)


def test_there_are_parameters_and_fields_to_check():
    assert len(PARAM_KEYS) > 80 and "traffic.headway_rate_per_s" in PARAM_KEYS
    assert "queue_vehicles" in SPEC_FIELDS and "time_limit_s" in SPEC_FIELDS


@pytest.mark.parametrize("key", PARAM_KEYS)
def test_every_parameter_far_above_range_is_refused(key):
    params = load_params()
    value = FAR_OUT if isinstance(eval_key(params, key), float) else int(FAR_OUT)
    with pytest.raises(ParameterError) as info:
        with_overrides(params, {key: value})
    message = str(info.value)
    assert key.rsplit(".", 1)[-1] in message and "\n" not in message


def eval_key(params, dotted):
    for part in dotted.split("."):
        params = params[part]
    return params


@pytest.mark.parametrize("field", SPEC_FIELDS)
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_every_scenario_field_far_above_range_is_refused(name, field):
    spec = SCENARIOS[name]
    with pytest.raises(ScenarioError) as info:
        spec.with_overrides({field: str(FAR_OUT)})
    assert field.removesuffix("_max_s").removesuffix("_max_m") in str(info.value) or "does not hold" in str(
        info.value
    )


@pytest.mark.parametrize("field", sorted(SPEC_UPPER_BOUNDS))
def test_a_bounded_field_is_accepted_at_its_bound_and_refused_just_above(field):
    bound, why = SPEC_UPPER_BOUNDS[field]
    spec = SCENARIOS["crossing"]
    assert getattr(spec.with_overrides({field: bound}), field) == bound
    above = bound + 1
    with pytest.raises(
        ScenarioError, match=re.escape(f"{field} must be at most {bound:g} ({why}), got {above:g}")
    ):
        spec.with_overrides({field: above})


def test_conflict_offset_has_a_lower_bound_too():
    with pytest.raises(ScenarioError, match="conflict_offset_min_s must be at least -10"):
        SCENARIOS["crossing"].with_overrides({"conflict_offset_min_s": -11})


def test_the_calibrated_desired_speed_law_is_bounded_like_the_fit():
    """traffic.desired_speed_calibrated_* are among the checked keys, bounded as the fit."""
    for key in ("traffic.desired_speed_calibrated_log_mu", "traffic.desired_speed_calibrated_log_sigma"):
        assert key in PARAM_KEYS
    with pytest.raises(ParameterError, match="desired_speed_calibrated_log_sigma' must be at most 2"):
        with_overrides(load_params(), {"traffic.desired_speed_calibrated_log_sigma": 2.5})
