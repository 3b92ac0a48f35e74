"""A protocol with one value changed: the runs of a sensitivity sweep over a fixed study.

`python -m pedsafe_sumo.sweep --protocol FILE --preset NAME` runs, for each value of the swept key, the
protocol's study with that one value replaced and every other value as the file fixes it. Each
combination's protocol is written as a file of its own (OUT/protocols/<label>.toml) before its batch
starts: the file's text with the swept lines replaced and a first line naming the protocol it comes from
and that file's SHA-256, so its run directory records exactly what it ran (run.json: the derived file and
its SHA-256) and `--resume` refuses a derived file that has changed.

A scenario field (a key without a dot, e.g. `occluder_class`) is replaced in every [scenarios.<name>]
table of the protocol; a parameter (`algorithm.reaction_time_s`) in its [parameters.<section>] table.
The value is read as the type the protocol gives the key (a number, true/false, a text, a list of
numbers), so `--vary occluder_class=car,van` and `--vary algorithm.reaction_time_s=0.4,1.5` read as the
protocol's own values would.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

import pandas as pd
import tomllib

from pedsafe_sumo.io.run_store import EPISODES_FILE, RUN_FILE
from pedsafe_sumo.protocol import Protocol, _toml_value
from pedsafe_sumo.settings import UsageError

#: In a sweep's combination whose rows come from --base-run: where they came from.
BASE_ROWS_FILE = "rows_from.json"
_TABLE = re.compile(r"^\[([^\]]+)\]\s*$")
_ASSIGNMENT = re.compile(r"^([A-Za-z0-9_]+)\s*=")


def _typed(text: str, like: Any, key: str) -> Any:
    """`text` read as the type of the protocol's value `like`."""
    try:
        if isinstance(like, bool):
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return text.lower() in ("true", "1")
        if isinstance(like, int):
            return int(text)
        if isinstance(like, float):
            return float(text)
        if isinstance(like, str):
            return text
        if isinstance(like, list):
            return [float(v) for v in json.loads(text if text.startswith("[") else f"[{text}]")]
    except (ValueError, TypeError, json.JSONDecodeError):
        pass
    raise UsageError(f"--vary {key}: '{text}' is not a value of the protocol's type ({type(like).__name__})")


def _targets(protocol: Protocol, key: str) -> tuple[set[str], str, Any]:
    """(tables whose `name` line is replaced, name, the protocol's value) of a swept key."""
    if "." not in key:
        missing = [s for s in protocol.scenarios if key not in protocol.scenario_fields[s]]
        if missing:
            raise UsageError(f"--vary {key}: protocol {protocol.path.name} has no scenario field '{key}'")
        tables = {f"scenarios.{s}" for s in protocol.scenarios}
        return tables, key, protocol.scenario_fields[protocol.scenarios[0]][key]
    *sections, name = key.split(".")
    tree: Any = protocol.parameters
    for part in [*sections, name]:
        if not isinstance(tree, dict) or part not in tree:
            raise UsageError(f"--vary {key}: protocol {protocol.path.name} names no parameter '{key}'")
        tree = tree[part]
    return {"parameters." + ".".join(sections)}, name, tree


def derived_protocol_text(protocol: Protocol, changes: dict[str, str]) -> str:
    """The protocol's file with each `key = value` of `changes` replaced, and a first comment line naming
    the protocol it comes from; its [protocol] name gets the changes as a suffix."""
    text = protocol.path.read_text(encoding="utf-8")
    replace: dict[tuple[str, str], str] = {}
    for key, value_text in changes.items():
        tables, name, like = _targets(protocol, key)
        value = _toml_value(_typed(value_text, like, key))
        for table in tables:
            replace[(table, name)] = value
    suffix = ",".join(f"{k}={v}" for k, v in changes.items())
    lines, table, done = [], "", set()
    for line in text.splitlines():
        header = _TABLE.match(line.strip())
        if header:
            table = header.group(1).strip()
        assignment = _ASSIGNMENT.match(line)
        if assignment and (table, assignment.group(1)) in replace:
            lines.append(f"{assignment.group(1)} = {replace[(table, assignment.group(1))]}")
            done.add((table, assignment.group(1)))
            continue
        if assignment and table == "protocol" and assignment.group(1) == "name":
            lines.append(f"name = {_toml_value(protocol.header['name'] + '+' + suffix)}")
            continue
        lines.append(line)
    if done != set(replace):  # a value written inline in a table header's line, or a dotted key: not ours
        table, name = sorted(set(replace) - done)[0]
        raise UsageError(f"--vary: cannot find '{name} = ...' in [{table}] of {protocol.path.name}")
    source = hashlib.sha256(protocol.path.read_bytes()).hexdigest()
    head = (
        f"# Derived from {protocol.path.name} (SHA-256 {source}) by python -m pedsafe_sumo.sweep: "
        f"{suffix}; every other value as that protocol fixes it."
    )
    out = "\n".join([head, *lines]) + "\n"
    tomllib.loads(out)  # what we wrote is TOML
    return out


