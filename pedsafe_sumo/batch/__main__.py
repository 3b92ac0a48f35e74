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

The command line only: batch/plan.py checks the command and builds the run (`prepare`), batch/execute.py
carries it out (`run_batch`), batch/summary.py prints its Table I. `parse_args`, `plan_batch` and
`execute` are the steps of `main`; pedsafe_sumo.api.run_batch takes the same steps from Python.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from pedsafe_sumo.batch.arguments import DEFAULT_EPISODES
from pedsafe_sumo.batch.execute import Backend, run_batch
from pedsafe_sumo.batch.executors import DEFAULT_RECYCLE_CHUNKS, MAX_RECYCLE_CHUNKS, BatchError, make_backend
from pedsafe_sumo.batch.plan import INPUT_ERRORS, MAX_CHUNK_PAIRS, MAX_WORKERS, Plan, prepare
from pedsafe_sumo.batch.sampled import (
    FAMILIES,
    FAMILY_JOINT,
    SAMPLER_IS,
    SAMPLER_MC,
    V2I_FACTOR_CONTRAST_V2I_ONLY,
    V2I_FACTORS,
)
from pedsafe_sumo.batch.stop import stop_on_signals
from pedsafe_sumo.cli import DEFAULT_MAX_RUNS, MAX_EPISODES, OneLineParser, max_runs_help
from pedsafe_sumo.control.stack_names import stack_names_help
from pedsafe_sumo.control.timeout import DEFAULT_AGENT_TIMEOUT_S
from pedsafe_sumo.io.run_store import STATE_COMPLETE
from pedsafe_sumo.io.step_logs import KEEP_EVENTS, KEEP_LOGS_CHOICES
from pedsafe_sumo.network.sites import SITE_HELP
from pedsafe_sumo.sampling.importance import SQRT_HALF
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
    SCORE_TTC,
    SCORES,
)
from pedsafe_sumo.scenarios.specs import SCENARIOS
from pedsafe_sumo.sim.episode import DEFAULT_ALGORITHM


def parse_args(
    argv: list[str] | None, parser_class: type[argparse.ArgumentParser] = OneLineParser
) -> argparse.Namespace:
    """The command's options; `parser_class` decides what a bad one does (OneLineParser: one line, exit 2)."""
    parser = parser_class(prog="python -m pedsafe_sumo.batch", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenario",
        help=f"{', '.join(SCENARIOS)}, a comma-separated list, or all (required unless --resume)",
    )
    parser.add_argument("--condition", help="sv, v2i or both (paired: same seed) [both]")
    parser.add_argument(
        "--episodes",
        type=int,
        help=f"episodes per scenario (each run under every condition), 1 to {MAX_EPISODES:,} "
        f"[{DEFAULT_EPISODES}]",
    )
    parser.add_argument("--seed", type=int, help="run seed, 0 to 2**63 - 1; episode seeds derive from it [1]")
    parser.add_argument(
        "--workers",
        type=int,
        help=f"local worker processes, one SUMO each, 1 to {MAX_WORKERS} [min(2, cores)]; not with --cluster",
    )
    parser.add_argument(
        "--recycle-chunks",
        type=int,
        dest="recycle_chunks",
        metavar="CHUNKS",
        help="replace the pool's worker processes after every CHUNKS chunks per worker, 0 (never) to "
        f"{MAX_RECYCLE_CHUNKS:,} (libsumo keeps ~1 KiB per episode; the rows do not change) "
        f"[{DEFAULT_RECYCLE_CHUNKS}]; not with --cluster",
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
        help=f"episode pairs per chunk (the unit written, retried and resumed), 1 to {MAX_CHUNK_PAIRS:,} "
        "[about 8 chunks per worker, at most 25]",
    )
    parser.add_argument("--out", type=Path, help="run directory [results/<scenario>-<time>]")
    parser.add_argument(
        "--max-runs",
        type=int,
        dest="max_runs",
        default=DEFAULT_MAX_RUNS,
        metavar="EPISODES",
        help=max_runs_help() + "; a resumed run is not bounded again",
    )
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue the stopped run in --out with its recorded configuration; flags given again must "
        "repeat the recorded values",
    )
    parser.add_argument("--site", help=SITE_HELP)
    parser.add_argument(
        "--approach",
        help="a leg of the junction (N, E, S, W; NE, SE, SW, NW or B055 for legs sharing a compass "
        "sector; python -m pedsafe_sumo.site --site NAME lists them) or all: the leg the ego comes in on "
        "(staging, poles and signals follow it); all runs every approach the site can host [the site's own "
        "approach]",
    )
    parser.add_argument("--params", type=Path, help="parameter file laid over the defaults")
    parser.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="override a scenario or parameter value"
    )
    parser.add_argument(
        "--algorithm",
        help=f"AD stack as package.module:Class, or a shipped one by name: {stack_names_help()} "
        f"[{DEFAULT_ALGORITHM}]",
    )
    parser.add_argument(
        "--perception", help="replace the stack's detector by package.module:Class (docs/ad_interface.md)"
    )
    parser.add_argument(
        "--agent-timeout",
        type=float,
        dest="agent_timeout",
        metavar="SECONDS",
        help="time limit of each run_step call of the AD stack, above 0 and at most 3600: an episode whose "
        f"stack exceeds it ends with status timeout, and the batch goes on [{DEFAULT_AGENT_TIMEOUT_S:g}]",
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
        metavar="FILE.toml|NAME",
        help="run a protocol: a file, or the name of a shipped one (paper-v7): it fixes every value of the "
        "model; beside it only --episodes,"
        " how the run is carried out (--workers, --recycle-chunks, --keep-logs, --out) and how it samples "
        "(--sampler, --is-*) may be given (docs/protocols.md)",
    )
    return parser.parse_args(argv)


