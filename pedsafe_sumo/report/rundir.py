"""Reading a batch's run directory (docs/batch.md) for the report, with every problem as one message.

DIR/episodes.parquet   one row per episode and condition (required)
DIR/run.json           the run's global information (optional: only its header line needs it)
DIR/cases/             per-step logs `<scenario>_<condition>_<seed>.parquet` (optional: the case figure)

A batch that has not finished (run.json state "running": stopped, killed, or still going) has no
complete episodes.parquet. It is refused with one line saying how to finish it, or, with
`partial=True`, read from the part files its manifest lists (pedsafe_sumo.io.run_store), and flagged
incomplete so that every output says so.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pedsafe_sumo.io.cases import case_stem
from pedsafe_sumo.io.run_store import (
    CASES_DIR,
    EPISODES_FILE,
    MANIFEST_FILE,
    RUN_FILE,
    STATE_COMPLETE,
    Manifest,
    RunStoreError,
    check_part,
    read_parts,
)

#: The episodes.parquet columns the report reads (a subset of docs/columns.md's).
REQUIRED_COLUMNS = (
    "scenario",
    "condition",
    "episode",
    "seed",
    "ped_age",
    "ego_initial_speed_mps",
    "collision",
    "injury_probability",
    "conflict",
    "first_detection_distance_m",
    "first_detection_time_s",
    "status",
)


class ReportError(ValueError):
    """A run directory the report cannot read; the message is one line naming the problem."""


@dataclass(frozen=True)
class RunDirectory:
    path: Path
    #: episodes.parquet as written by the batch
    episodes: pd.DataFrame
    #: run.json, or None when absent
    run_info: dict[str, Any] | None
    #: one line saying why run.json could not be read ("" when it was read or is absent)
    run_info_problem: str = ""
    #: for a batch that has not finished, read with partial=True: one line saying how much is there
    incomplete: str = ""
    #: The approach reported (report --approach, or the only one of the run; "" for a run without an
    #: approach column).
    approach: str = ""
    #: report --approach: the tables and figures go to DIR/approach_<arm>/ (one report per approach).
    selected_approach: str = ""

    @property
    def cases_dir(self) -> Path:
        return self.path / CASES_DIR

    def case_path(self, scenario: str, condition: str, seed: int, approach: str = "") -> Path:
        """The case log of an episode: a batch with --approach names it after the arm, one without not.
        `approach`: the episode's arm ("" = the run's)."""
        approach = approach or self.approach
        if approach:
            named = self.cases_dir / f"{case_stem(scenario, condition, int(seed), approach)}.parquet"
            if named.is_file():
                return named
        return self.cases_dir / f"{case_stem(scenario, condition, int(seed))}.parquet"


def _read_run_info(path: Path) -> tuple[dict[str, Any] | None, str]:
    """run.json as a dict (None when absent or unreadable) and the problem, if any, in one line."""
    run_path = path / RUN_FILE
    if not run_path.is_file():
        return None, ""
    try:
        loaded = json.loads(run_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return None, f"{run_path} is unreadable ({exc}); header left out"
    if not isinstance(loaded, dict):
        return None, f"{run_path} is not a JSON object; header left out"
    return loaded, ""


def _finished_parts(path: Path, run_info: dict[str, Any], partial: bool) -> tuple[pd.DataFrame, str]:
    """The rows of the chunks an unfinished batch has recorded, and the line that says so."""
    try:
        manifest = Manifest.load(path / MANIFEST_FILE)
    except RunStoreError as exc:
        raise ReportError(f"{path} is an unfinished batch run whose manifest cannot be read: {exc}") from None
    records = [r for _, r in sorted(manifest.chunks.items()) if not check_part(path, r)]
    total = run_info.get("chunks_total", "?")
    rows = sum(r.rows for r in records)
    done = f"{len(records)} of {total} chunks, {rows} of {run_info.get('episodes_total', '?')} episode rows"
    if not partial:
        raise ReportError(
            f"{path} is an unfinished batch run ({done} done): finish it with "
            f"python -m pedsafe_sumo.batch --resume --out {path}, or report what is done with --partial"
        )
    if not records:
        raise ReportError(f"{path} is an unfinished batch run with no finished chunk yet")
    return read_parts(path, records), f"INCOMPLETE RUN: {done}; every number covers these episodes only"


def _read_run(path: Path, partial: bool) -> tuple[pd.DataFrame, dict[str, Any] | None, str, str, Path]:
    """The run's episode rows, run.json, its problem line, the incomplete line and the rows' source file;
    raises ReportError with a one-line message on bad input."""
    path = Path(path)
    if not path.exists():
        raise ReportError(f"run directory {path} does not exist")
    if not path.is_dir():
        raise ReportError(f"{path} is not a directory (expected a run directory with {EPISODES_FILE})")
    run_info, problem = _read_run_info(path)
    episodes_path = path / EPISODES_FILE
    incomplete = ""
    # run.json without a state: written by a batch that could not be resumed, always at its end.
    if run_info is not None and run_info.get("state", STATE_COMPLETE) != STATE_COMPLETE:
        episodes, incomplete = _finished_parts(path, run_info, partial)
        source = path / MANIFEST_FILE
    else:
        if not episodes_path.is_file():
            raise ReportError(f"{path} has no {EPISODES_FILE}: not a batch run directory")
        try:
            episodes = pd.read_parquet(episodes_path, partitioning=None)
        except Exception as exc:  # pyarrow raises several unrelated types for a broken file
            first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ReportError(f"cannot read {episodes_path}: {first_line}") from exc
        source = episodes_path
    missing = [c for c in REQUIRED_COLUMNS if c not in episodes.columns]
    if missing:
        raise ReportError(f"{source} lacks required column(s): {', '.join(missing)}")
    if episodes.empty:
        raise ReportError(f"{source} has no rows")
    return episodes, run_info, problem, incomplete, source


def _approaches(episodes: pd.DataFrame) -> list[str]:
    """The arms a run's rows are on, in the order first met ([] for a run without an approach column)."""
    return [str(a) for a in episodes["approach"].unique() if a] if "approach" in episodes.columns else []


