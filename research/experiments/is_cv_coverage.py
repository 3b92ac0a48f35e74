"""Do the intervals of the joint family's estimators hold the truth as often as they say, on the real
episodes? Offline, no SUMO.

The population: a plain MC run's SV rows of one scenario (v5_full: 10,000), taken as the nominal law
itself (its empirical distribution), so that the truth is known exactly: the rows' mean collision. A
final stage of n episodes from a joint proposal (the final-stage proposal of an IS run, run.json's
`sampler_proposals`) is drawn from that population exactly, with replacement, each row with probability
proportional to (q/p)(x_i); its weight against the empirical law is mean_j (q/p)(x_j) / (q/p)(x_i).
Per replicate, both estimators of report/tables.py: plain IS (sampling.importance.is_estimate) and the
control variate (sampling.control_variate.cv_estimate, with E_p[pi_hat] the rows' own mean of pi_hat
and its standard error 0: exact for this population). Over `--replicates` replicates: how often each
95% interval holds the truth, the estimators' bias and their variance ratio.

    .venv/bin/python research/experiments/is_cv_coverage.py V5_FULL IS_RUN --n 300 800
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from pedsafe_sumo.sampling.control_variate import cv_estimate
from pedsafe_sumo.sampling.importance import is_estimate
from pedsafe_sumo.sampling.joint import proposal_of_json


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("is_runs", type=Path, nargs="+", help="IS runs with a joint final stage")
    parser.add_argument("--n", type=int, nargs="+", default=[300, 800])
    parser.add_argument("--replicates", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=8)
    args = parser.parse_args(argv)
    rows = pd.read_parquet(args.mc_run / "episodes.parquet")
    rows = rows[(rows["status"] == "ok") & (rows["condition"] == "sv")]
    out = []
    for is_run in args.is_runs:
        info = json.loads((is_run / "run.json").read_text())
        for scenario, stages in info["sampler_proposals"].items():
            proposal = proposal_of_json(stages[-1])
            if not getattr(proposal, "is_joint", False):
                print(f"{is_run}: {scenario}'s final stage is not joint; skipped", file=sys.stderr)
                continue
            sc = rows[rows["scenario"] == scenario]
            records = [json.loads(t)["inputs"] for t in sc["sampler_inputs"]]
            x = {name: np.array([r[name] for r in records], dtype=float) for name in proposal.names}
            f = sc["collision"].astype(float).to_numpy()
            ratio = proposal.q_over_p(x)
            g = proposal.pi_hat(x)
            truth, mean_g = float(f.mean()), float(g.mean())
            chance = ratio / ratio.sum()
            rng = np.random.default_rng(args.seed)
            for n in args.n:
                plain, control = [], []
                for _ in range(args.replicates):
                    idx = rng.choice(len(f), size=n, p=chance)
                    w = ratio.mean() / ratio[idx]
                    p_est = is_estimate(f[idx], w)
                    c_est = cv_estimate(f[idx], w, g[idx], mean_g, 0.0) or p_est
                    plain.append((p_est.mean, p_est.low <= truth <= p_est.high))
                    control.append((c_est.mean, c_est.low <= truth <= c_est.high))
                p_arr, c_arr = np.array(plain), np.array(control)
                out.append(
                    {
                        "run": is_run.name,
                        "scenario": scenario,
                        "n": n,
                        "truth": truth,
                        "plain holds": float(p_arr[:, 1].mean()),
                        "cv holds": float(c_arr[:, 1].mean()),
                        "plain bias / sd": float((p_arr[:, 0].mean() - truth) / p_arr[:, 0].std()),
                        "cv bias / sd": float((c_arr[:, 0].mean() - truth) / c_arr[:, 0].std()),
                        "var cv / var plain": float(c_arr[:, 0].var() / p_arr[:, 0].var()),
                    }
                )
    with pd.option_context("display.width", 250):
        print(pd.DataFrame(out).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
