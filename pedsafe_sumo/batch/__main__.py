"""python -m pedsafe_sumo.batch --scenario crossing: a batch of paired SV/V2I episodes, and its Table I.

    python -m pedsafe_sumo.batch --scenario crossing                      # ~1 minute, 100 pairs
    python -m pedsafe_sumo.batch --scenario all --episodes 10000 --workers 2 --out results/protocol
    python -m pedsafe_sumo.batch --resume --out results/protocol          # after a crash or a kill
    python -m pedsafe_sumo.batch --scenario all --episodes 10000 --cluster tcp://host:8786 --out DIR
    python -m pedsafe_sumo.batch --scenario jaywalking --set perception.v2i.latency_s=0.3 \
        --algorithm my.stack:Stack

Writes DIR/episodes.parquet (one row per episode and condition), DIR/run.json (configuration,
parameters, seeds, versions, timings: the paper's global information file), DIR/cases/ (per-step logs
of both conditions of every episode pair with a collision or a conflict), and while it runs
DIR/parts/ and DIR/manifest.json (finished chunks; docs/batch.md). `--resume` continues a stopped
run with the configuration recorded in its run.json. Bad input ends in one line on stderr and exit
code 2, and nothing is written.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.batch.chunks import EPISODE_SEED_RULE, Chunk, auto_chunk_size, plan_chunks
from pedsafe_sumo.batch.executors import (
    DEFAULT_RECYCLE_CHUNKS,
    MAX_RECYCLE_CHUNKS,
    BatchError,
    DaskBackend,
    ProcessPoolBackend,
    make_backend,
)
from pedsafe_sumo.batch.inputs import InputFileError, check_site
from pedsafe_sumo.batch.rundir import BatchRunDirectory, utc_now
from pedsafe_sumo.batch.runner import ChunkOutput, WorkerConfig, site_file_digests, worker_versions
from pedsafe_sumo.batch.sampled import (
    FAMILIES,
    FAMILY_JOINT,
    FAMILY_PRODUCT,
    PROPOSALS_KEY,
    SAMPLER_IS,
    SAMPLER_MC,
    V2I_FACTOR_CONTRAST_V2I_ONLY,
    V2I_FACTOR_NONE,
    V2I_FACTORS,
    SamplerError,
    plan_sampled_chunks,
    run_sampled,
    sampler_identity,
)
from pedsafe_sumo.batch.stop import stop_on_signals
from pedsafe_sumo.batch.trust import check_stack_from_file
from pedsafe_sumo.control.agent import AlgorithmLoadError, load_agent_class, stack_spec
from pedsafe_sumo.control.timeout import DEFAULT_AGENT_TIMEOUT_S, TIMEOUT_STATUS, check_timeout_s
from pedsafe_sumo.io.run_store import (
    RUN_FILE,
    STATE_COMPLETE,
    STATE_RUNNING,
    STEPLOGS_DIR,
    RunStoreError,
    holds_run,
    read_json,
)
from pedsafe_sumo.io.step_logs import KEEP_ALL, KEEP_EVENTS, KEEP_LOGS_CHOICES
from pedsafe_sumo.network.sites import SITE_HELP, UnknownSiteError, resolve_site, site_reference
from pedsafe_sumo.params import ParameterError
from pedsafe_sumo.safety.stats import ERROR_STATUS
from pedsafe_sumo.sampling.importance import SQRT_HALF
from pedsafe_sumo.sampling.pooling import first_estimated_stage
from pedsafe_sumo.sampling.stages import (
    DEFAULT_PILOT_EPISODES,
    DEFAULT_PILOT_STAGES,
    DEFAULT_POOL_FROM_STAGE,
    INPUT_MODES,
    INPUTS_SCREENED,
    MAX_PILOT_EPISODES,
    MAX_PILOT_STAGES,
    MIN_PILOT_EPISODES,
    MIN_SPREAD_FLAG,
    SCORE_CLEARANCE,
    SCORE_TTC,
    SCORES,
)
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.hosting import check_hosting, split_hosted
from pedsafe_sumo.scenarios.specs import SCENARIOS
from pedsafe_sumo.settings import UsageError, check_roadside_units, configure, parse_set
from pedsafe_sumo.sim.episode import CONDITIONS, DEFAULT_ALGORITHM

if TYPE_CHECKING:
    import pandas as pd

    from pedsafe_sumo.network.sites import Site

Backend = DaskBackend | ProcessPoolBackend
DEFAULT_EPISODES = 100
#: The arguments that decide a run's results (and its chunk layout), with their defaults. run.json
#: records them; --resume takes them from there, and a flag given again must repeat its value.
RUN_ARGUMENT_DEFAULTS: dict[str, Any] = {
    "scenario": None,
    "condition": "both",
    "episodes": DEFAULT_EPISODES,
    "seed": 1,
    "site": "xueqing",
    "params": None,
    "set": [],
    "algorithm": DEFAULT_ALGORITHM,
    "perception": None,
    "chunk_size": None,
    "protocol": None,
    "agent_timeout": DEFAULT_AGENT_TIMEOUT_S,
    "keep_logs": KEEP_EVENTS,
    "approach": None,
    "sampler": SAMPLER_MC,
    "is_pilot_stages": DEFAULT_PILOT_STAGES,
    "is_pilot_episodes": DEFAULT_PILOT_EPISODES,
    "is_inputs": INPUTS_SCREENED,
    "is_min_spread": SQRT_HALF,
    "is_proposal": None,
    # TTC since session 6: the clearance score drove the proposal away from collisions on Xueqing's
    # crossing; the TTC score agreed with plain MC on all four scenarios (docs/sampling.md).
    "is_score": SCORE_TTC,
    # joint since session 10: against the 10,000-pair MC run it needed fewer episodes than the
    # product on all four scenarios (research/EXPERIMENTS.md, sessions 6-8); the product stays one flag away.
    "is_family": FAMILY_JOINT,
    # since session 11: Table I pools the pilot stages from stage 2 with the final one (docs/sampling.md).
    "is_pool_from": DEFAULT_POOL_FROM_STAGE,
    # since session 12: the joint proposal also aims at V2I's collisions where the pilots hold enough of
    # them (sampling/joint.py, "The V2I factor"; research/EXPERIMENTS.md, session 12); since session 13
    # also at those where SV does not collide ("The V2I-only term"; research/EXPERIMENTS.md, session 13).
    "is_v2i_factor": V2I_FACTOR_CONTRAST_V2I_ONLY,
}
#: What runs recorded before an argument existed (or before its default changed) had: --resume fills a
#: key missing from an older run.json with this, not with today's default, so the run stays the same run.
RESUME_DEFAULTS_OF_OLDER_RUNS: dict[str, Any] = {
    "is_score": SCORE_CLEARANCE,
    "is_family": FAMILY_PRODUCT,
    # None: the final stage alone, Table I's estimator before --is-pool-from.
    "is_pool_from": None,
    "is_v2i_factor": V2I_FACTOR_NONE,
}
#: Upper bounds of the batch's numbers, so that no value can make a batch run for ever or exhaust the
#: machine before its first episode. Episodes per scenario: a million pairs take about 20 hours on 2
#: cores (28 episodes/s, BENCHMARKS.md), and part files number episodes with six digits.
MAX_EPISODES = 1_000_000
#: Run seeds are stored in run.json and compared as 64-bit integers.
MAX_SEED = 2**63 - 1
#: Local worker processes (one SUMO each, about 150 MB): 256 need about 40 GB, beyond one machine;
#: more workers belong on a cluster (--cluster).
MAX_WORKERS = 256
#: A chunk's rows and case logs are held by its worker and rerun whole after a kill.
MAX_CHUNK_PAIRS = 10_000
#: run.json keys compared on --resume: what makes two runs' episodes the same episodes.
IDENTITY_KEYS = (
    "site",
    "scenarios",
    "conditions",
    "episodes_per_scenario",
    "run_seed",
    "episode_seed_rule",
    "algorithm",
    "parameters",
    "site_files_sha256",
    "chunk_size_pairs",
    "sampler",
)
#: Versions that must be the same on --resume (another SUMO or pedsafe_sumo may give other episodes).
PINNED_VERSIONS = ("pedsafe_sumo", "sumo")
INPUT_ERRORS = (
    UsageError,
    ParameterError,
    ScenarioError,
    AlgorithmLoadError,
    UnknownSiteError,
    InputFileError,
)


def _git_commit() -> str:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=5
        )
        dirty = subprocess.run(
            ["git", "status", "--porcelain"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=5
        )
        return out.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "") if out.returncode == 0 else ""
    except (OSError, subprocess.SubprocessError):
        return ""


def _versions() -> dict[str, str]:
    import numpy
    import pandas

    return {
        **worker_versions(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "pandas": pandas.__version__,
        "platform": platform.platform(),
    }


class _OneLineParser(argparse.ArgumentParser):
    """argparse whose errors are one line on stderr (exit 2), like every other bad input."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"error: {message} (see --help)\n")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = _OneLineParser(prog="python -m pedsafe_sumo.batch", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenario",
        help=f"{', '.join(SCENARIOS)}, a comma-separated list, or all (required unless --resume)",
    )
    parser.add_argument("--condition", help="sv, v2i or both (paired: same seed) [both]")
    parser.add_argument(
        "--episodes",
        type=int,
        help=f"episodes per scenario (each run under every condition) [{DEFAULT_EPISODES}]",
    )
    parser.add_argument("--seed", type=int, help="run seed; episode seeds derive from it [1]")
    parser.add_argument(
        "--workers",
        type=int,
        help="local worker processes, one SUMO each [min(2, cores)]; not with --cluster",
    )
    parser.add_argument(
        "--recycle-chunks",
        type=int,
        dest="recycle_chunks",
        metavar="CHUNKS",
        help="replace the pool's worker processes after every CHUNKS chunks per worker, 0 = never (libsumo "
        f"keeps ~1 KiB per episode; the rows do not change) [{DEFAULT_RECYCLE_CHUNKS}]; not with --cluster",
    )
    parser.add_argument(
        "--cluster",
        metavar="ADDRESS",
        help="run the chunks on a Dask cluster: a scheduler address (tcp://host:8786) or local:N to start "
        "N local workers; needs pip install 'pedsafe_sumo[cluster]'",
    )
    parser.add_argument(
        "--chunk-size",
        type=int,
        dest="chunk_size",
        metavar="PAIRS",
        help="episode pairs per chunk (the unit written, retried and resumed) [about 8 chunks per worker, "
        "at most 25]",
    )
    parser.add_argument("--out", type=Path, help="run directory [results/<scenario>-<time>]")
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue the stopped run in --out with its recorded configuration; flags given again must "
        "repeat the recorded values",
    )
    parser.add_argument("--site", help=SITE_HELP)
    parser.add_argument(
        "--approach",
        help="N, E, S, W or all: the arm the ego comes in on (staging, poles and signals follow it); all "
        "runs every approach the site can host [the site's own approach]",
    )
    parser.add_argument("--params", type=Path, help="parameter file laid over the defaults")
    parser.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="override a scenario or parameter value"
    )
    parser.add_argument("--algorithm", help=f"AD stack as package.module:Class [{DEFAULT_ALGORITHM}]")
    parser.add_argument(
        "--perception", help="replace the stack's detector by package.module:Class (docs/ad_interface.md)"
    )
    parser.add_argument(
        "--agent-timeout",
        type=float,
        dest="agent_timeout",
        metavar="SECONDS",
        help="time limit of each run_step call of the AD stack: an episode whose stack exceeds it ends "
        f"with status timeout, and the batch goes on [{DEFAULT_AGENT_TIMEOUT_S:g}]",
    )
    parser.add_argument(
        "--keep-logs",
        dest="keep_logs",
        choices=KEEP_LOGS_CHOICES,
        help="which per-step logs to keep: 'events' = both conditions of every pair with a collision or "
        "a conflict, in cases/; 'all' = those and every episode's log, one Parquet file per chunk in "
        f"steplogs/ [{KEEP_EVENTS}]",
    )
    parser.add_argument(
        "--sampler",
        choices=(SAMPLER_MC, SAMPLER_IS),
        help="mc: plain Monte Carlo from the nominal distributions; is: importance sampling, the proposal "
        "adapted by cross-entropy pilot stages, every row weighted (docs/sampling.md); may be given "
        f"with --protocol [{SAMPLER_MC}]",
    )
    parser.add_argument(
        "--is-pilot-stages",
        type=int,
        dest="is_pilot_stages",
        metavar="N",
        help=f"--sampler is: cross-entropy pilot stages per scenario, 1 to {MAX_PILOT_STAGES} "
        f"[{DEFAULT_PILOT_STAGES}]",
    )
    parser.add_argument(
        "--is-pilot-episodes",
        type=int,
        dest="is_pilot_episodes",
        metavar="PAIRS",
        help=f"--sampler is: episode pairs per pilot stage, {MIN_PILOT_EPISODES} to {MAX_PILOT_EPISODES:,}; "
        f"they come on top of --episodes and count in the cost [{DEFAULT_PILOT_EPISODES}]",
    )
    parser.add_argument(
        "--is-inputs",
        choices=INPUT_MODES,
        dest="is_inputs",
        help="--sampler is: which inputs the proposal moves: 'screened' = those whose pilot elite differs "
        "from the nominal (chi-square at p < 0.01, docs/sampling.md), 'all' = every input a collision may "
        f"depend on [{INPUTS_SCREENED}]",
    )
    parser.add_argument(
        "--is-min-spread",
        type=float,
        dest="is_min_spread",
        metavar="FRACTION",
        help=f"--sampler is: a proposed input's spread never falls below this fraction of the nominal's, "
        f"{MIN_SPREAD_FLAG}..1 [sqrt(1/2) = {SQRT_HALF:.4f}: below it a normal's weights have infinite "
        "variance]",
    )
    parser.add_argument(
        "--is-score",
        choices=SCORES,
        dest="is_score",
        help="--sampler is: how the pilot stages rank an episode without a collision: 'clearance' = "
        "closest clearance [m], 'ttc' = smallest time to collision [s] (docs/sampling.md) "
        f"[{SCORE_TTC}]",
    )
    parser.add_argument(
        "--is-family",
        choices=FAMILIES,
        dest="is_family",
        help="--sampler is: the proposal's shape: 'product' = one family per input, refitted by the "
        "cross-entropy method; 'joint' = p sqrt(pi_hat) with pi_hat a logistic fit of the collision on "
        f"every pilot row so far, drawn by rejection (docs/sampling.md); --is-inputs, --is-min-spread and "
        f"--is-score need --is-family product [{FAMILY_JOINT}]",
    )
    parser.add_argument(
        "--is-v2i-factor",
        choices=V2I_FACTORS,
        dest="is_v2i_factor",
        help="--sampler is, --is-family joint: 'contrast' = the proposal also aims at V2I's collisions, "
        "modelled from the pilots by the contrast between the clothing and the vehicles' colours, where "
        "the pilots' SV collisions hold at least 5 V2I ones (docs/sampling.md, 'The V2I factor'); "
        "'contrast+v2i-only' = also at V2I's collisions where SV does not collide, where the pilots hold at "
        "least 5 of those, or 2 that make up a tenth of their V2I collisions; 'none' "
        f"= fitted on SV's collisions alone [{V2I_FACTOR_CONTRAST_V2I_ONLY}]",
    )
    parser.add_argument(
        "--is-pool-from",
        type=int,
        dest="is_pool_from",
        metavar="STAGE",
        help="--sampler is: Table I estimates from the episodes of stages STAGE..final, each stage with its "
        "own estimate weighted by its share of the episodes (docs/sampling.md, 'Pooling the stages'); fixed "
        "with the run, 0 to --is-pilot-stages (that number: the final stage alone) "
        f"[{DEFAULT_POOL_FROM_STAGE}, or the final stage when there are fewer pilot stages]",
    )
    parser.add_argument(
        "--is-proposal",
        dest="is_proposal",
        metavar="RUN",
        help="--sampler is: take every stage's proposal (and the pilot settings) of this earlier IS run "
        "(its directory or run.json) instead of adapting one: with the same --seed the two runs draw the "
        "same episodes with the same weights, and `compare` pairs them (build against build)",
    )
    parser.add_argument(
        "--protocol",
        type=Path,
        metavar="FILE.toml",
        help="run a protocol file (protocols/): it fixes every value of the model; beside it only --episodes,"
        " how the run is carried out (--workers, --recycle-chunks, --keep-logs, --out) and how it samples "
        "(--sampler, --is-*) may be given (docs/protocols.md)",
    )
    return parser.parse_args(argv)


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


