"""python -m pedsafe_sumo.sweep: one paired batch per combination of settings, and Table I across them.

    python -m pedsafe_sumo.sweep --scenario crossing --episodes 500 --out results/sweep \
        --vary algorithm.reaction_time_s=0.4,1.0,1.5 --vary algorithm.max_decel_mps2=6,4

Each combination of the --vary values (their Cartesian product) is a full batch run
(`python -m pedsafe_sumo.batch ... --set KEY=VALUE ...`, same seed, so every combination sees the same
worlds) in its own run directory OUT/<key>=<value>,... ; a combination whose run directory already
holds episodes.parquet is not run again and one stopped part-way is resumed (`--resume`), so a
stopped sweep continues where it stopped. At the end
OUT/sweep.csv and OUT/sweep.md hold Table I of every combination with its settings, and
OUT/sweep.png plots collision and conflict rates (95% Wilson intervals) against the first --vary key;
OUT/findings.csv and findings.png say which of the paper's qualitative findings hold in each
combination (pedsafe_sumo/report/findings.py).
Every --set / --vary key is validated for every combination before anything runs. Before it starts, the
sweep says in one line how many episodes it will run (combinations x scenarios x conditions x episodes);
it refuses more than --max-runs (1,000,000 unless given: about a day on 2 cores) and more than 1,000
combinations.

`--protocol FILE` sweeps a protocol's study (docs/protocols.md): each combination is the protocol with the
swept values replaced and everything else as it fixes it, written to OUT/protocols/<label>.toml (its
first line names the protocol and that file's SHA-256) and run as `batch --protocol` of that file, so
each run directory records what it ran (pedsafe_sumo/sweep_protocol.py):

    python -m pedsafe_sumo.sweep --protocol protocols/approach-v2.toml --preset reaction --episodes 500 \
        --out results/approach-v2-reaction

`--base-run RUN` (with --protocol): a complete run of that protocol file; the combination whose every
value is the protocol's own takes RUN's first --episodes pairs instead of running them (the same seed
gives the same rows; OUT/<label>/rows_from.json says where they came from).

`--preset NAME` is one of the sensitivity sweeps (PRESETS: the parameters the paper
does not report that move the indexes most, each over a range around its default), in place of --vary.
`--combine DIR ... --out OUT` puts the findings of several one-key sweeps side by side:
OUT/findings_across_sweeps.csv and .png (one panel per sweep).
"""

from __future__ import annotations

import itertools
import math
import sys
import tempfile
from pathlib import Path

import pandas as pd

from pedsafe_sumo.batch.__main__ import main as batch_main
from pedsafe_sumo.batch.plan import MAX_WORKERS
from pedsafe_sumo.cli import (
    DEFAULT_MAX_RUNS,
    MAX_EPISODES,
    OneLineParser,
    check_max_runs,
    check_run_count,
    check_seed,
    max_runs_help,
)
from pedsafe_sumo.control.agent import AlgorithmLoadError, load_agent_class
from pedsafe_sumo.io.outputs import check_output_dir, probe_output_dir
from pedsafe_sumo.network.sites import SITE_HELP, UnknownSiteError, resolve_site
from pedsafe_sumo.params import ParameterError
from pedsafe_sumo.protocol import load_protocol
from pedsafe_sumo.report.findings import (
    findings_across_sweeps,
    findings_across_sweeps_figure,
    findings_figure,
    findings_table,
)
from pedsafe_sumo.safety.stats import table_one
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.specs import SCENARIOS
from pedsafe_sumo.settings import UsageError, check_roadside_units, configure
from pedsafe_sumo.sim.episode import DEFAULT_ALGORITHM
from pedsafe_sumo.sweep_protocol import (
    base_run_rows,
    is_protocol_itself,
    write_base_rows,
    write_derived_protocol,
)

