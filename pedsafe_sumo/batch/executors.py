"""Where the chunks of a batch run: a pool of local worker processes, or a Dask distributed cluster.

Both call pedsafe_sumo.batch.runner.run_chunk in worker processes (one SUMO each) and hand every
finished chunk to the driver's callback exactly once, in completion order; the driver records it.

A worker process that dies (killed by the OS, a crash in native code, an AD stack that exits the
process) must neither stop the batch nor lose or repeat an episode:

* Process pool: the death breaks the whole pool (every pending chunk fails with BrokenProcessPool). Each
  worker notes the chunk it starts, so the driver knows which chunks were really running: those are
  rerun one at a time, alone in a fresh worker process (the others are requeued as they were). A chunk
  that kills its worker alone too is split into its pairs, each run alone up to twice; a pair that
  kills its worker every time becomes two error rows saying so, and the batch goes on.
* Dask: the scheduler reruns the tasks of a dead worker elsewhere by itself, up to its
  `distributed.scheduler.allowed-failures` (set to 1 for `local:N`, so a chunk runs at most twice);
  then the task fails with KilledWorker, and the chunk is split into pairs as above, a pair that fails
  so becoming error rows.

Worker memory. libsumo's `load` (one per episode) keeps about 0.9 KiB each time it is called (SUMO's, not
ours: a loop of `load` alone shows it; BENCHMARKS.md), so a worker's RSS creeps by about
1 MiB per 1,000 episodes. The process pool therefore replaces its worker processes after every
`recycle_chunks` chunks per worker (--recycle-chunks): the chunks go to the pool in generations of
workers x recycle_chunks, each generation on a fresh pool. Rows do not change (an episode's rows depend on
its seed only, never on the process); the cost is one worker start per generation and the wait for a
generation's last chunk. Dask's workers are not recycled here: each runs under its nanny's memory limit
(Dask's `distributed.worker.memory.terminate`, 95 % of the worker's memory_limit, restarts it), and a
long-lived cluster can restart its workers with `dask worker --lifetime`.

Any other exception out of a worker means the worker cannot run this batch at all (another network
file, another version, a broken install): the batch stops with that message, and what is recorded
stays for --resume.
"""

from __future__ import annotations

import logging
import multiprocessing
import shutil
import tempfile
import uuid
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from pedsafe_sumo.batch.chunks import Chunk, Task
from pedsafe_sumo.batch.runner import ChunkOutput, WorkerConfig, error_row, init_pool_worker, run_chunk
from pedsafe_sumo.io import step_logs
from pedsafe_sumo.settings import UsageError

OnChunkDone = Callable[[Chunk, ChunkOutput], None]

#: Runs of one pair alone in a fresh worker process before it is recorded as killing its worker.
PAIR_ATTEMPTS_ALONE = 2
#: Pool breaks in a row in which no chunk had even started before the batch gives up.
MAX_STARTUP_DEATHS = 3
#: Chunks per worker process before the pool's processes are replaced (--recycle-chunks; module docstring):
#: with the automatic chunk size (at most 25 pairs) at most about 5,000 episodes per process, so libsumo's
#: creep (about 1 MiB per 1,000 episodes) stays under about 5 MiB, while a fresh pool (spawn, imports,
#: SUMO's start: 2-4 s) per 100 chunks of about 4 s each costs under 1 % (BENCHMARKS.md).
DEFAULT_RECYCLE_CHUNKS = 100
#: Upper bound of --recycle-chunks (0 = never): beyond it a run's processes are never replaced anyway.
MAX_RECYCLE_CHUNKS = 1_000_000
LOCAL_CLUSTER_PREFIX = "local:"
#: Most Dask workers local:N starts (one SUMO process each, as --workers; the same bound).
MAX_LOCAL_CLUSTER_WORKERS = 256
CLUSTER_EXTRA_HINT = "Dask is not installed: install the cluster extra, pip install 'pedsafe_sumo[cluster]'"


class BatchError(RuntimeError):
    """The batch cannot go on; one-line message. What was recorded stays for --resume."""


#: The error of a pair whose worker process died every time it ran; the same on every executor, so a
#: table does not depend on where it was computed.
WORKER_DIED_MESSAGE = (
    "worker process died each time this episode pair ran (docs/batch.md: faults): killed by the OS, "
    "or a crash in SUMO or the AD stack"
)


