"""How random is the SV collision once the proposable inputs are fixed?

Importance sampling over the episode's proposable inputs x (ego speed, walking speed, offsets, gaps, age
group, risk type, occluder classes: the `nominal` families a row's sampler_inputs records) cannot remove
the randomness the episode keeps given x. With pi(x) = P(collision | x), no proposal over x does better
than q ∝ p sqrt(pi) (Owen 2013, section 9.1), whose efficiency per episode against plain Monte Carlo is

    P (1 - P) / (E_p[sqrt(pi)]^2 - P^2)          (research/experiments/is_efficiency_bound.py's form),

a ceiling no fit of pi can beat. Here pi(x) is measured directly: episodes of a plain MC run (rows of its
episodes.parquet, SV) are re-run with their x and fresh within-episode randomness, `--repeats` times each.

Where the randomness given x comes from (sim/episode.py; the episode seed s is split by SeedSequence):
- world: stream 0 of s draws, besides x, the inputs no proposal moves (the pedestrian's sex and age within
  the group, clothing and vehicle colours, queued vehicles' classes and gaps, the point of the signal
  cycle `signal_cycle_u`);
- traffic: stream 2 of s, the background vehicles' departures, lanes, routes and desired speeds;
- perception: stream 1 of run's seed, the onboard camera's and LiDAR's per-frame misses, drawn only when
  a sensor's miss_probability is > 0 (0 in defaults.toml: under SV the sensors draw nothing); stream 3,
  the V2I link's loss and noise, draws only under V2I; SUMO's own --seed reaches no row (see
  sim/connection.py); the pedestrian model and the reference stack draw nothing.

Modes, each a set of sources kept at the episode's own draws while the others are fresh (the run's
seed is fresh in every mode but `keep_link` and `reproduce`):
- `fresh`: every source fresh, x alone kept: pi(x);
- `keep_world` (the whole world stream), `keep_traffic`, and the world's groups `keep_ped_traits` (sex,
  age within the group), `keep_clothing`, `keep_signal` (signal_cycle_u), `keep_vehicles` (the other
  world inputs: vehicle colours, queued vehicles, gaps not proposed), `keep_colours` (the vehicles'
  colours alone), `keep_approach` (approach staging's start distance and walk-in), `keep_link` (the run
  seed: the V2I link's losses and noise): that source kept too
  (switched off as a source of variance): pi(x, source), whose ceiling is what a proposal over x AND that
  source could reach at best (the kept draws are the episode's, drawn from p within its stratum, as x is);
- keep_ modes joined by "+" (`keep_clothing+colours`): those sources kept at once;
- `reproduce` (once per episode): every source kept; must give the recorded outcome (a check).

Sampling of the episodes: `--collisions` collision episodes and `--others` other episodes of the run (ok
rows of `--condition`, sv by default; of an IS run, its final stage, each weighted by p/q), each set
drawn at random (Generator of `--seed`). The collision stratum alone gives the figures: x given Y = 1 has
the law pi(x) p(x) / P, so E_p[sqrt(pi)] = P E[pi^(-1/2) | Y = 1] and E_p[pi^2] = P E[pi | Y = 1] (a
sample of nominal episodes would need thousands to see the rare x where pi is small but not 0, which
weigh most in E_p[sqrt(pi)]). The other stratum is a check (`summarise`).

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_within_episode.py \\
        V5_FULL --scenario jaywalking --collisions 20 --others 20 --repeats 12 \\
        --set traffic.background_speed_limit_scaled=false --set pedestrians.detour_wait_s=600 --out DIR

A run made with `--protocol` takes `--protocol FILE` (its values in place of `--set`):

    OMP_NUM_THREADS=1 .venv/bin/python research/experiments/is_within_episode.py RUN --protocol \\
        protocols/paper-v10-xueqing.toml --scenario jaywalking --modes fresh --collisions 20 --others 10 \\
        --out DIR

Writes DIR/<scenario>[_v2i]_outcomes.csv (one row per episode, mode and repeat) and prints the summary; with
`--summarise DIR` only reads the CSVs back.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.batch.runner import sampler_proposal
from pedsafe_sumo.sampling.importance import Family
from pedsafe_sumo.sampling.stages import DEFENSIVE_SHARE

#: World inputs no proposal moves, by group (the names sampler_inputs records; `vehicles` takes the rest).
WORLD_GROUPS = {
    "ped_traits": ("ped_female", "ped_age_in_group"),
    "clothing": ("clothing",),
    "signal": ("signal_cycle_u",),
    # Approach staging's own draws: where the ego starts, how long the pedestrian walks in.
    "approach": ("ego_start_distance_m", "walk_in_s"),
}
MODES = (
    "fresh",
    "keep_world",
    "keep_traffic",
    "keep_ped_traits",
    "keep_clothing",
    "keep_signal",
    "keep_vehicles",
    "keep_colours",
    "keep_approach",
    "keep_link",
)
#: What each mode keeps at the MC episode's draws besides x: world groups ("all": the whole world
#: stream), and whether the background traffic.
KEPT: dict[str, tuple[tuple[str, ...], bool]] = {
    "fresh": ((), False),
    "keep_world": (("all",), False),
    "keep_traffic": ((), True),
    "keep_ped_traits": (("ped_traits",), False),
    "keep_clothing": (("clothing",), False),
    "keep_signal": (("signal",), False),
    "keep_vehicles": (("vehicles", "colours"), False),
    "keep_colours": (("colours",), False),
    "keep_approach": (("approach",), False),
    "keep_link": ((), False),
    "reproduce": (("all",), True),
}
#: Modes that keep the episode's own run seed, which draws the sensors' per-frame misses (none at
#: miss_probability 0) and, under V2I, the link's losses and noise: `keep_link` keeps it alone.
KEEPS_RUN_SEED = {"keep_link", "reproduce"}
CONDITIONS = ("sv", "v2i")


def kept_by(mode: str) -> tuple[tuple[str, ...], bool, bool]:
    """(world groups kept, whether the background traffic, whether the run seed) of `mode`: one of MODES,
    or keep_ modes joined by "+" (`keep_ped_traits+vehicles`: both sources kept at once)."""
    parts = mode.removeprefix("keep_").split("+") if "+" in mode else [mode.removeprefix("keep_")]
    names = [mode] if "+" not in mode else [f"keep_{part}" for part in parts]
    if any(name not in KEPT or name == "reproduce" for name in names):
        raise ValueError(f"unknown mode {mode!r}: one of {', '.join(MODES)}, or keep_ modes joined by '+'")
    groups = tuple(sorted({group for name in names for group in KEPT[name][0]}))
    return groups, any(KEPT[name][1] for name in names), any(name in KEEPS_RUN_SEED for name in names)


def mode_argument(text: str) -> str:
    try:
        kept_by(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc
    return text


def group_of(name: str) -> str:
    """The world group of input `name`: WORLD_GROUPS', "colours" for the other vehicles' colours (what the
    cameras' contrast rule compares the clothing with), else "vehicles" (classes, gaps, positions)."""
    for group, names in WORLD_GROUPS.items():
        if name in names:
            return group
    return "colours" if name.endswith(".colour") else "vehicles"


@dataclasses.dataclass(frozen=True)
class FixedInputs:
    """A stand-in for a joint proposal (sampling/joint.py) that always serves the same x, weight 1: Draws
    then draws every other input by its native call from the (fresh) world stream."""

    nominal: dict[str, Family]
    values: dict[str, float]

    is_joint = True

    @property
    def names(self) -> list[str]:
        return sorted(self.nominal)

    def sample(self, rng: np.random.Generator) -> tuple[dict[str, float], float]:
        return dict(self.values), 0.0


def fresh_seed(seed: int, episode: int, repeat: int) -> int:
    """The fresh episode seed of repeat `repeat` of `episode` (the same for every mode: common draws)."""
    sequence = np.random.SeedSequence(entropy=seed, spawn_key=(episode, repeat, 1))
    return int(sequence.generate_state(1, dtype=np.uint32)[0])


def pick_episodes(rows: pd.DataFrame, n_collisions: int, n_others: int, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    hit, other = rows[rows["collision"]], rows[~rows["collision"]]
    take = [
        hit.iloc[np.sort(rng.choice(len(hit), min(n_collisions, len(hit)), replace=False))],
        other.iloc[np.sort(rng.choice(len(other), min(n_others, len(other)), replace=False))],
    ]
    return pd.concat(take)


def setup_for(runner: Any, spec: Any, row: pd.Series, mode: str, fresh: int, proposal: str = "") -> Any:
    """The episode's initial world under `mode`: x from the row; the kept world groups and background
    traffic from its own seed, the rest from `fresh`. `proposal` is the JSON of the proposal the row's stage
    drew from (run.json's sampler_proposals; "" under MC): the row's own draw is rebuilt through it."""
    seed = int(row["seed"])
    groups, keep_traffic, _ = kept_by(mode) if mode != "reproduce" else (("all",), True, True)
    record = json.loads(row["sampler_inputs"])
    x = {name: float(record["inputs"][name]) for name in record["nominal"]}
    original, draws = runner.draw_setup_sampled(
        spec, seed, sampler_proposal(proposal), DEFENSIVE_SHARE if proposal else 0.0
    )
    for name, value in x.items():
        if draws.inputs[name] != value:
            raise RuntimeError(
                f"episode {row['episode']}: input {name} drawn {draws.inputs[name]}, recorded {value}"
            )
    if "all" in groups:
        setup = original
    else:
        kept = [
            name
            for name, family in draws.nominals.items()
            if family is not None and (name in x or group_of(name) in groups)
        ]
        fixed = FixedInputs({n: draws.nominals[n] for n in kept}, {n: draws.inputs[n] for n in kept})
        setup, fresh_draws = runner.draw_setup_sampled(spec, fresh, fixed)
        for name in kept:  # served as kept
            if fresh_draws.inputs[name] != draws.inputs[name]:
                raise RuntimeError(f"episode {row['episode']}: input {name} not kept")
    background = original.background if keep_traffic else runner.draw_setup_sampled(spec, fresh)[0].background
    return dataclasses.replace(setup, background=background)


def final_stage(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows of the run's last sampler stage: every row of an MC run, the final stage of an IS run (one
    proposal, whose weights summarise takes back to the nominal)."""
    if "sampler_stage" not in rows:
        return rows
    return rows[rows["sampler_stage"] == rows["sampler_stage"].max()]


def rows_and_runner(
    mc_run: Path, scenario: str, settings: list[str], condition: str = "sv", protocol: Path | None = None
) -> tuple[pd.DataFrame, Any, Any, str]:
    """The run's ok rows of `scenario` and `condition` in its final stage (final_stage, by episode), its
    scenario spec under `settings` (--set) or the `protocol` file's values (a run made with --protocol), an
    EpisodeRunner on the run's site and algorithm, and the JSON of the proposal that stage drew from (""
    under MC)."""
    from pedsafe_sumo.batch.runner import scenario_spec
    from pedsafe_sumo.control.agent import load_agent_class
    from pedsafe_sumo.network.sites import get_site
    from pedsafe_sumo.settings import configure, parse_set
    from pedsafe_sumo.sim.episode import EpisodeRunner

    rows = pd.read_parquet(mc_run / "episodes.parquet")
    rows = rows[(rows["scenario"] == scenario) & (rows["condition"] == condition) & (rows["status"] == "ok")]
    info = json.loads((mc_run / "run.json").read_text())
    if protocol is not None:
        from pedsafe_sumo.protocol import load_protocol

        fixed = load_protocol(protocol)
        params, spec = fixed.params(), fixed.specs()[scenario]
    else:
        _, params = configure([scenario], None, settings)
        spec = scenario_spec(scenario, parse_set(settings)[0])
    runner = EpisodeRunner(get_site(info["site"]), params, load_agent_class(info["algorithm"]))
    rows = final_stage(rows)
    proposals = info.get("sampler_proposals", {}).get(scenario, [])
    stage = int(rows["sampler_stage"].max()) if "sampler_stage" in rows and len(rows) else 0
    proposal = proposals[stage] if stage < len(proposals) else ""
    return rows.sort_values("episode"), spec, runner, proposal or ""


def run_scenario(args: argparse.Namespace, scenario: str) -> pd.DataFrame:
    rows, spec, runner, proposal = rows_and_runner(
        args.mc_run, scenario, args.set, args.condition, args.protocol
    )
    chosen = pick_episodes(rows, args.collisions, args.others, args.seed)
    out = []
    started = time.perf_counter()
    try:
        for i, (_, row) in enumerate(chosen.iterrows()):
            plan = [("reproduce", 0)] + [(mode, r) for mode in args.modes for r in range(args.repeats)]
            for mode, repeat in plan:
                fresh = fresh_seed(args.seed, int(row["episode"]), repeat)
                setup = setup_for(runner, spec, row, mode, fresh, proposal)
                # The run's seed draws SV's per-frame misses (none at miss_probability 0) and V2I's link.
                run_seed = int(row["seed"]) if mode == "reproduce" or kept_by(mode)[2] else fresh
                result = runner.run(spec, args.condition, run_seed, setup=setup)
                out.append(
                    {
                        "scenario": scenario,
                        "episode": int(row["episode"]),
                        "stratum": int(bool(row["collision"])),
                        "weight": float(row["weight"]) if "weight" in row else 1.0,
                        "mode": mode,
                        "repeat": repeat,
                        "collision": int(bool(result.outcome["collision"])),
                        "min_ttc_s": result.outcome.get("min_ttc_s"),
                    }
                )
                if mode == "reproduce" and out[-1]["collision"] != int(bool(row["collision"])):
                    print(f"warning: episode {row['episode']} did not reproduce its outcome", file=sys.stderr)
            print(
                f"{scenario}: {i + 1}/{len(chosen)} episodes, {time.perf_counter() - started:.0f} s",
                file=sys.stderr,
                flush=True,
            )
    finally:
        runner.close()
    return pd.DataFrame(out)


#: Bootstrap resamples of the collision episodes for the ceiling's interval (any fixed seed).
BOOTSTRAP = 2000
BOOTSTRAP_SEED = 7


def ceiling(rate: float, inverse_root: np.ndarray, weight: np.ndarray | None = None) -> float:
    """P (1 - P) / (E_p[sqrt(pi)]^2 - P^2) with E_p[sqrt(pi)] = P E[pi^(-1/2) | Y = 1] (module docstring):
    (1 - P) / (P (E[pi^(-1/2) | Y = 1]^2 - 1)); the mean over the collision episodes weighted by `weight`
    (p/q of episodes drawn from a proposal q; None: every episode 1, drawn from p)."""
    excess = float(np.average(inverse_root, weights=weight)) ** 2 - 1.0
    return (1 - rate) / (rate * excess) if excess > 0 else math.inf


def ceiling_with_interval(
    rate: float, inverse_root: np.ndarray, weight: np.ndarray | None = None
) -> dict[str, float]:
    """The ceiling and its bootstrap 90% interval over the collision episodes (columns of the summaries)."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    weight = np.ones(len(inverse_root)) if weight is None else np.asarray(weight, dtype=float)
    picks = [rng.choice(len(inverse_root), len(inverse_root)) for _ in range(BOOTSTRAP)]
    # Sorted, not np.quantile: resamples of pi = 1 alone give inf, which np.quantile turns into NaN.
    boot = np.sort([ceiling(rate, inverse_root[k], weight[k]) for k in picks])
    return {
        "ceiling": ceiling(rate, inverse_root, weight),
        "ceiling 5%": float(boot[int(0.05 * BOOTSTRAP)]),
        "ceiling 95%": float(boot[int(0.95 * BOOTSTRAP)]),
    }


def summarise(outcomes: pd.DataFrame, rate: float) -> pd.DataFrame:
    """Per mode, from the collision stratum (p(x | Y = 1) = pi(x) p(x) / P, so E_p[g(pi)] = P E[g(pi) / pi |
    Y = 1] for any g): the ceiling of a proposal over what the mode keeps, with pi per episode taken as
    (k + 1) / (m + 1) (its m repeats and its own recorded collision: never 0, and biased up, which biases
    the ceiling up: it stays a ceiling) and a bootstrap 90% interval over the collision episodes; the
    share of Var(Y) = P (1 - P) left given what is kept, E_p[pi (1 - pi)] / (P (1 - P)) = (1 - E[pi | Y =
    1]) / (1 - P), E[pi | Y = 1] by k / m (unbiased); and the other stratum as a check: its mean pi
    should be P (1 - E[pi | Y = 1]) / (1 - P). Episodes of an IS run's final stage (drawn from q) carry
    their weight p/q in the CSV's `weight`: every mean over a stratum is weighted by it, which takes x given
    the stratum back to its nominal law (1 for an MC run: the plain means)."""
    table = []
    for mode, by_mode in outcomes[outcomes["mode"] != "reproduce"].groupby("mode", sort=False):
        if "weight" not in by_mode:
            by_mode = by_mode.assign(weight=1.0)
        per = (
            by_mode.groupby(["stratum", "episode"])
            .agg(sum=("collision", "sum"), count=("collision", "count"), weight=("weight", "first"))
            .reset_index()
        )
        hit, other = per[per["stratum"] == 1], per[per["stratum"] == 0]
        k, m = hit["sum"].to_numpy(float), hit["count"].to_numpy(float)
        w_hit = hit["weight"].to_numpy(float)
        inverse_root = np.sqrt((m + 1) / (k + 1))
        pi_hit = float(np.average(k / m, weights=w_hit))
        pi_other = float(np.average(other["sum"] / other["count"], weights=other["weight"]))
        table.append(
            {
                "mode": mode,
                "collision episodes": len(hit),
                "repeats": int(m.min()),
                "E[pi | Y=1]": pi_hit,
                "collision episodes with pi < 1": f"{int((k < m).sum())}/{len(hit)}",
                "E[pi | Y=0] (implied)": f"{pi_other:.4f} ({rate * (1 - pi_hit) / (1 - rate):.4f})",
                "other episodes with pi > 0": f"{int((other['sum'] > 0).sum())}/{len(other)}",
                "share of Var(Y) left": (1 - pi_hit) / (1 - rate),
                **ceiling_with_interval(rate, inverse_root, w_hit),
            }
        )
    return pd.DataFrame(table)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("--scenario", action="append", required=True)
    parser.add_argument("--collisions", type=int, default=20)
    parser.add_argument("--others", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=12)
    parser.add_argument(
        "--modes",
        nargs="+",
        default=list(MODES),
        type=mode_argument,
        help=f"of {', '.join(MODES)}; keep_ modes joined by '+' keep several sources at once",
    )
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--set", action="append", default=[])
    parser.add_argument("--protocol", type=Path, help="the run's protocol file (a run made with --protocol)")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--condition", choices=CONDITIONS, default="sv", help="whose collisions (default sv)")
    parser.add_argument("--summarise", action="store_true", help="only read the CSVs in --out back")
    args = parser.parse_args(argv)
    if args.repeats < 2:
        print("is_within_episode: --repeats must be at least 2", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    rows = pd.read_parquet(args.mc_run / "episodes.parquet")
    suffix = "" if args.condition == "sv" else f"_{args.condition}"
    for scenario in args.scenario:
        path = args.out / f"{scenario}{suffix}_outcomes.csv"
        if not args.summarise:
            run_scenario(args, scenario).to_csv(path, index=False)
        outcomes = pd.read_csv(path)
        ok = rows[
            (rows["scenario"] == scenario) & (rows["condition"] == args.condition) & (rows["status"] == "ok")
        ]
        ok = final_stage(ok)
        weight = ok["weight"].to_numpy(float) if "weight" in ok else np.ones(len(ok))
        # The plain (IS) estimate over the final stage: the rows' mean under MC.
        rate = float(np.mean(weight * ok["collision"].to_numpy(float)))
        reproduced = outcomes[outcomes["mode"] == "reproduce"]
        print(
            f"\n{scenario}: {args.condition.upper()} collision rate P = {rate:.4f} ({len(ok)} episodes"
            f"{', weighted' if np.any(weight != 1) else ''}); reproduce: "
            f"{int((reproduced['collision'] == reproduced['stratum']).sum())}/{len(reproduced)} as recorded"
        )
        with pd.option_context("display.width", 250, "display.max_columns", 20):
            print(summarise(outcomes, rate).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
