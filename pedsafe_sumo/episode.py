"""Run one episode and tell a human what happened.

    python -m pedsafe_sumo.episode --scenario jaywalking --condition sv --seed 3
    python -m pedsafe_sumo.episode --scenario crossing --condition both --seed 7 --log /tmp/steps.csv
    python -m pedsafe_sumo.episode --scenario crossing --set conflict_offset_max_s=0 \
        --set perception.v2i.latency_s=0.3

`--set key=value` sets a scenario field (see pedsafe_sumo/scenarios/specs.py) or, with a dotted
key, a value of the parameter file (pedsafe_sumo/params/defaults.toml). Bad input ends in one line
on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pedsafe_sumo.cli import OneLineParser, check_seed
from pedsafe_sumo.compiled_kernels import prepare_compiled_kernels
from pedsafe_sumo.control.agent import AlgorithmLoadError, load_agent_class, stack_spec
from pedsafe_sumo.control.stack_calls import StackError
from pedsafe_sumo.control.timeout import DEFAULT_AGENT_TIMEOUT_S, AgentTimeoutError, check_timeout_s
from pedsafe_sumo.io.cases import write_case
from pedsafe_sumo.io.outputs import check_output_dir, check_output_file
from pedsafe_sumo.network.approaches import leg_argument
from pedsafe_sumo.network.sites import SITE_HELP, Site, UnknownSiteError, resolve_site
from pedsafe_sumo.network.sumo_inputs import check_gui_site
from pedsafe_sumo.params import ParameterError
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.hosting import check_hosting, site_hosting
from pedsafe_sumo.scenarios.signals import NO_LINK, colour_of_link
from pedsafe_sumo.scenarios.specs import SCENARIOS, ScenarioSpec
from pedsafe_sumo.settings import UsageError, check_roadside_units, configure
from pedsafe_sumo.sim.connection import SimulatorError
from pedsafe_sumo.sim.episode import CONDITIONS, DEFAULT_ALGORITHM, EpisodeRunner
from pedsafe_sumo.sim.outcome import EpisodeResult, conflict_step

SENSOR_NAMES = {
    "onboard_camera": "onboard camera",
    "onboard_lidar": "onboard LiDAR",
    "roadside": "roadside camera",
}


def describe(result: EpisodeResult, algorithm: str) -> list[str]:
    setup, outcome, log = result.setup, result.outcome, result.log
    ped = setup.pedestrian
    gender = {"f": "woman", "m": "man"}.get(ped.gender, "person")
    lines = [
        f"{setup.scenario}, condition {result.condition}, seed {setup.seed}",
        f"  pedestrian: {ped.age_years:.0f}-year-old {gender}, {ped.risk}, "
        f"walking {ped.walking_speed_mps:.2f} m/s, steps off at t={ped.start_delay_s:.2f} s",
        f"  ego: {setup.ego.speed_mps:.2f} m/s ({setup.ego.speed_mps * 3.6:.0f} km/h) initial speed, "
        f"driven by {algorithm}",
    ]
    if math.isnan(outcome["first_detection_distance_m"]):
        lines.append("  first perceived: never")
    else:
        sensors = " + ".join(SENSOR_NAMES.get(s, s) for s in outcome["detected_by"].split("+") if s)
        lines.append(
            f"  first perceived: t={outcome['first_detection_time_s']:.2f} s "
            f"at {outcome['first_detection_distance_m']:.1f} m ({sensors})"
        )
    raw = log[log["roadside_raw"]]
    if len(raw):
        first = raw.iloc[0]
        distance = math.hypot(first.ped_x_m - first.ego_x_m, first.ped_y_m - first.ego_y_m)
        note = "" if result.condition == "v2i" else ", not available under SV"
        lines.append(f"  roadside camera first saw them: t={first.time_s:.2f} s at {distance:.1f} m{note}")
    gap = log["clearance_m"]
    closest = log.loc[gap.idxmin()]
    lines.append(
        f"  closest approach: {max(gap.min(), 0.0):.2f} m between car body and pedestrian "
        f"at t={closest.time_s:.2f} s"
    )
    lines += describe_signals(result)
    if outcome["collision"]:
        impact_mps = outcome["impact_speed_mps"]
        lines.append(
            f"  COLLISION at {impact_mps:.2f} m/s ({impact_mps * 3.6:.1f} km/h); "
            f"injury probability {outcome['injury_probability']:.3f}"
        )
        sumo = outcome["sumo_collision"]
        seen = {True: "also recorded", False: "not recorded"}.get(
            sumo, "cannot tell (SUMO checks persons against vehicles only on crossings and walking areas)"
        )
        lines.append(f"  SUMO's own collision check: {seen}")
    else:
        conflict = "yes" if outcome["conflict"] else "no"
        probability = outcome["conflict_probability"]
        detail = f" (risk p = {probability:.2f})" if not math.isnan(probability) else ""
        lines.append(
            f"  no collision; conflict: {conflict}{detail}; minimum TTC {outcome['min_ttc_s']:.2f} s"
        )
        if outcome.get("contact_stationary"):
            lines.append("  contact with the standing car (below 0.1 m/s): no collision, no injury")
    pet_s = outcome["pet_s"]
    lines.append(f"  post-encroachment time: {pet_s:.2f} s" if not math.isnan(pet_s) else "  PET: undefined")
    lines.append(
        f"  ended: {result.end_reason.replace('_', ' ')} at t={log['time_s'].iloc[-1]:.2f} s "
        f"after {len(log)} steps"
    )
    return lines


def describe_signals(result: EpisodeResult) -> list[str]:
    """Each road user's signal at the staged conflict, as SUMO showed it."""
    staging = result.setup.signals
    if staging is None or not result.signal_states:
        return ["  signals: none (the junction has no traffic light, or the episode was not staged in it)"]
    step = conflict_step(result.log, result.setup)
    state = result.signal_states[step]
    users = [("ego", staging.ego_link_index), ("pedestrian", staging.ped_link_index)]
    if result.setup.parked:
        oncoming = any(v.vehicle_id.startswith("oncoming_") for v in result.setup.parked)
        name = "oncoming vehicle (through)" if oncoming else "occluder (kerb-lane right turn)"
        users.append((name, staging.occluder_link_index))
    parts = [
        f"{name} {colour_of_link(state, link)}" + (f" (link {link})" if link != NO_LINK else "")
        for name, link in users
    ]
    return [
        f"  signals at the conflict (t={result.log['time_s'].iloc[step]:.2f} s): {', '.join(parts)}; "
        f"traffic light {staging.tls_id} program "
        f"{staging.program_id}, started {staging.cycle_start_s:.2f} s into its cycle"
    ]


