"""Find one logged episode of a batch run, with everything needed to run it again as it was run.

A run directory (docs/design.md, 'Contracts') holds episodes.parquet, run.json and cases/. Replaying
episode N of a scenario under a condition takes, from the run and never from today's defaults:
- the episode seed: episodes.parquet's `seed` of (scenario, episode, condition);
- the scenario: `run.json["scenarios"][name]`, every field of the ScenarioSpec the batch used (with its
  --set overrides applied), rebuilt field by field so a changed default in the registry cannot leak in;
- the parameters: run.json["parameters"], the full merged parameter file of the run;
- the AD stack: run.json["algorithm"], imported only when installed or shipped (control.stack_source),
  or the one given as --algorithm;
- the site: the folder run.json["site_path"] names (else the site named run.json["site"]), or the one
  given as --site; its files must be the run's (run.json["site_files_sha256"]);
- the case, when there is one: cases/<scenario>_<condition>_<seed>.parquet (the per-step log the
  replay is checked against) and .json (the episode's initial world, its outcome and end reason);
- the approach: a batch run with --approach records its units as `<scenario>@<arm>` in run.json and
  names its case logs `<scenario>_<condition>_<seed>_<arm>`; the same episode runs on every approach, so
  a run of several approaches needs --approach (a run of one approach, or one made without --approach,
  does not).
Every problem is a ReplayError whose message is one line naming it.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd
import sumolib

from pedsafe_sumo import __version__
from pedsafe_sumo.batch.runner import site_file_digests
from pedsafe_sumo.control.agent import Agent, AlgorithmLoadError, load_agent_class
from pedsafe_sumo.control.stack_source import stack_to_replay
from pedsafe_sumo.io.cases import case_stem, read_case
from pedsafe_sumo.network.sites import Site, UnknownSiteError, resolve_site
from pedsafe_sumo.params import ParameterError, load_params, validate
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.specs import ScenarioSpec
from pedsafe_sumo.sim.episode import CONDITIONS, STEP_LENGTH_S

EPISODES_FILE = "episodes.parquet"
RUN_FILE = "run.json"
CASES_DIR = "cases"
#: run.json keys a replay cannot do without.
REQUIRED_RUN_KEYS = ("site", "scenarios", "parameters", "algorithm")
#: episodes.parquet columns that identify an episode.
KEY_COLUMNS = ("scenario", "condition", "episode", "seed")


class ReplayError(ValueError):
    """A run directory, episode or setting the replay cannot use; the message is one line."""


@dataclass
class LoggedEpisode:
    """One episode of a run and the run's settings for it."""

    run_dir: Path
    run_info: dict[str, Any]
    site: Site
    spec: ScenarioSpec
    params: dict[str, Any]
    algorithm: str
    agent_class: type[Agent]
    scenario: str
    episode: int
    condition: str
    seed: int
    #: The episode's row of episodes.parquet.
    outcome: dict[str, Any]
    #: The per-step log and metadata (setup as an EpisodeSetup, outcome, end_reason) of its case, or None
    #: when the batch kept no case for it (neither condition of the pair had a collision or conflict).
    case_log: pd.DataFrame | None
    case_meta: dict[str, Any] | None
    step_length_s: float
    #: Differences between the run and this installation the user should know about (one line each).
    notes: list[str] = field(default_factory=list)

    @property
    def case_path(self) -> Path:
        return case_log_path(self.run_dir, self.scenario, self.condition, self.seed, self.spec.approach)

    def describe(self) -> str:
        where = f" on approach {self.spec.approach}" if self.spec.approach else ""
        return f"{self.scenario} episode {self.episode}{where}, condition {self.condition}, seed {self.seed}"


def case_log_path(run_dir: Path, scenario: str, condition: str, seed: int, approach: str = "") -> Path:
    """Where the batch wrote the case log of an episode; `approach` is the spec's field (the arm of a
    batch --approach unit, "" otherwise), which the batch put in the case's name."""
    return Path(run_dir) / CASES_DIR / f"{case_stem(scenario, condition, int(seed), approach)}.parquet"


