"""Why V2I gains less than SV under a proposal fitted on SV's collisions (offline).

For the final stage of each importance-sampling run given: how many pairs collide under SV and under V2I,
the median weight and SV pi_hat at each kind of collision, and the relative variance per episode of w f
(var(w f) / mean(w f)^2) for both. Then, pooled over the runs given in one argument (comma-separated),
whether the proposable inputs predict V2I's collision among the pairs where SV collides: the 2-fold
cross-validated AUC of a ridge logistic on the standardised inputs and their squares (0.5: no information),
and the best single inputs by their own AUC.

    .venv/bin/python research/experiments/is_v2i_within_sv.py RUN[,RUN...] [RUN[,RUN...] ...]
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
import pandas as pd
from scipy.special import expit

from pedsafe_sumo.sampling.control_variate import pi_hat_of_inputs, stage_control


def stage_pairs(rows: pd.DataFrame) -> pd.DataFrame:
    """The pairs of `rows` with both conditions ok, by episode: SV's weight, inputs, stage and collision,
    and V2I's collision (`collision_v2i`)."""
    ok = rows[rows["status"] == "ok"]
    sv = ok[ok["condition"] == "sv"].set_index("episode")
    v2i = ok[ok["condition"] == "v2i"].set_index("episode")
    return sv[["weight", "collision", "sampler_inputs", "sampler_stage"]].merge(
        v2i[["collision"]], left_index=True, right_index=True, suffixes=("", "_v2i")
    )


def final_pairs(run: str) -> tuple[pd.DataFrame, list[str]]:
    """The final stage's pairs (stage_pairs), and the scenario's stored proposals."""
    rows = pd.read_parquet(f"{run}/episodes.parquet")
    info = json.loads(open(f"{run}/run.json").read())
    pairs = stage_pairs(rows[rows["sampler_stage"] == rows["sampler_stage"].max()])
    return pairs, info["sampler_proposals"][str(rows["scenario"].iloc[0])]


def relative_variance(products: np.ndarray) -> float:
    return float(np.var(products, ddof=1) / np.mean(products) ** 2)


def auc(score: np.ndarray, label: np.ndarray) -> float:
    """Mann-Whitney AUC of `score` for the positives of `label`."""
    ranks = np.empty(len(score))
    ranks[np.argsort(score)] = np.arange(1, len(score) + 1)
    n1 = float(label.sum())
    n0 = len(label) - n1
    return float((ranks[label == 1].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def ridge_logistic(design: np.ndarray, label: np.ndarray, ridge: float = 1.0) -> np.ndarray:
    """Newton's method on the ridge-penalised log-likelihood."""
    b = np.zeros(design.shape[1])
    for _ in range(50):
        p = expit(design @ b)
        hessian = design.T @ (design * (p * (1 - p))[:, None]) + ridge * np.eye(design.shape[1])
        b += np.linalg.solve(hessian, design.T @ (label - p) - ridge * b)
    return b


def describe_run(run: str) -> None:
    pairs, proposals = final_pairs(run)
    control = stage_control(proposals, int(pairs["sampler_stage"].iloc[0]))
    w = pairs["weight"].to_numpy(dtype=float)
    sv = pairs["collision"].to_numpy(dtype=bool)
    v2i = pairs["collision_v2i"].to_numpy(dtype=bool)
    line = f"{run}: {len(w)} pairs, SV hits {sv.sum()}, V2I hits {v2i.sum()}, V2I only {np.sum(v2i & ~sv)}"
    line += f"; median weight at SV hits {np.median(w[sv]):.3f}, at V2I hits {np.median(w[v2i]):.3f}"
    if control is not None:
        g = pi_hat_of_inputs(control, pairs["sampler_inputs"].tolist())
        line += f"; median SV pi_hat at SV hits {np.median(g[sv]):.2f}, at V2I hits {np.median(g[v2i]):.2f}"
    line += f"; relative variance SV {relative_variance(w * sv):.1f}, V2I {relative_variance(w * v2i):.1f}"
    print(line)


def predictability(runs: list[str], rng: np.random.Generator) -> None:
    inputs, labels = [], []
    for run in runs:
        pairs, _ = final_pairs(run)
        hit = pairs[pairs["collision"].astype(bool)]
        inputs += [json.loads(text)["inputs"] for text in hit["sampler_inputs"]]
        labels.append(hit["collision_v2i"].to_numpy(dtype=float))
    label = np.concatenate(labels)
    names = sorted(name for name in inputs[0] if all(name in record for record in inputs))
    x = np.array([[record[name] for name in names] for record in inputs], dtype=float)
    varying = x.std(axis=0) > 0
    x, names = x[:, varying], [name for name, keep in zip(names, varying, strict=True) if keep]
    z = (x - x.mean(axis=0)) / x.std(axis=0)
    design = np.column_stack([np.ones(len(z)), z, z**2])
    fold = rng.permutation(len(label)) % 2
    score = np.empty(len(label))
    for k in (0, 1):
        coefficients = ridge_logistic(design[fold != k], label[fold != k])
        score[fold == k] = design[fold == k] @ coefficients
    single = {name: max(auc(z[:, i], label), 1 - auc(z[:, i], label)) for i, name in enumerate(names)}
    best = sorted(single.items(), key=lambda item: -item[1])[:3]
    print(
        f"{', '.join(runs)}: among {len(label)} SV collisions, V2I collides in {int(label.sum())} "
        f"({label.mean():.2f}); cross-validated AUC {auc(score, label):.3f}; best single inputs "
        + ", ".join(f"{name} {value:.2f}" for name, value in best)
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("groups", nargs="+", help="IS run directories, comma-separated within a group")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    for group in args.groups:
        runs = group.split(",")
        for run in runs:
            describe_run(run)
        predictability(runs, rng)
    return 0


if __name__ == "__main__":
    sys.exit(main())
