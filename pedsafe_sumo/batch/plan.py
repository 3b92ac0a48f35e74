"""A batch planned from its command: every flag and input file checked, the run's identity and the
workers' configuration built, and nothing written (`prepare`).

A protocol file (--protocol) stands in for the flags that fix the model (`with_protocol`); --approach
turns the scenarios into `<scenario>@<arm>` units (`approach_units`); --resume takes the recorded run's
arguments and refuses a command that describes another run (batch/resume.py).
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from pedsafe_sumo import WRITE_ROOT
from pedsafe_sumo.batch.arguments import RUN_ARGUMENT_DEFAULTS, explicit_arguments, resumed_arguments
from pedsafe_sumo.batch.chunks import EPISODE_SEED_RULE
from pedsafe_sumo.batch.executors import MAX_RECYCLE_CHUNKS
from pedsafe_sumo.batch.inputs import InputFileError, check_site
from pedsafe_sumo.batch.resume import check_new_run_directory, check_same_run, recorded_run
from pedsafe_sumo.batch.runner import WorkerConfig, site_file_digests, worker_versions
from pedsafe_sumo.batch.sampled import FAMILY_JOINT, SAMPLER_IS, SAMPLER_MC, SamplerError, sampler_identity
from pedsafe_sumo.batch.staging_check import unstageable_units
from pedsafe_sumo.batch.trust import check_stack_from_file
from pedsafe_sumo.cli import MAX_EPISODES, check_max_runs, check_run_count, check_seed
from pedsafe_sumo.control.agent import AlgorithmLoadError, load_agent_class, stack_spec
from pedsafe_sumo.control.stack_names import resolve_stack_name
from pedsafe_sumo.control.timeout import check_timeout_s
from pedsafe_sumo.io.outputs import check_output_dir, probe_output_dir
from pedsafe_sumo.io.step_logs import KEEP_EVENTS
from pedsafe_sumo.network.approaches import is_leg_name
from pedsafe_sumo.network.sites import Site, UnknownSiteError, resolve_site, site_reference
from pedsafe_sumo.network.traffic_side import LEFTHAND_MEANING, network_is_lefthand
from pedsafe_sumo.params import ParameterError
from pedsafe_sumo.protocol import Protocol, load_protocol
from pedsafe_sumo.sampling.stages import (
    MAX_PILOT_EPISODES,
    MAX_PILOT_STAGES,
    MIN_PILOT_EPISODES,
    MIN_SPREAD_FLAG,
    stage_layout,
)
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.geometry import default_arm, leg_order_key, site_approaches
from pedsafe_sumo.scenarios.hosting import check_hosting, hosting_matrix, split_hosted
from pedsafe_sumo.scenarios.specs import SCENARIOS
from pedsafe_sumo.settings import UsageError, check_roadside_units, configure, parse_set
from pedsafe_sumo.sim.episode import CONDITIONS

#: Upper bounds of the batch's numbers, so that no value can make a batch run for ever or exhaust the
#: machine before its first episode (--episodes and --seed: pedsafe_sumo/cli.py). Local worker processes
#: (one SUMO each, about 150 MB): 256 need about 40 GB, beyond one machine; more workers belong on a
#: cluster (--cluster).
MAX_WORKERS = 256
#: A chunk's rows and case logs are held by its worker and rerun whole after a kill.
MAX_CHUNK_PAIRS = 10_000
#: The errors of bad input: one line on stderr and exit code 2, nothing written.
INPUT_ERRORS = (
    UsageError,
    ParameterError,
    ScenarioError,
    AlgorithmLoadError,
    UnknownSiteError,
    InputFileError,
)


@dataclass
class Plan:
    """A validated batch: what to run (identity), how (backend), where (run directory)."""

    arguments: dict[str, Any]
    scenarios: list[str]
    conditions: list[str]
    identity: dict[str, Any]
    config: WorkerConfig
    out: Path
    recorded: dict[str, Any] | None  # run.json of the run being resumed
    #: Episodes the run makes in all (every unit, condition and sampler stage), and how they multiply up.
    total_episodes: int = 0
    count_text: str = ""


def prepare(args: argparse.Namespace) -> Plan:
    """Check everything about the command and its input files; writes nothing."""
    _check_execution_flags(args)
    explicit = explicit_arguments(args)
    recorded = None
    if args.resume:
        if args.out is None:
            raise UsageError("--resume needs --out DIR, the run directory to continue")
        recorded = recorded_run(args.out)
        kept = recorded["arguments"].get("keep_logs", KEEP_EVENTS)
        if explicit.get("keep_logs", kept) != kept:
            raise UsageError(
                f"{args.out} was started with --keep-logs {kept}; a resumed run keeps the same logs "
                "(leave the flag out or repeat its value)"
            )
        arguments = resumed_arguments(recorded["arguments"], explicit)
    else:
        if args.out is not None:
            check_new_run_directory(args.out)
        arguments = {**RUN_ARGUMENT_DEFAULTS, **explicit}
    protocol = None
    if arguments["protocol"] is not None:
        protocol, arguments = with_protocol(args, arguments, explicit, recorded)
    scenario = arguments["scenario"]
    if scenario is None:
        raise UsageError(f"--scenario is required ({', '.join(SCENARIOS)} or all)")
    # One scenario, a comma-separated list (as a protocol's runs record it), or all.
    scenarios = (
        protocol.scenarios if protocol else list(SCENARIOS) if scenario == "all" else scenario.split(",")
    )
    unknown = [name for name in scenarios if name not in SCENARIOS]
    if unknown:
        raise UsageError(f"unknown scenario '{unknown[0]}' (known: {', '.join(SCENARIOS)}, all)")
    if arguments["condition"] not in (*CONDITIONS, "both"):
        raise UsageError(f"unknown condition '{arguments['condition']}' (known: sv, v2i, both)")
    conditions = list(CONDITIONS) if arguments["condition"] == "both" else [arguments["condition"]]
    _check_run_numbers(arguments)
    _check_sampler_arguments(arguments, explicit)
    try:
        agent_timeout_s = check_timeout_s(arguments["agent_timeout"])
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    site = resolve_site(arguments["site"])
    if network_is_lefthand(site.file("net.xml")):
        print(LEFTHAND_MEANING.format(site=site.name))
    params_file = Path(arguments["params"]) if arguments["params"] else None
    if protocol is not None:
        specs, params = protocol.specs(), protocol.params()
    else:
        specs, params = configure(scenarios, params_file, arguments["set"])
    stack = resolve_stack_name(stack_spec(arguments["algorithm"], arguments.get("perception")))
    # A stack named by run.json or a protocol file alone is imported only from outside the cwd.
    check_stack_from_file(args, stack, arguments, recorded is not None)
    load_agent_class(stack)
    check_site(site, params)
    check_roadside_units(specs, site)  # after check_site: it reads the site's rsu.add.xml
    if arguments["approach"] is not None:
        # scenario@ARM units: every combination the site hosts, or the one named (refused when it cannot).
        scenarios, specs = approach_units(site, specs, params, conditions, scenario, arguments["approach"])
    elif scenario == "all" and protocol is None:  # every scenario the site hosts; the others named with why
        scenarios, skipped = split_hosted(site, specs, params, conditions)
        for name, why in skipped.items():
            print(f"skipping scenario '{name}' on site {site.name}: {why}")
        if not scenarios:
            raise UsageError(f"site {site.name} hosts none of the scenarios (see the lines above)")
        specs = {name: specs[name] for name in scenarios}
    check_hosting(site, specs, params, conditions)  # its roadside poles see each scenario's staging area
    # Hosted is what can be staged for every seed the run will draw (batch/staging_check.py).
    # A protocol's scenarios, or scenarios named on an approach named (or the site's own): refused, not
    # skipped, when one cannot be staged.
    named = protocol is not None or (scenario != "all" and arguments["approach"] != "all")
    if recorded is None:
        # A new run is bounded before its episodes are staged (the check stages every one of them).
        total, count_text = episode_count(
            scenarios, conditions, arguments, _sampler_identity(arguments, scenarios)
        )
        check_run_count(total, args.max_runs, count_text)
        scenarios, specs, unstageable = stageable_units(site, params, specs, scenarios, arguments, named)
    else:  # a resumed run skips what its start skipped (the site's files are checked to be the same)
        unstageable = recorded.get("skipped_unstageable", {})
        scenarios = [name for name in scenarios if name not in unstageable]
        specs = {name: specs[name] for name in scenarios}
    reference = site_reference(arguments["site"], site)
    digests = site_file_digests(reference)
    identity = {
        "site": site.name,
        "scenarios": {name: dataclasses.asdict(specs[name]) for name in scenarios},
        "conditions": conditions,
        "episodes_per_scenario": arguments["episodes"],
        "run_seed": arguments["seed"],
        "episode_seed_rule": EPISODE_SEED_RULE,
        "algorithm": stack,
        "parameters": params,
        "site_files_sha256": digests,
        "chunk_size_pairs": arguments["chunk_size"],
        "sampler": _sampler_identity(arguments, scenarios),
    }
    if unstageable:  # recorded in run.json; not part of the identity a resume compares
        identity["skipped_unstageable"] = unstageable
    scenario_overrides, _ = parse_set(arguments["set"])
    if protocol is not None:
        identity["protocol"] = protocol.record()
        scenario_overrides = protocol.worker_overrides()
    versions = worker_versions()
    config = WorkerConfig(
        reference,
        params,
        scenario_overrides,
        stack,
        digests,
        versions,
        keep_logs=arguments["keep_logs"],
        agent_timeout_s=agent_timeout_s,
    )
    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    out = args.out or WRITE_ROOT / "results" / f"{scenario}-{stamp}"
    total, count_text = episode_count(scenarios, conditions, arguments, identity["sampler"])
    plan = Plan(arguments, scenarios, conditions, identity, config, out, recorded, total, count_text)
    if recorded is not None:
        check_same_run(out, identity, versions, recorded)
    else:
        # A run accepted when it started is resumed whatever its size; a new one is bounded.
        check_run_count(total, args.max_runs, count_text)
        check_output_dir(out, "--out", UsageError)
        probe_output_dir(out, "--out", UsageError)
    return plan


def episode_count(
    units: list[str], conditions: list[str], arguments: dict[str, Any], sampler: dict[str, Any] | None
) -> tuple[int, str]:
    """The episodes a run makes in all, and a phrase saying how they multiply up (units x conditions x
    episodes per unit, the importance sampler's pilot stages included)."""
    per_unit = arguments["episodes"]
    pilots = ""
    if sampler is not None:
        layout = stage_layout(sampler["pilot_stages"], sampler["pilot_episodes"], arguments["episodes"])
        per_unit = sum(stage.n_episodes for stage in layout)
        pilots = " (pilot stages included)"
    text = f"{len(units)} scenario unit(s) x {len(conditions)} condition(s) x {per_unit:,} episodes{pilots}"
    return len(units) * len(conditions) * per_unit, text


def _check_execution_flags(args: argparse.Namespace) -> None:
    """The flags of how the run is carried out (--workers, --cluster, --recycle-chunks, --out)."""
    if args.workers is not None and args.cluster:
        raise UsageError("--workers and --cluster exclude each other (local:N starts N Dask workers)")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    if args.workers is not None and args.workers > MAX_WORKERS:
        raise UsageError(f"--workers must be at most {MAX_WORKERS}, got {args.workers} (more: use --cluster)")
    if args.recycle_chunks is not None and args.cluster:
        raise UsageError(
            "--recycle-chunks applies to the process pool; Dask's workers are bounded by their nanny's "
            "memory limit (docs/batch.md)"
        )
    if args.recycle_chunks is not None and not 0 <= args.recycle_chunks <= MAX_RECYCLE_CHUNKS:
        raise UsageError(
            f"--recycle-chunks must be between 0 (never) and {MAX_RECYCLE_CHUNKS:,}, "
            f"got {args.recycle_chunks}"
        )
    if args.out is not None and args.out.exists() and not args.out.is_dir():
        raise UsageError(f"--out {args.out} is a file, not a run directory")
    check_max_runs(args.max_runs)


def _check_run_numbers(arguments: dict[str, Any]) -> None:
    """--episodes, --seed and --chunk-size within their bounds."""
    if arguments["episodes"] < 1:
        raise UsageError(f"--episodes must be at least 1, got {arguments['episodes']}")
    if arguments["episodes"] > MAX_EPISODES:
        raise UsageError(
            f"--episodes must be at most {MAX_EPISODES:,} per scenario, got {arguments['episodes']}"
        )
    check_seed(arguments["seed"])
    if arguments["chunk_size"] is not None and arguments["chunk_size"] < 1:
        raise UsageError(f"--chunk-size must be at least 1, got {arguments['chunk_size']}")
    if arguments["chunk_size"] is not None and arguments["chunk_size"] > MAX_CHUNK_PAIRS:
        raise UsageError(
            f"--chunk-size must be at most {MAX_CHUNK_PAIRS:,} pairs, got {arguments['chunk_size']}"
        )


def _check_sampler_arguments(arguments: dict[str, Any], explicit: dict[str, Any]) -> None:
    """The --sampler and --is-* flags: given together only where they apply, each within its bounds."""
    # The proposal's settings: --is-proposal takes them from the run it names.
    pilot_flags = (
        "is_pilot_stages",
        "is_pilot_episodes",
        "is_inputs",
        "is_min_spread",
        "is_score",
        "is_family",
        "is_pool_from",
        "is_v2i_factor",
    )
    is_flags = (*pilot_flags, "is_proposal")
    if arguments["sampler"] == SAMPLER_MC and any(name in explicit for name in is_flags):
        given = ", ".join(f"--{name.replace('_', '-')}" for name in is_flags if name in explicit)
        raise UsageError(f"{given}: need --sampler is")
    if arguments.get("is_proposal") and any(name in explicit for name in pilot_flags):
        raise UsageError(
            "--is-proposal takes the pilot settings of that run: leave out the other --is-* flags"
        )
    unused_by_joint = [name for name in ("is_inputs", "is_min_spread", "is_score") if name in explicit]
    if arguments["is_family"] == FAMILY_JOINT and unused_by_joint:
        # The joint proposal moves every proposable input at once, fitted on the pilots' collisions: no
        # input screen, spread floor or score for the pilots' elite (docs/sampling.md).
        given = ", ".join(f"--{name.replace('_', '-')}" for name in unused_by_joint)
        raise UsageError(f"{given}: not used by --is-family joint (give --is-family product)")
    if arguments["is_family"] != FAMILY_JOINT and "is_v2i_factor" in explicit:
        raise UsageError("--is-v2i-factor: used only by --is-family joint")
    if not MIN_SPREAD_FLAG <= arguments["is_min_spread"] <= 1.0:
        raise UsageError(
            f"--is-min-spread must lie in {MIN_SPREAD_FLAG}..1, got {arguments['is_min_spread']}"
        )
    if not 1 <= arguments["is_pilot_stages"] <= MAX_PILOT_STAGES:
        raise UsageError(
            f"--is-pilot-stages must lie in 1..{MAX_PILOT_STAGES}, got {arguments['is_pilot_stages']}"
        )
    pool_from, final_stage = arguments.get("is_pool_from"), arguments["is_pilot_stages"]
    if "is_pool_from" in explicit and pool_from is not None and not 0 <= pool_from <= final_stage:
        raise UsageError(
            f"--is-pool-from must lie in 0..{arguments['is_pilot_stages']} (the final stage, after "
            f"--is-pilot-stages {arguments['is_pilot_stages']}), got {pool_from}"
        )
    if not MIN_PILOT_EPISODES <= arguments["is_pilot_episodes"] <= MAX_PILOT_EPISODES:
        raise UsageError(
            f"--is-pilot-episodes must lie in {MIN_PILOT_EPISODES}..{MAX_PILOT_EPISODES:,}, "
            f"got {arguments['is_pilot_episodes']}"
        )
    if arguments["sampler"] == SAMPLER_IS and arguments["condition"] == "v2i":
        raise UsageError("--sampler is adapts its proposal on the SV condition: --condition sv or both")


def approach_units(
    site: Site,
    specs: dict[str, Any],
    params: dict[str, Any],
    conditions: list[str],
    scenario_arg: str,
    approach_arg: str,
) -> tuple[list[str], dict[str, Any]]:
    """The run's units `<scenario>@<arm>` under --approach, with their specs (the field `approach` set).
    With --scenario all or --approach all, every combination the site hosts (the others printed with why);
    a combination named explicitly that the site cannot host is refused in one line (UsageError)."""
    if approach_arg != "all" and not is_leg_name(approach_arg):
        raise UsageError(
            f"unknown approach '{approach_arg}' (a leg: N, E, S, W, NE, SE, SW, NW or B000-B359; or all)"
        )
    known = list(site_approaches(site))
    own = default_arm(site)
    if approach_arg == "all":
        # Every leg, the site's own first, the others clockwise from north.
        arms = [own] + sorted((arm for arm in known if arm != own), key=leg_order_key)
    elif approach_arg not in known:
        raise UsageError(
            f"site {site.name} has no approach from the {approach_arg} (approaches: {', '.join(known)})"
        )
    else:
        arms = [approach_arg]
    hosted, skipped = hosting_matrix(site, specs, params, arms, conditions)
    if scenario_arg != "all" and approach_arg != "all" and skipped:
        (name, arm), why = next(iter(skipped.items()))
        raise UsageError(f"site {site.name} cannot host scenario '{name}' on approach {arm}: {why}")
    for (name, arm), why in skipped.items():
        print(f"skipping scenario '{name}' on approach {arm} of site {site.name}: {why}")
    if not hosted:
        raise UsageError(f"site {site.name} hosts none of these combinations (see the lines above)")
    units = [f"{name}@{arm}" for name, arm in hosted]
    return units, {f"{name}@{arm}": dataclasses.replace(specs[name], approach=arm) for name, arm in hosted}


def unit_label(unit: str) -> str:
    """How a line names a unit: "scenario 'crossing'" or "scenario 'crossing' on approach S"."""
    name, _, arm = unit.partition("@")
    return f"scenario '{name}'" + (f" on approach {arm}" if arm else "")


def stageable_units(
    site: Site,
    params: dict[str, Any],
    specs: dict[str, Any],
    units: list[str],
    arguments: dict[str, Any],
    explicit: bool,
) -> tuple[list[str], dict[str, Any], dict[str, str]]:
    """(units, specs, {unit: why} of those skipped): the units whose every episode of this run can be
    staged (staging_check.unstageable_units, over the episodes each unit runs, pilot stages included).
    A unit that cannot is refused in one line when the user named exactly it (`explicit`), else skipped
    with the reason printed."""
    episodes = arguments["episodes"]
    if arguments["sampler"] == SAMPLER_IS:
        layout = stage_layout(arguments["is_pilot_stages"], arguments["is_pilot_episodes"], episodes)
        episodes = sum(stage.n_episodes for stage in layout)
    failed = unstageable_units(site, params, {u: specs[u] for u in units}, arguments["seed"], episodes)
    if failed and explicit:
        unit, why = next(iter(failed.items()))
        raise UsageError(f"site {site.name} cannot stage {unit_label(unit)}: {why}")
    for unit, why in failed.items():
        print(f"skipping {unit_label(unit)} on site {site.name}: cannot be staged: {why}")
    kept = [u for u in units if u not in failed]
    if not kept:
        raise UsageError(f"site {site.name} can stage none of these scenarios (see the lines above)")
    return kept, {u: specs[u] for u in kept}, failed


def _sampler_identity(arguments: dict[str, Any], scenarios: list[str]) -> dict[str, Any] | None:
    try:
        return sampler_identity(arguments, scenarios)
    except SamplerError as exc:
        raise UsageError(str(exc)) from None


def with_protocol(
    args: argparse.Namespace,
    arguments: dict[str, Any],
    explicit: dict[str, Any],
    recorded: dict[str, Any] | None,
) -> tuple[Protocol, dict[str, Any]]:
    """The protocol's values in place of the flags: a protocol fixes everything but the number of
    episodes and workers (and where the run goes). Another flag with --protocol is refused."""
    fixed = (
        "scenario", "condition", "seed", "site", "params", "set", "algorithm", "chunk_size", "cluster",
        "agent_timeout", "approach",
    )  # fmt: skip
    given = [name for name in fixed if getattr(args, name, None) not in (None, [])]
    if args.protocol is not None and given:
        flags = ", ".join(f"--{name.replace('_', '-')}" for name in given)
        raise UsageError(
            f"--protocol fixes every value: {flags} cannot be given with it (only --episodes, --workers, "
            "--recycle-chunks, --keep-logs, --out, --sampler and --is-*)"
        )
    protocol = load_protocol(Path(arguments["protocol"]))
    if recorded is not None and recorded.get("protocol", {}).get("sha256") != protocol.sha256:
        raise UsageError(f"{arguments['protocol']} has changed since the run started (its SHA-256 differs)")
    header = protocol.header
    return protocol, {
        **arguments,
        "scenario": "all" if protocol.scenarios == list(SCENARIOS) else ",".join(protocol.scenarios),
        "condition": header["conditions"],
        "episodes": explicit.get("episodes", arguments["episodes"] if recorded else header["episodes"]),
        "seed": header["seed"],
        "site": header["site"],
        "algorithm": header["algorithm"],
    }
