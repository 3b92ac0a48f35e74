"""Would a joint proposal learned from the pilots beat the product family? Measured on a plain Monte Carlo
run's own rows, no SUMO.

The proposal over the scenario's proposable inputs x (the `nominal` families recorded in sampler_inputs)
is q = lambda p + (1 - lambda) p sqrt(pi_hat(x)) / E_p[sqrt(pi_hat)] (lambda = 0.1, the sampler's
defensive share), with pi_hat(x) a ridge logistic regression of the SV collision on x (continuous inputs
standardised by the nominal's moments, their squares and pairwise products; categories as indicators),
fitted on PILOT-SIZED samples only:

- `nominal N`: the first pilot stage alone, N nominal episodes (rows of the MC run);
- `2-stage`: a stage 0 of 200 nominal episodes, pi_hat fitted on it, then a stage 1 of 200 episodes drawn
  from that stage's joint proposal, simulated exactly by rejection from further MC rows (a row is kept
  with probability (q/p) / max(q/p); q/p <= lambda + (1 - lambda) / E_p[sqrt(pi_hat)]), and pi_hat refitted
  on the 400 pooled rows (pi is a conditional probability, so rows from any proposal pool unweighted);
- `near`: as `nominal N`, but pi_hat fitted to the pilot's elite (the top 10% by the sampler's TTC score,
  1 + impact speed for a collision, -min_ttc_s otherwise, -1000 without a TTC) rather than to its few
  collisions: a shape that sees more events, at the price of aiming at near misses.

Each is evaluated, as research/is_limits.py does, on the MC rows neither the pilot nor the rejection step
used: efficiency per final episode P(1 - P) / (E_p[w f] - P^2), w = p / q. Repeated on `--replicates` disjoint
blocks of rows (pilot sets that do not overlap), the median and range reported.

    .venv/bin/python research/experiments/is_joint_pilot.py V5_FULL [--ridge 1 3 10]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import special

from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.draws import family_from_json
from pedsafe_sumo.sampling.importance import Categorical
from pedsafe_sumo.sampling.joint import Block, fit_logistic, quadratic_design

DEFENSIVE_SHARE = 0.1
ELITE_FRACTION = 0.1
NO_TTC_SCORE = -1000.0


#: `--ridge cv`: the penalties it chooses from (a log grid around the sampler's 1, spanning the values the
#: ridge table of EXPERIMENTS.md looked at), fixed before the measurement, and its folds.
RIDGE_GRID = (0.1, 0.3, 1.0, 3.0, 10.0)
CV_FOLDS = 5


def cv_folds(y: np.ndarray, folds: int, rng: np.random.Generator) -> np.ndarray:
    """Each row's fold, 0..folds-1: the collisions and the other rows each shuffled by `rng` and dealt
    round-robin (stratified, so that every fold holds about as many of the pilot's few collisions)."""
    fold = np.empty(len(y), dtype=int)
    for members in (np.flatnonzero(y > 0), np.flatnonzero(y <= 0)):
        fold[rng.permutation(members)] = np.arange(len(members)) % folds
    return fold


def cv_log_likelihood(x: np.ndarray, y: np.ndarray, ridge: float, fold: np.ndarray) -> float:
    """The held-out Bernoulli log-likelihood of the fits with penalty `ridge`, summed over the folds."""
    total = 0.0
    for k in np.unique(fold):
        held = fold == k
        eta = x[held] @ fit_logistic(x[~held], y[~held], ridge)
        total -= float(np.sum(np.logaddexp(0, eta) - y[held] * eta))
    return total


def cv_ridge(
    x: np.ndarray,
    y: np.ndarray,
    rng: np.random.Generator,
    grid: tuple[float, ...] = RIDGE_GRID,
    folds: int = CV_FOLDS,
) -> tuple[float, dict[float, float]]:
    """The penalty of `grid` with the largest K-fold cross-validated log-likelihood on (x, y) (the first of
    equals: the smallest), and every penalty's score. With fewer collisions than folds some folds hold
    none; the score is still the held-out likelihood of every row."""
    fold = cv_folds(np.asarray(y, dtype=float), min(folds, len(y)), rng)
    scores = {float(r): cv_log_likelihood(x, np.asarray(y, dtype=float), float(r), fold) for r in grid}
    best = max(scores, key=lambda r: (scores[r], -r))
    return best, scores


def design(inputs: pd.DataFrame, spec: dict) -> np.ndarray:
    """Features of `inputs` under a fixed `spec` (the nominal's moments and categories), the same for the
    pilot and the rows it is evaluated on: sampling.joint's model."""
    blocks: list[Block] = []
    for name, (kind, a, b) in spec.items():
        v = inputs[name].to_numpy(dtype=float)
        blocks.append([(v == k).astype(float) for k in range(1, int(a))] if kind == "cat" else (v - a) / b)
    return quadratic_design(len(inputs), blocks)


def efficiency(y: np.ndarray, root_pi: np.ndarray, norm: float) -> float:
    w = 1.0 / (DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * root_pi / norm)
    p = float(np.mean(y))
    variance = float(np.mean(w * y)) - p * p
    return p * (1 - p) / variance if variance > 0 else math.inf


def evaluate(beta: np.ndarray, x_eval: np.ndarray, y_eval: np.ndarray) -> float:
    root_pi = np.sqrt(special.expit(x_eval @ beta))
    # E_p[sqrt(pi_hat)]: the eval rows are nominal draws (the implementation would use nominal draws of a
    # fixed seed, no SUMO).
    return efficiency(y_eval, root_pi, float(np.mean(root_pi)))


def fitter(ridge: str, replicate: int, chosen: list[float]):
    """fit(x, y) with a fixed penalty, or with the penalty chosen by sampling.joint.cv_ridge on the very
    rows it fits (folds from a Generator of the replicate, as the sampler's come from the run seed)."""
    if ridge != "cv":
        return lambda x, y: fit_logistic(x, y, float(ridge))
    rng = np.random.default_rng(replicate)

    def fit(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        best, _ = cv_ridge(x, y, rng)
        chosen.append(best)
        return fit_logistic(x, y, best)

    return fit


def design_spec(nominal: dict, inputs: pd.DataFrame) -> dict:
    """`design`'s description of each input: a category's number of levels, or a continuous input's mean
    and sd over these rows (nominal draws: their moments are the nominal's)."""
    spec = {}
    for name, fam in nominal.items():
        if isinstance(fam, Categorical):
            spec[name] = ("cat", len(fam.probabilities), 0)
        else:
            v = inputs[name].to_numpy(dtype=float)
            spec[name] = ("cont", float(v.mean()), float(v.std()))
    return spec


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("--ridge", nargs="+", default=["1", "3", "10"], help="penalties, or cv")
    parser.add_argument("--replicates", type=int, default=5)
    parser.add_argument("--condition", default="sv")
    parser.add_argument(
        "--with-sex",
        action="store_true",
        help="add the pedestrian's sex (ped_female, drawn but not proposed by the sampler; its nominal "
        "from defaults.toml) to the inputs the proposal and pi_hat cover (a lead of is_within_episode.py)",
    )
    args = parser.parse_args(argv)
    rows = pd.read_parquet(args.mc_run / "episodes.parquet")
    rows = rows[(rows["status"] == "ok") & (rows["condition"] == args.condition)]
    out = []
    for scenario, sc in rows.groupby("scenario"):
        sc = sc.sort_values("episode")
        records = [json.loads(t) for t in sc["sampler_inputs"]]
        nominal = {n: family_from_json(f) for n, f in records[0]["nominal"].items()}
        if args.with_sex:
            share = float(load_params()["pedestrians"]["gender_female_share"])
            nominal["ped_female"] = Categorical((1.0 - share, share))
        inputs = pd.DataFrame([r["inputs"] for r in records])[sorted(nominal)].fillna(0.0)
        x = design(inputs, design_spec(nominal, inputs))
        y = sc["collision"].astype(float).to_numpy()
        ttc = sc["min_ttc_s"].to_numpy(dtype=float)
        impact = sc["impact_speed_mps"].fillna(0.0).to_numpy(dtype=float)
        score = np.where(y > 0, 1 + impact, np.where(np.isnan(ttc), NO_TTC_SCORE, -ttc))
        n = len(y)
        block = n // args.replicates
        for ridge in args.ridge:
            kinds = ("nominal 200", "nominal 400", "2-stage", "near 200", "near 400", "all-but-block (8,000)")
            res: dict[str, list[float]] = {kind: [] for kind in kinds}
            chosen: dict[str, list[float]] = {kind: [] for kind in kinds}
            for r in range(args.replicates):
                fits = {kind: fitter(ridge, r, chosen[kind]) for kind in kinds}
                start = r * block
                order = np.r_[np.arange(start, n), np.arange(0, start)]  # this replicate's rows first
                for size in (200, 400):
                    pilot, held = order[:size], order[size:]
                    if y[pilot].sum() > 0:
                        beta = fits[f"nominal {size}"](x[pilot], y[pilot])
                        res[f"nominal {size}"].append(evaluate(beta, x[held], y[held]))
                    else:
                        res[f"nominal {size}"].append(1.0)  # no collision: the sampler would stay nominal
                    level = min(1.0, float(np.quantile(score[pilot], 1 - ELITE_FRACTION)))
                    elite = (score[pilot] >= level).astype(float)
                    res[f"near {size}"].append(
                        evaluate(fits[f"near {size}"](x[pilot], elite), x[held], y[held])
                    )
                # 2-stage: stage 0 on 200 nominal rows, stage 1 by rejection from the next rows.
                s0 = order[:200]
                beta0 = fits["2-stage"](x[s0], y[s0]) if y[s0].sum() > 0 else None
                rest = order[200:]
                if beta0 is None:
                    s1, used = rest[:200], 200
                else:
                    root = np.sqrt(special.expit(x[rest] @ beta0))
                    norm = float(np.mean(root))  # on nominal rows: E_p[sqrt(pi_hat)]
                    ratio = DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * root / norm
                    bound = DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) / norm
                    u = np.random.default_rng(r).random(len(rest))
                    kept = np.flatnonzero(u < ratio / bound)[:200]
                    s1, used = rest[kept], int(kept[-1]) + 1
                pooled = np.r_[s0, s1]
                held = rest[used:]
                beta1 = fits["2-stage"](x[pooled], y[pooled])
                res["2-stage"].append(evaluate(beta1, x[held], y[held]))
                # reference: pi_hat from the 8,000 rows outside this replicate's block
                inside = order[:block]
                outside = order[block:]
                res["all-but-block (8,000)"].append(
                    evaluate(fits["all-but-block (8,000)"](x[outside], y[outside]), x[inside], y[inside])
                )
            for kind, values in res.items():
                v = np.array(values)
                out.append(
                    {
                        "scenario": scenario,
                        "ridge": ridge,
                        "pi_hat from": kind,
                        "median": float(np.median(v)),
                        "min": float(v.min()),
                        "max": float(v.max()),
                        "replicates": " ".join(f"{e:.3g}" for e in v),
                        "cv chose": " ".join(f"{c:g}" for c in chosen[kind]),
                    }
                )
    table = pd.DataFrame(out)
    with pd.option_context("display.width", 200, "display.max_rows", 500):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
