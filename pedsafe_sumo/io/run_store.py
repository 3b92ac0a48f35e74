"""The files of a batch run directory, written so that a kill at any instant damages nothing.

    DIR/run.json          the run's identity (everything that decides its results) and its state:
                          "running" from the first moment, "complete" once episodes.parquet is whole
    DIR/manifest.json     the chunks finished so far: part file, row count, SHA-256 of its bytes
    DIR/parts/<scenario>-<first>-<last>.parquet   the rows of one chunk of episodes
    DIR/episodes.parquet  all parts, sorted; written last
    DIR/cases/            per-step logs (pedsafe_sumo.io.cases)
    DIR/steplogs/<scenario>-<first>-<last>.parquet   with --keep-logs all: every step log of one chunk

Every file is written to a temporary name beside its final one, flushed to disk, and renamed over it
(`os.replace` is atomic on POSIX): a reader sees the old file or the new one, never half of one. Only
the batch's driver process writes here. A part file that the manifest does not list (the driver died
between writing it and recording it) is an orphan: a resumed run deletes it and runs its chunk again,
which gives the same rows because every episode is a function of its seed alone.

The batch (pedsafe_sumo.batch) and the report (pedsafe_sumo.report) both read through this module.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import pandas as pd

from pedsafe_sumo.confine import ConfinementError, confined
from pedsafe_sumo.io.episodes import sort_rows, to_table

RUN_FILE = "run.json"
MANIFEST_FILE = "manifest.json"
PARTS_DIR = "parts"
CASES_DIR = "cases"
#: Per-step logs of every episode, one file per chunk (--keep-logs all; pedsafe_sumo.io.step_logs).
STEPLOGS_DIR = "steplogs"
EPISODES_FILE = "episodes.parquet"
#: Held (flock) by the driver writing the directory; removed when the run completes.
LOCK_FILE = ".lock"
TMP_SUFFIX = ".tmp"

STATE_RUNNING = "running"
STATE_COMPLETE = "complete"
MANIFEST_FORMAT = 1


class RunStoreError(ValueError):
    """A run directory whose files cannot be read as a run; the message is one line."""


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write `data` to `path` through a temporary file, flushed and fsynced before the rename."""
    tmp = path.with_name(path.name + TMP_SUFFIX)
    tmp.unlink(missing_ok=True)  # a link left at the temporary name would carry the write elsewhere
    try:
        with open(tmp, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except Exception:
        # A write that fails (no room, a folder at the target) leaves nothing beside the target; a process
        # that dies on the way leaves the temporary file, which the next write (or --resume) removes.
        tmp.unlink(missing_ok=True)
        raise


def write_json_atomic(path: Path, obj: Any) -> None:
    text = json.dumps(obj, indent=1, ensure_ascii=False, default=str) + "\n"
    write_bytes_atomic(path, text.encode("utf-8"))


def read_json(path: Path) -> dict[str, Any]:
    """A JSON object from `path`; RunStoreError (one line) when missing, unreadable or not an object."""
    try:
        loaded = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RunStoreError(f"{path} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RunStoreError(f"{path} is unreadable: {exc}") from None
    if not isinstance(loaded, dict):
        raise RunStoreError(f"{path} is not a JSON object")
    return loaded


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def parquet_bytes(table: pd.DataFrame) -> bytes:
    buffer = io.BytesIO()
    table.to_parquet(buffer, index=False)
    return buffer.getvalue()


def part_file_name(scenario: str, first_episode: int, last_episode: int) -> str:
    """parts/ name of the chunk holding episodes first..last (inclusive) of a scenario."""
    return f"{scenario}-{first_episode:06d}-{last_episode:06d}.parquet"


@dataclass(frozen=True)
class ChunkRecord:
    """One finished chunk as the manifest lists it."""

    key: str
    scenario: str
    first_episode: int
    last_episode: int
    #: Path relative to the run directory.
    file: str
    rows: int
    sha256: str
    n_error: int
    #: Which session of the run (0 = the first, then one per --resume) computed it, when, and how long
    #: after that session started (the wall time of a session that was killed ends at its last chunk).
    session: int
    completed_utc: str
    session_elapsed_s: float
    #: The worker process(es) that ran it ("host:pid") and the seconds they spent on it.
    worker: str = ""
    compute_s: float = 0.0
    #: With --keep-logs all: the chunk's step-log file (relative path) and the SHA-256 of its bytes.
    steplog_file: str = ""
    steplog_sha256: str = ""


#: The JSON types a manifest entry's fields may have, by the field's annotation (a bool is no number here).
_ENTRY_TYPES: dict[str, tuple[type, ...]] = {"str": (str,), "int": (int,), "float": (int, float)}


def _check_chunk_entry(path: Path, key: str, entry: Any) -> None:
    """RunStoreError (one line) when a manifest entry is not an object or a field has the wrong type."""
    if not isinstance(entry, dict):
        raise RunStoreError(f"{path} entry {key} is not a JSON object")
    for field in fields(ChunkRecord):
        if field.name not in entry:
            continue  # a missing field is ChunkRecord's TypeError, reported as a malformed entry
        value = entry[field.name]
        if isinstance(value, bool) or not isinstance(value, _ENTRY_TYPES[str(field.type)]):
            raise RunStoreError(
                f"{path} entry {key}: {field.name} must be of type {field.type}, got {value!r}"
            )


class Manifest:
    """DIR/manifest.json: the chunks whose part files are complete. Written by the driver only."""

    def __init__(self, path: Path, chunks: dict[str, ChunkRecord] | None = None) -> None:
        self.path = path
        self.chunks: dict[str, ChunkRecord] = dict(chunks or {})
        # The JSON line of each record, kept: the manifest is rewritten whole after every chunk, and
        # encoding a thousand records each time would cost the driver more than writing them.
        self._lines: dict[str, tuple[ChunkRecord, str]] = {}

    @classmethod
    def load(cls, path: Path) -> Manifest:
        data = read_json(path)
        if data.get("format") != MANIFEST_FORMAT or not isinstance(data.get("chunks"), dict):
            raise RunStoreError(f"{path} is not a manifest of format {MANIFEST_FORMAT}")
        try:
            for key, entry in data["chunks"].items():
                _check_chunk_entry(path, key, entry)
            chunks = {key: ChunkRecord(**entry) for key, entry in data["chunks"].items()}
        except TypeError as exc:
            raise RunStoreError(f"{path} has a malformed chunk entry: {exc}") from None
        try:  # the files it names are the run's own (docs/trust.md)
            for record in chunks.values():
                for name in filter(None, (record.file, record.steplog_file)):
                    confined(path.parent, name, f"{path} entry {record.key}")
        except ConfinementError as exc:
            raise RunStoreError(str(exc)) from None
        return cls(path, chunks)

    def _line(self, key: str) -> str:
        record = self.chunks[key]
        cached = self._lines.get(key)
        if cached is None or cached[0] is not record:
            cached = (record, f"  {json.dumps(key)}: {json.dumps(asdict(record), ensure_ascii=False)}")
            self._lines[key] = cached
        return cached[1]

    def save(self) -> None:
        """Rewrite the manifest (atomically): one line per chunk, in key order."""
        lines = ",\n".join(self._line(key) for key in sorted(self.chunks))
        text = f'{{"format": {MANIFEST_FORMAT}, "chunks": {{\n{lines}\n}}}}\n'
        write_bytes_atomic(self.path, text.encode("utf-8"))

    def record(self, record: ChunkRecord) -> None:
        self.chunks[record.key] = record
        self.save()


def check_part(run_dir: Path, record: ChunkRecord) -> str:
    """ "" when the chunk's part file is there with the recorded checksum, else why not (one phrase)."""
    files = [(record.file, record.sha256)]
    if record.steplog_file:
        files.append((record.steplog_file, record.steplog_sha256))
    for name, digest in files:
        path = run_dir / name
        if not path.is_file():
            return f"{name} is missing"
        if sha256_file(path) != digest:
            return f"{name} does not match its recorded checksum"
    return ""


def stray_files(run_dir: Path, manifest: Manifest) -> list[Path]:
    """Files a killed driver may have left: part files no manifest entry names, and temporary files."""
    listed = {run_dir / record.file for record in manifest.chunks.values()}
    listed |= {run_dir / record.steplog_file for record in manifest.chunks.values() if record.steplog_file}
    strays = []
    for folder in (run_dir / PARTS_DIR, run_dir / STEPLOGS_DIR):
        if folder.is_dir():
            strays += [p for p in sorted(folder.iterdir()) if p.is_file() and p not in listed]
    for folder in (run_dir, run_dir / CASES_DIR):
        if folder.is_dir():
            strays += sorted(p for p in folder.iterdir() if p.is_file() and p.name.endswith(TMP_SUFFIX))
    return strays


def read_parts(run_dir: Path, records: list[ChunkRecord]) -> pd.DataFrame:
    """The rows of the given chunks as one table in the episodes.parquet order and dtypes."""
    # partitioning=None: pandas would turn a 'key=value' folder of the path (a sweep's run
    # directories) into an extra column.
    tables = [pd.read_parquet(run_dir / record.file, partitioning=None) for record in records]
    if not tables:
        return to_table([])
    # Parts were written from to_table, so their dtypes already are the contract's.
    return sort_rows(pd.concat(tables, ignore_index=True))


def holds_run(directory: Path) -> bool:
    """Whether `directory` holds (part of) a batch run."""
    return directory.is_dir() and any(
        (directory / name).exists() for name in (RUN_FILE, MANIFEST_FILE, EPISODES_FILE, PARTS_DIR, CASES_DIR)
    )
