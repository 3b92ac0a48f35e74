"""What the top of the report page says: per scenario and condition the rates with their intervals, per
scenario the paired SV-versus-V2I test read in words, and the run's configuration as a short table.

Only arranging: the numbers are Table I's and the paired table's (report/tables.py), formatted as there.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import pandas as pd

from pedsafe_sumo.report.tables import condition_label, interval_cell

#: The level of the paired test's reading ("V2I lower", "no difference shown").
SIGNIFICANCE_LEVEL = 0.05


@dataclass(frozen=True)
class RateRow:
    scenario: str
    condition: str
    n: int
    #: episodes with a collision, "n/a" in an importance-sampling run (its rates are weighted estimates)
    collisions: str
    collision: str
    injury: str
    conflict: str


@dataclass(frozen=True)
class PairedReading:
    scenario: str
    outcome: str
    pairs: int
    sv_rate: str
    v2i_rate: str
    discordant: str
    p_value: str
    reading: str


def rate_rows(table: pd.DataFrame, weighted: bool) -> list[RateRow]:
    """One row per scenario and condition of Table I, with the count of collisions where it is one."""
    return [
        RateRow(
            str(r.scenario),
            condition_label(str(r.condition)),
            int(r.n),
            "n/a" if weighted or not math.isfinite(r.collision_rate) else str(round(r.collision_rate * r.n)),
            interval_cell(r.collision_rate, r.collision_low, r.collision_high),
            interval_cell(r.injury_mean, r.injury_low, r.injury_high),
            interval_cell(r.conflict_rate, r.conflict_low, r.conflict_high),
        )
        for r in table.itertuples(index=False)
    ]


def _rate(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.4f}"


def _p(value: float) -> str:
    return "n/a" if not math.isfinite(value) else (f"{value:.4f}" if value >= 1e-4 else f"{value:.1e}")


def reading(n_pairs: int, sv_rate: float, v2i_rate: float, p_value: float) -> str:
    """The paired test in words, at SIGNIFICANCE_LEVEL."""
    if n_pairs == 0:
        return "not compared: the scenario ran under one condition only"
    if not math.isfinite(p_value) or p_value >= SIGNIFICANCE_LEVEL:
        return f"no difference shown at the {SIGNIFICANCE_LEVEL:.0%} level"
    lower = "V2I" if v2i_rate < sv_rate else "SV"
    return f"{lower} lower (p < {SIGNIFICANCE_LEVEL:g})"


def paired_readings(paired: pd.DataFrame) -> list[PairedReading]:
    return [
        PairedReading(
            str(r.scenario),
            str(r.outcome),
            int(r.n_pairs),
            _rate(r.sv_rate),
            _rate(r.v2i_rate),
            f"{r.b} SV only, {r.c} V2I only",
            _p(r.p_value),
            reading(int(r.n_pairs), float(r.sv_rate), float(r.v2i_rate), float(r.p_value)),
        )
        for r in paired.itertuples(index=False)
    ]


def _text(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (dict, list)):
        return json.dumps(value, sort_keys=True, default=str)
    return str(value)


def config_rows(run_info: Mapping[str, Any] | None) -> list[tuple[str, str]]:
    """The run's configuration as (what, value) rows: the protocol, the site, the stack, the scenarios and
    the sampling first, then the other plain values of run.json (the nested ones stay in the raw file)."""
    if not run_info:
        return []
    info = dict(run_info)
    rows: list[tuple[str, str]] = []
    protocol = info.pop("protocol", None)
    if isinstance(protocol, dict):
        name = protocol.get("name", "")
        detail = ", ".join(f"{k} {protocol[k]}" for k in ("file", "date") if protocol.get(k))
        rows.append(("protocol", f"{name} ({detail})" if detail else str(name)))
    elif protocol:
        rows.append(("protocol", _text(protocol)))
    scenarios = info.pop("scenarios", None)
    if isinstance(scenarios, dict):
        rows.append(("scenarios", ", ".join(str(s) for s in scenarios)))
    elif scenarios:
        rows.append(("scenarios", _text(scenarios)))
    for key in ("site", "algorithm", "conditions", "episodes_per_scenario", "run_seed", "sampler"):
        if key in info:
            value = info.pop(key)
            rows.append((key, "plain Monte Carlo" if key == "sampler" and value is None else _text(value)))
    arguments = info.get("arguments")
    if isinstance(arguments, dict) and arguments.get("approach"):
        rows.append(("approach", _text(arguments["approach"])))
    versions = info.pop("versions", None)
    if isinstance(versions, dict):
        rows.append(("versions", ", ".join(f"{k} {v}" for k, v in versions.items())))
    for key, value in info.items():
        if value is None or isinstance(value, (dict, list)):
            continue
        rows.append((key, _text(value)))
    return rows
