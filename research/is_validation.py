"""Importance sampling against plain Monte Carlo: per scenario and condition, the IS
estimate of a run made with --sampler is and the MC estimate of a reference run, their 95% intervals,
whether they agree, and the efficiency (episodes MC needs for the IS interval's half-width h,
p(1 - p)(1.96 / h)^2 with p the IS estimate, over the episodes IS ran, pilots included; and over the
final stage's episodes alone), and `z_vs_mc`, the difference over the two estimates' combined standard
error (|z| > 1.96: a disagreement at the 5 % level).

Where the IS run's final stage drew from a joint proposal with a stored E_p[pi_hat] (--is-family joint),
the IS estimate is Table I's: pi_hat as a control variate (docs/sampling.md, "Control variate"; the column
`estimator` says which), with the plain weighted estimate and its efficiencies beside it (`plain_*`);
`--plain` gives the plain weighted estimate alone, the columns of the tables before the control variate.

The stages estimated are Table I's (run.json's `estimate_from_stage`, `--is-pool-from`); `--pool-from
STAGE` evaluates the run as if it had been made with `--is-pool-from STAGE` (for runs made before the
flag, or to see what another choice would have given: a look at the data, not the run's estimate).
`efficiency_final` counts the estimated stages' episodes only (the other pilots' cost aside). Without
MC_RUN the MC columns are left out: the efficiency needs the IS run alone.

    .venv/bin/python research/is_validation.py IS_RUN [MC_RUN] [--markdown] [--plain] [--pool-from STAGE]

Either run may be unfinished: the rows of its recorded chunks are read (parts/ and manifest.json).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import pandas as pd

from pedsafe_sumo.io.run_store import EPISODES_FILE, Manifest, read_parts
from pedsafe_sumo.report.tables import table_one_weighted
from pedsafe_sumo.safety.stats import table_one
from pedsafe_sumo.sampling.pooling import first_estimated_stage

Z = 1.959964


def rows_of(run: Path) -> pd.DataFrame:
    if (run / EPISODES_FILE).exists():
        return pd.read_parquet(run / EPISODES_FILE, partitioning=None)
    manifest = Manifest.load(run / "manifest.json")
    return read_parts(run, list(manifest.chunks.values()))


def _efficiency(p: float, high: float, n: int) -> float:
    """Episodes MC needs for the half-width high - p, p(1 - p)(1.96 / h)^2, over `n` (the interval is
    symmetric before its cut at 0)."""
    half = high - p
    mc_needed = p * (1 - p) * (Z / half) ** 2 if half > 0 and 0 < p < 1 else math.nan
    return mc_needed / n if math.isfinite(mc_needed) and n > 0 else math.nan


def _z_difference(p: float, high: float, mc: float, mc_n: int) -> float:
    """(IS - MC) over the two estimates' combined standard error: the IS one from its interval's upper
    half-width (symmetric before its cut at 0), MC's the binomial sqrt(p(1 - p) / n). The two runs are
    independent, so |z| above 1.96 is a disagreement at the 5 % level; MC's point outside the IS interval
    is not one (MC's own error is left out of that)."""
    se_is = (high - p) / Z
    se_mc = math.sqrt(mc * (1 - mc) / mc_n) if mc_n > 0 else math.nan
    se = math.hypot(se_is, se_mc)
    return (p - mc) / se if se > 0 else math.nan


def compare(
    is_rows: pd.DataFrame,
    mc_rows: pd.DataFrame | None,
    proposals: dict[str, list[str]] | None = None,
    first_stage: int | None = None,
) -> pd.DataFrame:
    """The comparison table; `proposals` (the IS run's sampler_proposals) for the control variate of a
    joint proposal, with the plain weighted figures beside (plain_*) when it is used somewhere;
    `first_stage` the first stage pooled (None: the final stage alone); without `mc_rows`, no MC columns."""
    is_table = table_one_weighted(is_rows, proposals=proposals, first_stage=first_stage)
    plain_table = (
        table_one_weighted(is_rows, first_stage=first_stage) if "estimator" in is_table.columns else None
    )
    mc_table = table_one(mc_rows) if mc_rows is not None else None
    out = []
    for i, r in is_table.iterrows():
        m = None
        if mc_table is not None:
            same = mc_table[(mc_table.scenario == r.scenario) & (mc_table.condition == r.condition)]
            if same.empty:
                continue
            m = same.iloc[0]
        for index, (est, lo, hi, mest, mlo, mhi) in {
            "collision": ("collision_rate", "collision_low", "collision_high") * 2,
            "injury": ("injury_mean", "injury_low", "injury_high") * 2,
            "conflict": ("conflict_rate", "conflict_low", "conflict_high") * 2,
        }.items():
            p, low, high = float(r[est]), float(r[lo]), float(r[hi])
            row = {
                "scenario": r.scenario,
                "condition": r.condition,
                "index": index,
                "is_estimate": p,
                "is_low": low,
                "is_high": high,
                "ess": float(r.ess),
                "mean_weight": float(r.mean_weight) if "mean_weight" in r else math.nan,
                "weight_note": str(r.weight_note) if "weight_note" in r else "",
                "is_episodes_run": int(r.n_run),
                "stages": str(r.stages) if "stages" in r else "final",
            }
            if m is not None:
                row.update(
                    mc_estimate=float(m[mest]),
                    mc_low=float(m[mlo]),
                    mc_high=float(m[mhi]),
                    mc_n=int(m.n),
                    intervals_overlap=bool(low <= float(m[mhi]) and float(m[mlo]) <= high),
                    mc_in_is_interval=bool(low <= float(m[mest]) <= high),
                    z_vs_mc=_z_difference(p, high, float(m[mest]), int(m.n)),
                )
            row.update(
                efficiency=_efficiency(p, high, int(r.n_run)),
                # The estimated stages alone (their n episodes, errors left out): the other pilots aside.
                efficiency_final=_efficiency(p, high, int(r.n)),
            )
            if plain_table is not None:
                plain = plain_table.loc[i]
                q, q_high = float(plain[est]), float(plain[hi])
                row.update(
                    estimator=str(r.estimator),
                    plain_estimate=q,
                    plain_low=float(plain[lo]),
                    plain_high=q_high,
                    plain_efficiency=_efficiency(q, q_high, int(r.n_run)),
                    plain_efficiency_final=_efficiency(q, q_high, int(r.n)),
                )
            out.append(row)
    return pd.DataFrame(out)


def markdown_table(table: pd.DataFrame) -> str:
    """The table as a Markdown pipe table, floats to 4 places (pandas' to_markdown needs tabulate, which the
    project does not install)."""

    def cell(value) -> str:
        return f"{value:.4f}" if isinstance(value, float) else str(value)

    lines = ["| " + " | ".join(map(str, table.columns)) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in table.itertuples(index=False)]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("is_run", type=Path)
    parser.add_argument("mc_run", type=Path, nargs="?", help="a plain MC run of the same scenarios")
    parser.add_argument(
        "--pool-from",
        type=int,
        metavar="STAGE",
        help="estimate from stages STAGE..final (default: the run's own, run.json's estimate_from_stage)",
    )
    parser.add_argument("--markdown", action="store_true")
    parser.add_argument(
        "--plain",
        action="store_true",
        help="the plain weighted IS estimate only (no control variate), as the tables before it",
    )
    args = parser.parse_args(argv)
    try:
        info = json.loads((args.is_run / "run.json").read_text())
        proposals = None if args.plain else info.get("sampler_proposals")
        first = args.pool_from if args.pool_from is not None else first_estimated_stage(info)
        mc_rows = rows_of(args.mc_run) if args.mc_run is not None else None
        table = compare(rows_of(args.is_run), mc_rows, proposals, first)
    except (OSError, ValueError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.markdown:
        print(markdown_table(table))
    else:
        with pd.option_context("display.width", 250, "display.max_columns", 30):
            print(table.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    levels = info.get("sampler_levels", {})
    print(json.dumps(levels))
    return 0


if __name__ == "__main__":
    sys.exit(main())
