"""Build against build: is stack B at least as safe as stack A on the same episodes?

    python -m pedsafe_sumo.compare RUN_A RUN_B [--margin collision=0.01 ...] [--approach ARM] [--out DIR]

RUN_A and RUN_B are batch run directories made with the same seed, scenarios and sites (e.g. the
same `batch` command with `--algorithm` set to the two builds), so that episode i of a scenario and
condition meets the same world in both. For every scenario, condition and index (collision rate,
mean injury probability, conflict rate), the comparison gives the paired difference B - A with its
interval and a one-sided non-inferiority test: B is declared not worse (PASS) when the upper end of
the two-sided interval of B - A lies below the margin (a difference of that size is ruled out by a
one-sided test at level (1 - confidence) / 2, 2.5% by default, as ICH E9 frames non-inferiority).
Otherwise FAIL: the data do not rule out that B is worse by the margin or more.

Intervals, per index:
- binary indexes under plain Monte Carlo (every weight 1): Tango's asymptotic score interval for the
  difference of paired proportions (Tango 1998, Statistics in Medicine 17:891-908; recommended for
  paired binomial data by Fagerland, Lydersen & Laake 2014, "Recommended tests and confidence
  intervals for paired binomial proportions", Statistics in Medicine 33:2850-2875), which stays
  sensible with few discordant pairs;
- the injury probability, and every index under importance sampling (weights != 1): the central-limit
  interval of the weighted paired differences w_i (B_i - A_i), the unbiased estimator of the
  difference of the two expectations under the nominal distribution; with no differing pair at all,
  the difference is bounded by the rule-of-three bound on the share of differing pairs.

The episodes where B did worse than A (a collision or conflict that A avoided, or a higher injury
probability) are listed with the command that replays each in sumo-gui. A run made with `batch --approach
all` is compared arm by arm (or one arm, `--approach`). Exit status: 0 when every
comparison passes, 1 when any fails, 2 on bad input.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import optimize, special

from pedsafe_sumo.cli import OneLineParser
from pedsafe_sumo.io.outputs import check_output_dir
from pedsafe_sumo.network.approaches import leg_argument
from pedsafe_sumo.report.html import replay_commands
from pedsafe_sumo.report.rundir import ReportError, RunDirectory, load_run, load_run_per_approach
from pedsafe_sumo.safety.conflict import conflict_without_collision
from pedsafe_sumo.sampling.importance import is_estimate, no_event_bound
from pedsafe_sumo.sampling.pooling import stage_max_weight

#: Indexes compared, each "higher is worse", with default non-inferiority margins (absolute
#: differences of the rate or mean). The margins are a decision of the user, not a fact: these
#: defaults (one percentage point of collisions, two of conflicts, half a point of mean injury
#: probability) are a starting point for a regression gate, to be set per study with --margin.
DEFAULT_MARGINS = {"collision": 0.01, "injury_probability": 0.005, "conflict": 0.02}
BINARY_INDEXES = ("collision", "conflict")
OK_STATUS = "ok"


class CompareError(ValueError):
    """Bad input for the comparison; the message is one line."""


@dataclass(frozen=True)
class Difference:
    estimate: float
    low: float
    high: float


def tango_interval(b_only: int, a_only: int, n: int, confidence: float) -> Difference:
    """Tango's score interval for p_B - p_A from n pairs, `b_only` with the event under B only and
    `a_only` under A only.

    For a hypothesised difference d, the restricted maximum-likelihood estimate of the probability of
    an A-only pair q solves 2n q^2 + (-(b + a) + (2n - b + a) d) q - a d (1 - d) = 0, and the score
    statistic T(d) = (b - a - n d) / sqrt(n (2 q + d (1 - d))) is standard normal; the interval is the
    set of d with |T(d)| <= z (Tango 1998, eqs. 3-5).
    """
    if n <= 0:
        return Difference(math.nan, math.nan, math.nan)
    z = float(special.ndtri(0.5 + confidence / 2))
    b, a = float(b_only), float(a_only)

    def score(d: float) -> float:
        linear = -(b + a) + (2 * n - b + a) * d
        constant = -a * d * (1 - d)
        q = (math.sqrt(max(linear * linear - 8 * n * constant, 0.0)) - linear) / (4 * n)
        variance = n * (2 * q + d * (1 - d))
        return (
            (b - a - n * d) / math.sqrt(variance) if variance > 0 else math.copysign(math.inf, b - a - n * d)
        )

    estimate = (b - a) / n
    eps = 1e-12
    low = -1.0 if estimate <= -1 + eps else optimize.brentq(lambda d: score(d) - z, -1 + eps, estimate + eps)
    high = 1.0 if estimate >= 1 - eps else optimize.brentq(lambda d: score(d) + z, estimate - eps, 1 - eps)
    return Difference(estimate, low, high)


def weighted_difference(
    a: np.ndarray,
    b: np.ndarray,
    weights: np.ndarray,
    confidence: float,
    no_difference_bound: float = math.nan,
) -> Difference:
    """Unbiased estimate of E_p[B - A] from paired draws with likelihood ratios, and its interval.
    `no_difference_bound`: the bound on the share of differing pairs where none differs, from the stages'
    known weight bounds (sampling.importance.no_event_bound); NaN: the rule of three on the ESS."""
    diff = b - a
    estimate = is_estimate(diff, weights, confidence)
    if np.any(diff * weights != 0):
        return Difference(estimate.mean, estimate.low, estimate.high)
    # No pair differs: |B - A| <= 1 for indexes in [0, 1], so the difference is bounded by the share
    # of differing pairs, whose bound with none seen is the rule of three on the equivalent nominal draws.
    bound = no_difference_bound
    if not math.isfinite(bound):
        bound = is_estimate(np.zeros_like(diff), weights, confidence).high
    return Difference(0.0, -bound, bound)


def _index_values(side: pd.DataFrame, index: str) -> np.ndarray:
    if index == "conflict":
        # Table I's conflict rate: a conflict counts only in an episode without a collision.
        return conflict_without_collision(
            side["conflict"].to_numpy(dtype=bool), side["collision"].to_numpy(dtype=bool)
        ).astype(float)
    return side[index].to_numpy(dtype=float)


def pair_runs(episodes_a: pd.DataFrame, episodes_b: pd.DataFrame) -> pd.DataFrame:
    """Rows of A and B matched on (scenario, condition, episode), both with status ok; refuses runs whose
    draws differ (seed or weight of a matched episode) or that share no episode."""
    key = ["scenario", "condition", "episode"]
    for name, table in (("A", episodes_a), ("B", episodes_b)):
        if table.duplicated(key).any():
            raise CompareError(f"run {name} repeats (scenario, condition, episode) rows")
    pairs = episodes_a.merge(episodes_b, on=key, suffixes=("_a", "_b"))
    if pairs.empty:
        raise CompareError("the two runs share no (scenario, condition, episode): not runs of the same draws")
    differing = pairs[pairs["seed_a"] != pairs["seed_b"]]
    if not differing.empty:
        row = differing.iloc[0]
        raise CompareError(
            f"the runs do not share their draws: {row['scenario']} {row['condition']} episode "
            f"{row['episode']} has seed {row['seed_a']} in A and {row['seed_b']} in B (use the same --seed)"
        )
    weight_a = pairs["weight_a"] if "weight_a" in pairs else pd.Series(1.0, index=pairs.index)
    weight_b = pairs["weight_b"] if "weight_b" in pairs else pd.Series(1.0, index=pairs.index)
    if not np.allclose(weight_a.to_numpy(dtype=float), weight_b.to_numpy(dtype=float), rtol=1e-9):
        raise CompareError(
            "the runs weight the same episodes differently: they were drawn from different proposals "
            "(run B with `batch --sampler is --is-proposal RUN_A` to draw A's episodes)"
        )
    pairs["weight"] = weight_a.to_numpy(dtype=float)
    ok = (pairs["status_a"] == OK_STATUS) & (pairs["status_b"] == OK_STATUS)
    return pairs[ok].reset_index(drop=True)


def compare_runs(
    episodes_a: pd.DataFrame,
    episodes_b: pd.DataFrame,
    margins: dict[str, float],
    confidence: float = 0.95,
    proposals: Mapping[str, Sequence[str]] | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per scenario, condition and index: n, A's and B's estimates, the difference B - A with its
    interval, the margin and PASS/FAIL; and the episodes where B did worse than A. `proposals` (run A's
    run.json sampler_proposals, which B shares) bound the weights of each stage for the interval where no
    pair differs (docs/sampling.md, "No event")."""
    pairs = pair_runs(episodes_a, episodes_b)
    rows, worse = [], []
    for (scenario, condition), group in pairs.groupby(["scenario", "condition"], sort=False):
        weights = group["weight"].to_numpy(dtype=float)
        plain = bool(np.all(weights == 1.0))
        no_difference_bound = math.nan
        if proposals is not None and "sampler_stage_a" in group:
            stages = group["sampler_stage_a"].astype(int).value_counts().sort_index()
            no_difference_bound = no_event_bound(
                [(int(n), stage_max_weight(proposals.get(str(scenario)), int(s))) for s, n in stages.items()],
                confidence,
            )
        side_a = pd.DataFrame({c[:-2]: group[c] for c in group.columns if c.endswith("_a")})
        side_b = pd.DataFrame({c[:-2]: group[c] for c in group.columns if c.endswith("_b")})
        for index, margin in margins.items():
            values_a, values_b = _index_values(side_a, index), _index_values(side_b, index)
            if plain and index in BINARY_INDEXES:
                b_only = int(np.sum((values_b > 0) & (values_a == 0)))
                a_only = int(np.sum((values_a > 0) & (values_b == 0)))
                diff = tango_interval(b_only, a_only, len(group), confidence)
            else:
                diff = weighted_difference(values_a, values_b, weights, confidence, no_difference_bound)
            rows.append(
                {
                    "scenario": scenario,
                    "condition": condition,
                    "index": index,
                    "n_pairs": len(group),
                    "a": float(np.mean(weights * values_a)),
                    "b": float(np.mean(weights * values_b)),
                    "difference": diff.estimate,
                    "low": diff.low,
                    "high": diff.high,
                    "margin": margin,
                    # Non-inferiority as ICH E9 states it: the upper end of the two-sided interval
                    # (a one-sided test at (1 - confidence) / 2) below the margin.
                    "verdict": "PASS" if diff.high < margin else "FAIL",
                }
            )
        worse_mask = np.zeros(len(group), dtype=bool)
        for index in margins:
            worse_mask |= _index_values(side_b, index) > _index_values(side_a, index)
        for _, row in group[worse_mask].iterrows():
            worse.append(
                {
                    "scenario": scenario,
                    "condition": condition,
                    "episode": int(row["episode"]),
                    "seed": int(row["seed_a"]),
                    "collision_a": bool(row["collision_a"]),
                    "collision_b": bool(row["collision_b"]),
                    "injury_a": float(row["injury_probability_a"]),
                    "injury_b": float(row["injury_probability_b"]),
                }
            )
    return pd.DataFrame(rows), pd.DataFrame(worse)