def load_logged_episode(
    run_dir: Path,
    episode: int,
    condition: str,
    scenario: str | None = None,
    site: str | None = None,
    approach: str | None = None,
    algorithm: str | None = None,
) -> LoggedEpisode:
    """Episode `episode` of `scenario` under `condition` in the run at `run_dir`; ReplayError if any of
    them is missing or the run's settings cannot be rebuilt. `site` (a name or folder) replaces the
    site the run recorded, e.g. a copy of its folder on another machine; its files must be the run's.
    `approach` (N, E, S, W) picks the episode of a batch run with --approach on that arm. `algorithm`
    (--algorithm) replaces the AD stack the run recorded (control.stack_source)."""
    run_dir = Path(run_dir)
    if not run_dir.exists():
        raise ReplayError(f"run directory {run_dir} does not exist")
    if not run_dir.is_dir():
        raise ReplayError(f"{run_dir} is not a directory (expected a batch run directory)")
    for name in (RUN_FILE, EPISODES_FILE):
        if not (run_dir / name).is_file():
            raise ReplayError(
                f"{run_dir} has no {name}: not a batch run directory (python -m pedsafe_sumo.batch)"
            )
    run_info = _read_run_info(run_dir / RUN_FILE)
    episodes = _read_episodes(run_dir / EPISODES_FILE)

    if condition not in CONDITIONS:
        raise ReplayError(f"unknown condition '{condition}' (known: {', '.join(CONDITIONS)})")
    scenarios = sorted(episodes["scenario"].unique())
    if scenario is None:
        if len(scenarios) > 1:
            raise ReplayError(
                f"run {run_dir} holds several scenarios ({', '.join(scenarios)}): say which with --scenario"
            )
        scenario = scenarios[0]
    elif scenario not in scenarios:
        raise ReplayError(f"scenario '{scenario}' is not in run {run_dir} (it has: {', '.join(scenarios)})")
    of_scenario = episodes[episodes["scenario"] == scenario]
    unit, of_scenario = _approach_unit(run_dir, run_info, scenario, of_scenario, approach)
    ran = sorted(of_scenario["condition"].unique())
    if condition not in ran:
        raise ReplayError(f"condition '{condition}' was not run in {run_dir} (it has: {', '.join(ran)})")
    rows = of_scenario[(of_scenario["episode"] == episode) & (of_scenario["condition"] == condition)]
    if rows.empty:
        numbers = sorted(of_scenario["episode"].unique())
        raise ReplayError(
            f"episode {episode} is not in run {run_dir} ({scenario} has episodes {_ranges(numbers)})"
        )
    outcome = rows.iloc[0].to_dict()
    seed = int(outcome["seed"])

    notes: list[str] = []
    missing = [key for key in REQUIRED_RUN_KEYS if key not in run_info]
    if missing:
        raise ReplayError(
            f"{run_dir / RUN_FILE} lacks {', '.join(missing)}: cannot rebuild the run's settings"
        )
    resolved_site = run_site(run_info, site)
    spec = scenario_from_record(run_info["scenarios"], unit, notes)
    params = params_from_record(run_info["parameters"], notes)
    try:  # a stack run.json names is imported only under control.stack_source's rule
        algorithm, stack_note = stack_to_replay(str(run_info["algorithm"]), algorithm, run_dir)
        notes += [stack_note] if stack_note else []
        agent_class = load_agent_class(algorithm)
    except AlgorithmLoadError as exc:
        raise ReplayError(f"the run's algorithm cannot be loaded: {exc}") from None
    notes += _version_notes(run_info)
    if outcome.get("status") in ("error", "timeout"):  # timeout: the AD stack exceeded --agent-timeout
        notes.append(f"the batch recorded an error for this episode: {outcome.get('error', '')}")

    case_log, case_meta = None, None
    case_path = case_log_path(run_dir, scenario, condition, seed, spec.approach)
    if case_path.is_file():
        try:
            case_log, case_meta = read_case(case_path)
        except Exception as exc:  # parquet/JSON readers raise many unrelated types for a broken file
            raise ReplayError(f"cannot read the case {case_path}: {_first_line(exc)}") from None
    step_length_s = _logged_step_length_s(case_log, notes)
    return LoggedEpisode(
        run_dir=run_dir,
        run_info=run_info,
        site=resolved_site,
        spec=spec,
        params=params,
        algorithm=algorithm,
        agent_class=agent_class,
        scenario=scenario,
        episode=int(episode),
        condition=condition,
        seed=seed,
        outcome=outcome,
        case_log=case_log,
        case_meta=case_meta,
        step_length_s=step_length_s,
        notes=notes,
    )