def load_run(path: Path, partial: bool = False, approach: str | None = None) -> RunDirectory:
    """Read and check a run directory; raises ReportError with a one-line message on bad input.

    An unfinished batch is refused, or with `partial` read from its finished chunks (module docstring).
    A run of several approaches (batch --approach all) is reported one approach at a time (`approach`).
    """
    path = Path(path)
    episodes, run_info, problem, incomplete, source = _read_run(path, partial)
    arms = _approaches(episodes)
    if approach is not None:
        if approach not in arms:
            raise ReportError(
                f"{source} has no episodes on approach {approach} (approaches: {', '.join(arms)})"
            )
        episodes = episodes[episodes["approach"] == approach].reset_index(drop=True)
    elif len(arms) > 1:
        raise ReportError(
            f"{source} holds episodes on approaches {', '.join(arms)}: report one at a time with --approach "
            f"{arms[0]} (the batch printed Table I per approach)"
        )
    return RunDirectory(
        path, episodes, run_info, problem, incomplete, approach or (arms[0] if arms else ""), approach or ""
    )


def load_run_per_approach(path: Path, partial: bool = False) -> dict[str, RunDirectory]:
    """Every approach of a run as its own RunDirectory, as `load_run(path, approach=arm)` reads it, keyed by
    the arm ("" for a run without an approach column); the rows are read once."""
    path = Path(path)
    episodes, run_info, problem, incomplete, _ = _read_run(path, partial)
    arms = _approaches(episodes)
    if len(arms) <= 1:
        arm = arms[0] if arms else ""
        return {arm: RunDirectory(path, episodes, run_info, problem, incomplete, arm, "")}
    return {
        arm: RunDirectory(
            path,
            episodes[episodes["approach"] == arm].reset_index(drop=True),
            run_info,
            problem,
            incomplete,
            arm,
            arm,
        )
        for arm in arms
    }


def _find(info: dict[str, Any], *names: str) -> Any:
    """The first of `names` found at the top of `info` or one level down (e.g. under "config")."""
    for name in names:
        if name in info:
            return info[name]
    for value in info.values():
        if isinstance(value, dict):
            for name in names:
                if name in value:
                    return value[name]
    return None


def _versions_text(versions: Any) -> str:
    if isinstance(versions, dict):
        flat = {k: v for k, v in versions.items() if not isinstance(v, (dict, list))}
        return ", ".join(f"{k} {v}" for k, v in flat.items())
    return "" if versions is None else str(versions)


def run_header(run: RunDirectory) -> str:
    """One line about the run from the batch's run.json: episodes per scenario (`episodes_per_scenario`),
    run seed (`run_seed`), wall time (`wall_time_s`), versions (`versions`), those that are there.
    Without run.json the line counts the parquet's rows.
    """
    n_rows = len(run.episodes)
    if run.run_info is None:
        return f"run {run.path}: {n_rows} episode rows (no {RUN_FILE})"
    info = run.run_info
    parts = [f"run {run.path}:"]
    episodes = _find(info, "episodes_per_scenario")
    if isinstance(episodes, (int, float)) and not isinstance(episodes, bool):
        parts.append(f"{episodes:g} episodes per scenario and condition ({n_rows} rows)")
    else:
        parts.append(f"{n_rows} episode rows")
    seed = _find(info, "run_seed")
    if seed is not None:
        parts.append(f"seed {seed}")
    wall = _find(info, "wall_time_s")
    if isinstance(wall, (int, float)) and not isinstance(wall, bool) and math.isfinite(wall):
        parts.append(f"wall time {wall:.1f} s")
    versions = _versions_text(_find(info, "versions"))
    if versions:
        parts.append(f"versions: {versions}")
    return parts[0] + " " + "; ".join(parts[1:])


def approaches_of(path: Path, partial: bool = False) -> list[str]:
    """The approaches a run's rows are on, in the order first met ([] without an approach column)."""
    return _approaches(_read_run(Path(path), partial)[0])


def load_pooled(path: Path, partial: bool = False) -> RunDirectory:
    """Every row of a run of several approaches as one RunDirectory (the pooled report: its case logs are
    found by each row's own approach)."""
    path = Path(path)
    episodes, run_info, problem, incomplete, _ = _read_run(path, partial)
    return RunDirectory(path, episodes, run_info, problem, incomplete, "", "")
