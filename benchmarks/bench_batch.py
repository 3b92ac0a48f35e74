"""Batch throughput: episodes per second on the local process pool and on a Dask LocalCluster
(`--cluster local:N`) with 1 and 2 workers, the effect of the chunk size, and the fixed cost of one
chunk (scheduling a no-op chunk through each executor; recording a chunk in the run directory).

    .venv/bin/python benchmarks/bench_batch.py --episodes 40                          # pool, 1 and 2 workers
    .venv/bin/python benchmarks/bench_batch.py --episodes 40 --executors pool dask    # and Dask
    .venv/bin/python benchmarks/bench_batch.py --episodes 50 --workers 2 --chunk-sizes 1 5 25 --no-throughput
    .venv/bin/python benchmarks/bench_batch.py --overhead 400 --workers 2 --no-throughput   # per-chunk costs

Episodes/s is the batch's own measure (run.json: the session's wall time, from the first chunk
submitted to the last recorded); "command" is the whole command's wall time, with interpreter start,
worker start-up (numba cache load, SUMO) and, for Dask, starting and stopping the LocalCluster.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# Measure the checkout this script is in, also where the virtual environment's install points elsewhere.
sys.path.insert(0, str(REPO))
PROTOCOL_EPISODES = 3 * 2 * 10_000
#: Rows of a chunk in the overhead measurement: 25 pairs, the automatic chunk size of large runs.
OVERHEAD_ROWS = 50


def run_batch(executor: str, workers: int, episodes: int, out: Path, chunk_size: int | None = None) -> dict:
    where = ["--workers", str(workers)] if executor == "pool" else ["--cluster", f"local:{workers}"]
    size = ["--chunk-size", str(chunk_size)] if chunk_size else []
    command = [sys.executable, "-m", "pedsafe_sumo.batch", "--scenario", "all", "--episodes", str(episodes)]
    started = time.perf_counter()
    subprocess.run(
        [*command, *where, *size, "--seed", "11", "--out", str(out)],
        cwd=REPO,
        check=True,
        capture_output=True,
        text=True,
    )
    info = json.loads((out / "run.json").read_text())
    info["command_s"] = time.perf_counter() - started
    chunks = json.loads((out / "manifest.json").read_text())["chunks"].values()
    # Seconds the workers spent inside chunks: per episode (worker speed) and as a share of the
    # workers' wall time (the rest is start-up, scheduling gaps and the tail).
    compute_s = sum(chunk["compute_s"] for chunk in chunks)
    info["compute_ms_per_episode"] = compute_s / info["episodes_total"] * 1e3
    info["busy_share"] = compute_s / (info["wall_time_s"] * workers)
    return info


def throughput(args, tmp: Path) -> None:
    for executor in args.executors:
        base = None
        for workers in args.workers:
            info = run_batch(executor, workers, args.episodes, tmp / f"{executor}{workers}")
            rate = info["episodes_per_s"]
            base = base or rate
            print(
                f"{executor:4s} {workers} worker(s): {info['episodes_total']} episodes "
                f"in {info['wall_time_s']:.1f} s "
                f"= {rate:.2f} episodes/s ({rate / workers:.2f} per worker, speed-up {rate / base:.2f}; "
                f"chunks of {info['chunk_size_pairs']} pairs, {info['chunks_total']} chunks); "
                f"in chunks {info['compute_ms_per_episode']:.0f} ms per episode, workers busy "
                f"{info['busy_share']:.0%} of the time; "
                f"command {info['command_s']:.1f} s; protocol of {PROTOCOL_EPISODES} episodes: "
                f"{PROTOCOL_EPISODES / rate / 60:.0f} min",
                flush=True,
            )


def chunk_sizes(args, tmp: Path) -> None:
    workers = args.workers[-1]
    for size in args.chunk_sizes:
        info = run_batch("pool", workers, args.episodes, tmp / f"chunk{size}", chunk_size=size)
        print(
            f"pool {workers} worker(s), chunks of {size:3d} pair(s) ({info['chunks_total']:4d} chunks): "
            f"{info['episodes_per_s']:.2f} episodes/s, workers busy {info['busy_share']:.0%}, "
            f"command {info['command_s']:.1f} s",
            flush=True,
        )


def noop_chunk(rows: list[dict]):
    """A chunk that runs no episode: what is left is the executor's cost of one chunk."""
    from pedsafe_sumo.batch.runner import ChunkOutput

    return ChunkOutput(rows, [], "")


