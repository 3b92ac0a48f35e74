"""Can the pilot rows alone tell which fit of pi_hat makes the better proposal? (Offline,
no SUMO.)

At stage s of an IS run made with many pilot stages (`--is-family joint`), two fits of pi_hat on the
pooled SV rows of stages 0..s-1 are candidates: the sampler's (every row counts 1) and the one weighted
by p/q (research/experiments/is_pilot_pool.py). Each is scored on the pilot rows only, by 2-fold
cross-validation: fitted on one half, its second moment E_p[f p/q_c] (what the proposal's variance grows
with) estimated on the other half by reweighting the held-out rows with their own weights,
sum w f (p/q_c) / sum w. The lower score is chosen. Beside it, each fit's true efficiency per final
episode (plain IS, refitted on all pooled rows) on the MC run's rows, as research/is_limits.py computes it.

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_fit_choice.py V5_FULL \\
        RUN [RUN ...] [--stages 3 4 6 8 10]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

sys.path.insert(0, str(Path(__file__).resolve().parent))

from is_limits import joint_efficiency, rows_of  # noqa: E402
from is_pilot_pool import refit, run_and_reference  # noqa: E402

from pedsafe_sumo.sampling.joint import JointProposal  # noqa: E402
from pedsafe_sumo.sampling.stages import _inputs_and_nominal  # noqa: E402


def held_out_second_moment(pool: pd.DataFrame, recorded: JointProposal, weighted: bool, seed: int) -> float:
    """The 2-fold cross-validated estimate of E_p[f p/q_c] from the pilot rows alone."""
    fold = np.random.default_rng(seed).integers(0, 2, len(pool))
    total = 0.0
    for k in (0, 1):
        candidate = refit(pool[fold != k], recorded, weighted)
        held = pool[fold == k]
        inputs, _ = _inputs_and_nominal(held)
        ratio = candidate.q_over_p({name: np.asarray(inputs[name], dtype=float) for name in candidate.names})
        w = held["weight"].to_numpy(dtype=float)
        y = held["collision"].astype(float).to_numpy()
        total += float(np.sum(w * y / ratio) / np.sum(w))
    return total / 2


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("runs", type=Path, nargs="+", help="IS runs of --is-family joint")
    parser.add_argument("--stages", type=int, nargs="+", default=[3, 4, 6, 8, 10])
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
            pool = rows[rows["sampler_stage"] < stage].reset_index(drop=True)
            score = {wt: held_out_second_moment(pool, recorded, wt, stage) for wt in (False, True)}
            true = {wt: joint_efficiency(f, inputs, refit(pool, recorded, wt))[0] for wt in (False, True)}
            chosen = min(score, key=lambda wt: score[wt])
            out.append(
                {
                    "run": run.name,
                    "stage": stage,
                    "score_unweighted": score[False],
                    "score_weighted": score[True],
                    "chosen": "weighted" if chosen else "unweighted",
                    "efficiency_unweighted": true[False],
                    "efficiency_weighted": true[True],
                    "efficiency_chosen": true[chosen],
                }
            )
    print(pd.DataFrame(out).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