def plan_batch(args: argparse.Namespace) -> tuple[Plan, Backend]:
    """The checked run and the backend that will carry it out (not started); raises one of INPUT_ERRORS
    (or OSError) on bad input, and writes nothing."""
    plan = prepare(args)
    backend = make_backend(
        args.cluster,
        args.workers or min(2, os.cpu_count() or 1),
        DEFAULT_RECYCLE_CHUNKS if args.recycle_chunks is None else args.recycle_chunks,
    )
    return plan, backend


def is_complete(plan: Plan) -> bool:
    """--resume of a run that has finished: nothing left to do."""
    return plan.recorded is not None and plan.recorded.get("state") == STATE_COMPLETE


def execute(plan: Plan, backend: Backend, argv: list[str], progress: bool = True) -> int:
    """Start the backend, run the plan with Ctrl-C and SIGTERM stopping it cleanly, close the backend;
    returns the exit code. Raises what the run raises (INPUT_ERRORS, BatchError, OSError,
    KeyboardInterrupt); the finished chunks are kept for --resume."""
    restore_signals = stop_on_signals()  # SIGINT, SIGTERM: workers stopped, run kept for --resume
    try:
        backend.start()
        return run_batch(plan, backend, argv, progress=progress)
    finally:
        backend.close()
        restore_signals()


def main(argv: list[str] | None = None) -> int:
    """The command. Exit code 0: done, or nothing left to resume; 1: the batch failed (the finished chunks
    are kept for --resume); 2: bad input (one line on stderr, nothing written); 130: interrupted."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    try:
        plan, backend = plan_batch(args)
    except (*INPUT_ERRORS, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{plan.count_text} = {plan.total_episodes:,} episodes (--max-runs {args.max_runs:,})")
    if is_complete(plan):
        total = (plan.recorded or {}).get("episodes_total", "?")
        print(f"{plan.out} is complete ({total} episodes): nothing to resume")
        return 0
    try:
        return execute(plan, backend, argv)
    except INPUT_ERRORS as exc:  # an unreachable cluster, a run directory another batch holds
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (BatchError, OSError) as exc:
        print(f"error: {exc}; the chunks finished so far are kept: continue with --resume", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted; the chunks finished so far are kept: continue with --resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
