"""Shaping pi_hat at pilot size: physical features, a product-then-joint hybrid, and a guard against a pilot
without collisions, at the cost of the 2-stage pilot. Offline, no SUMO.

Machinery of research/experiments/is_joint_pilot.py (same rows, replicate blocks, rejection step and held-out
estimator): on a plain Monte Carlo run's SV rows, a pilot is simulated from the rows (a nominal stage takes
the next rows; a stage drawn from a proposal q keeps each further row with probability (q/p) / max(q/p), an
exact draw from q restricted to the rows), the final proposal is fitted on the pooled pilot, and its
efficiency per final episode P(1 - P) / (E_p[w f] - P^2) is measured on the rows neither the pilot nor the
rejection step used. 5 replicates: replicate r's pilot starts at row 2,000 r. pi_hat is sampling.joint's
ridge logistic (ridge 1) on the design of is_joint_pilot.design; the joint proposal q = 0.1 p + 0.9 p
sqrt(pi_hat) / E_p[sqrt(pi_hat)].

Variants, fixed before any score was looked at:

- `ridge1`: the baseline, is_joint_pilot's `2-stage`: 200 nominal rows, pi_hat, 200 rows from that joint
  proposal, pi_hat refitted on the 400 pooled. Pilot cost 400.
- `physics`: the same pilot, the design extended by three physical features of x (each
  standardised by its moments on the scenario's rows, nominal draws, and entering the design as further
  continuous inputs: their squares and their products with every continuous input and each other): the
  ego's speed v (m/s), the pedestrian's time per metre 1/w (s/m) and the braking margin (`braking_margin_s`)

      margin_s = conflict_offset_s + D / w - t_r - v / (2 a_max).

  Source: scenarios/placements/ stages the ego so that, at its initial speed v, it reaches the conflict
  point (the pedestrian's path on the ego lane's centre line) conflict_offset_s after the pedestrian does;
  the pedestrian walks at w. So from the moment the pedestrian is D metres before the ego lane's centre
  the ego has conflict_offset_s + D / w seconds before it reaches the conflict point, and it needs the
  stack's reaction time t_r plus v / (2 a_max) (a full stop from v at a_max covers v^2 / (2 a_max) metres,
  which at speed v takes v / (2 a_max) seconds of the time budget) to stop there: margin_s < 0, a stop is
  impossible (kinematically, for the reference stack: [algorithm] reaction_time_s, max_decel_mps2 of
  defaults.toml). D = D_VISIBLE_M, an assumption: the lane width of SUMO's default (3.2 m) less half a
  car's width (0.9 m), the distance from the occluder's lane-side flank (where the pedestrian comes into
  the ego's view) to the ego lane's centre; the logistic can correct it through the separate 1/w feature.
  v = clip(exp(ego_speed_log), ego_speed_min_mps, ego_speed_max_mps) (the v5_full runs: no speed-limit
  scale) and w = exp(log_mu + log_sigma z) of the age group's lognormal (sampling/draws.py) are functions
  of x: the sampler could compute them at draw time. Checked against the rows' ego_initial_speed_mps and
  ped_speed_mps (printed).
- `hybrid`: stage 0 of 200 nominal rows; if it holds at least K_COLLISIONS SV collisions, stage
  1 is the joint stage of `ridge1`; else stage 1 is the product family's cross-entropy stage (the
  sampler's own update, sampling.stages.cross_entropy_update: TTC score, screened inputs, spread floor
  sqrt(1/2), elite 10%, defensive share 0.1), drawn by rejection. The final proposal: joint (pi_hat on
  the 400 pooled) if the pooled pilot holds at least K_COLLISIONS collisions, else the product's next
  cross-entropy update from stage 1. Pilot cost 400.
- `adaptive`: stage 0 of nominal rows in chunks of ADAPTIVE_CHUNK until it holds
  ADAPTIVE_MIN_COLLISIONS SV collisions (at most ADAPTIVE_MAX rows), then a joint stage of 200, pi_hat
  refitted on the pooled rows. Pilot cost: stage 0's rows + 200, counted per replicate.
- `physics+adaptive`: both.

Printed, not a variant: the efficiency on all rows of the proposal that puts the non-defensive mass on
{margin_s < 0} (post hoc as below; it needs no pilot: P_p(margin_s < 0) by nominal draws, no SUMO).

Added AFTER the first table (post hoc, so not a fair competitor: chosen with the margin's split of all
10,000 rows in view, see the printed P(collision | margin < 0); it needs a fresh reference to be judged):

- `margin-only`: the `ridge1` pilot, pi_hat on the physical features alone (v, 1/w, margin_s: the
  quadratic design of these three, 10 columns) instead of the inputs' design.
- `region0+physics` (added after the region's figures were printed, post hoc as well): stage 0 of 200
  rows drawn from the region proposal with D = GUARD_VISIBLE_M (the D whose region held every v5_full
  collision of the four scenarios but two: read off these rows), then the `physics` joint stage and refit.
  A guard against an empty first pilot that costs no episode. Cost 400.

With pilots: efficiency per final episode x n / (n + pilot cost), n final pairs (300, 1,000, 2,000). The
goal is 10x with pilots on every SV collision rate.

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_pihat_shape.py V5_FULL
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from is_joint_pilot import DEFENSIVE_SHARE, design, design_spec, evaluate  # noqa: E402
from is_limits import proposal_efficiency  # noqa: E402

from pedsafe_sumo.params import load_params  # noqa: E402
from pedsafe_sumo.sampling.distributions import age_group_speed_distributions  # noqa: E402
from pedsafe_sumo.sampling.draws import family_from_json  # noqa: E402
from pedsafe_sumo.sampling.importance import SQRT_HALF, Product  # noqa: E402
from pedsafe_sumo.sampling.joint import fit_logistic, quadratic_design  # noqa: E402
from pedsafe_sumo.sampling.stages import INPUTS_SCREENED, SCORE_TTC, cross_entropy_update  # noqa: E402
from pedsafe_sumo.scenarios.specs import get_scenario  # noqa: E402

RIDGE = 1.0
STAGE_ROWS = 200
#: Assumption (module docstring): SUMO's default lane width 3.2 m less half a car's width 0.9 m.
D_VISIBLE_M = 2.3
#: `region0+physics` (post hoc): the D of its stage-0 region.
GUARD_VISIBLE_M = 1.6
#: `hybrid`: collisions the pooled pilot must hold before the joint family takes over (fixed in advance).
K_COLLISIONS = 10
#: `adaptive`: stage 0 grows by this many nominal rows until it holds this many collisions, or the cap.
ADAPTIVE_CHUNK = 50
ADAPTIVE_MIN_COLLISIONS = 5
ADAPTIVE_MAX = 1_000
FINAL_PAIRS = (300, 1_000, 2_000)
VARIANTS = ("ridge1", "physics", "hybrid", "adaptive", "physics+adaptive", "margin-only", "region0+physics")
#: References, not pilots: pi_hat fitted on the 8,000 rows outside the replicate's block, evaluated on the
#: block (is_joint_pilot's `all-but-block`): what the model class reaches with far more data than a pilot.
REFERENCES = ("ridge1 8000", "physics 8000", "margin-only 8000")


def braking_margin_s(
    conflict_offset_s: np.ndarray,
    ego_speed_mps: np.ndarray,
    walking_speed_mps: np.ndarray,
    reaction_time_s: float,
    max_decel_mps2: float,
    visible_m: float = D_VISIBLE_M,
) -> np.ndarray:
    """Seconds the ego has, from the pedestrian's coming into view `visible_m` before the ego lane's centre
    until it reaches the conflict point, beyond what a stop needs: conflict_offset_s + visible_m / w - t_r
    - v / (2 a_max) (module docstring). Negative: no stop before the conflict point."""
    available_s = conflict_offset_s + visible_m / walking_speed_mps
    return available_s - reaction_time_s - ego_speed_mps / (2.0 * max_decel_mps2)


def speeds_of(inputs: pd.DataFrame, scenario: str, params: dict) -> tuple[np.ndarray, np.ndarray]:
    """(v, w) in m/s as functions of the proposable inputs (module docstring)."""
    spec = get_scenario(scenario)
    v = np.clip(
        np.exp(inputs["ego_speed_log"].to_numpy(float)), spec.ego_speed_min_mps, spec.ego_speed_max_mps
    )
    laws = list(age_group_speed_distributions(dict(params["pedestrians"])).values())
    group = inputs["ped_age_group"].to_numpy(int)
    mu = np.array([laws[g].log_mu for g in group])
    sigma = np.array([laws[g].log_sigma for g in group])
    w = np.exp(mu + sigma * inputs["ped_walking_speed_z"].to_numpy(float))
    return v, w


def standardised(v: np.ndarray) -> np.ndarray:
    return (v - v.mean()) / v.std()


def physics_design(inputs: pd.DataFrame, spec: dict, physics: list[np.ndarray]) -> np.ndarray:
    """is_joint_pilot.design's model with the physical features appended as further continuous inputs
    (standardised): their squares and their products with every continuous input and with each other."""
    blocks: list = []
    for name, (kind, a, b) in spec.items():
        v = inputs[name].to_numpy(dtype=float)
        blocks.append([(v == k).astype(float) for k in range(1, int(a))] if kind == "cat" else (v - a) / b)
    return quadratic_design(len(inputs), blocks + list(physics))


def joint_ratio(beta: np.ndarray, x: np.ndarray, norm_rows: np.ndarray) -> tuple[np.ndarray, float]:
    """(q/p on the rows x, its bound) for the joint proposal of pi_hat = expit(x beta); c estimated on the
    nominal rows `norm_rows` (the implementation: nominal draws of a fixed seed)."""
    root = np.sqrt(special.expit(x @ beta))
    norm = float(np.mean(np.sqrt(special.expit(norm_rows @ beta))))
    return DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * root / norm, DEFENSIVE_SHARE + (
        1 - DEFENSIVE_SHARE
    ) / norm


def product_ratio(proposal: Product, nominal: dict, inputs: pd.DataFrame) -> np.ndarray:
    """q/p of the product proposal with the defensive mixture (inputs not in it stay nominal)."""
    names = list(proposal.families)
    if not names:
        return np.ones(len(inputs))
    x = {name: inputs[name].to_numpy(dtype=float) for name in names}
    log_ratio = proposal.log_pdf(x) - Product({n: nominal[n] for n in names}).log_pdf(x)
    return DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * np.exp(log_ratio)


def efficiency(y: np.ndarray, ratio: np.ndarray) -> float:
    """P(1 - P) / (E_p[w f] - P^2) on nominal rows, w = 1 / (q/p)."""
    p = float(np.mean(y))
    variance = float(np.mean(y / ratio)) - p * p
    return p * (1 - p) / variance if variance > 0 else math.inf


def reject(
    ratio: np.ndarray, bound: float, rest: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, int]:
    """STAGE_ROWS rows of `rest` kept with probability ratio / bound; (kept rows, candidates used)."""
    u = rng.random(len(rest))
    kept = np.flatnonzero(u < ratio / bound)[:STAGE_ROWS]
    return rest[kept], int(kept[-1]) + 1


def run_replicate(variant: str, r: int, data: dict) -> tuple[float, int, int, int, int]:
    """(efficiency per final episode, pilot cost in episodes, pooled pilot collisions, held-out rows, their
    collisions) of one replicate."""
    x = {"physics": data["x_physics"], "margin-only": data["x_margin"]}.get(
        variant.split("+")[0].split(" ")[0], data["x"]
    )
    y, n = data["y"], len(data["y"])
    order = np.r_[np.arange(r * data["block"], n), np.arange(0, r * data["block"])]
    rng = np.random.default_rng(r)
    if variant in REFERENCES:
        inside, outside = order[: data["block"]], order[data["block"] :]
        beta = fit_logistic(x[outside], y[outside], RIDGE)
        return (
            evaluate(beta, x[inside], y[inside]),
            0,
            int(y[outside].sum()),
            len(inside),
            int(y[inside].sum()),
        )
    if variant == "region0+physics":
        x = data["x_physics"]
        region = data["guard_region"]
        ratio0 = DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * region / region.mean()
        s0, used0 = reject(ratio0[order], float(ratio0.max()), order, rng)
        rest = order[used0:]
        beta0 = fit_logistic(x[s0], y[s0], RIDGE)
        ratio, bound = joint_ratio(beta0, x[rest], x[rest])
        s1, used = reject(ratio, bound, rest, rng)
        pooled, held = np.r_[s0, s1], rest[used:]
        beta = fit_logistic(x[pooled], y[pooled], RIDGE)
        held_out = len(held), int(y[held].sum())
        return evaluate(beta, x[held], y[held]), 2 * STAGE_ROWS, int(y[pooled].sum()), *held_out
    if variant.endswith("adaptive"):
        size = ADAPTIVE_CHUNK
        while y[order[:size]].sum() < ADAPTIVE_MIN_COLLISIONS and size < ADAPTIVE_MAX:
            size += ADAPTIVE_CHUNK
    else:
        size = STAGE_ROWS
    s0, rest = order[:size], order[size:]
    if variant == "hybrid" and y[s0].sum() < K_COLLISIONS:
        frame = data["frame"].iloc[s0].assign(weight=1.0)
        current = cross_entropy_update(frame, {}, INPUTS_SCREENED, SQRT_HALF, SCORE_TTC).proposal
        ratio = product_ratio(current, data["nominal"], data["inputs"].iloc[rest])
        s1, used = reject(ratio, float(ratio.max()), rest, rng)
        pooled, held = np.r_[s0, s1], rest[used:]
        if y[pooled].sum() < K_COLLISIONS:
            # Still short of K: the product's next stage is the final proposal (weights of stage 1 rows).
            frame = (
                data["frame"]
                .iloc[s1]
                .assign(weight=1.0 / product_ratio(current, data["nominal"], data["inputs"].iloc[s1]))
            )
            final = cross_entropy_update(
                frame, current.families, INPUTS_SCREENED, SQRT_HALF, SCORE_TTC
            ).proposal
            eff, _ = proposal_efficiency(
                y[held], data["inputs"].iloc[held], data["nominal"], final, DEFENSIVE_SHARE
            )
            return eff, size + STAGE_ROWS, int(y[pooled].sum()), len(held), int(y[held].sum())
    elif y[s0].sum() > 0:
        beta0 = fit_logistic(x[s0], y[s0], RIDGE)
        ratio, bound = joint_ratio(beta0, x[rest], x[rest])
        s1, used = reject(ratio, bound, rest, rng)
        pooled, held = np.r_[s0, s1], rest[used:]
    else:  # no collision in stage 0: the joint sampler stays nominal
        s1, pooled, held = rest[:STAGE_ROWS], np.r_[s0, rest[:STAGE_ROWS]], rest[STAGE_ROWS:]
    if y[pooled].sum() == 0:
        return 1.0, size + STAGE_ROWS, 0, len(held), int(y[held].sum())
    beta = fit_logistic(x[pooled], y[pooled], RIDGE)
    held_out = len(held), int(y[held].sum())
    return evaluate(beta, x[held], y[held]), size + STAGE_ROWS, int(y[pooled].sum()), *held_out


def scenario_data(
    sc: pd.DataFrame, scenario: str, params: dict, replicates: int, visible_m: float = D_VISIBLE_M
) -> dict:
    records = [json.loads(t) for t in sc["sampler_inputs"]]
    nominal = {name: family_from_json(f) for name, f in records[0]["nominal"].items()}
    inputs = pd.DataFrame([rec["inputs"] for rec in records])[sorted(nominal)].fillna(0.0)
    spec = design_spec(nominal, inputs)
    x = design(inputs, spec)
    v, w = speeds_of(inputs, scenario, params)
    check = (
        float(np.max(np.abs(v - sc["ego_initial_speed_mps"].to_numpy(float)))),
        float(np.max(np.abs(w - sc["ped_speed_mps"].to_numpy(float)))),
    )
    algorithm = params["algorithm"]
    margin = braking_margin_s(
        inputs["conflict_offset_s"].to_numpy(float),
        v,
        w,
        float(algorithm["reaction_time_s"]),
        float(algorithm["max_decel_mps2"]),
        visible_m,
    )
    guard_margin = braking_margin_s(
        inputs["conflict_offset_s"].to_numpy(float),
        v,
        w,
        float(algorithm["reaction_time_s"]),
        float(algorithm["max_decel_mps2"]),
        GUARD_VISIBLE_M,
    )
    physics = [standardised(v), standardised(1.0 / w), standardised(margin)]
    return {
        "x": x,
        "x_physics": physics_design(inputs, spec, physics),
        "x_margin": quadratic_design(len(inputs), list(physics)),
        "y": sc["collision"].astype(float).to_numpy(),
        "frame": sc.reset_index(drop=True),
        "inputs": inputs,
        "nominal": nominal,
        "block": len(sc) // replicates,
        "check": check,
        "margin": margin,
        "guard_region": guard_margin < 0,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("--replicates", type=int, default=5)
    parser.add_argument(
        "--visible-m",
        type=float,
        default=D_VISIBLE_M,
        help="D of the braking margin (a sensitivity check of the stated assumption, not a choice)",
    )
    parser.add_argument(
        "--variants", nargs="+", default=list(VARIANTS + REFERENCES), choices=VARIANTS + REFERENCES
    )
    args = parser.parse_args(argv)
    params = load_params()
    rows = pd.read_parquet(args.mc_run / "episodes.parquet")
    rows = rows[(rows["status"] == "ok") & (rows["condition"] == "sv")]
    out = []
    for scenario, sc in rows.groupby("scenario"):
        data = scenario_data(sc.sort_values("episode"), scenario, params, args.replicates, args.visible_m)
        y, margin = data["y"], data["margin"]
        print(
            f"{scenario}: |v - ego_initial_speed_mps| max {data['check'][0]:.2g}, |w - ped_speed_mps| max "
            f"{data['check'][1]:.2g}; P(collision | margin < 0) {y[margin < 0].mean():.4f} "
            f"({int((margin < 0).sum())} rows), P(collision | margin >= 0) {y[margin >= 0].mean():.4f}",
            file=sys.stderr,
        )
        region = margin < 0
        ratio = DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * region / region.mean()
        print(
            f"  (post hoc, no pilot) q = 0.1 p + 0.9 p 1{{margin < 0}} / P(margin < 0): "
            f"{int(y[region].sum())} of "
            f"{int(y.sum())} collisions inside, efficiency per episode on all rows "
            f"{efficiency(y, ratio):.3g}",
            file=sys.stderr,
        )
        for variant in args.variants:
            results = [run_replicate(variant, r, data) for r in range(args.replicates)]
            eff = np.array([res[0] for res in results])
            cost = np.array([res[1] for res in results])
            row = {
                "scenario": scenario,
                "variant": variant,
                "per final episode": f"{np.median(eff):.3g} [{eff.min():.3g}, {eff.max():.3g}]",
                "replicates": " ".join(f"{e:.3g}" for e in eff),
                "pilot cost": " ".join(str(c) for c in cost),
                "pilot collisions": " ".join(str(res[2]) for res in results),
                "held-out rows (collisions)": " ".join(f"{res[3]} ({res[4]})" for res in results),
            }
            for n_final in FINAL_PAIRS if variant not in REFERENCES else ():
                with_pilots = eff * n_final / (n_final + cost)
                row[f"with pilots n={n_final}"] = (
                    f"{np.median(with_pilots):.3g} [{with_pilots.min():.3g}, {with_pilots.max():.3g}]"
                )
            out.append(row)
    table = pd.DataFrame(out)
    with pd.option_context("display.width", 250, "display.max_rows", 500, "display.max_colwidth", 60):
        print(table.to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
