"""The package from Python (notebooks, scripts): run a batch or one episode, read a run directory, its
Table I, paired comparison and figures.

    from pedsafe_sumo import api

    run = api.run_batch("results/quick", scenario="crossing", episodes=4, workers=2)
    run.episodes                      # episodes.parquet as a DataFrame
    api.table_one(run)                # Table I, the numbers the report prints
    api.paired_comparison(run)        # the paired SV-vs-V2I tests
    api.figure(run, "impact_speed")   # a report figure as a matplotlib Figure

Every function takes the options of its command line under the same names (`--keep-logs` is
`keep_logs`; `--set` is `overrides`, `--condition` is `conditions`) and hands them to the command's own
parsing and checks: a bad value raises `UsageError` with the line the command prints after "error:".
A script that calls `run_batch` needs `if __name__ == "__main__":` around it: the batch's worker
processes are spawned, and each imports the script's main module.
"""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import pandas as pd
from matplotlib.figure import Figure

from pedsafe_sumo import episode as episode_command
from pedsafe_sumo.batch import __main__ as batch_command
from pedsafe_sumo.batch.executors import BatchError
from pedsafe_sumo.batch.plan import INPUT_ERRORS
from pedsafe_sumo.cli import OneLineParser
from pedsafe_sumo.report import __main__ as report_command
from pedsafe_sumo.report.indexes import KeptLogs
from pedsafe_sumo.report.rundir import ReportError, RunDirectory
from pedsafe_sumo.report.rundir import load_run as load_run_directory
from pedsafe_sumo.settings import UsageError
from pedsafe_sumo.sim.outcome import EpisodeResult

__all__ = [
    "FIGURES",
    "BatchError",
    "EpisodeRun",
    "ReportError",
    "Run",
    "UsageError",
    "figure",
    "load_run",
    "paired_comparison",
    "run_batch",
    "run_episode",
    "table_one",
]

#: The report's figures by name (`figure(run, name)`), in the order the report draws them.
FIGURES = tuple(report_command.FIGURE_FILES)

PathLike = str | os.PathLike[str]


