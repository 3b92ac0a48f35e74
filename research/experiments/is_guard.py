"""Would a guard against pi_hat's underrated regions pay? (Offline, no SUMO.)

The live runs with the V2I-aware proposals (EXPERIMENTS.md, "why V2I gains less") lost most of their
efficiency, in one seed of four, to one or two collisions drawn
where the fitted pi_hat is 0.001-0.008: their weights (0.3-2.5) are 10-50 times a typical collision's, and
the squared weight is what the variance adds up. The sampler's proposal (sampling/joint.py) is

    q = p (lambda + (1 - lambda) h / c),    h = sqrt(pi_hat) (or with the V2I factor sqrt(pi_hat (a + (1 -
    a) r))),   c = E_p[h],

and it guards only through lambda, the defensive share: a draw anywhere weighs at most 1/lambda. This tool
scores, on each run's final stage and by reweighting (`is_v2i_proposal.reweighted_efficiency`: E_q'[w'^2 f]
= E_q[w w' f]), three ways of giving the underrated regions more room, each a function of the run's own
stored proposal (no refit):

- `share L`: another defensive share, q' = p (L + (1 - L) h / c);
- `shrink B`: h' = sqrt((1 - B) h^2 + B m), m = E_p[h^2] (a mixture of pi_hat with its own nominal mean:
  a region the fit puts at pi_hat ~ 0 keeps B m of it);
- `floor K`: h' = sqrt(max(h^2, K m)).

c' = E_p[h'] on NOMINAL_DRAWS nominal draws of a fixed seed. The efficiency per final episode is that of
plain IS and of IS with the run's own control variate (report/tables.py's: pi_hat for SV, pi_hat r for V2I
where the factor is on) at its best slope; its nominal mean is recomputed on the same draws. The rows of a
run's final stage are the only sample of where its fit errs, so one run's score is itself noisy: the
pooled line adds, per scenario, each run's variance relative to its own rate (the expectation over pilots
and final stages the runs sample).

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_guard.py RUN [RUN ...] [--markdown]
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

from is_v2i_proposal import final_pairs  # noqa: E402

from pedsafe_sumo.sampling.joint import NORM_SEED  # noqa: E402

#: Nominal draws for c' and the controls' means (as is_v2i_proposal).
NOMINAL_DRAWS = 400_000
#: The variants, fixed before any was scored.
VARIANTS: tuple[tuple[str, str, float], ...] = (
    ("sampler", "share", math.nan),
    ("share 0.05", "share", 0.05),
    ("share 0.2", "share", 0.2),
    ("share 0.3", "share", 0.3),
    ("shrink 0.05", "shrink", 0.05),
    ("shrink 0.1", "shrink", 0.1),
    ("shrink 0.2", "shrink", 0.2),
    ("shrink 0.4", "shrink", 0.4),
    ("floor 0.1", "floor", 0.1),
    ("floor 0.3", "floor", 0.3),
    ("floor 1", "floor", 1.0),
)


def guarded_root(h: np.ndarray, kind: str, level: float, mean_h2: float) -> np.ndarray:
    """h' of the variant (module docstring); `share` leaves h as it is."""
    if kind == "shrink":
        return np.sqrt((1 - level) * h * h + level * mean_h2)
    if kind == "floor":
        return np.sqrt(np.maximum(h * h, level * mean_h2))
    return h


def variances(
    f: np.ndarray, w: np.ndarray, w_new: np.ndarray, g: np.ndarray, g_mean: float
) -> tuple[float, float, float]:
    """(P, variance of plain IS, variance with g at its best slope) per episode under the proposal of
    weights `w_new`, from rows drawn with weights `w` (is_v2i_proposal.reweighted_efficiency)."""
    rate = float(np.mean(w * f))
    second = float(np.mean(w * w_new * f * f))
    cross, square = float(np.mean(w * w_new * f * g)), float(np.mean(w * w_new * g * g))
    slope = (cross - rate * g_mean) / (square - g_mean**2)
    with_cv = second - 2 * slope * cross + slope**2 * square - (rate - slope * g_mean) ** 2
    return rate, second - rate * rate, with_cv