def worker_died_rows(task: Task) -> list[dict[str, Any]]:
    """Error rows of a pair whose worker process died every time it ran."""
    return [error_row(task, condition, WORKER_DIED_MESSAGE) for condition in task.conditions]


def merge_outputs(outputs: list[ChunkOutput]) -> ChunkOutput:
    return ChunkOutput(
        [row for o in outputs for row in o.rows],
        [case for o in outputs for case in o.cases],
        ",".join(sorted({o.worker for o in outputs if o.worker})),
        sum(o.compute_s for o in outputs),
        step_logs.merge_bytes([o.step_logs for o in outputs]),
        [trace for o in outputs for trace in o.tracebacks],
    )


def _failure(chunk: Chunk, exc: BaseException) -> BatchError:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    message = f"chunk {chunk.key} failed in its worker: {type(exc).__name__}: {text}"
    if isinstance(exc, ModuleNotFoundError):
        message += " (every worker needs pedsafe_sumo and the --algorithm package installed)"
    return BatchError(message)


class ProcessPoolBackend:
    """Chunks on `workers` local processes (spawned: no SUMO state inherited from the driver)."""

    def __init__(self, workers: int, recycle_chunks: int = DEFAULT_RECYCLE_CHUNKS) -> None:
        self.workers = workers
        #: Chunks per worker before the pool's processes are replaced; 0 = never (module docstring).
        self.recycle_chunks = recycle_chunks
        #: Pools started: one per generation of chunks, and one more after each worker death.
        self.generations = 0
        self.worker_deaths = 0
        self._context = multiprocessing.get_context("spawn")
        self._solo: ProcessPoolExecutor | None = None

    @property
    def description(self) -> str:
        recycled = f", replaced every {self.recycle_chunks} chunks each" if self.recycle_chunks else ""
        return f"process pool, {self.workers} worker(s){recycled}"

    @property
    def n_workers(self) -> int:
        return self.workers

    def start(self) -> None:
        """Nothing to start: pools are created per pass."""

    def close(self) -> None:
        self._close_solo()

    def run(self, config: WorkerConfig, chunks: list[Chunk], on_done: OnChunkDone) -> None:
        remaining = list(chunks)
        startup_deaths = 0
        # One fresh pool per generation of chunks: its processes end with it (module docstring).
        generation = self.workers * self.recycle_chunks if self.recycle_chunks else len(remaining)
        while remaining:
            batch, rest = remaining[:generation], remaining[generation:]
            self.generations += 1
            left, suspects, broken = self._pass(config, batch, on_done)
            remaining = left + rest
            if not broken:
                continue
            self.worker_deaths += 1
            finished = len(batch) - len(left) - len(suspects)
            startup_deaths = 0 if suspects or finished else startup_deaths + 1
            if startup_deaths >= MAX_STARTUP_DEATHS:
                raise BatchError(
                    f"worker processes died {startup_deaths} times before starting any chunk "
                    "(out of memory? a crash while importing the AD stack?)"
                )
            for chunk in suspects:
                self._settle_alone(config, chunk, on_done)
            self._close_solo()

    def _pass(
        self, config: WorkerConfig, chunks: list[Chunk], on_done: OnChunkDone
    ) -> tuple[list[Chunk], list[Chunk], bool]:
        """Run `chunks` on a fresh pool until all are done or the pool breaks.

        Returns (chunks not started, chunks that were running when it broke, whether it broke).
        """
        progress_dir = Path(tempfile.mkdtemp(prefix="pedsafe-pool-"))
        done: set[str] = set()
        broken = False
        try:
            pool = ProcessPoolExecutor(
                min(self.workers, len(chunks)),
                mp_context=self._context,
                initializer=init_pool_worker,
                initargs=(str(progress_dir),),
            )
            try:
                futures: dict[Future[ChunkOutput], Chunk] = {
                    pool.submit(run_chunk, config, chunk.key, chunk.tasks): chunk for chunk in chunks
                }
                for future in as_completed(futures):
                    chunk = futures.pop(future)
                    try:
                        output = future.result()
                    except BrokenProcessPool:
                        broken = True
                        continue
                    except Exception as exc:
                        raise _failure(chunk, exc) from exc
                    on_done(chunk, output)
                    done.add(chunk.key)
            finally:
                pool.shutdown(wait=True, cancel_futures=True)
            started = {
                note.read_text(encoding="utf-8") for note in progress_dir.iterdir() if note.suffix != ".tmp"
            }
        finally:
            shutil.rmtree(progress_dir, ignore_errors=True)
        left = [chunk for chunk in chunks if chunk.key not in done]
        return (
            [chunk for chunk in left if chunk.key not in started],
            [chunk for chunk in left if chunk.key in started],
            broken,
        )

    def _alone(self, config: WorkerConfig, key: str, tasks: tuple[Task, ...]) -> ChunkOutput | None:
        """Run tasks alone in a one-process pool; None when that process died."""
        if self._solo is None:
            self._solo = ProcessPoolExecutor(
                1, mp_context=self._context, initializer=init_pool_worker, initargs=(None,)
            )
        future = self._solo.submit(run_chunk, config, key, tasks)
        try:
            return future.result()
        except BrokenProcessPool:
            self.worker_deaths += 1
            self._close_solo()
            return None

    def _close_solo(self) -> None:
        if self._solo is not None:
            self._solo.shutdown(wait=True, cancel_futures=True)
            self._solo = None

    def _settle_alone(self, config: WorkerConfig, chunk: Chunk, on_done: OnChunkDone) -> None:
        """A chunk that was running when a worker died: alone, then pair by pair (module docstring)."""
        try:
            output = self._alone(config, chunk.key, chunk.tasks)
            if output is None:
                outputs = []
                for task in chunk.tasks:
                    # A one-pair chunk has had its first run alone already.
                    tries_left = PAIR_ATTEMPTS_ALONE - (1 if len(chunk.tasks) == 1 else 0)
                    pair_output = None
                    while pair_output is None and tries_left > 0:
                        pair_output = self._alone(config, chunk.key, (task,))
                        tries_left -= 1
                    outputs.append(pair_output or ChunkOutput(worker_died_rows(task), []))
                output = merge_outputs(outputs)
        except (BrokenProcessPool, BatchError):
            raise
        except Exception as exc:
            raise _failure(chunk, exc) from exc
        on_done(chunk, output)


