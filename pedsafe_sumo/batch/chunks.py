"""Chunks: the unit a batch schedules, records and resumes.

A chunk is a contiguous range of episode indices of one scenario; each episode is a pair (both
conditions from one seed, in one worker). A chunk's rows go into one part file and one manifest entry
(pedsafe_sumo.io.run_store). The chunk layout decides nothing about the rows: an episode's rows are a
function of (run seed, scenario, episode index, settings) only, so any chunking gives the same table.

Chunk size. Per chunk the batch pays scheduling (a few ms on Dask, less on the process pool), one
part file and one manifest rewrite (a few ms, growing slowly with the number of chunks); a kill loses
the chunks in flight; the progress bar moves once per chunk; and the last chunks decide how long the
tail of the run is. The automatic size aims at about 8 chunks per worker and scenario, capped at
MAX_AUTO_CHUNK_PAIRS = 25 pairs (50 episodes, about 4 s on one worker of the 2-core development
machine): the per-chunk costs stay under 1 % of a chunk's time, a kill loses at most about 4 s of
work per worker, and the bar moves every 2 s on 2 workers. See BENCHMARKS.md for the measurements.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pedsafe_sumo.io.run_store import part_file_name

MAX_AUTO_CHUNK_PAIRS = 25
CHUNKS_PER_WORKER = 8


def episode_seed(run_seed: int, episode: int) -> int:
    """Seed of episode `episode` of a run: independent streams per episode (numpy SeedSequence)."""
    state = np.random.SeedSequence(entropy=run_seed, spawn_key=(episode,)).generate_state(1, dtype=np.uint32)
    return int(state[0])


EPISODE_SEED_RULE = "SeedSequence(entropy=run_seed, spawn_key=(episode,)).generate_state(1)[0]"


@dataclass(frozen=True)
class Task:
    """One episode pair: every condition of episode `episode` of a scenario, from one seed."""

    scenario: str
    episode: int
    seed: int
    conditions: tuple[str, ...]
    #: Importance sampling (--sampler is): the proposal the episode's inputs come from, as canonical JSON
    #: (sampling.draws.product_to_json; "" = the nominal, plain Monte Carlo), and its sampler stage.
    proposal: str = ""
    stage: int = 0


@dataclass(frozen=True)
class Chunk:
    """Episodes first_episode..last_episode (inclusive) of one scenario, each under every condition."""

    scenario: str
    first_episode: int
    last_episode: int
    tasks: tuple[Task, ...]

    @property
    def key(self) -> str:
        return part_file_name(self.scenario, self.first_episode, self.last_episode).removesuffix(".parquet")

    @property
    def n_rows(self) -> int:
        return sum(len(task.conditions) for task in self.tasks)


def auto_chunk_size(episodes_per_scenario: int, workers: int) -> int:
    """Pairs per chunk when --chunk-size is not given (module docstring: why these numbers)."""
    per_worker = math.ceil(episodes_per_scenario / (CHUNKS_PER_WORKER * max(1, workers)))
    return max(1, min(MAX_AUTO_CHUNK_PAIRS, per_worker))


def plan_chunks(
    scenarios: list[str], conditions: list[str], episodes_per_scenario: int, run_seed: int, chunk_pairs: int
) -> list[Chunk]:
    """Every chunk of a run, scenario by scenario, in episode order."""
    chunks = []
    for scenario in scenarios:
        for first in range(0, episodes_per_scenario, chunk_pairs):
            last = min(first + chunk_pairs, episodes_per_scenario) - 1
            tasks = tuple(
                Task(scenario, i, episode_seed(run_seed, i), tuple(conditions))
                for i in range(first, last + 1)
            )
            chunks.append(Chunk(scenario, first, last, tasks))
    return chunks
