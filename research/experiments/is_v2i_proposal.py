"""Would a proposal aimed at V2I's collisions too gain on V2I? (Offline, no SUMO.)

The sampler's joint proposal is q ∝ p (lambda + (1 - lambda) sqrt(pi_sv) / c), pi_sv a ridge logistic of
the SV collision on the pilots' inputs (sampling/joint.py). For two rates P_sv and P_v2i from one draw, the
proposal that minimises the sum of their relative variances is q ∝ p sqrt(pi_sv / P_sv^2 + pi_v2i / P_v2i^2)
(the argument of Owen 2013, section 9.1, for one rate, applied to the sum; pi the conditional probabilities
given x). This tool fits pi_v2i on the same pilot rows with the same design and ridge, and scores

    q_alpha ∝ p (lambda + (1 - lambda) sqrt(alpha pi_sv + (1 - alpha) pi_v2i) / c_alpha)

for alpha = 1 (the sampler's, a check: its pi_sv must equal the stored one), 1/2, the relative-variance
rule alpha = m_v2i^2 / (m_sv^2 + m_v2i^2) (m = E_p[pi_hat] on nominal draws) and 0 (V2I alone); and
"factor + v2i-only", the V2I factor plus a fit of the V2I-only collisions inside h, and
"mixture v2i-only", that fit as a mixture component of its own with a share mu of the draws.

Scoring without new episodes: the run's final stage drew x from its proposal q with weights w = p/q, so
for any q' with weights w' = p/q' (q' > 0 where q is: the defensive share keeps q >= lambda p)

    E_q'[w'^2 f] = E_p[f p/q'] = E_q[w w' f],

and the efficiency per final episode of plain IS under q' is P (1 - P) / (mean(w w' f) - P^2), P = mean(w
f). With pi_hat g as a control variate (known mean mu_g) at its best slope b, the variance is E_q[w w' (f - b
g)^2] - (P - b mu_g)^2. `--oracle` refits pi_sv and pi_v2i on the final stage's own rows (in-sample, so
optimistic): how much a sharper fit of the same form could give at most.

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_v2i_proposal.py RUN [RUN ...] \\
        [--oracle]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

from is_v2i_within_sv import stage_pairs  # noqa: E402

from pedsafe_sumo.sampling.joint import NORM_SEED, RIDGE, JointProposal, fit_logistic  # noqa: E402
from pedsafe_sumo.sampling.stages import _inputs_and_nominal  # noqa: E402

#: Nominal draws for c_alpha and m (a relative error of about 1e-3 on c, as the sampler's NORM_DRAWS / 2.5).
NOMINAL_DRAWS = 400_000
#: Shares of the draws given to the V2I-only mixture component.
MIXTURE_SHARES = (0.05, 0.1, 0.2)


def reweighted_efficiency(
    f: np.ndarray,
    weight: np.ndarray,
    new_weight: np.ndarray,
    control: np.ndarray | None = None,
    control_mean: float = math.nan,
) -> tuple[float, float, float]:
    """(P, efficiency of plain IS per episode, efficiency with `control` at its best slope) of the proposal
    whose weights are `new_weight`, from rows drawn from another proposal with weights `weight` (module
    docstring); the third is NaN without a control."""
    f, w, wn = (np.asarray(a, dtype=float) for a in (f, weight, new_weight))
    rate = float(np.mean(w * f))
    second = float(np.mean(w * wn * f * f))
    plain = rate * (1 - rate) / (second - rate * rate)
    if control is None:
        return rate, plain, math.nan
    g = np.asarray(control, dtype=float)
    cross, square = float(np.mean(w * wn * f * g)), float(np.mean(w * wn * g * g))
    slope = (cross - rate * control_mean) / (square - control_mean**2)
    variance = second - 2 * slope * cross + slope**2 * square - (rate - slope * control_mean) ** 2
    return rate, plain, rate * (1 - rate) / variance if variance > 0 else math.inf


def final_pairs(run: Path) -> tuple[pd.DataFrame, pd.DataFrame, JointProposal]:
    """The pilot rows (both conditions, ok), the final stage's pairs (is_v2i_within_sv.stage_pairs) and
    the final stage's stored joint proposal."""
    rows = pd.read_parquet(run / "episodes.parquet")
    info = json.loads((run / "run.json").read_text())
    proposals = info["sampler_proposals"][str(rows["scenario"].iloc[0])]
    rows = rows[rows["status"] == "ok"]
    final = int(rows["sampler_stage"].max())
    recorded = JointProposal.from_json(proposals[final])
    pairs = stage_pairs(rows[rows["sampler_stage"] == final])
    return rows[rows["sampler_stage"] < final], pairs, recorded


