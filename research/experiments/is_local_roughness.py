"""How rough is the SV collision as a function of the inputs? The ceiling of a proposal at a resolution
SUMO, small.

research/experiments/is_within_episode.py found the SV collision almost decided by the proposable inputs x
(re-run with fresh everything else, 13-20 of 20 collision episodes collide every time) and put the
ceiling of a proposal over x at 113x (jaywalking) to 2,710x (crossing) per final episode, with pi(x) at
the exact x. A proposal is fitted on a pilot, and a fit resolves x only to some scale: where the
collision flips between neighbouring x, what any smooth pi_hat can learn is the local average of the
outcome, not pi(x). This tool measures that average at given scales.

Method: `--collisions` SV collision episodes of a plain MC run (rows of its episodes.parquet, drawn at
random with a Generator of `--seed`) are re-run with every draw of the episode kept (its world stream and
background traffic: the `reproduce` mode of is_within_episode, which gives the recorded outcome) except
the continuous proposable inputs (the Normal and Beta families of the row's `nominal`), each moved by
delta x its nominal standard deviation x an independent standard normal draw (a Beta input reflected into
its range), `--directions` draws per delta. Categorical inputs stay. pi_delta(x) = (k + 1) / (m + 1) over
the m moved runs and the episode's own collision (never 0, biased up, as in is_within_episode), and the
ceiling of a proposal that knows x only to that resolution is is_within_episode's

    (1 - P) / (P (E[pi_delta^(-1/2) | Y = 1]^2 - 1)),

P the MC run's SV collision rate. As delta -> 0 it tends to is_within_episode's `keep_world` ceiling
(infinite where every collision episode collides at its own x). The per-delta share of moved runs that
still collide is printed too.

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_local_roughness.py \\
        V5_FULL --scenario jaywalking --collisions 20 --directions 8 \\
        --set traffic.background_speed_limit_scaled=false --set pedestrians.detour_wait_s=600 --out DIR
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

sys.path.insert(0, str(Path(__file__).resolve().parent))

from is_within_episode import (  # noqa: E402
    FixedInputs,
    ceiling_with_interval,
    pick_episodes,
    rows_and_runner,
)

from pedsafe_sumo.sampling.importance import Beta, Normal  # noqa: E402

DELTAS = (0.01, 0.03, 0.1, 0.3)


def nominal_sd(family: Any) -> float:
    if isinstance(family, Normal):
        return family.sd
    s = family.a + family.b
    return (family.high - family.low) * math.sqrt(family.a * family.b / (s * s * (s + 1)))


def moved(value: float, family: Any, step: float) -> float:
    """value + step, a Beta input reflected into [low, high]."""
    x = value + step
    if isinstance(family, Beta):
        width = family.high - family.low
        u = (x - family.low) % (2 * width)
        x = family.low + (u if u <= width else 2 * width - u)
    return x


def same_world(a: Any, b: Any) -> bool:
    """Equal up to the last bits of a float: an input served from its recorded value goes through the
    family's scale and back (the walking speed: ln, then exp), which can move its last bit."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_world(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same_world(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12)
    return bool(a == b)