def write_derived_protocol(protocol: Protocol, changes: dict[str, str], path: Path) -> Path:
    """Write the derived protocol to `path`; refuse when a different one is already there (the source
    protocol changed since the sweep started: its runs would mix two studies)."""
    text = derived_protocol_text(protocol, changes)
    if path.exists() and path.read_text(encoding="utf-8") != text:
        raise UsageError(
            f"{path} differs from the protocol it would be derived from now: {protocol.path.name} changed "
            "since this sweep started (a changed protocol is a new sweep in a new --out)"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def is_protocol_itself(protocol: Protocol, changes: dict[str, str]) -> bool:
    """Whether every value of `changes`, read as the protocol's type, is the protocol's own."""
    for key, value_text in changes.items():
        _, _, like = _targets(protocol, key)
        if _typed(value_text, like, key) != like:
            return False
    return True


def base_run_rows(protocol: Protocol, base_dir: Path, episodes: int) -> pd.DataFrame:
    """The first `episodes` pairs of every scenario and condition of `base_dir`, a complete plain Monte
    Carlo run of the very file `protocol` (its run.json names the file's SHA-256). An episode's rows are a
    function of the run seed and its number (the batch's seed rule), so these are the rows a run of the
    protocol with --episodes `episodes` writes. UsageError in one line when `base_dir` is not that run."""
    try:
        record = json.loads((base_dir / RUN_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise UsageError(f"--base-run: no readable {RUN_FILE} in {base_dir}") from None
    named = record.get("protocol") if isinstance(record, dict) else None
    if not isinstance(named, dict) or named.get("sha256") != protocol.sha256:
        raise UsageError(f"--base-run: {base_dir} is not a run of {protocol.path.name} (its SHA-256 differs)")
    if record.get("sampler") is not None:
        raise UsageError(
            f"--base-run: {base_dir} is an importance-sampled run; the sweep's runs are plain Monte Carlo"
        )
    if not (base_dir / EPISODES_FILE).is_file() or record.get("state") != "complete":
        raise UsageError(f"--base-run: {base_dir} is not complete (finish it with batch --resume first)")
    rows = pd.read_parquet(base_dir / EPISODES_FILE, partitioning=None)
    rows = rows[rows["episode"] < episodes].reset_index(drop=True)
    conditions = 2 if protocol.header["conditions"] == "both" else 1
    expected = len(protocol.scenarios) * conditions * episodes
    if len(rows) != expected:
        raise UsageError(
            f"--base-run: {base_dir} holds {len(rows):,} rows of its first {episodes:,} episodes, "
            f"not {expected:,}"
        )
    return rows


def write_base_rows(rows: pd.DataFrame, base_dir: Path, run_dir: Path) -> None:
    """The protocol's own combination: its rows from the base run, and where they came from."""
    run_dir.mkdir(parents=True, exist_ok=True)
    note = {
        "rows_from": str(base_dir.resolve()),
        "episodes_per_scenario": int(rows["episode"].max()) + 1 if len(rows) else 0,
        "why": "every swept value is the protocol's own: the first episodes of the protocol's run, "
        "not run again",
    }
    (run_dir / BASE_ROWS_FILE).write_text(json.dumps(note, indent=2) + "\n", encoding="utf-8")
    rows.to_parquet(run_dir / EPISODES_FILE, index=False)
