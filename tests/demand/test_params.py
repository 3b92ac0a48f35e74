"""The [traffic] and [pedestrians] sections: defaults hold the paper's numbers, bad values are rejected."""

from __future__ import annotations

import math

import pytest

from pedsafe_sumo.params import ParameterError, load_params, with_overrides


def test_defaults_carry_the_paper_numbers_and_errata():
    params = load_params()
    traffic, peds = params["traffic"], params["pedestrians"]
    assert traffic["headway_rate_per_s"] == 0.1742
    assert (traffic["speed_nonintersection_log_mu"], traffic["speed_nonintersection_log_sigma"]) == (
        1.8304,
        0.4857,
    )
    assert (traffic["speed_intersection_log_mu"], traffic["speed_intersection_log_sigma"]) == (1.5853, 0.3827)
    groups = peds["age_groups"]
    # Erratum: the paper's 4.46 m/s for 13-18 is read as 1.46 m/s; "31-36" as 31-60.
    assert groups["age_13_18"]["speed_mean_mps"] == 1.46
    assert groups["age_31_60"]["age_max_years"] == 60
    assert groups["over_60"]["speed_p15_mps"] == 0.92
    assert math.isclose(sum(g["weight_share"] for g in groups.values()), 1.0)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"traffic.headway_rate_per_s": -0.1}, "traffic.headway_rate_per_s' must be > 0"),
        ({"traffic.headway_rate_per_s": 0}, "traffic.headway_rate_per_s' must be > 0"),
        ({"traffic.speed_nonintersection_log_sigma": 0.0}, "speed_nonintersection_log_sigma' must be > 0"),
        ({"traffic.speed_intersection_log_sigma": -1.0}, "speed_intersection_log_sigma' must be > 0"),
        ({"traffic.speed_intersection_log_mu": "fast"}, "speed_intersection_log_mu' must be a finite number"),
        ({"traffic.turn_share_left": 0.5}, "must sum to 1"),
        ({"traffic.turn_share_right": -0.2, "traffic.turn_share_straight": 1.0}, "must lie in \\[0, 1\\]"),
        ({"pedestrians.risk_share_yield": 0.5}, "risk_share_unaware.*must sum to 1"),
        ({"pedestrians.gender_female_share": 1.5}, "gender_female_share' is a share"),
        ({"pedestrians.arrival_rate_per_h": -5.0}, "arrival_rate_per_h' must be > 0"),
        ({"pedestrians.hasten_factor": 0.5}, "hasten_factor' must be >= 1"),
        ({"pedestrians.age_groups.over_60.weight_share": 0.3}, "weight_share must sum to 1"),
        ({"pedestrians.age_groups.age_19_30.speed_p15_mps": 1.6}, "speed_p15_mps' \\(1.6\\) must be below"),
        ({"pedestrians.age_groups.age_13_18.age_max_years": 20}, "overlap"),
        ({"pedestrians.age_groups.over_60.speed_mean_mps": -1.03}, "over_60.speed_mean_mps' must be > 0"),
    ],
)
def test_out_of_range_values_are_rejected_naming_the_key(override, message):
    with pytest.raises(ParameterError, match=message):
        with_overrides(load_params(), override)


def test_bad_user_file_is_rejected_and_good_one_applies(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[traffic]\nspeed_nonintersection_log_sigma = -0.4\n")
    with pytest.raises(ParameterError, match="traffic.speed_nonintersection_log_sigma"):
        load_params(bad)
    good = tmp_path / "good.toml"
    good.write_text(
        "[traffic]\nheadway_rate_per_s = 0.05\n[pedestrians.age_groups.over_60]\nspeed_mean_mps = 1.1\n"
    )
    params = load_params(good)
    assert params["traffic"]["headway_rate_per_s"] == 0.05
    assert params["pedestrians"]["age_groups"]["over_60"]["speed_mean_mps"] == 1.1
    assert params["pedestrians"]["age_groups"]["over_60"]["speed_p15_mps"] == 0.92  # untouched default
