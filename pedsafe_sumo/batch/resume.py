"""The run directory's recorded run: read for --resume, checked to be the very run the command describes,
and, for a new run, checked to be absent (with nothing else in the way).

A run's identity is what makes two runs' episodes the same episodes (IDENTITY_KEYS of run.json) and the
versions that could give other episodes (PINNED_VERSIONS); `--resume` refuses a command that differs in
either, in one line that names the first difference.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pedsafe_sumo.batch.arguments import RUN_ARGUMENT_DEFAULTS
from pedsafe_sumo.io.run_store import RUN_FILE, RunStoreError, holds_run, read_json
from pedsafe_sumo.protocol import VALUES_BEFORE
from pedsafe_sumo.settings import UsageError

#: run.json keys compared on --resume: what makes two runs' episodes the same episodes.
IDENTITY_KEYS = (
    "site",
    "scenarios",
    "conditions",
    "episodes_per_scenario",
    "run_seed",
    "episode_seed_rule",
    "algorithm",
    "parameters",
    "site_files_sha256",
    "chunk_size_pairs",
    "sampler",
)
#: Versions that must be the same on --resume (another SUMO or pedsafe_sumo may give other episodes).
PINNED_VERSIONS = ("pedsafe_sumo", "sumo")


def _first_difference(recorded: Any, current: Any, path: str) -> str | None:
    """The dotted path of the first value that differs, or None when equal."""
    if isinstance(recorded, dict) and isinstance(current, dict):
        for key in sorted(set(recorded) | set(current), key=str):
            if key not in recorded or key not in current:
                return f"{path}.{key}"
            found = _first_difference(recorded[key], current[key], f"{path}.{key}")
            if found:
                return found
        return None
    return None if recorded == current else path


def _with_fields_before(recorded: Any, current: Any) -> Any:
    """The recorded scenarios' fields, each scenario field the current ones have and a recorded one lacks
    given its VALUES_BEFORE value: a run started before the field existed ran with that behaviour, so a
    command that gives the same value continues the same run (and one that gives another does not)."""
    if not isinstance(recorded, dict) or not isinstance(current, dict):
        return recorded
    before = VALUES_BEFORE["scenarios"]
    return {
        name: {**{k: before[k] for k in current.get(name, {}) if k in before and k not in fields}, **fields}
        if isinstance(fields, dict)
        else fields
        for name, fields in recorded.items()
    }


def _lookup(data: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        data = data.get(part, "(absent)") if isinstance(data, dict) else "(absent)"
    return data


def _is_foreign(out: Path) -> bool:
    """Whether `out` is an existing directory with something in it and no run of ours (holds_run)."""
    if not out.is_dir():
        return False
    try:
        return next(out.iterdir(), None) is not None
    except OSError:  # unreadable: certainly not ours to write into
        return True


def check_new_run_directory(out: Path) -> None:
    """Refuse to start a new run in `out` when it holds a run, or anything else (one line)."""
    if holds_run(out):
        state = "complete" if (out / "episodes.parquet").exists() else "incomplete"
        raise UsageError(
            f"output directory {out} already holds a run ({state}); continue it with --resume "
            "or choose another --out"
        )
    if _is_foreign(out):
        raise UsageError(
            f"--out {out} is a directory that is not empty and holds no run: choose a new or "
            "empty directory (nothing in it is touched)"
        )


def recorded_run(out: Path) -> dict[str, Any]:
    """run.json of the run in `out`, refused in one line where there is none or it cannot be resumed."""
    try:
        recorded = read_json(out / RUN_FILE)
    except RunStoreError as exc:
        if not (out / RUN_FILE).exists():
            raise UsageError(f"{out} holds no run to resume (no {RUN_FILE})") from None
        raise UsageError(f"cannot resume: {exc}") from None
    if not isinstance(recorded.get("arguments"), dict) or "sessions" not in recorded:
        raise UsageError(f"{out / RUN_FILE} was written by a batch that cannot be resumed (no arguments)")
    check_recorded_types(out / RUN_FILE, recorded)
    return recorded


def _json_type(value: Any) -> str:
    return {
        bool: "boolean",
        int: "number",
        float: "number",
        str: "string",
        list: "array",
        dict: "object",
    }.get(type(value), type(value).__name__)


def check_recorded_types(path: Path, recorded: dict[str, Any]) -> None:
    """UsageError (one line) where a hand-edited run.json holds a value of another JSON type than the
    batch writes: the recorded arguments (of the type of their default) and the tables --resume reads."""
    for key, value in recorded["arguments"].items():
        default = RUN_ARGUMENT_DEFAULTS.get(key)
        if value is None or default is None:
            continue
        if _json_type(value) != _json_type(default):
            raise UsageError(
                f"{path}: arguments.{key} must be a JSON {_json_type(default)}, got {value!r}: "
                "the file was edited; resume a run with the run.json its batch wrote"
            )
    expected = {"sessions": list, "versions": dict, "protocol": dict}
    for key, kind in expected.items():
        if key in recorded and recorded[key] is not None and not isinstance(recorded[key], kind):
            raise UsageError(
                f"{path}: {key} must be a JSON {_json_type(kind())}, got {recorded[key]!r}: "
                "the file was edited; resume a run with the run.json its batch wrote"
            )
    if not all(isinstance(session, dict) for session in recorded["sessions"]):
        raise UsageError(f"{path}: every entry of sessions must be a JSON object")


def check_same_run(
    out: Path, identity: dict[str, Any], versions: dict[str, str], recorded: dict[str, Any]
) -> None:
    """Refuse to resume a run whose recorded identity or pinned versions differ from this command's
    `identity` and `versions` (one line)."""
    # Compare as JSON would store them (tuples as lists, the same number types).
    current = json.loads(json.dumps({key: identity[key] for key in IDENTITY_KEYS}, default=str))
    previous = {key: recorded.get(key) for key in IDENTITY_KEYS}
    previous["scenarios"] = _with_fields_before(previous["scenarios"], current["scenarios"])
    where = _first_difference(previous, current, "")
    if where:
        where = where.lstrip(".")
        raise UsageError(
            f"{out} holds a different run: {where} is {_lookup(previous, where)!r} there, "
            f"{_lookup(current, where)!r} here; --resume continues the recorded run (leave the flag out "
            "or repeat its value), a new run needs another --out"
        )
    for name in PINNED_VERSIONS:
        was, now = recorded.get("versions", {}).get(name), versions.get(name)
        if was != now:
            raise UsageError(f"{out} was started with {name} {was}, this is {now}: resume it with {was}")