def fitted(rows: pd.DataFrame, recorded: JointProposal, ridge: float = RIDGE) -> JointProposal:
    """pi_hat of `rows`' collisions (one condition), unweighted, the sampler's design and ridge; c unset."""
    inputs, nominal = _inputs_and_nominal(rows)
    shell = JointProposal(
        dict(nominal.families), (), 1.0, recorded.defensive_share, kinematics=recorded.kinematics
    )
    y = rows["collision"].astype(float).to_numpy()
    coefficients = fit_logistic(shell.features(inputs), y, ridge)
    return JointProposal(
        dict(nominal.families),
        tuple(coefficients),
        1.0,
        recorded.defensive_share,
        kinematics=recorded.kinematics,
    )


def _q_over_p_and_tries(
    model: JointProposal, nominal_x: dict[str, np.ndarray], x: dict[str, np.ndarray], share: float
) -> tuple[np.ndarray, float]:
    """q/p at `x` of p (share + (1 - share) sqrt(pi_hat) / c) for `model`'s pi_hat, and its mean tries."""
    root_nominal = np.sqrt(model.pi_hat(nominal_x))
    norm = float(np.mean(root_nominal))
    return share + (1 - share) * np.sqrt(model.pi_hat(x)) / norm, share + (1 - share) * float(
        root_nominal.max()
    ) / norm


