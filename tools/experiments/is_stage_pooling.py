"""The estimate of an importance-sampling run with its later pilot stages pooled into the final stage
(issue 17, session 10; offline, not Table I's estimator).

Table I estimates from the final stage only (report/tables.py). Each stage t's weighted mean (1/n_t) sum
w_i f_i is unbiased given the stages before it, so a combination with weights fixed in advance is too.
Here every episode of stages `first`..K counts once (the stages' means weighted by their sizes; plain IS,
no control variate), with variance sum_t n_t s_t^2 / N^2 (s_t^2 the sample variance of w f in stage t) and
a central-limit 95% interval. Efficiency is against plain MC at the estimate, with every episode run
counted (pilots included): P (1 - P) (1.96 / h)^2 / n_run. With `--mc RUN` the MC estimate is shown
beside it.

    .venv/bin/python tools/experiments/is_stage_pooling.py IS_RUN [--mc /work/results/v5_full]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd


def pooled_estimate(rows: pd.DataFrame, first: int) -> tuple[float, float, int]:
    """(estimate, 95% half-width, episodes used) of stages >= first of one scenario and condition."""
    used = rows[rows["sampler_stage"] >= first]
    variance = 0.0
    for _, stage in used.groupby("sampler_stage"):
        y = stage["weight"].to_numpy(dtype=float) * stage["collision"].astype(float).to_numpy()
        variance += len(y) * float(np.var(y, ddof=1))
    y_all = used["weight"].to_numpy(dtype=float) * used["collision"].astype(float).to_numpy()
    return float(np.mean(y_all)), 1.96 * (variance / len(y_all) ** 2) ** 0.5, len(y_all)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--mc", type=Path, help="a plain MC run of the same scenarios")
    args = parser.parse_args(argv)
    rows = pd.read_parquet(args.run / "episodes.parquet")
    rows = rows[rows["status"] == "ok"]
    mc = pd.read_parquet(args.mc / "episodes.parquet") if args.mc else None
    out = []
    for (scenario, condition), group in rows.groupby(["scenario", "condition"]):
        last = int(group["sampler_stage"].max())
        for first in sorted({last, *range(1, last)}, reverse=True):
            estimate, half, n = pooled_estimate(group, first)
            row = {
                "scenario": scenario,
                "condition": condition,
                "stages": f"{first}..{last}",
                "n": n,
                "estimate": estimate,
                "low": estimate - half,
                "high": estimate + half,
                "efficiency_pilots_counted": estimate * (1 - estimate) * (1.96 / half) ** 2 / len(group),
            }
            if mc is not None:
                same = (mc["scenario"] == scenario) & (mc["condition"] == condition)
                ref = mc[same & (mc["status"] == "ok")]
                row["mc_estimate"] = float(ref["collision"].mean())
            out.append(row)
    print(pd.DataFrame(out).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