class _RaisingParser(OneLineParser):
    """The commands' parser, raising UsageError where the command line prints one line and exits."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def _argv(options: Mapping[str, Any]) -> list[str]:
    """The command line of `options` (name -> value; None = not given): `name` becomes --name with
    underscores as hyphens, True a flag alone, False nothing, a list the option repeated."""
    argv: list[str] = []
    for name, value in options.items():
        flag = "--" + name.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            argv.append(flag)
        elif isinstance(value, (list, tuple)):
            argv += [f"{flag}={item}" for item in value]
        else:
            argv.append(f"{flag}={os.fspath(value) if isinstance(value, os.PathLike) else value}")
    return argv


def _set_pairs(overrides: Mapping[str, Any] | Sequence[str] | None) -> list[str] | None:
    """--set pairs from a mapping {key: value} or a list of "key=value" strings."""
    if overrides is None:
        return None
    if isinstance(overrides, str):
        return [overrides]
    if isinstance(overrides, Mapping):
        return [
            f"{key}={str(value).lower() if isinstance(value, bool) else value}"
            for key, value in overrides.items()
        ]
    return list(overrides)


def _condition(conditions: str | Sequence[str] | None) -> str | None:
    """--condition from "sv", "v2i", "both" or a list of conditions (both of them: "both")."""
    if conditions is None or isinstance(conditions, str):
        return conditions
    given = list(dict.fromkeys(conditions))
    if sorted(given) == ["sv", "v2i"]:
        return "both"
    return ",".join(given)  # one condition, or a value the command refuses with its own message


@contextlib.contextmanager
def _quiet_unless(show: bool) -> Iterator[None]:
    """stdout as it is when `show`, else swallowed."""
    if show:
        yield
    else:
        with contextlib.redirect_stdout(io.StringIO()):
            yield


# ---------------------------------------------------------------- reading a run
@dataclass(frozen=True)
class Run:
    """A batch's run directory, read: its rows, its configuration, its kept step logs.

    `load_run` and `run_batch` return one; `table_one`, `paired_comparison` and `figure` take one.
    """

    #: The report's view of the run directory (pedsafe_sumo.report.RunDirectory).
    directory: RunDirectory

    @property
    def path(self) -> Path:
        """The run directory."""
        return self.directory.path

    @property
    def episodes(self) -> pd.DataFrame:
        """episodes.parquet: one row per episode and condition (columns: docs/columns.md)."""
        return self.directory.episodes

    @property
    def config(self) -> dict[str, Any]:
        """run.json as a dict: configuration, parameters, seeds, versions, timings ({} without one)."""
        return self.directory.run_info or {}

    def steps(
        self, episode: int | pd.Series, condition: str | None = None, scenario: str | None = None
    ) -> pd.DataFrame:
        """The per-step log of one episode, if the run kept it (cases/: the pairs with a collision or a
        conflict; steplogs/: every episode, with keep_logs="all").

        Args:
            episode: the episode number (column `episode`), or a row of `episodes` (which names its
                scenario and condition).
            condition: "sv" or "v2i"; needed with an episode number unless the run has one condition.
            scenario: needed with an episode number unless the run has one scenario.

        Raises:
            ReportError: no such episode, or its log was not kept (one line).
        """
        if isinstance(episode, pd.Series):
            scenario, condition, number = (
                str(episode["scenario"]),
                str(episode["condition"]),
                episode["episode"],
            )
        else:
            number = episode
        rows = self.episodes
        scenario = scenario if scenario is not None else self._only("scenario")
        condition = condition if condition is not None else self._only("condition")
        match = rows[
            (rows["scenario"] == scenario) & (rows["condition"] == condition) & (rows["episode"] == number)
        ]
        if match.empty:
            raise ReportError(f"{self.path}: no episode {number} of {scenario} under {condition}")
        log = KeptLogs(self.directory)(scenario, condition, int(number), int(match["seed"].iloc[0]))
        if log is None:
            raise ReportError(
                f"{self.path}: the step log of {scenario} episode {number} ({condition}) was not kept "
                '(cases/ holds the pairs with a collision or a conflict; keep_logs="all" keeps every one)'
            )
        return log

    def _only(self, column: str) -> str:
        values = list(pd.unique(self.episodes[column]))
        if len(values) != 1:
            raise ReportError(
                f"{self.path} has several values of {column} ({', '.join(map(str, values))}): name one"
            )
        return str(values[0])

    def __repr__(self) -> str:
        return f"Run({str(self.path)!r}, {len(self.episodes)} episode rows)"


def load_run(path: PathLike, *, partial: bool = False, approach: str | None = None) -> Run:
    """Read a batch's run directory, checked as the report checks it.

    Args:
        path: the run directory (`--out` of the batch).
        partial: read a batch that has not finished from its finished chunks (the report's --partial).
        approach: the approach to read, for a run of several (batch --approach all).

    Raises:
        ReportError: a missing directory, no episodes.parquet, missing columns, an unfinished run (one line).
    """
    return Run(load_run_directory(Path(path), partial=partial, approach=approach))


def table_one(run: Run) -> pd.DataFrame:
    """Table I: per scenario and condition, collision rate, mean injury probability and conflict rate with
    their 95% intervals, and the collisions by type: the numbers `python -m pedsafe_sumo.report` prints
    and writes to tables/table1.csv."""
    return report_command.tables_of(run.directory)[0]


def paired_comparison(run: Run) -> pd.DataFrame:
    """The paired SV-vs-V2I comparison per scenario (the same seeds under both conditions): the
    differences and their tests, as the report prints them and writes tables/paired.csv."""
    return report_command.tables_of(run.directory)[1]


def figure(run: Run, name: str) -> Figure:
    """One of the report's figures (a name of FIGURES) as a matplotlib Figure, drawn as the report draws
    it (save it with `.savefig(path)`; a notebook shows it).

    Raises:
        ReportError: an unknown name, or a run whose rows do not allow the figure (one line saying why).
    """
    notes: list[str] = []
    drawn = report_command.draw_figure(run.directory, name, say=notes.append)
    if drawn is None:
        why = notes[-1].removeprefix("note: ") if notes else "no data for it"
        raise ReportError(f"{run.path}: figure {name} cannot be drawn: {why}")
    return drawn


# ---------------------------------------------------------------- running
def run_batch(
    out: PathLike,
    *,
    scenario: str | Sequence[str] | None = None,
    episodes: int | None = None,
    protocol: PathLike | None = None,
    site: str | None = None,
    workers: int | None = None,
    seed: int | None = None,
    algorithm: str | None = None,
    conditions: str | Sequence[str] | None = None,
    keep_logs: str | None = None,
    approach: str | None = None,
    params: PathLike | None = None,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    perception: str | None = None,
    agent_timeout: float | None = None,
    chunk_size: int | None = None,
    recycle_chunks: int | None = None,
    cluster: str | None = None,
    max_runs: int | None = None,
    resume: bool = False,
    sampler: str | None = None,
    is_pilot_stages: int | None = None,
    is_pilot_episodes: int | None = None,
    is_inputs: str | None = None,
    is_min_spread: float | None = None,
    is_score: str | None = None,
    is_family: str | None = None,
    is_v2i_factor: str | None = None,
    is_pool_from: int | None = None,
    is_proposal: PathLike | None = None,
    progress: bool = True,
) -> Run:
    """Run a batch of paired SV/V2I episodes into the run directory `out`, as
    `python -m pedsafe_sumo.batch --out OUT ...` does, and read it.

    Each option is the command's flag of the same name (docs/batch.md; None: the command's default):
    `scenario` a name, a list of names or "all"; `conditions` "sv", "v2i", "both" or a list;
    `overrides` the `--set` values as {key: value} or ["key=value", ...]; `resume=True` continues the
    stopped run in `out`. `progress=False` shows neither the progress bar nor the command's lines.

    Returns:
        The finished run (`load_run(out)`).

    Raises:
        UsageError: bad input, with the command's one-line message; nothing is written.
        BatchError: the batch failed; the finished chunks are kept for `resume=True`.
    """
    options = {
        "scenario": scenario if scenario is None or isinstance(scenario, str) else ",".join(scenario),
        "condition": _condition(conditions),
        "episodes": episodes,
        "seed": seed,
        "workers": workers,
        "recycle_chunks": recycle_chunks,
        "cluster": cluster,
        "chunk_size": chunk_size,
        "out": out,
        "max_runs": max_runs,
        "resume": resume,
        "site": site,
        "approach": approach,
        "params": params,
        "set": _set_pairs(overrides),
        "algorithm": algorithm,
        "perception": perception,
        "agent_timeout": agent_timeout,
        "keep_logs": keep_logs,
        "sampler": sampler,
        "is_pilot_stages": is_pilot_stages,
        "is_pilot_episodes": is_pilot_episodes,
        "is_inputs": is_inputs,
        "is_min_spread": is_min_spread,
        "is_score": is_score,
        "is_family": is_family,
        "is_v2i_factor": is_v2i_factor,
        "is_pool_from": is_pool_from,
        "is_proposal": is_proposal,
        "protocol": protocol,
    }
    argv = _argv(options)
    with _quiet_unless(progress):
        args = batch_command.parse_args(argv, parser_class=_RaisingParser)
        try:
            plan, backend = batch_command.plan_batch(args)
        except UsageError:
            raise
        except (*INPUT_ERRORS, OSError) as exc:
            raise UsageError(str(exc)) from None
        print(f"{plan.count_text} = {plan.total_episodes:,} episodes (max_runs {args.max_runs:,})")
        if not batch_command.is_complete(plan):
            try:
                batch_command.execute(plan, backend, argv, progress=progress)
            except UsageError:
                raise
            except INPUT_ERRORS as exc:  # an unreachable cluster, a run directory another batch holds
                raise UsageError(str(exc)) from None
            except (BatchError, OSError) as exc:
                raise BatchError(
                    f"{exc}; the chunks finished so far are kept: continue with resume=True"
                ) from exc
    return load_run(plan.out)


@dataclass(frozen=True)
class EpisodeRun:
    """One episode under each condition asked for (the same seed), as `run_episode` returns it."""

    #: The engine's result per condition: setup, step log, outcome row, why it ended.
    results: dict[str, EpisodeResult]
    #: The stack that drove (package.module:Class).
    algorithm: str

    @property
    def outcomes(self) -> pd.DataFrame:
        """One row per condition: the columns of episodes.parquet (docs/columns.md)."""
        return pd.DataFrame([result.outcome for result in self.results.values()])

    def steps(self, condition: str | None = None) -> pd.DataFrame:
        """The per-step log under `condition` (may be left out when one condition ran)."""
        if condition is None:
            if len(self.results) != 1:
                raise UsageError(f"name the condition: {', '.join(self.results)}")
            condition = next(iter(self.results))
        if condition not in self.results:
            raise UsageError(f"condition '{condition}' did not run (ran: {', '.join(self.results)})")
        return self.results[condition].log

    def describe(self) -> str:
        """What happened, as `python -m pedsafe_sumo.episode` prints it."""
        return "\n".join(
            "\n".join(episode_command.describe(result, self.algorithm)) for result in self.results.values()
        )


def run_episode(
    scenario: str,
    *,
    conditions: str | Sequence[str] | None = None,
    seed: int | None = None,
    site: str | None = None,
    approach: str | None = None,
    params: PathLike | None = None,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    algorithm: str | None = None,
    perception: str | None = None,
    agent_timeout: float | None = None,
    log: PathLike | None = None,
    case_dir: PathLike | None = None,
    gui: bool = False,
    progress: bool = False,
) -> EpisodeRun:
    """Run one episode, as `python -m pedsafe_sumo.episode --scenario SCENARIO ...` does.

    Each option is the command's flag of the same name (None: the command's default; `conditions` "sv",
    "v2i", "both" or a list, `overrides` the `--set` values). `progress=True` prints what happened, as
    the command does (`EpisodeRun.describe()` returns it).

    Raises:
        UsageError: bad input, with the command's one-line message; nothing runs.
        pedsafe_sumo.sim.connection.SimulatorError: SUMO failed while the episode ran.
        pedsafe_sumo.control.timeout.AgentTimeoutError: a run_step call of the stack took too long.
        pedsafe_sumo.control.stack_calls.StackError: the stack misbehaved (an invalid command, sys.exit).
    """
    options = {
        "scenario": scenario,
        "condition": _condition(conditions),
        "seed": seed,
        "site": site,
        "approach": approach,
        "params": params,
        "set": _set_pairs(overrides),
        "algorithm": algorithm,
        "perception": perception,
        "log": log,
        "case_dir": case_dir,
        "gui": gui,
        "agent_timeout": agent_timeout,
    }
    args = episode_command.parse_args(_argv(options), parser_class=_RaisingParser)
    try:
        plan = episode_command.plan_episode(args)
    except UsageError:
        raise
    except episode_command.INPUT_ERRORS as exc:
        raise UsageError(str(exc)) from None
    results = episode_command.run_episode(plan, args, say=print if progress else lambda line: None)
    return EpisodeRun({result.condition: result for result in results}, plan.algorithm)
