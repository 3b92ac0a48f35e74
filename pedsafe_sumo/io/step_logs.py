"""The per-step logs of every episode of a run (`--keep-logs all`): one compact Parquet file per chunk.

    DIR/steplogs/<scenario>-<first>-<last>.parquet

A file holds every step of every episode of one chunk that ran (an episode with status "error" has no
log), one row per step: the key columns KEY_COLUMNS, then the episode log's own columns (the
`pedsafe_sumo.safety.log` contract plus the engine's diagnostics). Rows are ordered by episode, sv before
v2i, then time. Float columns stay float64 so that every index of episodes.parquet can be recomputed
from them exactly (`pedsafe_sumo.safety.episode_indexes`); zstd compression and Parquet's dictionary and
run-length encodings keep the constant columns (sizes, keys) nearly free. The batch's driver writes a
file atomically and records its checksum in the manifest with the chunk's part file (run_store).
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pandas as pd

from pedsafe_sumo.io.run_store import STEPLOGS_DIR

#: The values of `--keep-logs`: the logs of episode pairs with a collision or a conflict (cases/), or
#: those and every episode's step log besides.
KEEP_EVENTS, KEEP_ALL = "events", "all"
KEEP_LOGS_CHOICES = (KEEP_EVENTS, KEEP_ALL)
KEY_COLUMNS = ("scenario", "condition", "episode", "seed")
_CONDITION_ORDER = {"sv": 0, "v2i": 1}


def steplog_file_name(scenario: str, first_episode: int, last_episode: int) -> str:
    """steplogs/ name of the chunk holding episodes first..last (inclusive): the part file's name."""
    return f"{scenario}-{first_episode:06d}-{last_episode:06d}.parquet"


def chunk_step_log(episodes: list[tuple[int, Any]]) -> pd.DataFrame:
    """One table of the logs of (episode index, EpisodeResult) pairs, with the key columns first."""
    frames = []
    for episode, result in episodes:
        log = result.log.reset_index(drop=True)
        keys = pd.DataFrame(
            {
                "scenario": [result.setup.scenario] * len(log),
                "condition": [result.condition] * len(log),
                "episode": [int(episode)] * len(log),
                "seed": [int(result.setup.seed)] * len(log),
            }
        )
        frames.append(pd.concat([keys, log], axis=1))
    if not frames:
        return pd.DataFrame({c: [] for c in KEY_COLUMNS})
    return sort_steps(pd.concat(frames, ignore_index=True))


def sort_steps(table: pd.DataFrame) -> pd.DataFrame:
    if table.empty:
        return table.reset_index(drop=True)
    table = table.sort_values(
        ["episode", "condition", "time_s"],
        key=lambda s: s.map(_CONDITION_ORDER) if s.name == "condition" else s,
        kind="stable",
    )
    return table.reset_index(drop=True)


def to_bytes(table: pd.DataFrame) -> bytes:
    buffer = io.BytesIO()
    table.to_parquet(buffer, index=False, compression="zstd")
    return buffer.getvalue()


def from_bytes(data: bytes) -> pd.DataFrame:
    return pd.read_parquet(io.BytesIO(data))


def merge_bytes(parts: list[bytes]) -> bytes:
    """The step logs of a chunk run pair by pair (after a worker died), as one file's bytes."""
    tables = [from_bytes(p) for p in parts if p]
    if not tables:
        return b""
    return to_bytes(sort_steps(pd.concat(tables, ignore_index=True)))


def read_step_logs(run_dir: Path, files: list[str] | None = None) -> pd.DataFrame:
    """The kept step logs of a run (`files`: paths relative to the run directory; all of steplogs/ when
    None), as one table."""
    run_dir = Path(run_dir)
    if files is None:
        paths = sorted((run_dir / STEPLOGS_DIR).glob("*.parquet"))
    else:
        paths = [run_dir / f for f in files]
    # partitioning=None: a 'key=value' folder in the path must not become a column.
    tables = [pd.read_parquet(p, partitioning=None) for p in paths]
    return pd.concat(tables, ignore_index=True) if tables else pd.DataFrame({c: [] for c in KEY_COLUMNS})


def episode_logs(steps: pd.DataFrame) -> Iterator[tuple[tuple[str, str, int], pd.DataFrame]]:
    """((scenario, condition, episode), that episode's log without the key columns), in table order."""
    for key, log in steps.groupby(["scenario", "condition", "episode"], sort=False):
        yield (
            (str(key[0]), str(key[1]), int(key[2])),
            log.drop(columns=list(KEY_COLUMNS)).reset_index(drop=True),
        )