#: Bad input: one line on stderr, exit code 2 (ValueError: --agent-timeout out of range).
INPUT_ERRORS = (UsageError, ParameterError, ScenarioError, AlgorithmLoadError, UnknownSiteError, ValueError)
#: The stack's fault, or SUMO's, while an episode runs: one line, exit code 1.
RUN_ERRORS = (SimulatorError, AgentTimeoutError, StackError)


def parse_args(
    argv: list[str] | None, parser_class: type[argparse.ArgumentParser] = OneLineParser
) -> argparse.Namespace:
    """The command's options; `parser_class` decides what a bad one does (OneLineParser: one line, exit 2)."""
    parser = parser_class(prog="python -m pedsafe_sumo.episode", description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", required=True, help=f"one of: {', '.join(SCENARIOS)}")
    parser.add_argument("--condition", default="both", help="sv, v2i or both (default: both, same seed)")
    parser.add_argument("--seed", type=int, default=1, help="episode seed, 0 to 2**63 - 1 (default 1)")
    parser.add_argument("--site", default="xueqing", help=SITE_HELP)
    parser.add_argument(
        "--approach",
        type=leg_argument,
        help="the leg the ego comes in on (N, E, S, W, NE, ..., B055) [the site's own approach]",
    )
    parser.add_argument("--params", type=Path, help="parameter file laid over the defaults")
    parser.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="override a scenario or parameter value"
    )
    parser.add_argument("--algorithm", default=DEFAULT_ALGORITHM, help="AD stack as package.module:Class")
    parser.add_argument("--perception", help="replace the stack's detector by package.module:Class")
    parser.add_argument("--log", type=Path, help="write the per-step log as CSV (one file per condition)")
    parser.add_argument(
        "--case-dir", type=Path, help="write each episode as a case (Parquet log + JSON world)"
    )
    parser.add_argument("--gui", action="store_true", help="run in sumo-gui instead of headless libsumo")
    parser.add_argument(
        "--agent-timeout",
        type=float,
        default=DEFAULT_AGENT_TIMEOUT_S,
        metavar="SECONDS",
        help="time limit of each run_step call of the AD stack, above 0 and at most 3600 "
        f"(default {DEFAULT_AGENT_TIMEOUT_S:g})",
    )
    return parser.parse_args(argv)


