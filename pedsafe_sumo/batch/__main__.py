"""python -m pedsafe_sumo.batch --scenario crossing: a batch of paired SV/V2I episodes, and its Table I.

    python -m pedsafe_sumo.batch --scenario crossing                      # ~1 minute, 100 pairs
    python -m pedsafe_sumo.batch --scenario all --episodes 10000 --workers 2 --out results/protocol
    python -m pedsafe_sumo.batch --scenario jaywalking --set perception.v2i.latency_s=0.3 \
        --algorithm my.stack:Stack

Writes DIR/episodes.parquet (one row per episode and condition), DIR/run.json (configuration,
parameters, seeds, versions, timings: the paper's global information file) and DIR/cases/ (per-step
logs of both conditions of every episode pair with a collision or a conflict). Bad input ends in one
line on stderr and exit code 2, and nothing is written.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from pedsafe_sumo import REPO_ROOT, __version__
from pedsafe_sumo.batch.runner import Task, WorkerConfig, episode_seed, run_tasks
from pedsafe_sumo.control.agent import AlgorithmLoadError, load_agent_class
from pedsafe_sumo.network.sites import SITES, UnknownSiteError, get_site
from pedsafe_sumo.params import ParameterError
from pedsafe_sumo.scenarios.registry import SCENARIOS, ScenarioError
from pedsafe_sumo.settings import UsageError, check_roadside_units, configure, parse_set
from pedsafe_sumo.sim.episode import CONDITIONS, DEFAULT_ALGORITHM

DEFAULT_EPISODES = 100


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
    import sumolib

    return {
        "pedsafe_sumo": __version__,
        "sumo": sumolib.version.gitDescribe(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "pandas": pandas.__version__,
        "platform": platform.platform(),
    }


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="python -m pedsafe_sumo.batch", description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", required=True, help=f"{', '.join(SCENARIOS)} or all")
    parser.add_argument("--condition", default="both", help="sv, v2i or both (paired: same seed) [both]")
    parser.add_argument(
        "--episodes",
        type=int,
        default=DEFAULT_EPISODES,
        help=f"episodes per scenario (each run under every condition) [{DEFAULT_EPISODES}]",
    )
    parser.add_argument("--seed", type=int, default=1, help="run seed; episode seeds derive from it [1]")
    parser.add_argument(
        "--workers",
        type=int,
        default=min(2, os.cpu_count() or 1),
        help="worker processes, one SUMO each [min(2, cores)]",
    )
    parser.add_argument("--out", type=Path, help="run directory [results/<scenario>-<time>]")
    parser.add_argument("--site", default="xueqing", help=f"study site [xueqing; known: {', '.join(SITES)}]")
    parser.add_argument("--params", type=Path, help="parameter file laid over the defaults")
    parser.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="override a scenario or parameter value"
    )
    parser.add_argument("--algorithm", default=DEFAULT_ALGORITHM, help="AD stack as package.module:Class")
    return parser.parse_args(argv)


def validate(args) -> tuple[list[str], list[str], dict, dict]:
    scenarios = list(SCENARIOS) if args.scenario == "all" else [args.scenario]
    if args.scenario != "all" and args.scenario not in SCENARIOS:
        raise UsageError(f"unknown scenario '{args.scenario}' (known: {', '.join(SCENARIOS)}, all)")
    if args.condition not in (*CONDITIONS, "both"):
        raise UsageError(f"unknown condition '{args.condition}' (known: sv, v2i, both)")
    conditions = list(CONDITIONS) if args.condition == "both" else [args.condition]
    if args.episodes < 1:
        raise UsageError(f"--episodes must be at least 1, got {args.episodes}")
    if args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    if args.seed < 0:
        raise UsageError(f"--seed must not be negative, got {args.seed}")
    site = get_site(args.site)
    specs, params = configure(scenarios, args.params, args.set)
    check_roadside_units(specs, site)
    load_agent_class(args.algorithm)
    if (
        args.out is not None
        and args.out.exists()
        and any((args.out / name).exists() for name in ("episodes.parquet", "run.json", "cases"))
    ):
        raise UsageError(f"output directory {args.out} already holds a run; choose another --out")
    return scenarios, conditions, specs, params


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        scenarios, conditions, specs, params = validate(args)
    except (UsageError, ParameterError, ScenarioError, AlgorithmLoadError, UnknownSiteError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    out = args.out or REPO_ROOT / "results" / f"{args.scenario}-{stamp}"
    cases = out / "cases"
    cases.mkdir(parents=True, exist_ok=True)
    scenario_overrides, _ = parse_set(args.set or [])
    tasks = [
        Task(name, i, episode_seed(args.seed, i), tuple(conditions))
        for name in scenarios
        for i in range(args.episodes)
    ]
    total = len(tasks) * len(conditions)
    config = WorkerConfig(args.site, params, scenario_overrides, args.algorithm, str(cases))

    from tqdm import tqdm

    print(
        f"{total} episodes ({', '.join(scenarios)} x {', '.join(conditions)}) "
        f"on {args.workers} worker(s) -> {out}"
    )
    started = time.perf_counter()
    with tqdm(total=total, unit="episode", smoothing=0.1, mininterval=1.0, file=sys.stderr) as bar:
        table = run_tasks(tasks, config, args.workers, progress=bar.update)
    wall_s = time.perf_counter() - started

    tmp = out / "episodes.parquet.tmp"
    table.to_parquet(tmp, index=False)
    os.replace(tmp, out / "episodes.parquet")
    run_info = {
        "command": "python -m pedsafe_sumo.batch " + " ".join(sys.argv[1:] if argv is None else argv),
        "created_utc": stamp,
        "site": args.site,
        "scenarios": {name: _spec_dict(specs[name]) for name in scenarios},
        "conditions": conditions,
        "episodes_per_scenario": args.episodes,
        "run_seed": args.seed,
        "episode_seed_rule": "SeedSequence(entropy=run_seed, spawn_key=(episode,)).generate_state(1)[0]",
        "algorithm": args.algorithm,
        "workers": args.workers,
        "parameters": params,
        "versions": _versions(),
        "commit": _git_commit(),
        "wall_time_s": round(wall_s, 3),
        "episodes_per_s": round(total / wall_s, 3) if wall_s > 0 else None,
        "n_error": int((table["status"] == "error").sum()),
        "cases_written": len(list(cases.glob("*.parquet"))),
    }
    (out / "run.json.tmp").write_text(json.dumps(run_info, indent=2, ensure_ascii=False, default=str) + "\n")
    os.replace(out / "run.json.tmp", out / "run.json")

    print(
        f"{total} episodes in {wall_s:.1f} s ({total / wall_s:.1f} episodes/s); "
        f"{run_info['n_error']} error(s); {run_info['cases_written']} case log(s) in {cases}"
    )
    print_table(table)
    print(f"tables and figures: python -m pedsafe_sumo.report {out}")
    return 0


def _spec_dict(spec) -> dict:
    import dataclasses

    return dataclasses.asdict(spec)


def print_table(table) -> None:
    from pedsafe_sumo.safety.stats import table_one

    summary = table_one(table)
    print("Table I (95% Wilson intervals):")
    for _, row in summary.iterrows():
        print(
            f"  {row['scenario']:20s} {row['condition']:4s} n={int(row['n']):5d} "
            f"(errors {int(row['n_error'])})  collision {row['collision_rate']:.4f} "
            f"[{row['collision_low']:.4f}, {row['collision_high']:.4f}]  "
            f"injury {row['injury_mean']:.4f} [{row['injury_low']:.4f}, {row['injury_high']:.4f}]  "
            f"conflict {row['conflict_rate']:.4f} [{row['conflict_low']:.4f}, {row['conflict_high']:.4f}]"
        )


if __name__ == "__main__":
    sys.exit(main())