#: Combinations of one sweep: each is a run directory and a batch of its own, and every one is validated
#: before the first runs; a thousand is three values of six keys.
MAX_COMBINATIONS = 1000
#: The sensitivity sweeps, one key each, over a range that holds its default (the
#: values of defaults.toml and the scenario registry: reaction 0.4 s, deceleration 6 m/s2, blend gap 0,
#: occluder SUV, queue of 3, V2I latency 0.1 s, gap acceptance t_s 3 s). Ranges are assumptions: a
#: slower or gentler AD stack, the classes of the fleet, queues from one vehicle to twice the default,
#: latencies to 1 s (a congested cellular link), the HCM pedestrian start-up time t_s from 1 to 5 s.
PRESETS: dict[str, str] = {
    "reaction": "algorithm.reaction_time_s=0.4,1.0,1.5",
    "deceleration": "algorithm.max_decel_mps2=6,4.5,3",
    "blend_gap": "blend_gap_max_m=0,0.1,0.2",
    "occluder_class": "occluder_class=car,suv,van",
    "queue_length": "queue_vehicles=1,3,6",
    "v2i_latency": "perception.v2i.latency_s=0.1,0.5,1.0",
    "gap_acceptance": "pedestrians.gap_startup_clearance_s=1,3,5",
    # The V2I link's position noise: half, as stated (0.2 m) and 2.5 times; the reference stack's tracker
    # keeps its stated 0.2 m, so the wider values also test a stack whose noise model is wrong.
    "v2i_noise": "perception.v2i.position_noise_sigma_m=0.1,0.2,0.5",
}


def parse_vary(text: str) -> tuple[str, list[str]]:
    key, sep, values = text.partition("=")
    items = [v.strip() for v in values.split(",") if v.strip()]
    if not sep or not key or not items:
        raise UsageError(f"--vary needs KEY=V1,V2,..., got '{text}'")
    return key, items


def combinations(varied: list[tuple[str, list[str]]]) -> list[dict[str, str]]:
    keys = [key for key, _ in varied]
    if len(set(keys)) != len(keys):
        raise UsageError("each --vary key may appear once")
    count = math.prod(len(values) for _, values in varied)  # before the product is expanded
    if count > MAX_COMBINATIONS:
        raise UsageError(
            f"--vary gives {count:,} combinations, more than {MAX_COMBINATIONS:,} (each is a run directory "
            "and a batch of its own): vary fewer values"
        )
    return [dict(zip(keys, values)) for values in itertools.product(*(values for _, values in varied))]


def label(combination: dict[str, str]) -> str:
    return ",".join(f"{key}={value}" for key, value in combination.items()) or "defaults"


def parse_args(argv):
    parser = OneLineParser(prog="python -m pedsafe_sumo.sweep", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenario", help=f"{', '.join(SCENARIOS)}, a comma-separated list of them, or all (required)"
    )
    parser.add_argument("--condition", help="sv, v2i or both [both]")
    parser.add_argument(
        "--episodes",
        type=int,
        help=f"episodes per scenario and combination, 1 to {MAX_EPISODES:,} [200; with --protocol: the "
        "protocol's]",
    )
    parser.add_argument(
        "--seed", type=int, help="run seed, the same for every combination, 0 to 2**63 - 1 [1]"
    )
    parser.add_argument(
        "--workers", type=int, default=2, help=f"worker processes per batch, 1 to {MAX_WORKERS} [2]"
    )
    parser.add_argument(
        "--max-runs", type=int, dest="max_runs", default=DEFAULT_MAX_RUNS, metavar="EPISODES",
        help=max_runs_help() + f"; at most {MAX_COMBINATIONS:,} combinations",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, required=True, help="sweep directory")
    parser.add_argument(
        "--vary", action="append", default=[], metavar="KEY=V1,V2", help="a setting and its values"
    )
    parser.add_argument(
        "--preset", help=f"one of the sensitivity sweeps, each varying one key: {', '.join(PRESETS)}"
    )
    parser.add_argument(
        "--combine",
        nargs="+",
        type=Path,
        metavar="DIR",
        help="sweep directories whose findings to put together",
    )
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="fixed for all")
    parser.add_argument("--algorithm", help="AD stack as package.module:Class [reference]")
    parser.add_argument("--site", help=SITE_HELP)
    parser.add_argument(
        "--protocol",
        type=Path,
        help="sweep a protocol's study: each combination is the protocol with the swept value(s) replaced "
        "(its scenarios, conditions, seed, site and stack; --episodes may ask for fewer)",
    )
    parser.add_argument(
        "--base-run",
        type=Path,
        metavar="RUN",
        help="with --protocol: a complete run of that protocol file; a combination whose every value is the "
        "protocol's own takes its first --episodes pairs from it instead of running them again",
    )
    return parser.parse_args(argv)


