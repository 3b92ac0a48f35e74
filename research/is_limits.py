"""What limits importance sampling's efficiency on a scenario, measured on a plain Monte Carlo run's own rows.
Two numbers per scenario and condition, no SUMO run:

1. `proposal`: the efficiency of a fixed proposal q (the final stage's of an IS run) per final-stage
   episode, P(1 - P) / Var_q(w f), with Var_q(w f) = E_q[w^2 f^2] - P^2 = E_p[w f^2] - P^2 estimated on the
   MC rows (drawn from the nominal p): w(x) = p(x) / (lambda p(x) + (1 - lambda) q(x)) is the weight the IS
   run gives an episode with inputs x (the defensive mixture of sampling/draws.py), f the collision.
   It is the efficiency the IS run's final stage would show on average, without its run's noise. For a
   joint proposal also `proposal_efficiency_cv`: the same with pi_hat as a control variate at its best
   slope (the estimator of Table I under --is-family joint).
2. `sqrt_pi`: what a proposal shaped by the inputs' collision probability gives, whatever its form (not
   a product of one family per input as the cross-entropy stages fit). An episode's collision is random
   given its inputs x (background traffic, sensor noise, the SUMO dynamics are not proposed): with
   pi(x) = P(collision | x), Var_q(w f) = E_p[pi p / q] - P^2 is smallest at q ∝ p sqrt(pi) (Lagrange;
   the zero-variance proposal needs pi in {0, 1}). pi is estimated by a ridge logistic regression of the
   collision on the inputs (each continuous input, its square and pairwise products; categories as
   indicators) on one half of the rows; the proposal q = lambda p + (1 - lambda) p sqrt(pi) / E_p sqrt(pi)
   (the same defensive share) is then evaluated as in 1 on the other half, and the halves swapped: an
   out-of-sample efficiency of a real proposal, so neither the fit's smoothing nor its noise inflates it
   (it is not an upper bound: a sharper pi would do better). Also `r2` = Var(pi) / (P (1 - P)) on the
   held-out half, the share of the collision's variance the inputs explain.
3. `product_fit` (with --proposal): the cross-entropy method's own family, one per input the run proposed,
   fitted by its weighted maximum likelihood (Family.refit) on every collision of one half of the MC
   rows (the event itself as the elite, no smoothing, the spread floor of `--min-spread`), evaluated as
   in 1 on the other half and swapped: what the product family reaches on those inputs when its elite
   is every collision of 5,000 nominal episodes rather than a pilot stage's 20 episodes near the event.

    .venv/bin/python research/is_limits.py MC_RUN [--proposal IS_RUN [--stage S] [--min-spread F]] \
        [--inputs ...]
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

from pedsafe_sumo.sampling.draws import family_from_json, product_from_json
from pedsafe_sumo.sampling.importance import MIN_SPREAD_OF_NOMINAL, Categorical, Product
from pedsafe_sumo.sampling.joint import Block, JointProposal, fit_logistic, is_joint_json, quadratic_design
from pedsafe_sumo.sampling.stages import DEFENSIVE_SHARE

#: Ridge penalty of the logistic fit (on standardised inputs); small against 10,000 rows.
RIDGE = 1.0


def rows_of(run: Path) -> pd.DataFrame:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from is_validation import rows_of as read  # the same reader, unfinished runs included

    return read(run)


def inputs_of(rows: pd.DataFrame) -> tuple[pd.DataFrame, dict]:
    """The recorded inputs of `rows` (one column per input) and the nominal families of the proposable
    ones."""
    records = [json.loads(text) for text in rows["sampler_inputs"]]
    nominal: dict = {}
    for record in records:
        for name, family in record["nominal"].items():
            nominal.setdefault(name, family_from_json(family))
    return pd.DataFrame([r["inputs"] for r in records], index=rows.index), nominal


def proposal_efficiency(
    f: np.ndarray, inputs: pd.DataFrame, nominal: dict, proposal: Product, defensive_share: float
) -> tuple[float, float]:
    """(efficiency per final-stage episode, mean weight over the nominal rows) of `proposal` (module
    docstring, item 1); `f` the index per nominal row (0/1 for a rate)."""
    names = list(proposal.families)
    x = {name: inputs[name].to_numpy(dtype=float) for name in names}
    log_p = Product({name: nominal[name] for name in names}).log_pdf(x)
    log_q = proposal.log_pdf(x)
    lam = float(defensive_share)
    if lam > 0:
        # w = 1 / (lam + (1 - lam) q / p), as Draws.log_weight computes it.
        w = np.exp(-np.logaddexp(math.log(lam), math.log1p(-lam) + log_q - log_p))
    else:
        w = np.exp(log_p - log_q)
    p_hat = float(np.mean(f))
    variance = float(np.mean(w * f**2)) - p_hat**2
    efficiency = p_hat * (1 - p_hat) / variance if variance > 0 else math.inf
    return efficiency, float(np.mean(1.0 / w))  # E_p[q_mix / p] = 1: a check of the proposal's density


def joint_efficiency(f: np.ndarray, inputs: pd.DataFrame, joint: JointProposal) -> tuple[float, float]:
    """Item 1 for a joint proposal (sampling/joint.py): w = 1 / (q/p), q/p = lambda + (1 - lambda)
    sqrt(pi_hat) / c, the defensive mixture being part of q."""
    ratio = joint.q_over_p({name: inputs[name].to_numpy(dtype=float) for name in joint.names})
    w = 1.0 / ratio
    p_hat = float(np.mean(f))
    variance = float(np.mean(w * f**2)) - p_hat**2
    return (p_hat * (1 - p_hat) / variance if variance > 0 else math.inf), float(np.mean(ratio))


def joint_cv_efficiency(f: np.ndarray, inputs: pd.DataFrame, joint: JointProposal) -> float:
    """Item 1 for a joint proposal with pi_hat as a control variate (sampling/control_variate.py): the
    regression estimator's variance per final-stage episode at its best slope, Var_q(Y - beta C) with
    Y = w f and C = w g - mu, g = pi_hat(x), mu = E_p[g]; every moment under q taken on the nominal rows as
    E_q[h] = E_p[h / w]. The slope is the one the run would estimate with many rows."""
    x = {name: inputs[name].to_numpy(dtype=float) for name in joint.names}
    w = 1.0 / joint.q_over_p(x)
    g = joint.pi_hat(x)
    p_hat, mu = float(np.mean(f)), float(np.mean(g))
    control = w * g - mu
    slope = float(np.mean(f * control)) / float(np.mean(control**2 / w))  # cov_q(Y, C) / var_q(C)
    variance = float(np.mean((w * f - slope * control) ** 2 / w)) - p_hat**2
    return p_hat * (1 - p_hat) / variance if variance > 0 else math.inf


def product_fit_efficiency(
    y: np.ndarray,
    inputs: pd.DataFrame,
    nominal: dict,
    names: list[str],
    defensive_share: float,
    min_spread: float,
    seed: int = 0,
) -> float:
    """Item 3 of the module docstring: the mean over the two held-out halves."""
    if not names or not 0 < float(np.mean(y)) < 1:
        return math.nan
    fold = np.random.default_rng(seed).integers(2, size=len(y))
    out = []
    for k in (0, 1):
        fit, held = (fold != k) & (y > 0), fold == k
        families = {
            name: nominal[name].smoothed(
                nominal[name].refit(inputs.loc[fit, name].to_numpy(dtype=float), np.ones(int(fit.sum()))),
                1.0,
                nominal[name],
                min_spread,
            )
            for name in names
        }
        efficiency, _ = proposal_efficiency(
            y[held], inputs[held], nominal, Product(families), defensive_share
        )
        out.append(efficiency)
    return float(np.mean(out))


def _design(inputs: pd.DataFrame, categorical: set[str]) -> np.ndarray:
    """sampling.joint's features, standardised by the rows' own moments (categories by the values seen)."""
    blocks: list[Block] = []
    for name in inputs.columns:
        v = inputs[name].to_numpy(dtype=float)
        if name in categorical:
            blocks.append([(v == k).astype(float) for k in np.unique(v)[1:]])
        elif np.std(v) > 0:
            blocks.append((v - v.mean()) / v.std())
    return quadratic_design(len(inputs), blocks)


def sqrt_pi_efficiency(
    y: np.ndarray, inputs: pd.DataFrame, categorical: set[str], defensive_share: float, seed: int = 0
) -> tuple[float, float, float]:
    """(efficiency on each held-out half, averaged; the two halves' spread as max - min; r2) of the
    module docstring, item 2."""
    p_hat = float(np.mean(y))
    if not 0 < p_hat < 1:
        return math.nan, math.nan, math.nan
    x = _design(inputs, categorical)
    fold = np.random.default_rng(seed).integers(2, size=len(y))
    efficiencies, r2 = [], []
    for k in (0, 1):
        beta = fit_logistic(x[fold != k], y[fold != k], RIDGE)
        pi = special.expit(x[fold == k] @ beta)
        held = y[fold == k]
        w = 1.0 / (defensive_share + (1 - defensive_share) * np.sqrt(pi) / np.mean(np.sqrt(pi)))
        p_k = float(np.mean(held))
        if p_k == 0:  # no collision in this half (a handful in the run): nothing to score it on
            efficiencies.append(math.nan)
            r2.append(math.nan)
            continue
        efficiencies.append(p_k * (1 - p_k) / (float(np.mean(w * held)) - p_k**2))
        r2.append(float(np.var(pi) / (p_k * (1 - p_k))))
    return float(np.nanmean(efficiencies)), max(efficiencies) - min(efficiencies), float(np.nanmean(r2))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("--proposal", type=Path, help="an IS run: its final-stage proposal per scenario")
    parser.add_argument("--inputs", choices=("proposed", "all"), default="proposed")
    parser.add_argument(
        "--min-spread", type=float, default=MIN_SPREAD_OF_NOMINAL, help="spread floor of product_fit [0.7071]"
    )
    parser.add_argument(
        "--stage",
        type=int,
        default=-1,
        help="which stage's proposal of --proposal (0 the nominal) [the final]",
    )
    args = parser.parse_args(argv)
    try:
        mc = rows_of(args.mc_run)
        info = json.loads((args.proposal / "run.json").read_text()) if args.proposal else {}
    except (OSError, ValueError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    proposals = info.get("sampler_proposals", {})
    share = float(info.get("sampler", {}).get("defensive_share", 0.0)) if info else 0.0
    out = []
    for (scenario, condition), rows in mc[mc["status"] == "ok"].groupby(["scenario", "condition"]):
        if args.proposal and scenario not in proposals:
            continue
        inputs, nominal = inputs_of(rows)
        categorical = {n for n, fam in nominal.items() if isinstance(fam, Categorical)}
        categorical |= {"ped_female", "ped_age_in_group", "clothing"}
        kept = [c for c in inputs.columns if not c.endswith(".colour") and not c.startswith("queued_")]
        chosen = sorted(nominal) if args.inputs == "proposed" else kept
        y = rows["collision"].astype(float).to_numpy()
        sqrt_pi, spread, r2 = sqrt_pi_efficiency(
            y, inputs[chosen].fillna(0.0), categorical, share or DEFENSIVE_SHARE
        )
        row = {"scenario": scenario, "condition": condition, "n": len(y), "collision_rate": y.mean()}
        row.update(r2=r2, sqrt_pi=sqrt_pi, sqrt_pi_halves_differ=spread)
        if args.proposal:
            final = proposals[scenario][args.stage]
            if is_joint_json(final):  # --is-family joint: q/p from the stored coefficients
                joint = JointProposal.from_json(final)
                row["proposed"] = "joint:" + ",".join(joint.names)
                row["proposal_efficiency"], row["mean_q_over_p"] = joint_efficiency(y, inputs, joint)
                row["proposal_efficiency_cv"] = joint_cv_efficiency(y, inputs, joint)
                out.append(row)
                continue
            proposal = product_from_json(final) if final else Product({})
            row["proposed"] = ",".join(sorted(proposal.families)) or "-"
            row["proposal_efficiency"], row["mean_q_over_p"] = proposal_efficiency(
                y, inputs, nominal, proposal, share
            )
            row["product_fit"] = product_fit_efficiency(
                y, inputs, nominal, sorted(proposal.families), share, args.min_spread
            )
        out.append(row)
    with pd.option_context("display.width", 250, "display.max_columns", 20, "display.max_colwidth", 80):
        print(pd.DataFrame(out).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
