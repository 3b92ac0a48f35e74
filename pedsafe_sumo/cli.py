"""The commands' shared command-line pieces: a parser whose errors are one line, the range checks of
numeric options, and the bound on how many episodes one command may start (docs/trust.md).

Every numeric option has a documented range, checked before any work starts; NaN and infinities lie in
no range. A command that expands a grid (a sweep's combinations, a batch over every scenario and
approach) says in one line how many episodes it will run and refuses more than `--max-runs`.
"""

from __future__ import annotations

import argparse
import math
from typing import NoReturn

from pedsafe_sumo.usage import UsageError

#: Default bound on the episodes one command starts (each condition of a pair counts): a million episodes
#: take about a day on 2 cores at 10-12 episodes/s (BENCHMARKS.md, "A whole protocol"), twelve times the
#: paper's protocol (80,000 episodes). A larger run is one flag away (--max-runs); the bound catches a
#: grid that multiplied beyond what was meant (docs/decisions/2026-11-27-max-runs.md).
DEFAULT_MAX_RUNS = 1_000_000
#: The largest --max-runs accepted: a billion episodes take about three years on 2 cores, a month on 64.
MAX_MAX_RUNS = 1_000_000_000
#: Seeds are stored in run.json and compared as 64-bit integers.
MAX_SEED = 2**63 - 1
#: Episodes per scenario of a run: part files number episodes with six digits, and a million pairs take
#: about two days on 2 cores (10-12 episodes/s, BENCHMARKS.md).
MAX_EPISODES = 1_000_000


class OneLineParser(argparse.ArgumentParser):
    """argparse whose errors are one line on stderr (exit 2), like every other bad input."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"error: {message} (see --help)\n")


def check_range(
    value: float,
    option: str,
    low: float,
    high: float,
    *,
    unit: str = "",
    low_open: bool = False,
    error: type[Exception] = UsageError,
) -> None:
    """Raise `error` (one line) unless low <= value <= high (low < value with `low_open`); NaN and
    infinities are refused."""
    number = float(value)
    above_low = number > low if low_open else number >= low
    if not (math.isfinite(number) and above_low and number <= high):
        opening = "(" if low_open else "["
        raise error(f"{option} must be in {opening}{low:g}, {high:g}]{unit}, got {value}")


def check_seed(seed: int, option: str = "--seed", error: type[Exception] = UsageError) -> None:
    """A run seed: a whole number from 0 to 2**63 - 1."""
    if seed < 0:
        raise error(f"{option} must not be negative, got {seed} (seeds lie in 0..2**63 - 1)")
    if seed > MAX_SEED:
        raise error(f"{option} must be at most 2**63 - 1, got {seed}")


def check_max_runs(max_runs: int) -> None:
    """--max-runs itself: 1 to MAX_MAX_RUNS."""
    if not 1 <= max_runs <= MAX_MAX_RUNS:
        raise UsageError(f"--max-runs must lie in 1..{MAX_MAX_RUNS:,}, got {max_runs}")


def check_run_count(total: int, max_runs: int, what: str) -> None:
    """Refuse (one line) a command that would start more than `max_runs` episodes; `what` says how the
    total multiplies up."""
    if total > max_runs:
        raise UsageError(
            f"{what} = {total:,} episodes, more than --max-runs {max_runs:,}: "
            "give fewer, or a larger --max-runs"
        )


def max_runs_help(default: int = DEFAULT_MAX_RUNS) -> str:
    return (
        f"refuse to start more than this many episodes in all (each condition counts), 1 to "
        f"{MAX_MAX_RUNS:,} [{default:,}: about a day on 2 cores]"
    )