def parse_cluster_address(text: str) -> tuple[str, int]:
    """('local', N) for local:N, (address, 0) for a scheduler address; UsageError otherwise."""
    if text.startswith(LOCAL_CLUSTER_PREFIX):
        count = text[len(LOCAL_CLUSTER_PREFIX) :]
        if not count.isdigit() or int(count) < 1:
            raise UsageError(f"--cluster local:N needs a number of workers N >= 1, got '{text}'")
        if int(count) > MAX_LOCAL_CLUSTER_WORKERS:
            raise UsageError(
                f"--cluster local:N starts at most {MAX_LOCAL_CLUSTER_WORKERS} local workers, got '{text}' "
                "(more: start a Dask cluster and give its scheduler's address)"
            )
        return "local", int(count)
    scheme, sep, rest = text.partition("://")
    if not sep or not rest or scheme not in ("tcp", "tls", "ws", "wss", "inproc", "ucx"):
        raise UsageError(
            f"--cluster must be a Dask scheduler address like tcp://host:8786, or local:N; got '{text}'"
        )
    return text, 0


class DaskBackend:
    """Chunks as tasks on a Dask distributed cluster: an existing one, or a LocalCluster for local:N."""

    def __init__(self, address: str) -> None:
        self.address = address
        self.target, self.local_workers = parse_cluster_address(address)
        self.worker_deaths = 0
        self.notes: list[str] = []
        self._client: Any = None  # distributed.Client (imported only when used)
        self._cluster: Any = None

    @property
    def description(self) -> str:
        return f"Dask cluster {self.address}, {self.n_workers} worker(s)"

    @property
    def n_workers(self) -> int:
        if self._client is None:
            return self.local_workers
        return max(1, len(self._client.scheduler_info()["workers"]))

    def start(self) -> None:
        """Connect (or start local:N); UsageError with one line when Dask is missing or unreachable."""
        try:  # Dask is an optional dependency (pip install 'pedsafe_sumo[cluster]'): imported only here
            import dask
            import distributed
        except ImportError:
            raise UsageError(CLUSTER_EXTRA_HINT) from None
        if self.target == "local":
            # allowed-failures 1: a chunk whose worker dies runs once more, then is split (module docstring).
            # worker-saturation 1.0: one chunk per single-threaded worker at a time, none queued behind it
            # (a queued chunk would be blamed too when the worker dies).
            with dask.config.set(
                {
                    "distributed.scheduler.allowed-failures": 1,
                    "distributed.scheduler.worker-saturation": 1.0,
                }
            ):
                # One thread per worker process: libsumo is one SUMO instance per process.
                self._cluster = distributed.LocalCluster(
                    n_workers=self.local_workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    silence_logs=logging.ERROR,
                )
                self._client = distributed.Client(self._cluster)
            return
        try:
            # How long to wait for the scheduler: Dask's own setting distributed.comm.timeouts.connect
            # (30 s; environment variable DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT).
            self._client = distributed.Client(self.target)
        except (OSError, TimeoutError, ValueError) as exc:
            text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise UsageError(f"cannot reach the Dask scheduler at {self.target}: {text}") from None
        threads = self._client.nthreads()
        if not threads:
            self.notes.append(f"the Dask cluster at {self.target} has no workers yet: chunks wait for them")
        elif any(n > 1 for n in threads.values()):
            self.notes.append(
                "some Dask workers have more than one thread; each process runs one chunk at a time "
                "(one SUMO per process): start workers with --nthreads 1 and --nworkers K"
            )

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def run(self, config: WorkerConfig, chunks: list[Chunk], on_done: OnChunkDone) -> None:
        from distributed import KilledWorker, as_completed  # optional dependency, present once start() ran

        client = self._client
        # Keys unique to this session: a resumed batch on a long-lived cluster never meets its past tasks.
        token = uuid.uuid4().hex[:12]
        #: future -> (chunk, index of the pair within the chunk, or None for the whole chunk)
        owners: dict[Any, tuple[Chunk, int | None]] = {}
        #: chunk key -> outputs of its pairs so far, when the chunk had to be split
        split: dict[str, list[ChunkOutput | None]] = {}

        def submit(chunk: Chunk, pair: int | None) -> Any:
            tasks = chunk.tasks if pair is None else (chunk.tasks[pair],)
            key = f"pedsafe-{token}-{chunk.key}" + ("" if pair is None else f"-pair{pair}")
            future = client.submit(run_chunk, config, chunk.key, tasks, key=key, pure=False)
            owners[future] = (chunk, pair)
            return future

        pending = as_completed([submit(chunk, None) for chunk in chunks])
        for future in pending:
            chunk, pair = owners.pop(future)
            if future.status == "cancelled":
                raise BatchError(f"the Dask scheduler cancelled chunk {chunk.key} (restarted or lost?)")
            # exception() waits for the task: one yielded as "lost" with a killed worker is recomputed by
            # Dask meanwhile, and then has no exception (it was taken for a failure "NoneType: None").
            exc = None if future.status == "finished" else future.exception()
            if exc is None:
                output = future.result()
            else:
                if not isinstance(exc, KilledWorker):
                    raise _failure(chunk, exc)
                self.worker_deaths += 1
                if pair is None and len(chunk.tasks) > 1:
                    split[chunk.key] = [None] * len(chunk.tasks)
                    for index in range(len(chunk.tasks)):
                        pending.add(submit(chunk, index))
                    future.release()
                    continue
                task = chunk.tasks[0 if pair is None else pair]
                output = ChunkOutput(worker_died_rows(task), [])
            future.release()
            if pair is None:
                on_done(chunk, output)
                continue
            parts = split[chunk.key]
            parts[pair] = output
            if all(p is not None for p in parts):
                del split[chunk.key]
                on_done(chunk, merge_outputs([p for p in parts if p is not None]))


def make_backend(
    cluster: str | None, workers: int, recycle_chunks: int = DEFAULT_RECYCLE_CHUNKS
) -> DaskBackend | ProcessPoolBackend:
    return DaskBackend(cluster) if cluster else ProcessPoolBackend(workers, recycle_chunks)