def run_scenario(args: argparse.Namespace, scenario: str) -> pd.DataFrame:
    sv, spec, runner, _ = rows_and_runner(args.mc_run, scenario, args.set)  # an MC run: "" proposal
    chosen = pick_episodes(sv, args.collisions, 0, args.seed)
    rng = np.random.default_rng(args.seed)
    out = []
    started = time.perf_counter()
    try:
        for i, (_, row) in enumerate(chosen.iterrows()):
            seed = int(row["seed"])
            record = json.loads(row["sampler_inputs"])
            original, draws = runner.draw_setup_sampled(spec, seed)
            kept = {n: f for n, f in draws.nominals.items() if f is not None}
            continuous = [n for n in sorted(record["nominal"]) if isinstance(kept[n], (Normal, Beta))]
            if args.only:
                continuous = [n for n in continuous if n == args.only]
            plan = [(0.0, 0)] + [(d, r) for d in args.deltas for r in range(args.directions)]
            for delta, direction in plan:
                values = dict(draws.inputs)
                if delta > 0:
                    for name in continuous:
                        step = delta * nominal_sd(kept[name]) * float(rng.standard_normal())
                        values[name] = moved(values[name], kept[name], step)
                fixed = FixedInputs(kept, {n: values[n] for n in kept})
                # The very world, only x moved: every world input served as kept, the same traffic.
                setup, _ = runner.draw_setup_sampled(spec, seed, fixed)
                setup = dataclasses.replace(setup, background=original.background)
                if delta == 0 and not same_world(dataclasses.asdict(setup), dataclasses.asdict(original)):
                    raise RuntimeError(f"episode {row['episode']}: the kept world differs from its own")
                result = runner.run(spec, "sv", seed, setup=setup)
                out.append(
                    {
                        "scenario": scenario,
                        "episode": int(row["episode"]),
                        "delta": delta,
                        "direction": direction,
                        "collision": int(bool(result.outcome["collision"])),
                    }
                )
                if delta == 0 and out[-1]["collision"] != 1:
                    print(
                        f"warning: episode {row['episode']} did not reproduce its collision", file=sys.stderr
                    )
            print(
                f"{scenario}: {i + 1}/{len(chosen)} episodes, {time.perf_counter() - started:.0f} s",
                file=sys.stderr,
                flush=True,
            )
    finally:
        runner.close()
    return pd.DataFrame(out)


def summarise(outcomes: pd.DataFrame, rate: float) -> pd.DataFrame:
    table = []
    own = outcomes[outcomes["delta"] == 0].set_index("episode")["collision"]
    for delta, by_delta in outcomes[outcomes["delta"] > 0].groupby("delta"):
        per = by_delta.groupby("episode")["collision"].agg(["sum", "count"])
        k = per["sum"].to_numpy(float) + own.loc[per.index].to_numpy(float)
        m = per["count"].to_numpy(float) + 1
        inverse_root = np.sqrt(m / k)
        table.append(
            {
                "delta (nominal sd)": delta,
                "moved runs that collide": float(by_delta["collision"].mean()),
                "episodes that always collide": f"{int((per['sum'] == per['count']).sum())}/{len(per)}",
                **ceiling_with_interval(rate, inverse_root),
            }
        )
    return pd.DataFrame(table)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("--scenario", action="append", required=True)
    parser.add_argument("--collisions", type=int, default=20)
    parser.add_argument("--directions", type=int, default=8)
    parser.add_argument("--deltas", type=float, nargs="+", default=list(DELTAS))
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--only", help="move this input alone (default: every continuous proposable input)")
    parser.add_argument("--set", action="append", default=[])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--summarise", action="store_true", help="only read the CSVs in --out back")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = pd.read_parquet(
        args.mc_run / "episodes.parquet", columns=["scenario", "condition", "status", "collision"]
    )
    for scenario in args.scenario:
        path = args.out / f"{scenario}{'_' + args.only if args.only else ''}_roughness.csv"
        if not args.summarise:
            run_scenario(args, scenario).to_csv(path, index=False)
        outcomes = pd.read_csv(path)
        sv = rows[(rows["scenario"] == scenario) & (rows["condition"] == "sv") & (rows["status"] == "ok")]
        rate = float(sv["collision"].mean())
        reproduced = outcomes[outcomes["delta"] == 0]
        print(
            f"\n{scenario}: MC SV collision rate P = {rate:.4f}; reproduced "
            f"{int(reproduced['collision'].sum())}/{len(reproduced)} collisions at their own x"
        )
        with pd.option_context("display.width", 250, "display.max_columns", 20):
            print(summarise(outcomes, rate).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
