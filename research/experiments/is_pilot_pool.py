"""What more pilot stages buy a `--is-family joint` proposal, stage by stage.
Offline, no SUMO: it reads IS runs made with many pilot stages and a plain Monte Carlo run.

For each IS run (its scenario's proposals in run.json) and each stage s, the proposal of stage s was fitted
on the SV rows of pilot stages 0..s-1 pooled (s x pilot pairs). Each is evaluated on the MC run's SV rows
as research/is_limits.py does (efficiency per final-stage episode, plain IS / with pi_hat as a control
variate at its best slope), in three forms:

- `recorded`: the proposal the run drew from (the sampler's fit: every pooled row counts 1);
- `weighted`: pi_hat refitted on the same pooled rows, each row's log-likelihood scaled by its importance
  weight p/q (normalised to mean 1), so the fit aims at the nominal law rather than at where the pilots
  drew; the same design, ridge and defensive share;
- `mixture s0-s`: the deterministic mixture of the recorded proposals of stages s0..s, q/p averaged
  (plain IS only): what drawing from all of them at once gives, the form a pilot-recycling estimator
  (the balance heuristic) weights every stage's rows by.

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_pilot_pool.py V5_FULL \\
        RUN [RUN ...] [--stages 1 2 3 4 5 6 8 10] [--mixture-from 2]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

TOOLS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(TOOLS))

from is_limits import inputs_of, joint_cv_efficiency, joint_efficiency, rows_of  # noqa: E402

from pedsafe_sumo.sampling.joint import RIDGE, JointProposal, fit_logistic, normalised  # noqa: E402
from pedsafe_sumo.sampling.stages import _inputs_and_nominal  # noqa: E402


def refit(pool: pd.DataFrame, recorded: JointProposal, weighted: bool = True) -> JointProposal:
    """pi_hat refitted on `pool` (SV rows of the pilot stages before), rows weighted by p/q or, with
    `weighted` False, unweighted (the sampler's own fit)."""
    inputs, nominal = _inputs_and_nominal(pool)
    shell = JointProposal(
        dict(nominal.families), (), 1.0, recorded.defensive_share, kinematics=recorded.kinematics
    )
    weight = pool["weight"].to_numpy(dtype=float)
    y = pool["collision"].astype(float).to_numpy()
    row_weight = weight / weight.mean() if weighted else None
    coefficients = fit_logistic(shell.features(inputs), y, RIDGE, row_weight)
    return normalised(nominal.families, coefficients, recorded.defensive_share, recorded.kinematics)


def run_and_reference(
    run: Path, mc: pd.DataFrame
) -> tuple[list[str], pd.DataFrame, pd.DataFrame, np.ndarray]:
    """An IS run's stored proposals and ok SV rows, and the MC run's ok SV rows of the same scenario
    (`mc`, already cut to those): their inputs and collision indicators."""
    info = json.loads((run / "run.json").read_text())
    scenario = info["arguments"]["scenario"]
    rows = pd.read_parquet(run / "episodes.parquet")
    rows = rows[(rows["condition"] == "sv") & (rows["status"] == "ok")]
    reference = mc[mc["scenario"] == scenario]
    inputs, _ = inputs_of(reference)
    return info["sampler_proposals"][scenario], rows, inputs, reference["collision"].astype(float).to_numpy()


def mixture_efficiency(f: np.ndarray, inputs: pd.DataFrame, proposals: list[JointProposal]) -> float:
    """Plain IS per final-stage episode of the equal mixture of `proposals` (q/p averaged)."""
    ratio = np.mean(
        [j.q_over_p({name: inputs[name].to_numpy(dtype=float) for name in j.names}) for j in proposals],
        axis=0,
    )
    p_hat = float(np.mean(f))
    variance = float(np.mean(f / ratio)) - p_hat**2
    return p_hat * (1 - p_hat) / variance


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("runs", type=Path, nargs="+", help="IS runs of --is-family joint")
    parser.add_argument("--stages", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6, 8, 10])
    parser.add_argument("--mixture-from", type=int, default=2, help="first stage of the mixture [2]")
    args = parser.parse_args(argv)
    mc = rows_of(args.mc_run)
    mc = mc[(mc["status"] == "ok") & (mc["condition"] == "sv")]
    out = []
    for run in args.runs:
        stored, rows, inputs, f = run_and_reference(run, mc)
        for stage in args.stages:
            if stage >= len(stored) or not stored[stage]:
                continue
            recorded = JointProposal.from_json(stored[stage])
            pool = rows[rows["sampler_stage"] < stage]
            refitted = refit(pool, recorded)
            first = args.mixture_from
            mixed = [JointProposal.from_json(stored[s]) for s in range(first, stage + 1) if stored[s]]
            out.append(
                {
                    "run": run.name,
                    "stage": stage,
                    "pooled_pairs": int(len(pool)),
                    "pooled_collisions": int(pool["collision"].sum()),
                    "recorded": joint_efficiency(f, inputs, recorded)[0],
                    "recorded_cv": joint_cv_efficiency(f, inputs, recorded),
                    "weighted": joint_efficiency(f, inputs, refitted)[0],
                    "weighted_cv": joint_cv_efficiency(f, inputs, refitted),
                    f"mixture_{first}_to_s": mixture_efficiency(f, inputs, mixed) if mixed else np.nan,
                }
            )
    print(pd.DataFrame(out).to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
