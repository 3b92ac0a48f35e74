"""The driver's side of a run directory: create or reopen it, record chunks, assemble episodes.parquet.

The file layout and the atomic writes are pedsafe_sumo.io.run_store's; docs/batch.md describes both.
One driver at a time: it holds an exclusive lock (flock on DIR/.lock) while it writes, which the OS
releases when the driver dies however it dies, so a --resume after a kill -9 never finds it taken.
"""

from __future__ import annotations

import os
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pandas as pd

from pedsafe_sumo.batch.chunks import Chunk
from pedsafe_sumo.batch.executors import BatchError
from pedsafe_sumo.batch.runner import ChunkOutput
from pedsafe_sumo.batch.trust import check_run_entries
from pedsafe_sumo.io import step_logs
from pedsafe_sumo.io.cases import write_case
from pedsafe_sumo.io.episodes import to_table
from pedsafe_sumo.io.error_cases import write_error_case
from pedsafe_sumo.io.run_store import (
    CASES_DIR,
    EPISODES_FILE,
    LOCK_FILE,
    MANIFEST_FILE,
    PARTS_DIR,
    RUN_FILE,
    STEPLOGS_DIR,
    ChunkRecord,
    Manifest,
    RunStoreError,
    check_part,
    parquet_bytes,
    part_file_name,
    read_parts,
    sha256_bytes,
    stray_files,
    write_bytes_atomic,
    write_json_atomic,
)
from pedsafe_sumo.safety.stats import FAILED_STATUSES
from pedsafe_sumo.settings import UsageError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no lock, one driver per directory is then on the user
    fcntl = None  # type: ignore[assignment]


def utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