def _approach_unit(
    run_dir: Path, run_info: dict[str, Any], scenario: str, rows: pd.DataFrame, approach: str | None
) -> tuple[str, pd.DataFrame]:
    """The key of the scenario's settings in run.json["scenarios"] (`<scenario>@<arm>` for a unit of a
    batch run with --approach, else `<scenario>`) and the scenario's rows on that approach."""
    scenarios = run_info.get("scenarios")
    recorded: dict[str, Any] = scenarios if isinstance(scenarios, dict) else {}
    arms = sorted(key.partition("@")[2] for key in recorded if key.partition("@")[0] == scenario)
    in_rows = sorted({str(a) for a in rows["approach"]}) if "approach" in rows.columns else []
    if "" in arms or not arms:
        # A run without --approach: one approach, the site's own (the rows say which, "" before the column).
        if approach is not None and approach not in in_rows:
            ran = f"approach {', '.join(in_rows)}" if in_rows else "no --approach"
            raise ReplayError(f"run {run_dir} ran {scenario} on {ran}, not on approach {approach}")
        return scenario, rows
    if approach is None:
        if len(arms) > 1:
            raise ReplayError(
                f"run {run_dir} ran {scenario} on approaches {', '.join(arms)}: say which with --approach"
            )
        approach = arms[0]
    elif approach not in arms:
        raise ReplayError(
            f"run {run_dir} did not run {scenario} on approach {approach} (it has: {', '.join(arms)})"
        )
    if "approach" in rows.columns:
        rows = rows[rows["approach"] == approach]
    return f"{scenario}@{approach}", rows


#: The roadside pole every scenario's V2I condition received before ScenarioSpec.roadside_units.
BEFORE_ROADSIDE_UNITS_FIELD = "rsu_camera_0"


def scenario_from_record(recorded: Any, name: str, notes: list[str]) -> ScenarioSpec:
    """The ScenarioSpec exactly as run.json recorded it (dataclasses.asdict of the spec the batch ran).

    A field this version does not know is an error (its effect cannot be reproduced); a field the run
    predates takes today's default, with a note.
    """
    if not isinstance(recorded, dict) or name not in recorded or not isinstance(recorded[name], dict):
        raise ReplayError(f"run.json records no settings for scenario '{name}'")
    fields = {f.name for f in dataclasses.fields(ScenarioSpec)}
    values = dict(recorded[name])
    unknown = sorted(set(values) - fields)
    if unknown:
        raise ReplayError(
            f"run.json records scenario field(s) {', '.join(unknown)} that this version of pedsafe_sumo "
            "does not know: the run was made with another version"
        )
    absent = sorted(fields - set(values))
    if "roadside_units" in absent:
        # Before scenarios named their roadside poles, V2I received the site's only pole.
        values["roadside_units"] = BEFORE_ROADSIDE_UNITS_FIELD
        absent.remove("roadside_units")
        notes.append(
            f"run.json predates roadside_units: the one pole of that time ({BEFORE_ROADSIDE_UNITS_FIELD})"
        )
    if absent:
        notes.append(f"run.json predates scenario field(s) {', '.join(absent)}: today's defaults used")
    try:
        return ScenarioSpec(**values)
    except (ScenarioError, TypeError) as exc:
        raise ReplayError(f"run.json's settings for scenario '{name}' are invalid: {exc}") from None


