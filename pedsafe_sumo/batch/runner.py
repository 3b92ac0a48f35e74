"""The worker side of a batch: the episode pairs of one chunk, on this process's SUMO.

Both executors (a local process pool, a Dask cluster) call `run_chunk` in a worker process. Each worker
process owns one EpisodeRunner, hence one SUMO instance (libsumo holds a single instance per process),
built on its first chunk and reused while the configuration stays the same. The runner reloads SUMO for
every episode (`load`), and every random draw comes from the episode's seed, so an episode's rows do not
depend on the worker, on the episodes it ran before, or on the order: tests/batch checks 1 against 2
workers, a resumed run against an uninterrupted one, and Dask against the process pool.

A failing episode (SUMO refusing it, an exception, sys.exit or an invalid command in the AD stack under
test: pedsafe_sumo.control.stack_calls) becomes a row with status "error" and its message, its traceback
sent along for the case logs; an AD stack that exceeds the time limit of setup or run_step
(--agent-timeout) a row with status "timeout". The runner is rebuilt (SUMO may be in any state) and the
chunk goes on; the episode is not run again. Rows
are returned to the driver, which alone writes the run directory: workers on other machines need no
shared file system.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import threading
import time
import traceback
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import sumolib

from pedsafe_sumo import __version__
from pedsafe_sumo.batch.chunks import Task
from pedsafe_sumo.control.agent import load_agent_class
from pedsafe_sumo.control.stack_calls import episode_error_message, stack_failure, stack_label
from pedsafe_sumo.control.timeout import DEFAULT_AGENT_TIMEOUT_S, TIMEOUT_STATUS, AgentTimeoutError
from pedsafe_sumo.io import step_logs
from pedsafe_sumo.io.cases import case_stem
from pedsafe_sumo.io.episodes import EPISODE_COLUMNS
from pedsafe_sumo.io.step_logs import KEEP_ALL, KEEP_EVENTS
from pedsafe_sumo.network.sites import get_site, resolve_site
from pedsafe_sumo.sampling.joint import proposal_of_json
from pedsafe_sumo.sampling.stages import DEFENSIVE_SHARE
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sim.staging import SITE_FILES_READ

ERROR_STATUS = "error"
#: How often a pool worker checks that its driver is still alive [s].
PARENT_POLL_S = 1.0


class WorkerEnvironmentError(RuntimeError):
    """This worker cannot give the driver's results (other network files, other versions)."""


@dataclass(frozen=True)
class WorkerConfig:
    """Everything a worker needs besides the tasks; the same for every chunk of a run."""

    site: str
    params: dict[str, Any]
    #: --set scenario fields ("field") and a protocol's per-scenario values ("scenario:field").
    scenario_overrides: dict[str, Any]
    algorithm: str
    #: SHA-256 of each site file as the driver read it (file name -> digest). A worker whose files differ
    #: (another machine, another checkout) refuses to run instead of giving other results.
    site_digests: dict[str, str] = field(default_factory=dict)
    #: The driver's pedsafe_sumo and SUMO versions, checked the same way.
    versions: dict[str, str] = field(default_factory=dict)
    #: Per-step time limit of the AD stack's run_step [s] (--agent-timeout).
    agent_timeout_s: float = DEFAULT_AGENT_TIMEOUT_S
    #: --keep-logs: "events" (case logs of pairs with a collision or conflict) or "all" (every step log
    #: besides). Decides what is kept, not what is computed, so it stays out of the fingerprint.
    keep_logs: str = KEEP_EVENTS

    @cached_property
    def fingerprint(self) -> str:
        text = json.dumps(
            [
                self.site,
                self.params,
                self.scenario_overrides,
                self.algorithm,
                self.site_digests,
                self.versions,
                self.agent_timeout_s,
            ],
            sort_keys=True,
            default=str,
        )
        return hashlib.sha256(text.encode("utf-8")).hexdigest()


@dataclass
class ChunkOutput:
    """What a worker sends back for a chunk (or part of one)."""

    rows: list[dict[str, Any]]
    #: EpisodeResults of both conditions of every pair with a collision or a conflict (the cases/ logs).
    cases: list[Any]
    #: "host:pid" of the worker process, and the seconds it spent on the chunk.
    worker: str = ""
    compute_s: float = 0.0
    #: With --keep-logs all: every step log of the chunk's episodes that ran, as the bytes of one
    #: Parquet file (pedsafe_sumo.io.step_logs); b"" otherwise.
    step_logs: bytes = b""
    #: (case stem, traceback) of every episode of the chunk that ended in an error or a timeout.
    tracebacks: list[tuple[str, str]] = field(default_factory=list)