def _parse_margins(pairs: Sequence[str]) -> dict[str, float]:
    margins = dict(DEFAULT_MARGINS)
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep:
            raise CompareError(f"--margin needs INDEX=VALUE, got '{pair}'")
        if key not in DEFAULT_MARGINS:
            raise CompareError(f"unknown index '{key}' in --margin (known: {', '.join(DEFAULT_MARGINS)})")
        try:
            margin = float(value)
        except ValueError:
            raise CompareError(f"--margin {key} must be a number, got '{value}'") from None
        if not (math.isfinite(margin) and 0 < margin <= 1):
            raise CompareError(f"--margin {key} must lie in (0, 1], got {value}")
        margins[key] = margin
    return margins


def _format(table: pd.DataFrame) -> str:
    # A run of several approaches (batch --approach all) gets the arm beside the scenario.
    arm_of = (
        table["approach"].tolist() if "approach" in table and table["approach"].any() else [""] * len(table)
    )
    width = 20 + (3 if any(arm_of) else 0)
    lines = [
        f"{'scenario':<{width}} {'cond':<4} {'index':<18} {'pairs':>6} {'A':>8} {'B':>8} "
        f"{'B - A [95% interval]':>30} {'margin':>7}  verdict"
    ]
    for arm, row in zip(arm_of, table.itertuples(), strict=True):
        interval = f"{row.difference:+.4f} [{row.low:+.4f}, {row.high:+.4f}]"
        where = f"{row.scenario} {arm}" if arm else str(row.scenario)
        lines.append(
            f"{where:<{width}} {row.condition:<4} {row.index:<18} {row.n_pairs:>6} {row.a:>8.4f} "
            f"{row.b:>8.4f} {interval:>30} {row.margin:>7.4f}  {row.verdict}"
        )
    return "\n".join(lines)


