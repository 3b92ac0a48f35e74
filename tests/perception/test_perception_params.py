"""The [perception] section: defaults load, bad values are rejected with the key named."""

from __future__ import annotations

import pytest

from pedsafe_sumo.params import ParameterError, load_params, with_overrides


def test_defaults_hold_the_issue_numbers(params):
    p = params["perception"]
    assert p["camera"]["hfov_deg"] == 90 and (p["camera"]["width_px"], p["camera"]["height_px"]) == (
        1280,
        720,
    )
    assert (p["camera"]["forward_offset_m"], p["camera"]["height_m"]) == (1.5, 1.6)
    assert p["camera"]["min_visible_fraction"] == 0.3 and p["camera"]["min_height_px"] == 20
    assert p["camera"]["delta_e_threshold"] == 15
    lid = p["lidar"]
    assert (lid["channels"], lid["elevation_min_deg"], lid["elevation_max_deg"]) == (32, -25, 15)
    assert (lid["horizontal_resolution_deg"], lid["range_m"], lid["min_returns"]) == (0.2, 100, 5)
    assert lid["cluster_tolerance_m"] == 0.5
    assert p["v2i"] == {
        "latency_s": 0.1,
        "packet_loss_probability": 0.01,
        "position_noise_sigma_m": 0.2,
        "signal_source": "fresher",
    }
    assert p["roadside_camera"]["default_height_m"] == 6.0 and p["roadside_camera"]["hfov_deg"] == 90


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("perception.v2i.packet_loss_probability", 1.5, "probability"),
        ("perception.v2i.packet_loss_probability", -0.1, "probability"),
        ("perception.camera.miss_probability", 2, "probability"),
        ("perception.camera.min_visible_fraction", 1.2, "probability"),
        ("perception.lidar.range_m", 0.0, "> 0"),
        ("perception.lidar.horizontal_resolution_deg", -0.2, "horizontal_resolution_deg"),
        ("perception.lidar.cluster_tolerance_m", -1.0, "> 0"),
        ("perception.lidar.channels", 0, "positive integer"),
        ("perception.lidar.channels", 3.5, "positive integer"),
        ("perception.lidar.elevation_min_deg", 20.0, "elevation"),
        ("perception.camera.hfov_deg", 180.0, "hfov_deg"),
        ("perception.camera.width_px", -1280, "positive integer"),
        ("perception.v2i.latency_s", -0.1, ">= 0"),
        ("perception.v2i.position_noise_sigma_m", "0.2", "finite number"),
        ("perception.scene.ground_rgb", [300, 0, 0], "0-255"),
        ("perception.camera.sample_height_fractions", [], "non-empty"),
        ("perception.occluders.canopy_base_m", 9.0, "below"),
        ("perception.occluders.default_building_height_m", 0.0, "> 0"),
    ],
)
def test_out_of_range_values_are_rejected(params, key, value, message):
    with pytest.raises(ParameterError, match=message) as err:
        with_overrides(params, {key: value})
    assert key.split(".")[-1] in str(err.value)


def test_unknown_perception_key_in_a_user_file_is_rejected(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text("[perception.lidar]\nrange_metres = 80.0\n")
    with pytest.raises(ParameterError, match="unknown parameter 'perception.lidar.range_metres'"):
        load_params(path)


def test_user_file_overrides_a_perception_default(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text("[perception.v2i]\nlatency_s = 0.2\n")
    assert load_params(path)["perception"]["v2i"]["latency_s"] == 0.2
