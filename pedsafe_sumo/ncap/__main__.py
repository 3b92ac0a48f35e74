"""python -m pedsafe_sumo.ncap --out DIR [--tests CPNA-25,CPFA,...] [--speeds 10,20,...] [--site S]
[--algorithm pkg.module:Class] [--condition sv|v2i|both] [--lighting day|night|both] [--seed S] [--robustness]

Runs the Euro NCAP pedestrian AEB grid (protocol.toml) on the site's real approach, every cell under SV
and V2I, and writes:
  DIR/ncap.csv          one row per cell and condition (test, ego_speed_kmh, impact_point_pct, condition,
                        avoided, impact_speed_kmh, colour, cell_score, and what explains them);
  DIR/ncap_scores.csv   points per test and condition, and overall, as the official calculator computes;
  DIR/figures/ncap_grid.png   each test's grid coloured as Euro NCAP result sheets, SV and V2I side by side;
  DIR/cases/, DIR/episodes.parquet, DIR/run.json   every cell's per-step log, laid out as a run directory,
                        so `python -m pedsafe_sumo.replay DIR --scenario CELL_ID --episode 0 --condition sv
                        [--export-fcd F]` replays any cell (CELL_ID as in ncap.csv's cell_id).
Before it starts it says in one line how many runs it makes (cells x conditions); the grid is the
protocol's, at most 726 cells (152 by day without --robustness, 254 day and night) under two conditions.
Bad input ends in one line on stderr and exit status 2; a DIR that is not new or empty is refused, and
nothing in it is touched.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
import sumolib
from tqdm import tqdm

from pedsafe_sumo import __version__
from pedsafe_sumo.cli import OneLineParser, check_seed
from pedsafe_sumo.compiled_kernels import prepare_compiled_kernels
from pedsafe_sumo.control.agent import AlgorithmLoadError, load_agent_class
from pedsafe_sumo.io.cases import write_case
from pedsafe_sumo.io.episodes import to_table
from pedsafe_sumo.io.outputs import check_output_dir, probe_output_dir
from pedsafe_sumo.ncap.coverage import grid_summary
from pedsafe_sumo.ncap.figure import grid_figure
from pedsafe_sumo.ncap.night import night_params
from pedsafe_sumo.ncap.protocol import LIGHTINGS, NcapError, load_protocol, parse_speeds, select_cells
from pedsafe_sumo.ncap.staging import spec_for, stage_cell
from pedsafe_sumo.ncap.suite import NcapRunner, run_cells, score_tests
from pedsafe_sumo.network.sites import Site, UnknownSiteError, get_site
from pedsafe_sumo.network.traffic_side import NCAP_LEFTHAND_REFUSAL, network_is_lefthand
from pedsafe_sumo.params import ParameterError, load_params
from pedsafe_sumo.sim.connection import SimulatorError
from pedsafe_sumo.sim.episode import CONDITIONS, DEFAULT_ALGORITHM

DEFAULT_SITE = "xueqing"
RESULT_FILES = ("ncap.csv", "ncap_scores.csv", "run.json", "episodes.parquet")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = OneLineParser(prog="python -m pedsafe_sumo.ncap", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out",
        required=True,
        type=Path,
        help="new or empty directory for the results (one that is not is refused)",
    )
    parser.add_argument("--tests", help="tests or columns, e.g. CPNA,CPFA-50 [all: CPNA,CPFA,CPNCO,CPLA]")
    parser.add_argument(
        "--speeds", help="ego test speeds in km/h, e.g. 10,20, each one of the test's grid [each test's grid]"
    )
    parser.add_argument("--site", default=DEFAULT_SITE, help=f"site name or folder [{DEFAULT_SITE}]")
    parser.add_argument("--algorithm", default=DEFAULT_ALGORITHM, help="AD stack as package.module:Class")
    parser.add_argument("--condition", default="both", help="sv, v2i or both [both]")
    parser.add_argument("--seed", default="0", help="seed of the perception noise, 0 to 2**63 - 1 [0]")
    parser.add_argument("--params", type=Path, help="parameter file laid over the defaults")
    parser.add_argument(
        "--lighting",
        default="day",
        help="day, night (the night load cases: the onboard camera's night model) or both [day]",
    )
    parser.add_argument(
        "--robustness", action="store_true", help="add the robustness variations of the dummy per cell"
    )
    return parser.parse_args(argv)


def resolve_site(name_or_path: str) -> Site:
    """The one place the suite looks a site up (a folder once sites are folders)."""
    return get_site(name_or_path)


def error(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        protocol = load_protocol()
        lightings = LIGHTINGS if args.lighting == "both" else (args.lighting,)
        cells = select_cells(protocol, args.tests, parse_speeds(args.speeds), args.robustness, lightings)
        if not cells:
            raise NcapError(f"--tests {args.tests} has no {args.lighting} load case")
        if args.condition not in (*CONDITIONS, "both"):
            raise NcapError(f"--condition must be sv, v2i or both, got '{args.condition}'")
        conditions = CONDITIONS if args.condition == "both" else (args.condition,)
        try:
            seed = int(args.seed)
        except ValueError:
            raise NcapError(f"--seed must be a whole number, got '{args.seed}'") from None
        check_seed(seed, error=NcapError)
        site = resolve_site(args.site)
        if network_is_lefthand(site.file("net.xml")):
            raise NcapError(NCAP_LEFTHAND_REFUSAL.format(site=site.name))
        params = load_params(args.params)
        agent_class = load_agent_class(args.algorithm)
        out = args.out
        if out.exists() and not out.is_dir():
            raise NcapError(f"--out {out} exists and is not a directory")
        check_output_dir(out, "--out", NcapError)
        taken = [name for name in RESULT_FILES if (out / name).exists()]
        if taken:
            raise NcapError(f"--out {out} already holds results ({', '.join(taken)}): choose a new directory")
        if out.is_dir() and any(out.iterdir()):
            raise NcapError(
                f"--out {out} is a directory that is not empty and holds no Euro NCAP results: choose a new "
                "or empty directory (nothing in it is touched)"
            )
        probe_output_dir(out, "--out", NcapError)
    except (NcapError, UnknownSiteError, ParameterError, AlgorithmLoadError, OSError) as exc:
        return error(str(exc).strip("'\""))
    # The grid is the protocol's (select_cells refuses a cell it does not hold).
    print(
        f"ncap: {len(cells)} cell(s) x {len(conditions)} condition(s) = {len(cells) * len(conditions)} runs "
        f"on site {site.name} with {args.algorithm} -> {out}"
    )
    return run(args, argv, protocol, cells, conditions, seed, site, params, agent_class)


def run(args, argv, protocol, cells, conditions, seed, site, params, agent_class) -> int:
    out: Path = args.out
    try:
        runner = NcapRunner(site, params, agent_class)
    except (OSError, ValueError) as exc:
        return error(f"site {site.name}: {exc}")
    try:
        # Stage every cell first: a cell the site cannot hold is bad input, found before anything runs.
        poles = tuple(runner.roadside_units)
        net_file = site.file("net.xml")
        staged = {
            c.cell_id: stage_cell(protocol, runner.approach, net_file, c, seed, runner.step_length_s)
            for c in cells
        }
    except NcapError as exc:
        runner.close()
        return error(f"site {site.name}: {exc}")
    prepare_compiled_kernels()
    out.mkdir(parents=True, exist_ok=True)
    episodes: list[dict[str, Any]] = []
    started = time.perf_counter()
    with tqdm(total=len(cells) * len(conditions), unit="run", mininterval=1.0, file=sys.stderr) as bar:

        def on_result(cell, condition, result, row) -> None:
            if result is None:  # the AD stack raised: recorded as an error, like the batch does
                episodes.append(
                    {
                        "scenario": cell.cell_id,
                        "condition": condition,
                        "episode": 0,
                        "seed": seed,
                        "collision": False,
                        "conflict": False,
                        "close_pass": False,
                        "contact_stationary": False,
                        "sumo_collision": None,  # unknown: the run did not finish
                        "status": "error",
                        "error": row["error"],
                    }
                )
            else:
                write_case(out / "cases", result)
                episodes.append({**result.outcome, "episode": 0})
            bar.update(1)

        try:
            tables = []
            for lighting in LIGHTINGS:
                these = [c for c in cells if c.lighting == lighting]
                if not these:
                    continue
                if lighting == "night":  # the same engine with the onboard camera's night model
                    runner.close()
                    runner = NcapRunner(site, night_params(params, protocol), agent_class)
                tables.append(run_cells(runner, protocol, these, conditions, seed, on_result))
            table = pd.concat(tables, ignore_index=True)
        except SimulatorError as exc:
            return error(f"SUMO failed: {exc}")
        finally:
            runner.close()
    wall_s = time.perf_counter() - started
    scores = score_tests(protocol, table)
    run_info = {
        "kind": "ncap",
        "command": "python -m pedsafe_sumo.ncap " + " ".join(argv if argv is not None else sys.argv[1:]),
        "site": site.name,
        "algorithm": args.algorithm,
        "seed": seed,
        "conditions": list(conditions),
        "protocol": protocol.raw,
        # What replay runs every cell with: the night camera's when only night cells were run (a night
        # cell of a day-and-night run replays with the day camera; night_parameters records its own).
        "parameters": night_params(params, protocol) if set(table["lighting"]) == {"night"} else params,
        "night_parameters": night_params(params, protocol) if "night" in set(table["lighting"]) else None,
        "scenarios": {
            cid: dataclasses.asdict(spec_for(s.cell, poles, s.setup.time_limit_s))
            for cid, s in staged.items()
        },
        "versions": _versions(),
        "wall_time_s": round(wall_s, 3),
    }
    _write(out / "episodes.parquet", lambda p: to_table(episodes).to_parquet(p, index=False))
    _write(out / "ncap.csv", lambda p: table.to_csv(p, index=False))
    _write(out / "ncap_scores.csv", lambda p: scores.to_csv(p, index=False))
    _write(out / "run.json", lambda p: p.write_text(json.dumps(run_info, indent=1, default=str) + "\n"))
    figure = grid_figure(table, out / "figures" / "ncap_grid.png")
    n_error = int((table["status"] == "error").sum())
    print(
        f"{len(table)} runs in {wall_s:.1f} s ({n_error} error(s): see ncap.csv's error column); "
        f"cases in {out / 'cases'}; figure {figure}"
    )
    with pd.option_context("display.width", 120):
        print(scores.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    print(grid_summary(protocol, table))
    return 0


def _write(path: Path, writer) -> None:
    """Write through a temporary name, so a crash never leaves half a file."""
    tmp = path.with_name(path.name + ".tmp")
    writer(tmp)
    os.replace(tmp, path)


def _versions() -> dict[str, str]:
    return {"pedsafe_sumo": __version__, "sumo": sumolib.version.gitDescribe()}


if __name__ == "__main__":
    sys.exit(main())