def params_from_record(recorded: Any, notes: list[str]) -> dict[str, Any]:
    """The run's parameters (run.json["parameters"], the full merged file), validated.

    Keys the run predates take today's defaults and keys this version no longer has are dropped, each
    group with a note: the trajectory check then shows whether it mattered.
    """
    if not isinstance(recorded, dict):
        raise ReplayError("run.json's 'parameters' is not a table")
    params = load_params()
    added: list[str] = []
    dropped: list[str] = []

    def overlay(base: dict, record: dict, where: str) -> None:
        for key, value in record.items():
            dotted = f"{where}{key}"
            if key not in base:
                dropped.append(dotted)
            elif isinstance(base[key], dict) and isinstance(value, dict):
                overlay(base[key], value, dotted + ".")
            else:
                base[key] = copy.deepcopy(value)
        added.extend(f"{where}{key}" for key in base if key not in record)

    overlay(params, recorded, "")
    if added:
        notes.append(f"run.json predates parameter(s) {', '.join(sorted(added))}: today's defaults used")
    if dropped:
        notes.append(
            f"run.json has parameter(s) this version no longer knows, ignored: {', '.join(sorted(dropped))}"
        )
    try:
        validate(params)
    except ParameterError as exc:
        raise ReplayError(f"run.json's parameters are invalid here: {exc}") from None
    return params


def _read_run_info(path: Path) -> dict[str, Any]:
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ReplayError(f"cannot read {path}: {_first_line(exc)}") from None
    if not isinstance(info, dict):
        raise ReplayError(f"{path} is not a JSON object")
    return info


def _read_episodes(path: Path) -> pd.DataFrame:
    try:
        episodes = pd.read_parquet(path, partitioning=None)
    except Exception as exc:  # pyarrow raises several unrelated types for a broken file
        raise ReplayError(f"cannot read {path}: {_first_line(exc)}") from None
    missing = [c for c in KEY_COLUMNS if c not in episodes.columns]
    if missing:
        raise ReplayError(f"{path} lacks column(s) {', '.join(missing)}")
    if episodes.empty:
        raise ReplayError(f"{path} has no rows")
    return episodes


def run_site(run_info: dict[str, Any], given: str | None = None) -> Site:
    """The site of a run (see the module docstring); ReplayError, in one line, when it cannot be found
    or its files differ from the ones the run read."""
    recorded_path = run_info.get("site_path")
    if given is not None:
        reference = given
    elif recorded_path and Path(recorded_path).is_dir():
        reference = str(recorded_path)
    else:
        reference = str(run_info["site"])
    try:
        site = resolve_site(reference)
        digests = site_file_digests(reference)
    except UnknownSiteError as exc:
        raise ReplayError(f"the run's site: {exc}") from None
    recorded = run_info.get("site_files_sha256") or {}
    differ = sorted(name for name, digest in recorded.items() if digests.get(name) != digest)
    if differ:
        raise ReplayError(
            f"site {site.name} in {site.directory}: {', '.join(differ)} differ(s) from the file(s) the run "
            "read (run.json site_files_sha256): give --site the folder the run used"
        )
    return site


def _version_notes(run_info: dict[str, Any]) -> list[str]:
    notes = []
    versions: dict[str, Any] = run_info["versions"] if isinstance(run_info.get("versions"), dict) else {}
    sumo_then, sumo_now = versions.get("sumo"), sumolib.version.gitDescribe()
    if sumo_then and sumo_then != sumo_now:
        notes.append(f"the run used SUMO {sumo_then}, this is SUMO {sumo_now}: trajectories may differ")
    ours_then = versions.get("pedsafe_sumo")
    if ours_then and ours_then != __version__:
        notes.append(f"the run used pedsafe_sumo {ours_then}, this is {__version__}")
    return notes


def _logged_step_length_s(log: pd.DataFrame | None, notes: list[str]) -> float:
    """The step length the case was logged with (the batch does not record it elsewhere)."""
    if log is None or len(log) < 2:
        return STEP_LENGTH_S
    step_s = round(float(log["time_s"].diff().iloc[1:].median()), 6)
    if not math.isclose(step_s, STEP_LENGTH_S, abs_tol=1e-9):
        notes.append(
            f"the case was logged with {step_s} s steps (default {STEP_LENGTH_S} s): replaying with its step"
        )
    return step_s


def _ranges(numbers: list[int]) -> str:
    """'0-4, 7' for [0, 1, 2, 3, 4, 7]."""
    parts, start = [], None
    for i, n in enumerate(numbers):
        if start is None:
            start = n
        if i + 1 == len(numbers) or numbers[i + 1] != n + 1:
            parts.append(str(start) if start == n else f"{start}-{n}")
            start = None
    return ", ".join(parts)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
