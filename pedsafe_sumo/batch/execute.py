"""A planned batch carried out: its run directory created (or reopened on --resume), the chunks run on the
backend with a progress bar, the rows finalised, run.json completed, and Table I printed.
"""

from __future__ import annotations

import math
import platform
import sys
import time
from datetime import datetime, timezone
from typing import Any

import numpy
import pandas
from tqdm import tqdm

from pedsafe_sumo.batch.chunks import Chunk, auto_chunk_size, plan_chunks
from pedsafe_sumo.batch.executors import DaskBackend, ProcessPoolBackend
from pedsafe_sumo.batch.plan import Plan
from pedsafe_sumo.batch.rundir import BatchRunDirectory, utc_now
from pedsafe_sumo.batch.runner import ChunkOutput, worker_versions
from pedsafe_sumo.batch.sampled import plan_sampled_chunks, run_sampled
from pedsafe_sumo.batch.summary import print_table
from pedsafe_sumo.compiled_kernels import prepare_compiled_kernels
from pedsafe_sumo.control.timeout import TIMEOUT_STATUS
from pedsafe_sumo.io.run_store import STATE_COMPLETE, STATE_RUNNING, STEPLOGS_DIR
from pedsafe_sumo.io.step_logs import KEEP_ALL
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.provenance import git_commit
from pedsafe_sumo.safety.stats import ERROR_STATUS

Backend = DaskBackend | ProcessPoolBackend


