"""Settings layered defaults -> scenario -> parameter file -> command line, shared by the CLIs.

`--set key=value` sets a scenario field (pedsafe_sumo/scenarios/specs.py) or, with a dotted key, a
value of the parameter file (pedsafe_sumo/params/defaults.toml). Unknown keys and out-of-range values
raise, naming the key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pedsafe_sumo.params import load_params, with_overrides
from pedsafe_sumo.perception.world import load_roadside_units
from pedsafe_sumo.scenarios.specs import ScenarioSpec, get_scenario
from pedsafe_sumo.usage import UsageError


def parse_set(pairs: list[str]) -> tuple[dict[str, str], dict[str, Any]]:
    """Split --set key=value pairs into scenario fields and dotted parameter-file keys."""
    scenario: dict[str, str] = {}
    params: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise UsageError(f"--set needs key=value, got '{pair}'")
        if "." in key:
            params[key] = parse_value(value)
        else:
            scenario[key] = value
    return scenario, params


def parse_value(text: str) -> Any:
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        number = float(text)
    except ValueError:
        return text
    return int(number) if number.is_integer() and "." not in text and "e" not in lowered else number


def configure(
    scenario_names: list[str], params_file: Path | None, set_pairs: list[str] | None
) -> tuple[dict[str, ScenarioSpec], dict[str, Any]]:
    """Scenario specs with their overrides applied, and the validated parameters."""
    scenario_overrides, param_overrides = parse_set(set_pairs or [])
    params = load_params(params_file)
    if param_overrides:
        params = with_overrides(params, param_overrides)
    specs = {name: get_scenario(name).with_overrides(scenario_overrides) for name in scenario_names}
    return specs, params


def check_roadside_units(specs: dict[str, ScenarioSpec], site) -> None:
    """Every roadside pole a scenario names must exist at the site (else one clear line, before any work)."""
    # The poles the engine loads: the roadside_camera POIs of the site's rsu.add.xml (heights and
    # pitches do not matter here).
    try:
        known = tuple(unit.id for unit in load_roadside_units(site.file("rsu.add.xml"), 0.0, 0.0))
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    for spec in specs.values():
        # rsu_camera_K@exit is a turn's pole on the arm it leaves by: which one depends on the approach,
        # and the hosting check (scenarios/hosting.py) says when a site has none there.
        unknown = [u for u in spec.roadside_unit_ids if u not in known and not u.endswith("@exit")]
        if unknown:
            raise UsageError(
                f"scenario '{spec.name}': roadside_units names {', '.join(unknown)}, which site "
                f"{site.name} does not have (known: {', '.join(known)})"
            )
