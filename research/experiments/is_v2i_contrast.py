"""What decides V2I's collision inside SV's region, and what the V2I factor gains (offline,
no SUMO).

For the final stage of each importance-sampling run given (runs made with `--is-v2i-factor none`, whose
final stage drew from the proposal of SV alone):

1. Among the pairs whose SV episode collided, how well the contrast between the pedestrian's clothing
   and each vehicle colour the scenario draws (CIE76 delta E, perception/sensors.py) separates the pairs
   where V2I collided too: the AUC of -delta E (0.5: no information), and the share of each kind of pair
   below the roadside camera's threshold.
2. The proposal the sampler now fits (sampling/v2i_factor.py's with_v2i_factor on the run's pilot rows, added
   to the run's stored final proposal), scored on the final stage's rows by reweighting
   (research/experiments/is_v2i_proposal.py: E_q'[w'^2 f] = E_q[w w' f]) against the stored proposal:
   efficiency per final episode for SV and V2I, plain IS and with the control variate (pi_hat for SV;
   pi_hat r for V2I under the factor, pi_hat under the stored proposal).

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python research/experiments/is_v2i_contrast.py RUN [RUN ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

from is_v2i_proposal import final_pairs, reweighted_efficiency  # noqa: E402
from is_v2i_within_sv import auc  # noqa: E402

from pedsafe_sumo.params import load_params  # noqa: E402
from pedsafe_sumo.perception.sensors import delta_e_cie76  # noqa: E402
from pedsafe_sumo.sampling.joint import CLOTHING_INPUT, COLOUR_SUFFIX, JointProposal  # noqa: E402
from pedsafe_sumo.sampling.v2i_factor import low_contrast_table, with_v2i_factor  # noqa: E402
from pedsafe_sumo.scenarios.road_users import CAR_COLOURS_RGB, CLOTHING_COLOURS_RGB  # noqa: E402


def contrast_table(pairs: pd.DataFrame, threshold: float) -> pd.DataFrame:
    """Per vehicle colour input, among the pairs whose SV episode collided (part 1 of the docstring)."""
    hit = pairs[pairs["collision"].astype(bool)]
    records = [json.loads(text)["inputs"] for text in hit["sampler_inputs"]]
    v2i = hit["collision_v2i"].astype(bool).to_numpy()
    clothing = np.array([CLOTHING_COLOURS_RGB[int(r[CLOTHING_INPUT])] for r in records], dtype=float)
    names = sorted(
        name for name in records[0] if name.endswith(COLOUR_SUFFIX) and all(name in r for r in records)
    )
    table = []
    for name in names:
        car = np.array([CAR_COLOURS_RGB[int(r[name])] for r in records], dtype=float)
        delta_e = delta_e_cie76(clothing, car)
        table.append(
            {
                "colour input": name,
                "AUC of -delta E": auc(-delta_e, v2i.astype(int)),
                "V2I too: below threshold": float(np.mean(delta_e[v2i] < threshold)),
                "SV only: below threshold": float(np.mean(delta_e[~v2i] < threshold)),
            }
        )
    return pd.DataFrame(table)


def factor_scores(
    pilot: pd.DataFrame, pairs: pd.DataFrame, stored: JointProposal, low_contrast: tuple[tuple[int, ...], ...]
) -> pd.DataFrame:
    """Part 2 of the docstring: the stored proposal and the one with the V2I factor (fitted on `pilot`),
    scored on the final stage's `pairs`."""
    with_factor = with_v2i_factor(stored, pilot, low_contrast)
    w = pairs["weight"].to_numpy(float)
    outcome = {
        "sv": pairs["collision"].astype(float).to_numpy(),
        "v2i": pairs["collision_v2i"].astype(float).to_numpy(),
    }
    table = []
    for label, proposal in (("stored (SV alone)", stored), ("with the V2I factor", with_factor)):
        if proposal is None:
            table.append({"proposal": label, "note": "fewer than 5 V2I collisions in the pilots' SV ones"})
            continue
        records = [json.loads(text)["inputs"] for text in pairs["sampler_inputs"]]
        x = {name: np.array([r[name] for r in records], dtype=float) for name in proposal.names}
        new_weight = 1.0 / proposal.q_over_p(x)
        pi = proposal.pi_hat(x)
        controls = {"sv": (pi, proposal.mean_pi_hat), "v2i": (pi, proposal.mean_pi_hat)}
        if proposal.v2i_factor is not None:
            controls["v2i"] = (proposal.pi_v2i_hat(x), proposal.mean_pi_v2i)
        row: dict[str, object] = {"proposal": label}
        if proposal.v2i_factor is not None:
            row["a"] = proposal.v2i_factor.target_share
            row["b"] = " ".join(f"{b:.2f}" for b in proposal.v2i_factor.coefficients)
        row["mean tries"] = proposal.bound
        for condition in ("sv", "v2i"):
            g, mean = controls[condition]
            _, plain, with_cv = reweighted_efficiency(outcome[condition], w, new_weight, g, mean)
            row[f"{condition} plain"], row[f"{condition} cv"] = plain, with_cv
        table.append(row)
    return pd.DataFrame(table)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    args = parser.parse_args(argv)
    threshold = float(load_params()["perception"]["roadside_camera"]["delta_e_threshold"])
    low_contrast = low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, threshold)
    for run in args.runs:
        info = json.loads((run / "run.json").read_text())
        if info.get("sampler", {}).get("v2i_factor"):
            print(
                f"{run}: made with the V2I factor; give runs made with --is-v2i-factor none", file=sys.stderr
            )
            return 2
        pilot, pairs, stored = final_pairs(run)
        print(
            f"\n{run}: final stage {len(pairs)} pairs, SV collisions {int(pairs['collision'].sum())}, "
            f"V2I too {int((pairs['collision'] & pairs['collision_v2i']).sum())}"
        )
        with pd.option_context("display.width", 200, "display.max_columns", 20):
            print(contrast_table(pairs, threshold).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
            print(
                factor_scores(pilot, pairs, stored, low_contrast).to_string(
                    index=False, float_format=lambda v: f"{v:.3g}"
                )
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