#: What a protocol fixes: a sweep over a protocol takes none of these flags.
PROTOCOL_FIXED = ("scenario", "condition", "seed", "set", "algorithm", "site")


def validate(args) -> list[dict[str, str]]:
    if args.preset:
        if args.preset not in PRESETS:
            raise UsageError(f"unknown preset '{args.preset}' (known: {', '.join(PRESETS)})")
        args.vary = [*args.vary, PRESETS[args.preset]]
    if args.protocol is not None:
        return validate_protocol_sweep(args)
    if args.base_run is not None:
        raise UsageError("--base-run needs --protocol (the run of that protocol file)")
    args.condition = args.condition or "both"
    args.episodes = 200 if args.episodes is None else args.episodes
    args.seed = 1 if args.seed is None else args.seed
    args.algorithm = args.algorithm or DEFAULT_ALGORITHM
    args.site = args.site or "xueqing"
    if not args.scenario:
        raise UsageError("--scenario is required")
    if not args.vary:
        raise UsageError("give --vary KEY=V1,V2,... or --preset NAME")
    scenarios = list(SCENARIOS) if args.scenario == "all" else args.scenario.split(",")
    unknown = [name for name in scenarios if name not in SCENARIOS]
    if unknown:
        raise UsageError(f"unknown scenario '{unknown[0]}' (known: {', '.join(SCENARIOS)}, all)")
    if args.condition not in ("sv", "v2i", "both"):
        raise UsageError(f"unknown condition '{args.condition}' (known: sv, v2i, both)")
    if not 1 <= args.episodes <= MAX_EPISODES:
        raise UsageError(f"--episodes must lie in 1..{MAX_EPISODES:,}, got {args.episodes}")
    check_seed(args.seed)
    if not 1 <= args.workers <= MAX_WORKERS:
        raise UsageError(f"--workers must lie in 1..{MAX_WORKERS}, got {args.workers}")
    check_max_runs(args.max_runs)
    combos = combinations([parse_vary(text) for text in args.vary])
    n_conditions = 2 if args.condition == "both" else 1
    args.count_text = (
        f"{len(combos)} combination(s) x {len(scenarios)} scenario(s) x {n_conditions} condition(s) x "
        f"{args.episodes:,} episodes"
    )
    args.total_episodes = len(combos) * len(scenarios) * n_conditions * args.episodes
    check_run_count(args.total_episodes, args.max_runs, args.count_text)
    site = resolve_site(args.site)
    for combo in combos:
        specs, _ = configure(scenarios, None, [*args.set, *(f"{k}={v}" for k, v in combo.items())])
        check_roadside_units(specs, site)
    load_agent_class(args.algorithm)
    return combos


def validate_protocol_sweep(args) -> list[dict[str, str]]:
    """--protocol: the protocol loaded and every combination's derived protocol checked (written to a
    scratch folder, loaded and its values validated) before anything is written to --out."""
    given = [name for name in PROTOCOL_FIXED if getattr(args, name) not in (None, [])]
    if given:
        flags = ", ".join(f"--{name}" for name in given)
        raise UsageError(f"--protocol fixes {flags}: leave it out (only --episodes may ask for fewer)")
    if not args.vary:
        raise UsageError("give --vary KEY=V1,V2,... or --preset NAME")
    protocol = load_protocol(args.protocol)
    args.episodes = protocol.header["episodes"] if args.episodes is None else args.episodes
    if not 1 <= args.episodes <= MAX_EPISODES:
        raise UsageError(f"--episodes must lie in 1..{MAX_EPISODES:,}, got {args.episodes}")
    if not 1 <= args.workers <= MAX_WORKERS:
        raise UsageError(f"--workers must lie in 1..{MAX_WORKERS}, got {args.workers}")
    check_max_runs(args.max_runs)
    combos = combinations([parse_vary(text) for text in args.vary])
    with tempfile.TemporaryDirectory() as scratch:
        for combo in combos:
            derived = load_protocol(write_derived_protocol(protocol, combo, Path(scratch) / "p.toml"))
            derived.params()
            derived.specs()
            (Path(scratch) / "p.toml").unlink()
    n_conditions = 2 if protocol.header["conditions"] == "both" else 1
    args.base_rows, args.base_labels = None, set()
    own = [combo for combo in combos if is_protocol_itself(protocol, combo)]
    if args.base_run is not None and own:
        args.base_rows = base_run_rows(protocol, args.base_run, args.episodes)
        args.base_labels = {label(combo) for combo in own}
    to_run = len(combos) - (len(own) if args.base_rows is not None else 0)
    args.count_text = (
        f"{to_run} combination(s) x {len(protocol.scenarios)} scenario(s) x {n_conditions} "
        f"condition(s) x {args.episodes:,} episodes of protocol {protocol.header['name']}"
        + (f" ({len(own)} more from --base-run)" if args.base_rows is not None else "")
    )
    args.total_episodes = to_run * len(protocol.scenarios) * n_conditions * args.episodes
    check_run_count(args.total_episodes, args.max_runs, args.count_text)
    args.loaded_protocol = protocol
    return combos


