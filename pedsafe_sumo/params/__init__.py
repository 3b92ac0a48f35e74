"""One parameter file for every default of the model (docs/design.md, 'Sources of numbers'; sensor settings).

`defaults.toml` beside this module holds every number with its unit and source. A user points a run at
their own TOML file, which is laid over the defaults: it may set any subset of keys, but an unknown key
is an error (a typo must never silently fall back to a default). Each section has a validator that
rejects values out of range with a message naming the key.
"""

from __future__ import annotations

import copy
import importlib
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

DEFAULTS_PATH = Path(__file__).with_name("defaults.toml")


class ParameterError(ValueError):
    """A parameter file or override is invalid; the message names the key and the rule."""


#: section name -> validator(section_dict, section_name); sections register themselves here.
VALIDATORS: dict[str, Callable[[dict[str, Any], str], None]] = {}


Validator = Callable[[dict[str, Any], str], None]


def register_validator(section: str) -> Callable[[Validator], Validator]:
    """Decorator: register the validator of one top-level section of the parameter file."""

    def wrap(func: Validator) -> Validator:
        VALIDATORS[section] = func
        return func

    return wrap


#: An upper bound (or lower bound) of a numeric parameter and why it is there, as the validators use it.
Bounds = dict[str, tuple[float, str]]


def check_upper_bounds(section: dict[str, Any], bounds: Bounds, where: str) -> None:
    """Refuse a number above its sane upper bound, naming the key, the bound and the reason (one line).

    Validators call this after their own range checks; every number of the parameter file has one, so
    that no value (`--set traffic.headway_rate_per_s=1e9`) can make a batch run for ever."""
    for key, (bound, why) in bounds.items():
        value = section.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool) and value > bound:
            raise ParameterError(
                f"parameter '{where}.{key}' must be at most {bound:g} ({why}), got {value!r}"
            )


def check_lower_bounds(section: dict[str, Any], bounds: Bounds, where: str) -> None:
    """As check_upper_bounds, for the few numbers whose small values multiply the work of a step."""
    for key, (bound, why) in bounds.items():
        value = section.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool) and value < bound:
            raise ParameterError(
                f"parameter '{where}.{key}' must be at least {bound:g} ({why}), got {value!r}"
            )


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise ParameterError(f"parameter file not found: {path}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ParameterError(f"parameter file {path} is not valid TOML: {exc}") from None
    except OSError as exc:  # a directory, no permission
        raise ParameterError(f"cannot read parameter file {path}: {exc.strerror or exc}") from None


def overlay(base: dict[str, Any], override: dict[str, Any], where: str) -> None:
    """Lay `override` over `base` in place; an unknown key or a value for a table is an error."""
    for key, value in override.items():
        dotted = f"{where}.{key}" if where else key
        if key not in base:
            raise ParameterError(f"unknown parameter '{dotted}'")
        if isinstance(base[key], dict):
            if not isinstance(value, dict):
                raise ParameterError(f"parameter '{dotted}' must be a table")
            overlay(base[key], value, dotted)
        else:
            base[key] = value


def load_params(path: str | Path | None = None) -> dict[str, Any]:
    """Defaults, overlaid with the user's file when given, validated section by section."""
    params = _read_toml(DEFAULTS_PATH)
    if path is not None:
        overlay(params, _read_toml(Path(path)), "")
    validate(params)
    return params


def check_finite(value: Any, where: str) -> None:
    """Every number in `value` (a table, a list or a scalar) is finite: NaN and infinity mean nothing here."""
    if isinstance(value, dict):
        for key, item in value.items():
            check_finite(item, f"{where}.{key}" if where else key)
    elif isinstance(value, list):
        for item in value:
            check_finite(item, where)
    elif isinstance(value, float) and not math.isfinite(value):
        raise ParameterError(f"parameter '{where}' must be a finite number, got {value}")


def validate(params: dict[str, Any]) -> None:
    check_finite(params, "")
    # Importing the domain modules registers their validators.
    _import_validator_modules()
    for section, validator in VALIDATORS.items():
        if section in params:
            validator(params[section], section)


def _import_validator_modules() -> None:
    # Imported by name when validating, not at module top: each of these modules imports this one to
    # register its validator, so importing them here at load time would make a cycle.
    for module in (
        "pedsafe_sumo.demand.params",
        "pedsafe_sumo.perception.params",
        "pedsafe_sumo.control.params",
        "pedsafe_sumo.safety.params",
        "pedsafe_sumo.conflicts.params",
    ):
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            # Tolerate an absent domain module (or package), never an error inside it.
            if exc.name is None or not (module == exc.name or module.startswith(exc.name + ".")):
                raise


def with_overrides(params: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """A validated copy of `params` with dotted-key overrides ({'traffic.headway_rate_per_s': 0.2})."""
    out = copy.deepcopy(params)
    for dotted, value in overrides.items():
        nested: dict[str, Any] = {}
        cursor = nested
        parts = dotted.split(".")
        for part in parts[:-1]:
            cursor = cursor.setdefault(part, {})
        cursor[parts[-1]] = value
        overlay(out, nested, "")
    validate(out)
    return out