def _versions() -> dict[str, str]:
    """The versions run.json records: the workers' (pedsafe_sumo, SUMO), Python's, numpy's, pandas'."""
    return {
        **worker_versions(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "pandas": pandas.__version__,
        "platform": platform.platform(),
    }


def new_run_info(plan: Plan, backend: Backend, argv: list[str]) -> dict[str, Any]:
    """run.json of a new run, state running: its identity, where the site's files are, how many chunks and
    episodes, the arguments, the executor, versions and commit; the totals filled in at the end."""
    identity = plan.identity
    chunks_total = len(plan.scenarios) * math.ceil(
        identity["episodes_per_scenario"] / identity["chunk_size_pairs"]
    )
    per_scenario = identity["episodes_per_scenario"]
    if identity["sampler"] is not None:  # importance sampling: the pilot stages come on top
        chunks_total = len(plan_sampled_chunks(plan.scenarios, plan.conditions, identity, {}))
        per_scenario += identity["sampler"]["pilot_stages"] * identity["sampler"]["pilot_episodes"]
    return {
        "state": STATE_RUNNING,
        "command": "python -m pedsafe_sumo.batch " + " ".join(argv),
        "created_utc": datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S"),
        **identity,
        # Where the site's files were (the digests above say what they held): replay finds them here.
        "site_path": str(resolve_site(plan.arguments["site"], verify=False).directory.resolve()),
        "chunks_total": chunks_total,
        "episodes_total": len(plan.scenarios) * per_scenario * len(plan.conditions),
        "arguments": plan.arguments,
        "keep_logs": plan.arguments["keep_logs"],
        "workers": backend.n_workers,
        "executor": backend.description,
        "versions": _versions(),
        # Only when known: a package installed from a wheel has no commit to record.
        **({"commit": commit} if (commit := git_commit()) else {}),
        "sessions": [],
        "wall_time_s": None,
        "episodes_per_s": None,
        "n_error": None,
        "n_timeout": None,
        "cases_written": None,
    }


def run_batch(plan: Plan, backend: Backend, argv: list[str], progress: bool = True) -> int:
    """Run the planned batch on `backend` (already started): a new run directory, or the resumed one's
    missing chunks; then the table, run.json completed, and Table I printed. Returns the exit code.
    `progress` False: no progress bar."""
    run_dir = BatchRunDirectory(plan.out, plan.arguments["keep_logs"])
    if plan.recorded is None:
        if plan.identity["chunk_size_pairs"] is None:
            size = auto_chunk_size(plan.identity["episodes_per_scenario"], backend.n_workers)
            plan.identity["chunk_size_pairs"] = plan.arguments["chunk_size"] = size
        run_info = new_run_info(plan, backend, argv)
        run_dir.create(run_info)
    else:
        run_info = plan.recorded
        for note in run_dir.reopen():
            print(f"note: {note}", file=sys.stderr)
        commit = git_commit()
        if commit != run_info.get("commit", ""):
            print(
                f"note: the run was started at commit {run_info.get('commit') or '?'}, this is "
                f"{commit or '?'}",
                file=sys.stderr,
            )
    for note in getattr(backend, "notes", []):
        print(f"note: {note}", file=sys.stderr)

    if plan.identity.get("sampler") is not None:
        # Importance sampling: the chunks' layout is known, their proposals only stage by stage.
        chunks = plan_sampled_chunks(plan.scenarios, plan.conditions, plan.identity, {})
    else:
        chunks = plan_chunks(
            plan.scenarios,
            plan.conditions,
            plan.identity["episodes_per_scenario"],
            plan.identity["run_seed"],
            plan.identity["chunk_size_pairs"],
        )
    recorded = run_dir.manifest.chunks
    todo = [chunk for chunk in chunks if chunk.key not in recorded]
    total = sum(chunk.n_rows for chunk in chunks)
    done_rows = total - sum(chunk.n_rows for chunk in todo)
    session_index = len(run_info["sessions"])
    session: dict[str, Any] = {
        "started_utc": utc_now(),
        "command": "python -m pedsafe_sumo.batch " + " ".join(argv),
        "executor": backend.description,
        **({"commit": commit} if (commit := git_commit()) else {}),
        "chunks_to_run": len(todo),
        "wall_time_s": None,
    }
    run_info["sessions"].append(session)
    run_dir.save_run_info(run_info)

    what = f"{total} episodes ({', '.join(plan.scenarios)} x {', '.join(plan.conditions)})"
    resumed = f", {done_rows} done before" if plan.recorded is not None else ""
    print(
        f"{what} in {len(chunks)} chunk(s) of up to {plan.identity['chunk_size_pairs']} pair(s){resumed}; "
        f"{len(todo)} chunk(s) to run on {backend.description} -> {plan.out}"
    )
    prepare_compiled_kernels()  # here, once: the workers then load them from numba's cache
    started = time.perf_counter()
    with tqdm(
        total=total,
        initial=done_rows,
        unit="episode",
        smoothing=0.1,
        mininterval=1.0,
        file=sys.stderr,
        disable=not progress,
    ) as bar:

        def on_chunk_done(chunk: Chunk, output: ChunkOutput) -> None:
            if run_dir.record(chunk, output, session_index, time.perf_counter() - started):
                bar.update(chunk.n_rows)

        if plan.identity.get("sampler") is not None:
            chunks = run_sampled(plan, backend, run_dir, run_info, on_chunk_done)
        else:
            backend.run(plan.config, todo, on_chunk_done)
    session_wall_s = time.perf_counter() - started

    table = run_dir.finalize(chunks)
    session.update(wall_time_s=round(session_wall_s, 3), worker_deaths=backend.worker_deaths)
    wall_s = sum(run_dir.session_wall_times_s(run_info["sessions"]))
    n_timeout = int((table["status"] == TIMEOUT_STATUS).sum())
    n_error = int((table["status"] == ERROR_STATUS).sum()) + n_timeout
    cases_written = len(list(run_dir.cases_dir.glob("*.parquet")))
    run_info.update(
        state=STATE_COMPLETE,
        completed_utc=utc_now(),
        wall_time_s=round(wall_s, 3),
        episodes_per_s=round(total / wall_s, 3) if wall_s > 0 else None,
        n_error=n_error,
        n_timeout=n_timeout,
        cases_written=cases_written,
    )
    run_dir.save_run_info(run_info)
    run_dir.release(remove_lock=True)

    ran_rows = total - done_rows
    rate = f" ({ran_rows / session_wall_s:.1f} episodes/s)" if ran_rows and session_wall_s > 0 else ""
    print(
        f"{ran_rows} episodes run in {session_wall_s:.1f} s{rate}; {n_error} error(s) ({n_timeout} "
        f"timeout(s)), left out of the rates; {cases_written} case log(s) in {run_dir.cases_dir}"
    )
    if plan.arguments["keep_logs"] == KEEP_ALL:
        print(f"every episode's step log: {len(chunks)} file(s) in {plan.out / STEPLOGS_DIR}")
    if backend.worker_deaths:
        print(
            f"{backend.worker_deaths} worker process death(s): the chunks they were running ran again "
            "(a pair that killed its worker every time is recorded as errors)"
        )
    print_table(table, run_info)
    print(f"tables and figures: python -m pedsafe_sumo.report {plan.out}")
    return 0
