"""The parameter loader: a user file overlays the defaults; unknown keys and broken files are errors."""

from __future__ import annotations

import pytest

from pedsafe_sumo.params import ParameterError, load_params, with_overrides


def test_defaults_load_and_have_the_documented_sections():
    params = load_params()
    assert {"traffic", "pedestrians", "perception"} <= set(params)


def test_unknown_key_in_user_file_is_rejected(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text("[traffic]\nheadway_rate_typo = 0.2\n")
    with pytest.raises(ParameterError, match="unknown parameter 'traffic.headway_rate_typo'"):
        load_params(path)


def test_unknown_section_and_broken_toml_are_rejected(tmp_path):
    (tmp_path / "a.toml").write_text("[weather]\nrain = true\n")
    with pytest.raises(ParameterError, match="unknown parameter 'weather'"):
        load_params(tmp_path / "a.toml")
    (tmp_path / "b.toml").write_text("[traffic\n")
    with pytest.raises(ParameterError, match="not valid TOML"):
        load_params(tmp_path / "b.toml")
    with pytest.raises(ParameterError, match="not found"):
        load_params(tmp_path / "missing.toml")


def test_dotted_override_of_unknown_key_is_rejected():
    with pytest.raises(ParameterError, match="unknown parameter 'perception.no_such_key'"):
        with_overrides(load_params(), {"perception.no_such_key": 1})