@dataclass(frozen=True)
class EpisodePlan:
    """A checked command: the site, parameters and scenario, the conditions, and the stack to load."""

    site: Site
    params: dict[str, Any]
    spec: ScenarioSpec
    conditions: list[str]
    agent_class: type
    #: The stack as package.module:Class (with its --perception detector, if any).
    algorithm: str
    agent_timeout_s: float


def plan_episode(args: argparse.Namespace) -> EpisodePlan:
    """Check every option and input file; raises one of INPUT_ERRORS (one line) and runs nothing."""
    conditions = list(CONDITIONS) if args.condition == "both" else [args.condition]
    if any(c not in CONDITIONS for c in conditions):
        raise UsageError(f"unknown condition '{args.condition}' (known: sv, v2i, both)")
    site = resolve_site(args.site)
    if args.gui:  # sumo-gui loads the site's additionals and view settings (docs/trust.md)
        check_gui_site(site, site.file("view.xml"))
    # --approach is the scenario field `approach` (as in batch).
    set_pairs = [*(args.set or []), *([f"approach={args.approach}"] if args.approach else [])]
    specs, params = configure([args.scenario], args.params, set_pairs)
    check_roadside_units(specs, site)
    check_hosting(site, specs, params, conditions)  # the site's poles see the scenario's staging area
    spec = specs[args.scenario]
    if args.approach:  # can it be staged there at all (also without V2I)?
        problem = site_hosting(site, specs, params)[args.scenario] or ""
        if problem.startswith("cannot be staged"):
            raise UsageError(f"site {site.name} cannot host scenario '{args.scenario}': {problem}")
    algorithm = stack_spec(args.algorithm, args.perception)
    agent_class = load_agent_class(algorithm)
    check_seed(args.seed)
    agent_timeout_s = check_timeout_s(args.agent_timeout)
    if args.log is not None:
        check_output_file(args.log, "--log", UsageError)
    if args.case_dir is not None:
        check_output_dir(args.case_dir, "--case-dir", UsageError)
    return EpisodePlan(site, params, spec, conditions, agent_class, algorithm, agent_timeout_s)


def run_episode(
    plan: EpisodePlan, args: argparse.Namespace, say: Callable[[str], None] = print
) -> list[EpisodeResult]:
    """Run the episode under each condition of the plan (same seed), tell `say` what happened, write
    --log and --case-dir; raises one of RUN_ERRORS when the stack or SUMO fails."""
    prepare_compiled_kernels()
    runner = EpisodeRunner(
        plan.site, plan.params, plan.agent_class, gui=args.gui, agent_timeout_s=plan.agent_timeout_s
    )
    results = []
    try:
        for condition in plan.conditions:
            result = runner.run(plan.spec, condition, args.seed)
            results.append(result)
            say("\n".join(describe(result, plan.algorithm)))
            if args.log:
                path = (
                    args.log
                    if len(plan.conditions) == 1
                    else args.log.with_name(f"{args.log.stem}_{condition}{args.log.suffix or '.csv'}")
                )
                result.log.to_csv(path, index=False)
                say(f"  per-step log: {path}")
            if args.case_dir:
                say(f"  case: {write_case(args.case_dir, result)}")
    finally:
        runner.close()
    return results


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        plan = plan_episode(args)
    except INPUT_ERRORS as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        run_episode(plan, args)
    except RUN_ERRORS as exc:  # the stack's fault, in one line
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
