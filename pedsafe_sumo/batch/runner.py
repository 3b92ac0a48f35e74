"""Batches of episodes: paired SV/V2I runs of one or more scenarios over a pool of worker processes.

Episode i of a scenario gets seed `episode_seed(run_seed, i)`; both conditions of the pair run from
that seed, in the same worker, one after the other. Each worker owns one SUMO instance (libsumo) and
reuses it. Rows are sorted by (scenario, episode, condition) before writing, so the table is the
same whatever the number of workers.
"""

from __future__ import annotations

import concurrent.futures as futures
import multiprocessing
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.io.episodes import EPISODE_COLUMNS, to_table


def episode_seed(run_seed: int, episode: int) -> int:
    """Seed of episode `episode` of a run: independent streams per episode (numpy SeedSequence)."""
    state = np.random.SeedSequence(entropy=run_seed, spawn_key=(episode,)).generate_state(1, dtype=np.uint32)
    return int(state[0])


@dataclass(frozen=True)
class Task:
    scenario: str
    episode: int
    seed: int
    conditions: tuple[str, ...]


@dataclass(frozen=True)
class WorkerConfig:
    site: str
    params: dict[str, Any]
    scenario_overrides: dict[str, str]
    algorithm: str
    cases_dir: str | None


_RUNNER = None
_CONFIG: WorkerConfig | None = None


def init_worker(config: WorkerConfig) -> None:
    """Process-pool initializer: one EpisodeRunner (and one SUMO) per worker process."""
    global _RUNNER, _CONFIG
    from pedsafe_sumo.control.agent import load_agent_class
    from pedsafe_sumo.network.sites import get_site
    from pedsafe_sumo.sim.episode import EpisodeRunner

    _CONFIG = config
    _RUNNER = EpisodeRunner(get_site(config.site), config.params, load_agent_class(config.algorithm))


def error_row(task: Task, condition: str, message: str) -> dict[str, Any]:
    row: dict[str, Any] = {c: np.nan for c in EPISODE_COLUMNS}
    row.update(
        scenario=task.scenario,
        condition=condition,
        episode=task.episode,
        seed=task.seed,
        collision=False,
        conflict=False,
        sumo_collision=False,
        detected_by="",
        ped_gender="",
        ped_risk="",
        status="error",
        error=message,
    )
    return row


def run_task(task: Task) -> list[dict[str, Any]]:
    """Both conditions of one paired episode; cases written for the pair when either had an event."""
    from pedsafe_sumo.io.cases import write_case
    from pedsafe_sumo.scenarios.registry import get_scenario

    assert _RUNNER is not None and _CONFIG is not None, "init_worker was not called"
    rows, results = [], []
    try:
        spec = get_scenario(task.scenario).with_overrides(_CONFIG.scenario_overrides)
        setup = _RUNNER.draw_setup(spec, task.seed)
    except Exception as exc:  # the pair cannot even be set up: both rows are errors
        message = f"{type(exc).__name__}: {exc}"
        return [error_row(task, c, message) for c in task.conditions]
    for condition in task.conditions:
        try:
            result = _RUNNER.run(spec, condition, task.seed, setup=setup)
        except Exception as exc:
            rows.append(error_row(task, condition, f"{type(exc).__name__}: {exc}"))
            _reset_runner()
            continue
        rows.append({**result.outcome, "episode": task.episode})
        results.append(result)
    if _CONFIG.cases_dir and any(r.outcome["collision"] or r.outcome["conflict"] for r in results):
        for result in results:
            write_case(Path(_CONFIG.cases_dir), result)
    return rows


def _reset_runner() -> None:
    """After a failed episode SUMO may be in any state: start a fresh instance for the next one."""
    global _RUNNER
    try:
        _RUNNER.close()
    except Exception:  # noqa: BLE001 - the instance is being discarded anyway
        traceback.print_exc(limit=0)
    init_worker(_CONFIG)


def run_tasks(tasks: list[Task], config: WorkerConfig, workers: int, progress=None) -> pd.DataFrame:
    """Run every task; `progress(n_episodes_done)` is called as pairs complete."""
    rows: list[dict[str, Any]] = []
    if workers <= 1:
        init_worker(config)
        try:
            for task in tasks:
                rows += run_task(task)
                if progress:
                    progress(len(task.conditions))
        finally:
            _RUNNER.close()
    else:
        context = multiprocessing.get_context("spawn")  # no SUMO state inherited across fork
        with futures.ProcessPoolExecutor(
            workers, mp_context=context, initializer=init_worker, initargs=(config,)
        ) as pool:
            pending = [pool.submit(run_task, task) for task in tasks]
            for done in futures.as_completed(pending):
                task_rows = done.result()
                rows += task_rows
                if progress:
                    progress(len(task_rows))
    return to_table(rows)