class BatchRunDirectory:
    """A run directory as the batch driver writes it."""

    def __init__(self, path: Path, keep_logs: str = step_logs.KEEP_EVENTS) -> None:
        self.path = Path(path)
        self.manifest = Manifest(self.path / MANIFEST_FILE)
        self._lock_handle: Any = None
        #: --keep-logs: with "all", every chunk's step logs go to steplogs/ with its part file.
        self.keep_logs = keep_logs

    @property
    def cases_dir(self) -> Path:
        return self.path / CASES_DIR

    # ------------------------------------------------------------------ opening
    def _lock(self) -> None:
        handle = open(self.path / LOCK_FILE, "a+")  # noqa: SIM115 - held for the driver's lifetime
        if fcntl is not None:
            try:
                fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                handle.close()
                raise UsageError(f"another batch process is writing {self.path} right now") from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        self._lock_handle = handle

    def create(self, run_info: dict[str, Any]) -> None:
        """A new run: the directory, its lock, run.json (state running), an empty manifest, parts/, cases/."""
        self.path.mkdir(parents=True, exist_ok=True)
        self._lock()
        self.save_run_info(run_info)
        self.manifest.save()
        (self.path / PARTS_DIR).mkdir(exist_ok=True)
        self.cases_dir.mkdir(exist_ok=True)
        self._steplogs_dir()

    def _steplogs_dir(self) -> None:
        if self.keep_logs == step_logs.KEEP_ALL:
            (self.path / STEPLOGS_DIR).mkdir(exist_ok=True)

    def reopen(self) -> list[str]:
        """A stopped run: lock it, keep the recorded chunks whose part files are intact, and delete what
        a killed driver left behind (unrecorded parts, temporary files). Returns one note per change."""
        check_run_entries(self.path)  # no link in the directory leads a write or a deletion out of it
        self._lock()
        try:
            self.manifest = Manifest.load(self.path / MANIFEST_FILE)
        except RunStoreError as exc:
            raise UsageError(f"cannot resume: {exc}") from None
        notes = []
        for key, record in sorted(self.manifest.chunks.items()):
            problem = check_part(self.path, record)
            if problem:
                del self.manifest.chunks[key]
                (self.path / record.file).unlink(missing_ok=True)
                notes.append(f"chunk {key} runs again: {problem}")
        if notes:
            self.manifest.save()
        for stray in stray_files(self.path, self.manifest):
            stray.unlink()
            notes.append(f"removed {stray.relative_to(self.path)} (written but never recorded)")
        (self.path / PARTS_DIR).mkdir(exist_ok=True)
        self.cases_dir.mkdir(exist_ok=True)
        self._steplogs_dir()
        return notes

    def save_run_info(self, run_info: dict[str, Any]) -> None:
        write_json_atomic(self.path / RUN_FILE, run_info)

    def release(self, remove_lock: bool) -> None:
        if self._lock_handle is None:
            return
        if remove_lock:
            (self.path / LOCK_FILE).unlink(missing_ok=True)
        self._lock_handle.close()  # closing the descriptor releases the flock
        self._lock_handle = None

    # ------------------------------------------------------------------ chunks
    def record(self, chunk: Chunk, output: ChunkOutput, session: int, session_elapsed_s: float) -> bool:
        """Write a finished chunk: its case logs, its step logs (--keep-logs all), its part file, then its
        manifest entry (in that order, so a recorded chunk always has them all). False, and nothing
        written, if it was recorded already."""
        if chunk.key in self.manifest.chunks:
            return False
        table = to_table(output.rows)
        expected = sorted((task.episode, condition) for task in chunk.tasks for condition in task.conditions)
        got = sorted(zip(table["episode"].tolist(), table["condition"].tolist()))
        # A chunk of scenario@ARM (--approach) holds that scenario's rows.
        if got != expected or (table["scenario"] != chunk.scenario.partition("@")[0]).any():
            raise BatchError(f"chunk {chunk.key} came back with other episodes than it holds (a bug)")
        for result in output.cases:
            write_case(self.cases_dir, result)
        for stem, text in output.tracebacks:  # episodes that ended in an error or a timeout
            write_error_case(self.cases_dir, stem, text)
        steplog_file, steplog_sha256 = "", ""
        if self.keep_logs == step_logs.KEEP_ALL:
            # A chunk whose every pair killed its worker comes back without logs: an empty file says so.
            logs = output.step_logs or step_logs.to_bytes(step_logs.chunk_step_log([]))
            steplog_file = f"{STEPLOGS_DIR}/" + step_logs.steplog_file_name(
                chunk.scenario, chunk.first_episode, chunk.last_episode
            )
            write_bytes_atomic(self.path / steplog_file, logs)
            steplog_sha256 = sha256_bytes(logs)
        name = part_file_name(chunk.scenario, chunk.first_episode, chunk.last_episode)
        data = parquet_bytes(table)
        write_bytes_atomic(self.path / PARTS_DIR / name, data)
        self.manifest.record(
            ChunkRecord(
                key=chunk.key,
                scenario=chunk.scenario,
                first_episode=chunk.first_episode,
                last_episode=chunk.last_episode,
                file=f"{PARTS_DIR}/{name}",
                rows=len(table),
                sha256=sha256_bytes(data),
                n_error=int(table["status"].isin(FAILED_STATUSES).sum()),
                session=session,
                completed_utc=utc_now(),
                session_elapsed_s=round(session_elapsed_s, 3),
                worker=output.worker,
                compute_s=round(output.compute_s, 3),
                steplog_file=steplog_file,
                steplog_sha256=steplog_sha256,
            )
        )
        return True

    def finalize(self, chunks: list[Chunk]) -> pd.DataFrame:
        """episodes.parquet from the parts of every chunk of the plan (all must be recorded)."""
        missing = [chunk.key for chunk in chunks if chunk.key not in self.manifest.chunks]
        if missing:
            raise BatchError(f"{len(missing)} chunk(s) not recorded, first {missing[0]}")
        table = read_parts(self.path, [self.manifest.chunks[chunk.key] for chunk in chunks])
        expected_rows = sum(chunk.n_rows for chunk in chunks)
        keys = table[["scenario", "approach", "episode", "condition"]]
        if len(table) != expected_rows or keys.duplicated().any():
            raise BatchError(f"the parts hold {len(table)} rows, the plan {expected_rows} (a bug)")
        write_bytes_atomic(self.path / EPISODES_FILE, parquet_bytes(table))
        return table

    def session_wall_times_s(self, sessions: list[dict[str, Any]]) -> list[float]:
        """Wall time of each session: as it recorded at its end, or for a session that was killed, until
        its last recorded chunk (what it did after that was lost and redone)."""
        times = []
        for index, session in enumerate(sessions):
            wall = session.get("wall_time_s")
            if not isinstance(wall, (int, float)):
                elapsed = [r.session_elapsed_s for r in self.manifest.chunks.values() if r.session == index]
                wall = max(elapsed, default=0.0)
            times.append(float(wall))
        return times
