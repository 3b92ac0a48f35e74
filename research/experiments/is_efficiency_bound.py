"""How much can importance sampling gain? Two figures from a plain Monte Carlo run's own rows, no SUMO.

Run (needs scikit-learn, which the package does not depend on: `pip install scikit-learn` in any venv with
pandas and pyarrow):

    OMP_NUM_THREADS=1 python research/experiments/is_efficiency_bound.py RUN_DIR      # 1-8 min on 1 core

For a binary event Y (collision) whose probability given the episode's drawn inputs x is pi(x), the
proposal over x with the smallest variance is q*(x) ~ p(x) sqrt(pi(x)) (E[Y^2 | x] = pi(x) in the
optimal-proposal argument, Owen, Monte Carlo theory, methods and examples, 2013, section 9.1): the
randomness left once x is fixed (background traffic, SUMO's own draws, the stack) cannot be sampled away.
pi_hat is a 5-fold gradient-boosting fit, each row predicted by the model that did not see it. Per
scenario, condition and set of inputs (all drawn inputs, the ones the IS sampler can propose, those plus
the pedestrian's clothing), two figures:

- plug-in: p(1 - p) / ((E_p[sqrt(pi_hat)])^2 - p^2), pi_hat taken as if it were pi. Not a bound: the
  fit's noise spreads pi_hat and inflates it, its smoothing deflates it.
- held-out: the efficiency per final-stage episode of the real proposal q = 0.1 p + 0.9 p sqrt(pi_hat) /
  E_p[sqrt(pi_hat)] (the sampler's defensive share), scored on the rows' own outcomes, which its pi_hat
  never saw: P(1 - P) / (E_p[w f] - P^2), w = p / q. An achievable figure (a lower bound on what the best
  proposal of these inputs reaches), the same estimator as research/is_limits.py's `sqrt_pi` with a sharper
  pi_hat (is_limits fits a ridge logistic regression).

Neither counts the cost of learning the proposal: pi_hat here comes from 8,000 MC episodes per fold.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

try:
    from sklearn.ensemble import HistGradientBoostingClassifier
    from sklearn.model_selection import StratifiedKFold
except ImportError:
    sys.exit(
        "is_efficiency_bound: needs scikit-learn (pip install scikit-learn); the package does not use it"
    )

FOLDS = 5
MIN_COLLISIONS = 10


def out_of_fold_probability(features: pd.DataFrame, outcome: np.ndarray) -> np.ndarray:
    probability = np.zeros(len(outcome))
    for train, test in StratifiedKFold(FOLDS, shuffle=True, random_state=0).split(features, outcome):
        model = HistGradientBoostingClassifier(
            max_iter=100, learning_rate=0.1, min_samples_leaf=40, random_state=0
        ).fit(features.iloc[train], outcome[train])
        probability[test] = model.predict_proba(features.iloc[test])[:, 1]
    return probability * outcome.mean() / probability.mean()


def efficiency_bound(probability: np.ndarray, rate: float) -> float:
    return rate * (1 - rate) / (np.mean(np.sqrt(probability)) ** 2 - rate**2)


def held_out_efficiency(probability: np.ndarray, outcome: np.ndarray, defensive_share: float = 0.1) -> float:
    """Efficiency per episode of the real proposal q = s p + (1 - s) p sqrt(pi_hat) / E_p[sqrt(pi_hat)],
    pi_hat of each row predicted by a model that never saw it, scored on the rows' own outcomes:
    Var_q(w f) = E_p[w f] - P^2 with w = p / q (research/is_limits.py's `sqrt_pi`, with another pi_hat)."""
    shape = np.sqrt(probability) / np.mean(np.sqrt(probability))
    weight = 1.0 / (defensive_share + (1 - defensive_share) * shape)
    rate = outcome.mean()
    return rate * (1 - rate) / (np.mean(weight * outcome) - rate**2)


def main(run: Path) -> None:
    parts = sorted(run.glob("parts/*.parquet")) or [run / "episodes.parquet"]
    columns = ["scenario", "condition", "collision", "sampler_inputs", "status"]
    table = pd.concat(pd.read_parquet(p, columns=columns) for p in parts)
    table = table[table.status == "ok"]
    print(
        "| scenario | condition | episodes | collisions | rate | all drawn inputs | proposable | + clothing |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for (scenario, condition), group in table.groupby(["scenario", "condition"]):
        draws = [json.loads(text) for text in group.sampler_inputs]
        inputs = pd.DataFrame([d["inputs"] for d in draws]).fillna(-1.0)
        proposable = [name for name in draws[0]["nominal"] if name in inputs]
        outcome = group.collision.to_numpy().astype(int)
        rate = float(outcome.mean())
        cells = []
        for names in (list(inputs.columns), proposable, [*proposable, "clothing"]):
            if outcome.sum() < MIN_COLLISIONS:
                cells.append("n/a")
                continue
            probability = out_of_fold_probability(inputs[names], outcome)
            bound = efficiency_bound(probability, rate)
            cells.append(f"{bound:.1f}x / {held_out_efficiency(probability, outcome):.1f}x")
        print(
            f"| {scenario} | {condition} | {len(outcome)} | {outcome.sum()} | {rate:.4f} | "
            + " | ".join(cells)
            + " |",
            flush=True,
        )


if __name__ == "__main__":
    if len(sys.argv) != 2 or not Path(sys.argv[1]).is_dir():
        sys.exit("usage: is_efficiency_bound.py RUN_DIR (a plain Monte Carlo run with sampler_inputs)")
    main(Path(sys.argv[1]))