def runs_by_approach(
    path_a: Path, path_b: Path, approach: str | None
) -> list[tuple[str, RunDirectory, RunDirectory]]:
    """(arm, A, B) for the approach named, or for every approach the two runs hold (a run made with batch
    --approach all holds the same episodes on several arms; each arm is compared on its own). Runs on
    different arms are refused in one line."""
    if approach is not None:
        return [(approach, load_run(path_a, approach=approach), load_run(path_b, approach=approach))]
    arms_a, arms_b = load_run_per_approach(path_a), load_run_per_approach(path_b)
    if len(arms_a) == 1 and len(arms_b) == 1:
        # One arm each (or runs without an approach column): compared as they are, arm against arm.
        (arm, run_a), (_, run_b) = next(iter(arms_a.items())), next(iter(arms_b.items()))
        return [(arm, run_a, run_b)]
    if set(arms_a) != set(arms_b):
        raise CompareError(
            f"the runs hold different approaches (A: {', '.join(arms_a) or 'none'}, B: "
            f"{', '.join(arms_b) or 'none'}): compare one with --approach"
        )
    return [(arm, arms_a[arm], arms_b[arm]) for arm in arms_a]


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(
        prog="python -m pedsafe_sumo.compare",
        description="Paired build-against-build comparison of two batch runs of the same draws: the "
        "difference B - A per scenario, condition and index with its interval, and a non-inferiority "
        "verdict (PASS: B is not worse than A by the margin).",
    )
    parser.add_argument("run_a", type=Path, help="run directory of the reference build (A)")
    parser.add_argument("run_b", type=Path, help="run directory of the candidate build (B)")
    parser.add_argument(
        "--margin",
        action="append",
        default=[],
        metavar="INDEX=VALUE",
        help="non-inferiority margin of an index, an absolute difference of the rate or mean, above 0 and "
        "at most 1 " + ", ".join(f"[{k}={v:g}]" for k, v in DEFAULT_MARGINS.items()),
    )
    parser.add_argument(
        "--confidence", type=float, default=0.95, help="two-sided level, at least 0.5 and below 1 [0.95]"
    )
    parser.add_argument("--out", type=Path, help="also write compare.csv and worse_episodes.csv here")
    parser.add_argument(
        "--approach",
        type=leg_argument,
        help="compare the episodes on this approach only (default: every approach the runs hold, each on "
        "its own)",
    )
    args = parser.parse_args(argv)
    try:
        if not 0.5 <= args.confidence < 1:
            raise CompareError(f"--confidence must lie in [0.5, 1), got {args.confidence}")
        margins = _parse_margins(args.margin)
        if args.out is not None:
            check_output_dir(args.out, "--out", CompareError)
        tables, worse_lists, run_b_of = [], [], {}
        for arm, run_a, run_b in runs_by_approach(args.run_a, args.run_b, args.approach):
            arm_table, arm_worse = compare_runs(
                run_a.episodes,
                run_b.episodes,
                margins,
                args.confidence,
                (run_a.run_info or {}).get("sampler_proposals"),
            )
            tables.append(arm_table.assign(approach=arm))
            worse_lists.append(arm_worse.assign(approach=arm))
            run_b_of[arm] = run_b
        table, worse = pd.concat(tables, ignore_index=True), pd.concat(worse_lists, ignore_index=True)
        if args.out is not None:  # checked before the comparison (check_output_dir)
            args.out.mkdir(parents=True, exist_ok=True)
            table.to_csv(args.out / "compare.csv", index=False)
            worse.to_csv(args.out / "worse_episodes.csv", index=False)
    except (CompareError, ReportError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"A = {args.run_a}\nB = {args.run_b}\n")
    print(_format(table))
    failed = table[table["verdict"] == "FAIL"]
    print()
    if len(worse):
        print(f"{len(worse)} episode(s) where B did worse than A; replay each under B with:")
        for _, row in worse.iterrows():
            # The report's own command (scenario, and the approach of a batch run with --approach).
            print(f"  {replay_commands(run_b_of[row['approach']], row)[0]}")
        print()
    verdict = "PASS" if failed.empty else "FAIL"
    print(
        f"{verdict}: B is {'not worse than A by any margin' if failed.empty else 'not shown non-inferior'}"
        + ("" if failed.empty else f" on {len(failed)} of {len(table)} comparisons")
    )
    return 0 if failed.empty else 1


if __name__ == "__main__":
    sys.exit(main())