def batch_argv(args, combo: dict[str, str], run_dir: Path) -> list[str]:
    if args.protocol is not None:
        derived = write_derived_protocol(
            args.loaded_protocol, combo, args.out / "protocols" / f"{label(combo)}.toml"
        )
        return [
            "--protocol", str(derived), "--episodes", str(args.episodes), "--workers", str(args.workers),
            "--out", str(run_dir), "--max-runs", str(args.max_runs),
        ]  # fmt: skip
    argv = [
        "--scenario", args.scenario, "--condition", args.condition, "--episodes", str(args.episodes),
        "--seed", str(args.seed), "--workers", str(args.workers), "--out", str(run_dir),
        "--algorithm", args.algorithm, "--site", args.site, "--max-runs", str(args.max_runs),
    ]  # fmt: skip
    for pair in [*args.set, *(f"{k}={v}" for k, v in combo.items())]:
        argv += ["--set", pair]
    return argv


def collect(out: Path, combos: list[dict[str, str]]) -> pd.DataFrame:
    frames = []
    for combo in combos:
        table = table_one(pd.read_parquet(out / label(combo) / "episodes.parquet", partitioning=None))
        for key, value in reversed(combo.items()):
            table.insert(0, key, value)
        frames.append(table)
    return pd.concat(frames, ignore_index=True)