def score(run: Path) -> pd.DataFrame:
    _, pairs, recorded = final_pairs(run)
    records = [json.loads(t)["inputs"] for t in pairs["sampler_inputs"]]
    x = {name: np.array([r[name] for r in records], dtype=float) for name in recorded.names}
    w = pairs["weight"].to_numpy(float)
    expected = 1.0 / recorded.q_over_p(x)
    if not np.allclose(w, expected, rtol=1e-6):
        raise SystemExit(f"{run}: the recorded weights are not 1 / (q/p) of the stored proposal")
    nominal_x = recorded.sample_nominal(np.random.default_rng(NORM_SEED), NOMINAL_DRAWS)
    h_nominal, h_rows = recorded.root_pi(nominal_x), recorded.root_pi(x)
    mean_h2 = float(np.mean(h_nominal**2))
    factor = recorded.v2i_factor is not None
    controls = {
        "sv": (recorded.pi_hat(x), float(np.mean(recorded.pi_hat(nominal_x)))),
        "v2i": (
            (recorded.pi_v2i_hat(x), float(np.mean(recorded.pi_v2i_hat(nominal_x))))
            if factor
            else (recorded.pi_hat(x), float(np.mean(recorded.pi_hat(nominal_x))))
        ),
    }
    outcome = {
        "sv": pairs["collision"].astype(float).to_numpy(),
        "v2i": pairs["collision_v2i"].astype(float).to_numpy(),
    }
    scenario = str(pd.read_parquet(run / "episodes.parquet", columns=["scenario"])["scenario"].iloc[0])
    table = []
    for label, kind, level in VARIANTS:
        share = recorded.defensive_share if kind != "share" or math.isnan(level) else level
        root_nominal = guarded_root(h_nominal, kind, level, mean_h2)
        norm = float(np.mean(root_nominal))
        w_new = 1.0 / (share + (1 - share) * guarded_root(h_rows, kind, level, mean_h2) / norm)
        row = {"run": run.name, "scenario": scenario, "factor": factor, "variant": label}
        for condition in ("sv", "v2i"):
            g, g_mean = controls[condition]
            rate, plain, with_cv = variances(outcome[condition], w, w_new, g, g_mean)
            row[f"{condition} P"] = rate
            row[f"{condition} var"] = plain
            row[f"{condition} var cv"] = with_cv
            row[f"{condition} max w'"] = float(np.max(w_new * outcome[condition], initial=0.0))
        table.append(row)
    return pd.DataFrame(table)


def efficiency(frame: pd.DataFrame) -> pd.DataFrame:
    """Per row: efficiency per final episode, P (1 - P) / variance, plain and with the control."""
    out = frame[["run", "scenario", "factor", "variant"]].copy()
    for condition in ("sv", "v2i"):
        rate = frame[f"{condition} P"]
        for suffix in ("", " cv"):
            out[f"{condition}{suffix or ' plain'}"] = rate * (1 - rate) / frame[f"{condition} var{suffix}"]
    return out


def pooled(frame: pd.DataFrame) -> pd.DataFrame:
    """Per scenario and variant: P_bar (1 - P_bar) / (P_bar^2 mean_runs(var / P^2)) (module docstring)."""
    rows = []
    for (scenario, variant), group in frame.groupby(["scenario", "variant"], sort=False):
        row = {"scenario": scenario, "variant": variant, "runs": len(group)}
        for condition in ("sv", "v2i"):
            rate = group[f"{condition} P"].to_numpy()
            mean_rate = float(np.mean(rate))
            for suffix in ("", " cv"):
                relative = float(np.mean(group[f"{condition} var{suffix}"].to_numpy() / rate**2))
                row[f"{condition}{suffix or ' plain'}"] = (1 - mean_rate) / (mean_rate * relative)
        rows.append(row)
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--markdown", action="store_true")
    args = parser.parse_args(argv)
    frame = pd.concat([score(run) for run in args.runs], ignore_index=True)

    def show(table: pd.DataFrame) -> str:
        if args.markdown:
            return table.to_markdown(index=False, floatfmt=".3g")
        return table.to_string(index=False, float_format=lambda v: f"{v:.3g}")

    print(show(efficiency(frame)))
    print("\npooled over the runs of each scenario (efficiency per final episode)")
    print(show(pooled(frame)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