def fake_rows(first_episode: int) -> list[dict]:
    from pedsafe_sumo.batch.chunks import Task
    from pedsafe_sumo.batch.runner import error_row

    tasks = [Task("crossing", first_episode + i, i, ("sv", "v2i")) for i in range(OVERHEAD_ROWS // 2)]
    return [{**error_row(t, c, ""), "status": "ok"} for t in tasks for c in t.conditions]


def time_executor(submit, gather, count: int, rows: list[dict]) -> tuple[float, float]:
    """(ms per chunk one at a time, ms per chunk with all submitted at once)."""
    started = time.perf_counter()
    for _ in range(count // 4):
        gather([submit(rows)])
    latency_ms = (time.perf_counter() - started) / (count // 4) * 1e3
    started = time.perf_counter()
    gather([submit(rows) for _ in range(count)])
    throughput_ms = (time.perf_counter() - started) / count * 1e3
    return latency_ms, throughput_ms


def overhead(args, tmp: Path) -> None:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    workers = args.workers[-1]
    rows = fake_rows(0)
    count = args.overhead
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(noop_chunk, [rows] * workers))  # start the workers before timing
        latency, per_chunk = time_executor(
            lambda r: pool.submit(noop_chunk, r), lambda fs: [f.result() for f in fs], count, rows
        )
    print(
        f"pool {workers} workers, no-op chunk of {OVERHEAD_ROWS} rows: {latency:.2f} ms one at a time, "
        f"{per_chunk:.2f} ms each with {count} queued"
    )
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        print("dask: not installed (pip install 'pedsafe_sumo[cluster]')")
    else:
        import logging

        with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
            client = Client(cluster)
        try:
            client.gather([client.submit(noop_chunk, rows, pure=False) for _ in range(workers)])
            latency, per_chunk = time_executor(
                lambda r: client.submit(noop_chunk, r, pure=False), client.gather, count, rows
            )
        finally:
            client.close()
            cluster.close()
        print(
            f"dask {workers} workers, no-op chunk of {OVERHEAD_ROWS} rows: {latency:.2f} ms one at a time, "
            f"{per_chunk:.2f} ms each with {count} queued"
        )

    # Recording: case logs none, part file + manifest entry (both fsynced), as the driver does per chunk.
    from pedsafe_sumo.batch.chunks import plan_chunks
    from pedsafe_sumo.batch.rundir import BatchRunDirectory
    from pedsafe_sumo.batch.runner import ChunkOutput

    chunks = plan_chunks(["crossing"], ["sv", "v2i"], count * OVERHEAD_ROWS // 2, 1, OVERHEAD_ROWS // 2)
    run_dir = BatchRunDirectory(tmp / "record")
    run_dir.create({"state": "running"})
    times_ms = []
    for chunk in chunks:
        output = ChunkOutput(fake_rows(chunk.first_episode), [])
        started = time.perf_counter()
        run_dir.record(chunk, output, 0, 0.0)
        times_ms.append((time.perf_counter() - started) * 1e3)
    run_dir.release(remove_lock=True)
    tenth = max(1, len(times_ms) // 10)
    print(
        f"recording a chunk of {OVERHEAD_ROWS} rows (part file + manifest, fsynced): first {tenth} chunks "
        f"{sum(times_ms[:tenth]) / tenth:.1f} ms each, last {tenth} (manifest of {len(times_ms)} entries) "
        f"{sum(times_ms[-tenth:]) / tenth:.1f} ms each"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=40, help="episodes per scenario (x2 conditions)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--executors", nargs="+", default=["pool"], choices=["pool", "dask"])
    parser.add_argument("--chunk-sizes", type=int, nargs="*", default=[], help="pool runs with these sizes")
    parser.add_argument("--overhead", type=int, default=0, help="measure per-chunk costs over N chunks")
    parser.add_argument("--no-throughput", action="store_true", help="skip the episodes/s runs")
    args = parser.parse_args()
    print(
        f"machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}; load average {os.getloadavg()[0]:.2f} at start",
        flush=True,
    )
    tmp = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    try:
        if not args.no_throughput:
            throughput(args, tmp)
        if args.chunk_sizes:
            chunk_sizes(args, tmp)
        if args.overhead:
            overhead(args, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
