"""How far a proposal learned from episodes can reach, by the number of episodes it learns from and by the
model class, with and without pi_hat as a control variate. Offline, no SUMO.

On a plain Monte Carlo run's SV rows (v5_full: 10,000 per scenario), pi_hat is fitted on N rows drawn at
random (a nominal pilot of N episodes; a pilot drawn from a proposal holds more collisions per episode, so
this is the cautious side) and the joint proposal q = 0.1 p + 0.9 p sqrt(pi_hat) / E_p[sqrt(pi_hat)] is
evaluated on the other rows (nominal draws), as research/experiments/is_joint_pilot.py does:

- plain IS, efficiency per final episode P (1 - P) / (E_p[w f] - P^2), w = p/q;
- IS with pi_hat as a control variate (the estimator of report/tables.py for joint runs, here with the
  slope beta = 1 instead of the regression's, which can only do better): E_p[pi_hat] + mean_q[w (f -
  pi_hat)], variance E_p[w (f - pi_hat)^2] - (P - E_p[pi_hat])^2; E_p[pi_hat] and E_p[sqrt(pi_hat)] on
  all the rows (nominal draws).

Models: `logistic` is the sampler's (sampling.joint: ridge 1, the quadratic design of the inputs and the
kinematic features v, 1/w, margin_s of is_pihat_shape.py, D = 2.3 m); `boosting` is scikit-learn's
HistGradientBoostingClassifier on the inputs (+ the kinematic features), settings fixed before any score
(200 trees, learning rate 0.05, 15 leaves, 20 rows per leaf, l2 1.0); it needs scikit-learn, which is not
a dependency of pedsafe_sumo (pip install scikit-learn in a scratch environment; without it the boosting
rows are skipped with a line).

Medians over `--replicates` random splits (seeded by the replicate number).

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_model_reach.py V5_FULL
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import special

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from is_pihat_shape import scenario_data  # noqa: E402

from pedsafe_sumo.params import load_params  # noqa: E402
from pedsafe_sumo.sampling.joint import RIDGE, fit_logistic  # noqa: E402

DEFENSIVE_SHARE = 0.1
PILOT_ROWS = (400, 1_000, 2_000, 4_000, 8_000)
BOOSTING_ROWS = 8_000


def efficiencies(pi_eval: np.ndarray, y: np.ndarray, pi_all: np.ndarray) -> tuple[float, float]:
    """(plain IS, IS with the control variate) per final episode on the nominal rows y (module docstring)."""
    root = np.sqrt(pi_eval)
    ratio = DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * root / float(np.mean(np.sqrt(pi_all)))
    p = float(np.mean(y))
    plain = float(np.mean(y / ratio)) - p * p
    with_control = float(np.mean((y - pi_eval) ** 2 / ratio)) - (p - float(np.mean(pi_all))) ** 2
    return (
        p * (1 - p) / plain if plain > 0 else math.inf,
        p * (1 - p) / with_control if with_control > 0 else math.inf,
    )


def boosting_probabilities(x: np.ndarray, y: np.ndarray, train: np.ndarray) -> np.ndarray | None:
    try:
        from sklearn.ensemble import HistGradientBoostingClassifier
    except ImportError:
        return None
    model = HistGradientBoostingClassifier(
        max_iter=200,
        learning_rate=0.05,
        max_leaf_nodes=15,
        min_samples_leaf=20,
        l2_regularization=1.0,
        random_state=0,
    )
    model.fit(x[train], y[train])
    return np.clip(model.predict_proba(x)[:, 1], 1e-6, 1.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("--replicates", type=int, default=5)
    args = parser.parse_args(argv)
    params = load_params()
    rows = pd.read_parquet(args.mc_run / "episodes.parquet")
    rows = rows[(rows["status"] == "ok") & (rows["condition"] == "sv")]
    out = []
    boosting_missing = False
    for scenario, sc in rows.groupby("scenario"):
        data = scenario_data(sc.sort_values("episode"), scenario, params, args.replicates)
        y, n = data["y"], len(data["y"])
        inputs = data["inputs"].to_numpy(dtype=float)
        raw_kinematic = np.column_stack(
            [sc.sort_values("episode")["ego_initial_speed_mps"].to_numpy(float)]
            + [1.0 / sc.sort_values("episode")["ped_speed_mps"].to_numpy(float), data["margin"]]
        )
        fits = [("logistic", rows_n, data["x_physics"]) for rows_n in PILOT_ROWS]
        fits += [
            ("boosting, inputs", BOOSTING_ROWS, inputs),
            ("boosting, inputs + kinematic", BOOSTING_ROWS, np.column_stack([inputs, raw_kinematic])),
        ]
        for model, n_train, x in fits:
            results = []
            for r in range(args.replicates):
                order = np.random.default_rng(r).permutation(n)
                train, held = order[:n_train], order[n_train:]
                if model == "logistic":
                    pi = special.expit(x @ fit_logistic(x[train], y[train], RIDGE))
                else:
                    pi = boosting_probabilities(x, y, train)
                    if pi is None:
                        boosting_missing = True
                        break
                results.append(efficiencies(pi[held], y[held], pi))
            if not results:
                continue
            eff = np.array(results)
            out.append(
                {
                    "scenario": scenario,
                    "model": model,
                    "rows fitted": n_train,
                    "IS per final episode": f"{np.median(eff[:, 0]):.3g} [{eff[:, 0].min():.3g}, "
                    f"{eff[:, 0].max():.3g}]",
                    "IS + control variate": f"{np.median(eff[:, 1]):.3g} [{eff[:, 1].min():.3g}, "
                    f"{eff[:, 1].max():.3g}]",
                }
            )
    if boosting_missing:
        print("scikit-learn is not installed: the boosting rows are left out", file=sys.stderr)
    with pd.option_context("display.width", 250, "display.max_rows", 500):
        print(pd.DataFrame(out).to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
