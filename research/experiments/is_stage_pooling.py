"""The estimate of an importance-sampling run with its later pilot stages pooled into the final stage
(Table I's estimator with `--is-pool-from`, sampling/pooling.py).

Without pooling (`--is-pool-from` at the final stage) Table I estimates from the final stage only
(report/tables.py). Each stage t's weighted mean (1/n_t) sum
w_i f_i is unbiased given the stages before it, so a combination with weights fixed in advance is too.
Here every episode of stages `first`..K counts once (the stages' means weighted by their sizes; plain IS,
no control variate), with variance sum_t n_t s_t^2 / N^2 (s_t^2 the sample variance of w f in stage t) and
a central-limit 95% interval. With `--control`, each stage whose proposal is joint with a stored
E_p[pi_hat] is estimated with pi_hat as a control variate (sampling.control_variate.cv_estimate, Table I's
estimator under --is-family joint) and its variance taken from that estimate; the stages are still
weighted by their sizes. Efficiency is against plain MC at the estimate, with every episode run counted
(pilots included): P (1 - P) (1.96 / h)^2 / n_run. With `--mc RUN` the MC estimate is shown beside it.

    .venv/bin/python research/experiments/is_stage_pooling.py IS_RUN [--control] [--each] [--mc MC_RUN]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

from pedsafe_sumo.sampling.control_variate import pi_hat_of_inputs, stage_control
from pedsafe_sumo.sampling.pooling import StageRows
from pedsafe_sumo.sampling.pooling import pooled_estimate as pool


def stage_rows(stage: pd.DataFrame, proposals: list[str] | None) -> StageRows:
    """One stage's collision rows, with its pi_hat as a control where `proposals` is given and the stage's
    proposal allows it."""
    w = stage["weight"].to_numpy(dtype=float)
    f = stage["collision"].astype(float).to_numpy()
    control = stage_control(proposals, int(stage["sampler_stage"].iloc[0])) if proposals else None
    if control is None:
        return StageRows(f, w)
    g = pi_hat_of_inputs(control, stage["sampler_inputs"].tolist())
    return StageRows(f, w, g, control.mean_pi_hat, control.mean_pi_hat_se)


def pooled_estimate(
    rows: pd.DataFrame, first: int, proposals: list[str] | None = None
) -> tuple[float, float, int]:
    """(estimate, 95% half-width, episodes used) of stages >= first of one scenario and condition, each
    stage weighted by its size: Table I's estimator with `--is-pool-from` (sampling.pooling)."""
    used = rows[rows["sampler_stage"] >= first]
    stages = [stage_rows(stage, proposals) for _, stage in used.groupby("sampler_stage")]
    estimate = pool(stages).estimate
    return estimate.mean, estimate.high - estimate.mean, len(used)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--mc", type=Path, help="a plain MC run of the same scenarios")
    parser.add_argument("--control", action="store_true", help="pi_hat as a control variate per stage")
    parser.add_argument(
        "--each",
        action="store_true",
        help="also each stage alone, with its efficiency per episode of that stage",
    )
    args = parser.parse_args(argv)
    stored = json.loads((args.run / "run.json").read_text())["sampler_proposals"] if args.control else {}
    rows = pd.read_parquet(args.run / "episodes.parquet")
    rows = rows[rows["status"] == "ok"]
    mc = pd.read_parquet(args.mc / "episodes.parquet") if args.mc else None
    out = []
    for (scenario, condition), group in rows.groupby(["scenario", "condition"]):
        last = int(group["sampler_stage"].max())
        for first in sorted({last, *range(1, last)}, reverse=True):
            proposals = stored.get(scenario) if args.control else None
            estimate, half, n = pooled_estimate(group, first, proposals)
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
        if args.each:
            for stage, alone in group.groupby("sampler_stage"):
                proposals = stored.get(scenario) if args.control else None
                estimate, half, n = pooled_estimate(alone, int(stage), proposals)
                per_episode = estimate * (1 - estimate) * (1.96 / half) ** 2 / n if half > 0 else float("nan")
                out.append(
                    {
                        "scenario": scenario,
                        "condition": condition,
                        "stages": f"{stage} alone",
                        "n": n,
                        "estimate": estimate,
                        "low": estimate - half,
                        "high": estimate + half,
                        "efficiency_per_episode": per_episode,
                    }
                )
    print(pd.DataFrame(out).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