def _explicit_arguments(args: argparse.Namespace) -> dict[str, Any]:
    given = {name: getattr(args, name) for name in RUN_ARGUMENT_DEFAULTS if getattr(args, name) is not None}
    if "params" in given:
        given["params"] = str(Path(given["params"]).resolve())
    if "protocol" in given:
        given["protocol"] = str(Path(given["protocol"]))
    if "is_proposal" in given:
        given["is_proposal"] = str(Path(given["is_proposal"]).resolve())
    return given


def _first_difference(recorded: Any, current: Any, path: str) -> str | None:
    """The dotted path of the first value that differs, or None when equal."""
    if isinstance(recorded, dict) and isinstance(current, dict):
        for key in sorted(set(recorded) | set(current), key=str):
            if key not in recorded or key not in current:
                return f"{path}.{key}"
            found = _first_difference(recorded[key], current[key], f"{path}.{key}")
            if found:
                return found
        return None
    return None if recorded == current else path


def _lookup(data: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        data = data.get(part, "(absent)") if isinstance(data, dict) else "(absent)"
    return data


def _is_foreign(out: Path) -> bool:
    """Whether `out` is an existing directory with something in it and no run of ours (holds_run)."""
    if not out.is_dir():
        return False
    try:
        return next(out.iterdir(), None) is not None
    except OSError:  # unreadable: certainly not ours to write into
        return True


def _recorded_run(out: Path) -> dict[str, Any]:
    try:
        recorded = read_json(out / RUN_FILE)
    except RunStoreError as exc:
        if not (out / RUN_FILE).exists():
            raise UsageError(f"{out} holds no run to resume (no {RUN_FILE})") from None
        raise UsageError(f"cannot resume: {exc}") from None
    if not isinstance(recorded.get("arguments"), dict) or "sessions" not in recorded:
        raise UsageError(f"{out / RUN_FILE} was written by a batch that cannot be resumed (no arguments)")
    return recorded


def resumed_arguments(recorded: dict[str, Any], explicit: dict[str, Any]) -> dict[str, Any]:
    """A resumed run's arguments: the flags given again over the recorded ones, over what runs recorded
    before an argument existed had (RESUME_DEFAULTS_OF_OLDER_RUNS), over today's defaults."""
    return {**RUN_ARGUMENT_DEFAULTS, **RESUME_DEFAULTS_OF_OLDER_RUNS, **recorded, **explicit}


def prepare(args: argparse.Namespace) -> Plan:
    """Check everything about the command and its input files; writes nothing."""
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
    explicit = _explicit_arguments(args)
    recorded = None
    if args.resume:
        if args.out is None:
            raise UsageError("--resume needs --out DIR, the run directory to continue")
        recorded = _recorded_run(args.out)
        kept = recorded["arguments"].get("keep_logs", KEEP_EVENTS)
        if explicit.get("keep_logs", kept) != kept:
            raise UsageError(
                f"{args.out} was started with --keep-logs {kept}; a resumed run keeps the same logs "
                "(leave the flag out or repeat its value)"
            )
        arguments = resumed_arguments(recorded["arguments"], explicit)
    else:
        if args.out is not None and holds_run(args.out):
            state = "complete" if (args.out / "episodes.parquet").exists() else "incomplete"
            raise UsageError(
                f"output directory {args.out} already holds a run ({state}); continue it with --resume "
                "or choose another --out"
            )
        if args.out is not None and _is_foreign(args.out):
            raise UsageError(
                f"--out {args.out} is a directory that is not empty and holds no run: choose a new or "
                "empty directory (nothing in it is touched)"
            )
        arguments = {**RUN_ARGUMENT_DEFAULTS, **explicit}
    protocol = None
    if arguments["protocol"] is not None:
        protocol, arguments = _with_protocol(args, arguments, explicit, recorded)
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
    if arguments["episodes"] < 1:
        raise UsageError(f"--episodes must be at least 1, got {arguments['episodes']}")
    if arguments["episodes"] > MAX_EPISODES:
        raise UsageError(
            f"--episodes must be at most {MAX_EPISODES:,} per scenario, got {arguments['episodes']}"
        )
    if arguments["seed"] < 0:
        raise UsageError(f"--seed must not be negative, got {arguments['seed']}")
    if arguments["seed"] > MAX_SEED:
        raise UsageError(f"--seed must be at most 2**63 - 1, got {arguments['seed']}")
    if arguments["chunk_size"] is not None and arguments["chunk_size"] < 1:
        raise UsageError(f"--chunk-size must be at least 1, got {arguments['chunk_size']}")
    if arguments["chunk_size"] is not None and arguments["chunk_size"] > MAX_CHUNK_PAIRS:
        raise UsageError(
            f"--chunk-size must be at most {MAX_CHUNK_PAIRS:,} pairs, got {arguments['chunk_size']}"
        )
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
    try:
        agent_timeout_s = check_timeout_s(arguments["agent_timeout"])
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    site = resolve_site(arguments["site"])
    params_file = Path(arguments["params"]) if arguments["params"] else None
    if protocol is not None:
        specs, params = protocol.specs(), protocol.params()
    else:
        specs, params = configure(scenarios, params_file, arguments["set"])
    stack = stack_spec(arguments["algorithm"], arguments.get("perception"))
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
    out = args.out or REPO_ROOT / "results" / f"{scenario}-{stamp}"
    plan = Plan(arguments, scenarios, conditions, identity, config, out, recorded)
    if recorded is not None:
        _check_same_run(plan, recorded)
    return plan


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
    from pedsafe_sumo.scenarios.geometry import ARMS, default_arm, site_approaches
    from pedsafe_sumo.scenarios.hosting import hosting_matrix

    if approach_arg not in (*ARMS, "all"):
        raise UsageError(f"unknown approach '{approach_arg}' (known: {', '.join(ARMS)}, all)")
    known = list(site_approaches(site))
    own = default_arm(site)
    if approach_arg == "all":
        arms = [own] + [arm for arm in ARMS if arm in known and arm != own]
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


def _sampler_identity(arguments: dict[str, Any], scenarios: list[str]) -> dict[str, Any] | None:
    try:
        return sampler_identity(arguments, scenarios)
    except SamplerError as exc:
        raise UsageError(str(exc)) from None


def _with_protocol(
    args: argparse.Namespace,
    arguments: dict[str, Any],
    explicit: dict[str, Any],
    recorded: dict[str, Any] | None,
) -> tuple[Any, dict[str, Any]]:
    """The protocol's values in place of the flags: a protocol fixes everything but the number of
    episodes and workers (and where the run goes). Another flag with --protocol is refused."""
    from pedsafe_sumo.protocol import load_protocol

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


def _check_same_run(plan: Plan, recorded: dict[str, Any]) -> None:
    """Refuse to resume a run whose recorded identity differs from this command's (one line)."""
    # Compare as JSON would store them (tuples as lists, the same number types).
    current = json.loads(json.dumps({key: plan.identity[key] for key in IDENTITY_KEYS}, default=str))
    previous = {key: recorded.get(key) for key in IDENTITY_KEYS}
    where = _first_difference(previous, current, "")
    if where:
        where = where.lstrip(".")
        raise UsageError(
            f"{plan.out} holds a different run: {where} is {_lookup(previous, where)!r} there, "
            f"{_lookup(current, where)!r} here; --resume continues the recorded run (leave the flag out "
            "or repeat its value), a new run needs another --out"
        )
    for name in PINNED_VERSIONS:
        was, now = recorded.get("versions", {}).get(name), plan.config.versions.get(name)
        if was != now:
            raise UsageError(f"{plan.out} was started with {name} {was}, this is {now}: resume it with {was}")


def new_run_info(plan: Plan, backend: Backend, argv: list[str]) -> dict[str, Any]:
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
        "commit": _git_commit(),
        "sessions": [],
        "wall_time_s": None,
        "episodes_per_s": None,
        "n_error": None,
        "n_timeout": None,
        "cases_written": None,
    }


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    try:
        plan = prepare(args)
        backend = make_backend(
            args.cluster,
            args.workers or min(2, os.cpu_count() or 1),
            DEFAULT_RECYCLE_CHUNKS if args.recycle_chunks is None else args.recycle_chunks,
        )
    except (*INPUT_ERRORS, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if plan.recorded is not None and plan.recorded.get("state") == STATE_COMPLETE:
        print(
            f"{plan.out} is complete ({plan.recorded.get('episodes_total', '?')} episodes): nothing to resume"
        )
        return 0
    restore_signals = stop_on_signals()  # SIGINT, SIGTERM: workers stopped, run kept for --resume
    try:
        backend.start()
        return run(plan, backend, argv)
    except INPUT_ERRORS as exc:  # an unreachable cluster, a run directory another batch holds
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (BatchError, OSError) as exc:
        print(f"error: {exc}; the chunks finished so far are kept: continue with --resume", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted; the chunks finished so far are kept: continue with --resume", file=sys.stderr)
        return 130
    finally:
        backend.close()
        restore_signals()


def run(plan: Plan, backend: Backend, argv: list[str]) -> int:
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
        commit = _git_commit()
        if commit != run_info.get("commit"):
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
    session = {
        "started_utc": utc_now(),
        "command": "python -m pedsafe_sumo.batch " + " ".join(argv),
        "executor": backend.description,
        "commit": _git_commit(),
        "chunks_to_run": len(todo),
        "wall_time_s": None,
    }
    run_info["sessions"].append(session)
    run_dir.save_run_info(run_info)

    from tqdm import tqdm

    what = f"{total} episodes ({', '.join(plan.scenarios)} x {', '.join(plan.conditions)})"
    resumed = f", {done_rows} done before" if plan.recorded is not None else ""
    print(
        f"{what} in {len(chunks)} chunk(s) of up to {plan.identity['chunk_size_pairs']} pair(s){resumed}; "
        f"{len(todo)} chunk(s) to run on {backend.description} -> {plan.out}"
    )
    started = time.perf_counter()
    with tqdm(
        total=total, initial=done_rows, unit="episode", smoothing=0.1, mininterval=1.0, file=sys.stderr
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


def print_table(table: pd.DataFrame, run_info: dict[str, Any] | None = None) -> None:
    """Table I of the rows; `run_info` (run.json) for an importance-sampling run's stages pooled and the
    control variates of joint proposals (report/tables.py: table_one_weighted)."""
    from pedsafe_sumo.report.tables import is_weighted, table_one_of_run, v2i_only_note
    from pedsafe_sumo.safety.stats import table_one

    proposals = (run_info or {}).get(PROPOSALS_KEY)
    first_stage = first_estimated_stage(run_info)

    def summarise(rows: pd.DataFrame) -> pd.DataFrame:
        if not is_weighted(rows):
            return table_one(rows)
        return table_one_of_run(rows, proposals=proposals, first_stage=first_stage)

    summary = summarise(table)
    if is_weighted(table):
        which = "the final stage" if first_stage is None else f"stages {first_stage}..final, pooled"
        print(
            f"Table I (importance sampling: weighted estimates of {which}, 95% central-limit "
            "intervals; see tables/table1.csv for ess and the episodes run, pilots included):"
        )
    else:
        print(
            "Table I (95% Wilson intervals; n counts the episodes that ran, errors are left out of the "
            "rates):"
        )
    _print_rows(summary)
    note = v2i_only_note(run_info) if is_weighted(table) else ""
    if note:
        print(note)
    arms = [arm for arm in table["approach"].unique() if arm] if "approach" in table else []
    if len(arms) > 1:  # --approach all: the same table per approach
        for arm in arms:
            print(f"Table I on approach {arm}:")
            _print_rows(summarise(table[table["approach"] == arm]))


def _print_rows(summary: pd.DataFrame) -> None:
    for _, row in summary.iterrows():
        print(
            f"  {row['scenario']:20s} {row['condition']:4s} n={int(row['n']):5d} "
            f"(errors {int(row['n_error'])})  collision {row['collision_rate']:.4f} "
            f"[{row['collision_low']:.4f}, {row['collision_high']:.4f}]  "
            f"injury {row['injury_mean']:.4f} [{row['injury_low']:.4f}, {row['injury_high']:.4f}]  "
            f"conflict {row['conflict_rate']:.4f} [{row['conflict_low']:.4f}, {row['conflict_high']:.4f}]"
            + (f"  ({row['estimator']})" if "estimator" in summary.columns else "")
        )


if __name__ == "__main__":
    sys.exit(main())
