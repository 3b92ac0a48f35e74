"""Reading a batch's run directory (DESIGN section 3) for the report, with every problem as one message.

DIR/episodes.parquet   one row per episode and condition (required)
DIR/run.json           the run's global information (optional: only its header line needs it)
DIR/cases/             per-step logs `<scenario>_<condition>_<seed>.parquet` (optional: the case figure)
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pedsafe_sumo.io.cases import case_stem

EPISODES_FILE = "episodes.parquet"
RUN_FILE = "run.json"
CASES_DIR = "cases"

#: The episodes.parquet columns the report reads (a subset of DESIGN section 3's).
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

    @property
    def cases_dir(self) -> Path:
        return self.path / CASES_DIR

    def case_path(self, scenario: str, condition: str, seed: int) -> Path:
        return self.cases_dir / f"{case_stem(scenario, condition, int(seed))}.parquet"


def load_run(path: Path) -> RunDirectory:
    """Read and check a run directory; raises ReportError with a one-line message on bad input."""
    path = Path(path)
    if not path.exists():
        raise ReportError(f"run directory {path} does not exist")
    if not path.is_dir():
        raise ReportError(f"{path} is not a directory (expected a run directory with {EPISODES_FILE})")
    episodes_path = path / EPISODES_FILE
    if not episodes_path.is_file():
        raise ReportError(f"{path} has no {EPISODES_FILE}: not a batch run directory")
    try:
        episodes = pd.read_parquet(episodes_path)
    except Exception as exc:  # pyarrow raises several unrelated types for a broken file
        first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ReportError(f"cannot read {episodes_path}: {first_line}") from exc
    missing = [c for c in REQUIRED_COLUMNS if c not in episodes.columns]
    if missing:
        raise ReportError(f"{episodes_path} lacks required column(s): {', '.join(missing)}")
    if episodes.empty:
        raise ReportError(f"{episodes_path} has no rows")
    run_info, problem = None, ""
    run_path = path / RUN_FILE
    if run_path.is_file():
        try:
            loaded = json.loads(run_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            problem = f"{run_path} is unreadable ({exc}); header left out"
        else:
            if isinstance(loaded, dict):
                run_info = loaded
            else:
                problem = f"{run_path} is not a JSON object; header left out"
    return RunDirectory(path, episodes, run_info, problem)


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