def score(run: Path, oracle: bool = False, mc: Path | None = None) -> pd.DataFrame:
    pilot, pairs, recorded = final_pairs(run)
    final_outcome = {
        "sv": pairs["collision"].astype(float).to_numpy(),
        "v2i": pairs["collision_v2i"].astype(float).to_numpy(),
    }
    if mc is not None:  # score on a plain MC run's nominal pairs instead: E_p[w' f], w = 1
        mc_rows = pd.read_parquet(mc / "episodes.parquet")
        evaluated = stage_pairs(mc_rows[mc_rows["scenario"] == pilot["scenario"].iloc[0]])
        w = np.ones(len(evaluated))
    else:
        evaluated = pairs
        w = pairs["weight"].to_numpy(float)
    x = {
        name: np.array([json.loads(t)["inputs"][name] for t in evaluated["sampler_inputs"]])
        for name in recorded.names
    }
    outcome = {
        "sv": evaluated["collision"].astype(float).to_numpy(),
        "v2i": evaluated["collision_v2i"].astype(float).to_numpy(),
    }
    final_rows = (
        pd.DataFrame({"sampler_inputs": pairs["sampler_inputs"], "collision": final_outcome["sv"]}),
        pd.DataFrame({"sampler_inputs": pairs["sampler_inputs"], "collision": final_outcome["v2i"]}),
    )
    source = {
        "sv": final_rows[0] if oracle else pilot[pilot["condition"] == "sv"],
        "v2i": final_rows[1] if oracle else pilot[pilot["condition"] == "v2i"],
    }
    pilot_pairs = stage_pairs(pilot)
    either = pd.DataFrame(
        {
            "sampler_inputs": pilot_pairs["sampler_inputs"],
            "collision": pilot_pairs["collision"].astype(bool) | pilot_pairs["collision_v2i"].astype(bool),
        }
    )
    model = {condition: fitted(rows, recorded) for condition, rows in source.items()}
    either_model = fitted(either, recorded)
    v2i_only = pd.DataFrame(
        {
            "sampler_inputs": pilot_pairs["sampler_inputs"],
            "collision": ~pilot_pairs["collision"].astype(bool) & pilot_pairs["collision_v2i"].astype(bool),
        }
    )
    v2i_only_model = fitted(v2i_only, recorded)
    if not oracle and not np.allclose(model["sv"].coefficients, recorded.coefficients, atol=1e-4):
        raise SystemExit(f"{run}: the refitted pi_sv differs from the stored proposal's")
    nominal_x = recorded.sample_nominal(np.random.default_rng(NORM_SEED), NOMINAL_DRAWS)
    pi_nominal = {c: m.pi_hat(nominal_x) for c, m in model.items()}
    pi_rows = {c: m.pi_hat(x) for c, m in model.items()}
    mean = {c: float(np.mean(v)) for c, v in pi_nominal.items()}
    rule = mean["v2i"] ** 2 / (mean["sv"] ** 2 + mean["v2i"] ** 2)
    lam = recorded.defensive_share
    table = []
    variants = [
        ("as run", recorded.q_over_p(x), recorded.bound),
        ("sv or v2i", *_q_over_p_and_tries(either_model, nominal_x, x, lam)),
    ]
    if recorded.v2i_factor is not None:
        # V2I as pi_sv r + pi_vo: the factor's model of V2I inside SV's collisions, plus a fit of the V2I
        # collisions where SV does not collide (pi_vo), a by the relative-variance rule on their means.
        def v2i_model(at: dict[str, np.ndarray]) -> np.ndarray:
            return recorded.pi_v2i_hat(at) + v2i_only_model.pi_hat(at)

        m_sv, m_v2i = float(np.mean(recorded.pi_hat(nominal_x))), float(np.mean(v2i_model(nominal_x)))
        share = m_v2i**2 / (m_sv**2 + m_v2i**2)
        root_nominal = np.sqrt(share * recorded.pi_hat(nominal_x) + (1 - share) * v2i_model(nominal_x))
        norm = float(np.mean(root_nominal))
        root = np.sqrt(share * recorded.pi_hat(x) + (1 - share) * v2i_model(x))
        variants.append(
            (
                f"factor + v2i-only ({int(v2i_only['collision'].sum())})",
                lam + (1 - lam) * root / norm,
                lam + (1 - lam) * float(root_nominal.max()) / norm,
            )
        )
    n_only = int(v2i_only["collision"].sum())
    if n_only:
        # The V2I-only fit as a mixture component of its own, with a fixed share mu of the draws:
        # q/p = lambda + mu pi_vo / E_p[pi_vo] + (1 - lambda - mu) h / c, h the run's own. Whatever pi_vo
        # fitted on a few collisions looks like, it takes at most mu of the draws from the run's proposal.
        only_nominal = v2i_only_model.pi_hat(nominal_x)
        only_mean = float(np.mean(only_nominal))
        as_run_nominal = recorded.q_over_p(nominal_x)
        as_run_x = recorded.q_over_p(x)
        for mu in MIXTURE_SHARES:
            # recorded.q_over_p = lam + (1 - lam) h / c: rescale its aimed part to (1 - lam - mu).
            aimed_x = (as_run_x - lam) * (1 - lam - mu) / (1 - lam)
            aimed_max = (float(as_run_nominal.max()) - lam) * (1 - lam - mu) / (1 - lam)
            variants.append(
                (
                    f"mixture v2i-only ({n_only}), mu {mu}",
                    lam + mu * v2i_only_model.pi_hat(x) / only_mean + aimed_x,
                    lam + mu * float(only_nominal.max()) / only_mean + aimed_max,
                )
            )
    for label, q_over_p, tries in variants:
        row = {"proposal": label, "alpha": math.nan, "mean tries": tries}
        for condition in ("sv", "v2i"):
            _, plain, with_cv = reweighted_efficiency(
                outcome[condition], w, 1.0 / q_over_p, pi_rows[condition], mean[condition]
            )
            row[f"{condition} plain"], row[f"{condition} cv"] = plain, with_cv
        table.append(row)
    for label, alpha in (("sv (sampler)", 1.0), ("half", 0.5), ("relative variance", rule), ("v2i", 0.0)):
        root_nominal = np.sqrt(alpha * pi_nominal["sv"] + (1 - alpha) * pi_nominal["v2i"])
        norm = float(np.mean(root_nominal))
        root = np.sqrt(alpha * pi_rows["sv"] + (1 - alpha) * pi_rows["v2i"])
        new_weight = 1.0 / (lam + (1 - lam) * root / norm)
        row = {
            "proposal": label,
            "alpha": alpha,
            "mean tries": lam + (1 - lam) * float(root_nominal.max()) / norm,
        }
        for condition in ("sv", "v2i"):
            _, plain, with_cv = reweighted_efficiency(
                outcome[condition], w, new_weight, pi_rows[condition], mean[condition]
            )
            row[f"{condition} plain"], row[f"{condition} cv"] = plain, with_cv
        table.append(row)
    print(
        f"\n{run} ({'oracle: fitted on the final stage' if oracle else 'fitted on the pilots'}): "
        f"collisions in the fit SV {int(source['sv']['collision'].sum())}, V2I "
        f"{int(source['v2i']['collision'].sum())}; final-stage pairs {len(pairs)}; "
        f"E_p pi_sv {mean['sv']:.4f}, E_p pi_v2i {mean['v2i']:.4f}"
    )
    return pd.DataFrame(table)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--oracle", action="store_true", help="fit on the final stage's rows (in-sample)")
    parser.add_argument(
        "--mc", type=Path, help="score on this plain MC run's pairs (E_p[w' f]) instead of the final stage"
    )
    args = parser.parse_args(argv)
    for run in args.runs:
        table = score(run, args.oracle, args.mc)
        print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