# One runner per worker process. The lock serialises chunks in a process: a Dask worker started with
# more than one thread would otherwise drive the process's single SUMO from two threads at once.
_SUMO_LOCK = threading.Lock()
_RUNNER: Any = None  # an EpisodeRunner (imported lazily: the driver never builds one)
_RUNNER_FINGERPRINT = ""
_RUNNER_CONFIG: WorkerConfig | None = None
#: Set by the process pool's initializer: where this worker notes the chunk it has started.
_PROGRESS_DIR: Path | None = None


def worker_label() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def init_pool_worker(progress_dir: str | None) -> None:
    """Process-pool initializer (progress_dir None: no notes). Building the runner waits for the first
    chunk, so that a failure there reaches the driver as that chunk's exception, with its message."""
    global _PROGRESS_DIR
    _PROGRESS_DIR = Path(progress_dir) if progress_dir else None
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()


def _exit_with_parent(parent_pid: int) -> None:
    """A pool worker whose driver was killed (kill -9 never lets it stop its pool) would wait forever
    for work that never comes; it leaves within a second instead. Nothing is lost: only the driver
    writes the run directory."""
    while True:
        time.sleep(PARENT_POLL_S)
        if os.getppid() != parent_pid:
            os._exit(1)


def _note_started(chunk_key: str) -> None:
    """Tell the process-pool driver which chunk this process works on: if the process dies, the pool
    breaks for every chunk, and only this note says which chunks were really running."""
    if _PROGRESS_DIR is None:
        return
    note = _PROGRESS_DIR / str(os.getpid())
    tmp = note.with_suffix(".tmp")
    tmp.write_text(chunk_key, encoding="utf-8")
    os.replace(tmp, note)


def site_file_digests(site_name: str) -> dict[str, str]:
    """SHA-256 of every site file an episode reads, by file name (`site_name`: a site name or folder)."""
    site = resolve_site(site_name, verify=False)
    digests = {}
    for suffix in SITE_FILES_READ:
        path = site.file(suffix)
        digests[path.name] = hashlib.sha256(path.read_bytes()).hexdigest()
    return digests


def worker_versions() -> dict[str, str]:
    return {"pedsafe_sumo": __version__, "sumo": sumolib.version.gitDescribe()}


def check_environment(config: WorkerConfig) -> None:
    """Raise WorkerEnvironmentError when this process would not reproduce the driver's episodes."""
    where = worker_label()
    mine = worker_versions()
    for name, wanted in config.versions.items():
        if mine.get(name) != wanted:
            raise WorkerEnvironmentError(
                f"worker {where} has {name} {mine.get(name)}, the batch was started with {wanted}: "
                "install the same version on every machine"
            )
    try:
        digests = site_file_digests(config.site)
    except OSError as exc:
        raise WorkerEnvironmentError(f"worker {where} cannot read the site files: {exc}") from None
    for name, wanted in config.site_digests.items():
        if digests.get(name) != wanted:
            raise WorkerEnvironmentError(
                f"worker {where}: {name} differs from the file the batch was started with: "
                "every machine needs the same network files"
            )


def _runner_for(config: WorkerConfig) -> Any:
    global _RUNNER, _RUNNER_FINGERPRINT, _RUNNER_CONFIG
    fingerprint = config.fingerprint
    if _RUNNER is not None and _RUNNER_FINGERPRINT == fingerprint:
        return _RUNNER
    if _RUNNER is not None:
        _close_runner()
    check_environment(config)
    _RUNNER = EpisodeRunner(
        get_site(config.site),
        config.params,
        load_agent_class(config.algorithm),
        agent_timeout_s=config.agent_timeout_s,
    )
    _RUNNER_FINGERPRINT, _RUNNER_CONFIG = fingerprint, config
    return _RUNNER


def _close_runner() -> None:
    global _RUNNER, _RUNNER_FINGERPRINT
    runner, _RUNNER, _RUNNER_FINGERPRINT = _RUNNER, None, ""
    try:
        runner.close()
    except Exception:  # noqa: BLE001 - the instance is being discarded anyway
        traceback.print_exc(limit=0)


def error_row(task: Task, condition: str, message: str, status: str = ERROR_STATUS) -> dict[str, Any]:
    """The row of an episode that did not run to its end: its status ("error" or "timeout"), the
    message, the pair's keys."""
    row: dict[str, Any] = {c: np.nan for c in EPISODE_COLUMNS}
    scenario, _, arm = task.scenario.partition("@")
    row.update(
        scenario=scenario,
        approach=arm,
        condition=condition,
        episode=task.episode,
        seed=task.seed,
        collision=False,
        conflict=False,
        sumo_collision=None,  # SUMO witnessed nothing: unknown, not False
        contact_stationary=False,
        close_pass=False,
        detected_by="",
        ped_gender="",
        ped_risk="",
        status=status,
        error=message,
        weight=1.0,
        sampler_stage=task.stage,
        sampler_inputs="",
    )
    return row