def plot(table: pd.DataFrame, keys: list[str], path: Path) -> None:
    """Collision and conflict rate (rows) per scenario (columns) against the first --vary key; colour
    = condition, line style = the values of the other --vary keys."""
    import matplotlib  # here, not at the top: Agg is a process-wide choice, made only when a figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after matplotlib.use

    first, others = keys[0], keys[1:]
    scenarios = list(dict.fromkeys(table["scenario"]))
    colours = {"sv": "tab:red", "v2i": "tab:blue"}
    styles = ["-", "--", ":", "-."]
    other_values = list(dict.fromkeys(tuple(row) for row in table[others].itertuples(index=False)))
    fig, axes = plt.subplots(
        2, len(scenarios), figsize=(4.2 * len(scenarios), 6.4), squeeze=False, constrained_layout=True
    )
    for col, scenario in enumerate(scenarios):
        for row_index, (metric, title) in enumerate(
            [("collision", "collision rate"), ("conflict", "conflict rate")]
        ):
            ax = axes[row_index][col]
            rows_of_scenario = table[table["scenario"] == scenario]
            for (condition, *values), rows in rows_of_scenario.groupby(["condition", *others], sort=False):
                x = pd.to_numeric(rows[first], errors="coerce")
                x = x if x.notna().all() else rows[first]
                y = rows[f"{metric}_rate"]
                # Clipped at 0: at a rate of 0 or 1 the Wilson bound equals it up to rounding.
                err = [(y - rows[f"{metric}_low"]).clip(lower=0), (rows[f"{metric}_high"] - y).clip(lower=0)]
                style = styles[other_values.index(tuple(values)) % len(styles)]
                name = " ".join([condition.upper(), *(f"{k}={v}" for k, v in zip(others, values))])
                ax.errorbar(x, y, yerr=err, marker="o", capsize=3, linestyle=style,
                            color=colours.get(condition), label=name)  # fmt: skip
            ax.set_title(f"{scenario}: {title}", fontsize=9)
            ax.set_xlabel(first, fontsize=8)
            ax.grid(alpha=0.3)
            if col == 0:
                ax.set_ylabel(f"{title} (95% Wilson)", fontsize=8)
    axes[0][0].legend(fontsize=7)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def combine(dirs: list[Path], out: Path) -> int:
    try:
        check_output_dir(out, "--out", UsageError)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    """--combine: the findings of one-key sweeps side by side (OUT/findings_across_sweeps.csv, .png)."""
    missing = [str(d) for d in dirs if not (d / "findings.csv").is_file()]
    if missing:
        print(f"error: no findings.csv in {missing[0]} (run the sweep first)", file=sys.stderr)
        return 2
    try:
        table = findings_across_sweeps(dirs)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / "findings_across_sweeps.csv", index=False)
    findings_across_sweeps_figure(table, out / "findings_across_sweeps.png",
                                  title="the paper's qualitative findings across each sweep")  # fmt: skip
    print(table.to_string(index=False))
    print(f"written: {out / 'findings_across_sweeps.csv'}, findings_across_sweeps.png")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.combine:
        return combine(args.combine, args.out)
    try:
        combos = validate(args)
        check_output_dir(args.out, "--out", UsageError)
        probe_output_dir(args.out, "--out", UsageError)
    except (UsageError, ParameterError, ScenarioError, AlgorithmLoadError, UnknownSiteError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    total = f"at most {args.total_episodes:,} episodes (--max-runs {args.max_runs:,})"
    print(f"sweep: {args.count_text} = {total}")
    args.out.mkdir(parents=True, exist_ok=True)
    for number, combo in enumerate(combos, 1):
        run_dir = args.out / label(combo)
        if (run_dir / "episodes.parquet").exists():
            print(f"[{number}/{len(combos)}] {label(combo)}: done before, kept")
            continue
        if label(combo) in getattr(args, "base_labels", ()) and not (run_dir / "run.json").exists():
            write_base_rows(args.base_rows, args.base_run, run_dir)
            print(
                f"[{number}/{len(combos)}] {label(combo)}: the protocol's own values, the first "
                f"{args.episodes:,} pairs of {args.base_run} (the same seed: the same rows)"
            )
            continue
        try:
            argv = batch_argv(args, combo, run_dir)
        except UsageError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        if (run_dir / "run.json").exists():  # stopped part-way: the batch continues it
            argv.append("--resume")
        print(f"[{number}/{len(combos)}] {label(combo)}" + (" (resuming)" if "--resume" in argv else ""))
        code = batch_main(argv)
        if code != 0:
            print(f"error: the batch for {label(combo)} failed (exit {code})", file=sys.stderr)
            return code
    table = collect(args.out, combos)
    table.to_csv(args.out / "sweep.csv", index=False)
    keys = list(combos[0])
    (args.out / "sweep.md").write_text(_markdown(table, keys) + "\n", encoding="utf-8")
    plot(table, keys, args.out / "sweep.png")
    findings = write_findings(args.out, combos)
    print(_markdown(table, keys))
    print(findings.to_string(index=False))
    print(f"written: {args.out / 'sweep.csv'}, sweep.md, sweep.png, findings.csv, findings.png")
    return 0


def write_findings(out: Path, combos: list[dict[str, str]]) -> pd.DataFrame:
    """OUT/findings.csv and findings.png: the paper's qualitative findings in every combination
    (pedsafe_sumo/report/findings.py)."""
    table = findings_table({label(combo): out / label(combo) for combo in combos})
    table.to_csv(out / "findings.csv", index=False)
    findings_figure(table, out / "findings.png", title="the paper's qualitative findings, per combination")
    return table


def _markdown(table: pd.DataFrame, keys: list[str]) -> str:
    def rate(row, metric):
        return f"{row[f'{metric}_rate']:.4f} [{row[f'{metric}_low']:.4f}, {row[f'{metric}_high']:.4f}]"

    header = [*keys, "scenario", "condition", "n", "errors", "collision rate", "injury", "conflict rate"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for _, row in table.iterrows():
        cells = [str(row[k]) for k in keys] + [
            row["scenario"], row["condition"], str(int(row["n"])), str(int(row["n_error"])),
            rate(row, "collision"), f"{row['injury_mean']:.4f}", rate(row, "conflict"),
        ]  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
