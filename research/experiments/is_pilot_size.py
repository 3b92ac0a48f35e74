"""How the joint proposal's efficiency grows with the rows it is fitted on, measured without SUMO.

The sampler's own fit (sampling/joint_fit.fit_joint: ridge logistic over the proposed inputs, their squares
and products, and the kinematic features) on the first N SV rows of an importance-sampled run (its pilots
first, then its final stage; unweighted, as the sampler pools them: pi is a conditional probability), each
proposal scored by its efficiency per final-stage episode on the rows of an independent plain Monte Carlo
run (research/is_limits.py's joint_efficiency). The live final proposal is scored first, for comparison.

    OMP_NUM_THREADS=1 .venv/bin/python research/experiments/is_pilot_size.py IS_RUN MC_RUN \\
        --scenario jaywalking [--rows 200 500 800 1200] [--ridge 1.0]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from is_limits import inputs_of, joint_efficiency, rows_of  # noqa: E402

from pedsafe_sumo.sampling.joint import JointProposal  # noqa: E402
from pedsafe_sumo.sampling.joint_fit import fit_joint  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("is_run", type=Path)
    parser.add_argument("mc_run", type=Path)
    parser.add_argument("--scenario", required=True)
    parser.add_argument("--rows", type=int, nargs="+", default=[200, 500, 800, 1200])
    parser.add_argument("--ridge", type=float, nargs="+", default=[1.0])
    args = parser.parse_args(argv)
    try:
        info = json.loads((args.is_run / "run.json").read_text())
        stages = info["sampler_proposals"][args.scenario]
        final = JointProposal.from_json(stages[-1])
        mc, sampled = rows_of(args.mc_run), rows_of(args.is_run)
    except (OSError, ValueError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    names = final.design_names
    nominal = {name: final.nominal[name] for name in names}
    plain = mc[(mc.status == "ok") & (mc.scenario == args.scenario) & (mc.condition == "sv")]
    plain_inputs, _ = inputs_of(plain)
    y_plain = plain["collision"].astype(float).to_numpy()
    print(f"live final proposal: {joint_efficiency(y_plain, plain_inputs, final)[0]:.2f}x per final episode")
    sv = (sampled.scenario == args.scenario) & (sampled.condition == "sv") & (sampled.status == "ok")
    rows = sampled[sv]
    rows = rows.sort_values(["sampler_stage", "episode"])
    inputs, _ = inputs_of(rows)
    for n in args.rows:
        head = rows.iloc[:n]
        x = {name: inputs.loc[head.index, name].to_numpy(float) for name in names}
        y = head["collision"].astype(float).to_numpy()
        for ridge in args.ridge:
            fitted = fit_joint(x, y, nominal, final.defensive_share, ridge=ridge, kinematics=final.kinematics)
            if fitted is None:
                print(f"first {len(head)} rows ({int(y.sum())} collisions), ridge {ridge}: no proposal")
                continue
            efficiency = joint_efficiency(y_plain, plain_inputs, fitted)[0]
            print(
                f"first {len(head)} rows ({int(y.sum())} collisions), ridge {ridge}: {efficiency:.2f}x"
                f" per final episode, E_p[sqrt(pi_hat)] {fitted.norm:.4f}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