def sampler_proposal(text: str) -> Any:
    """The families of a task's proposal (None under plain Monte Carlo), parsed once per process."""
    if not text:
        return None
    if text not in _PROPOSALS:
        _PROPOSALS[text] = proposal_of_json(text)
    return _PROPOSALS[text]


_PROPOSALS: dict[str, Any] = {}


def scenario_spec(name: str, overrides: dict[str, Any]) -> Any:
    """The scenario's spec with the run's overrides: `field` keys (--set) for every scenario, then
    `<scenario>:<field>` keys (a protocol's per-scenario values) for this one. `name` may be
    `<scenario>@<arm>` (batch --approach): that scenario on the approach from that arm."""
    name, _, arm = name.partition("@")
    common = {key: value for key, value in overrides.items() if ":" not in key}
    own = {key.split(":", 1)[1]: value for key, value in overrides.items() if key.startswith(f"{name}:")}
    spec = get_scenario(name).with_overrides(common).with_overrides(own)
    return spec.with_overrides({"approach": arm}) if arm else spec


def _run_pair(
    config: WorkerConfig, task: Task, tracebacks: list[tuple[str, str]] | None = None
) -> tuple[list[dict[str, Any]], list[Any], list[Any]]:
    """Both conditions of one paired episode: its rows, both results when either had an event (the case
    logs), and every result that ran (for --keep-logs all). The traceback of an episode that failed is
    appended to `tracebacks` as (case stem, text)."""
    runner = _runner_for(config)
    rows, results = [], []
    try:
        spec = scenario_spec(task.scenario, config.scenario_overrides)
        setup, draws = runner.draw_setup_sampled(
            spec, task.seed, sampler_proposal(task.proposal), DEFENSIVE_SHARE if task.proposal else 0.0
        )
    except Exception as exc:  # the pair cannot even be set up: both rows are errors
        message = f"{type(exc).__name__}: {exc}"
        return [error_row(task, c, message) for c in task.conditions], [], []
    # Both conditions share the pair's draw, hence its weight (sampling/draws.py).
    sampled = {
        "weight": draws.weight,
        "sampler_stage": task.stage,
        "sampler_inputs": json.dumps(draws.record(), sort_keys=True),
    }
    for condition in task.conditions:
        try:
            result = runner.run(spec, condition, task.seed, setup=setup)
        except BaseException as exc:  # sys.exit in the AD stack is this episode's error, not the worker's end
            failure = stack_failure(exc, stack_label(runner.agent_class))
            if failure is None:  # KeyboardInterrupt: the batch is being stopped
                raise
            status = TIMEOUT_STATUS if isinstance(failure, AgentTimeoutError) else ERROR_STATUS
            message = episode_error_message(failure)
            rows.append({**error_row(task, condition, message, status), **sampled})
            if tracebacks is not None:
                stem = case_stem(setup.scenario, condition, setup.seed, setup.approach)
                tracebacks.append((stem, f"{message}\n\n{traceback.format_exc()}"))
            # After a failed episode SUMO may be in any state: a fresh instance for the next one.
            _close_runner()
            runner = _runner_for(config)
            continue
        rows.append({**result.outcome, "episode": task.episode, **sampled})
        results.append(result)
    event = any(r.outcome["collision"] or r.outcome["conflict"] for r in results)
    return rows, (results if event else []), results


def run_chunk(config: WorkerConfig, chunk_key: str, tasks: tuple[Task, ...]) -> ChunkOutput:
    """Run every pair of `tasks` (a chunk, or one pair of it) in this process; rows in task order."""
    with _SUMO_LOCK:
        started = time.perf_counter()
        _note_started(chunk_key)
        rows: list[dict[str, Any]] = []
        cases: list[Any] = []
        kept: list[tuple[int, Any]] = []
        tracebacks: list[tuple[str, str]] = []
        for task in tasks:
            pair_rows, pair_cases, ran = _run_pair(config, task, tracebacks)
            rows += pair_rows
            cases += pair_cases
            kept += [(task.episode, result) for result in ran]
        logs = step_logs.to_bytes(step_logs.chunk_step_log(kept)) if config.keep_logs == KEEP_ALL else b""
        return ChunkOutput(rows, cases, worker_label(), time.perf_counter() - started, logs, tracebacks)
