"""Per-step logs of single episodes ("cases"), written for analysis and replay.

A case is two files named after the scenario, condition and seed:
    <dir>/<scenario>_<condition>_<seed>.parquet   the per-step log (safety.log columns + diagnostics)
    <dir>/<scenario>_<condition>_<seed>.json      the initial world (EpisodeSetup), outcome and end reason
Both are written to a temporary name and renamed, so a crash never leaves half a case behind.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
from typing import Any

import pandas as pd

from pedsafe_sumo.scenarios.episode_setup import (
    BackgroundVehicle,
    EpisodeSetup,
    PedestrianSetup,
    SignalStaging,
    VehicleSetup,
)
from pedsafe_sumo.scenarios.road_users import VehicleSize


def case_stem(scenario: str, condition: str, seed: int, approach: str = "") -> str:
    """File stem of a case; an approach named with --approach (batch --approach all runs the same seeds
    on every approach) is its last part."""
    return f"{scenario}_{condition}_{seed}" + (f"_{approach}" if approach else "")


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "item"):  # numpy scalars
        return _jsonable(value.item())
    return value


def write_case(directory: Path, result) -> Path:
    """Write an EpisodeResult's log and setup; returns the path of the log."""
    directory.mkdir(parents=True, exist_ok=True)
    stem = case_stem(result.setup.scenario, result.condition, result.setup.seed, result.setup.approach)
    log_path = directory / f"{stem}.parquet"
    meta_path = directory / f"{stem}.json"
    tmp_log = log_path.with_suffix(".parquet.tmp")
    result.log.to_parquet(tmp_log, index=False)
    meta = {
        "setup": dataclasses.asdict(result.setup),
        "condition": result.condition,
        "outcome": result.outcome,
        "end_reason": result.end_reason,
        "sumo_collision": result.sumo_collision,
    }
    tmp_meta = meta_path.with_suffix(".json.tmp")
    tmp_meta.write_text(json.dumps(_jsonable(meta), indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    os.replace(tmp_log, log_path)
    os.replace(tmp_meta, meta_path)
    return log_path


def _tuples(value: Any) -> Any:
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def setup_from_dict(data: dict[str, Any]) -> EpisodeSetup:
    """Rebuild the frozen EpisodeSetup written by write_case (for replay)."""

    def vehicle(d: dict) -> VehicleSetup:
        return VehicleSetup(
            **{
                **d,
                "colour_rgb": tuple(d["colour_rgb"]),
                "size": VehicleSize(**d["size"]),
                "route": tuple(d.get("route", ())),
            }
        )

    return EpisodeSetup(
        scenario=data["scenario"],
        seed=data["seed"],
        ego=vehicle(data["ego"]),
        ego_route=tuple(data["ego_route"]),
        pedestrian=PedestrianSetup(**{k: _tuples(v) for k, v in data["pedestrian"].items()}),
        parked=tuple(vehicle(v) for v in data["parked"]),
        conflict_xy=tuple(data["conflict_xy"]),
        conflict_offset_s=data["conflict_offset_s"],
        time_limit_s=data["time_limit_s"],
        background=tuple(
            BackgroundVehicle(**{k: _tuples(v) for k, v in b.items()}) for b in data.get("background", [])
        ),
        # Cases written before scenarios were placed in the signal program have none of these.
        conflict_time_s=data.get("conflict_time_s", math.nan),
        ped_crossing_id=data.get("ped_crossing_id", ""),
        signals=SignalStaging(**data["signals"]) if data.get("signals") else None,
        approach=data.get("approach", ""),
        # NaN is written as null.
        ego_start_distance_m=(
            math.nan if data.get("ego_start_distance_m") is None else float(data["ego_start_distance_m"])
        ),
    )


def read_case(log_path: Path) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The per-step log and the metadata of a case (metadata 'setup' as an EpisodeSetup)."""
    # partitioning=None: pandas would turn a 'key=value' folder of the path (a sweep's run
    # directories) into an extra column.
    log = pd.read_parquet(log_path, partitioning=None)
    meta = json.loads(log_path.with_suffix(".json").read_text(encoding="utf-8"))
    meta["setup"] = setup_from_dict(meta["setup"])
    return log, meta
