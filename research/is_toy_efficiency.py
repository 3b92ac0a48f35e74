"""Importance sampling's efficiency on the toy problem of tests/sampling/test_stages.py (docs/sampling.md).

The toy's "collision" is the ego faster than 14 m/s under the intersection speed fit (known probability);
the pedestrian's traits and the conflict offset are drawn through the same `Draws` as an episode's but do
not matter. Per seed: `--pilot-stages` cross-entropy stages of `--pilot` draws, then `--final` draws from
the fixed proposal; prints the estimate, its interval, whether it holds the truth, the ESS, the mean
weight, the proposed inputs and the efficiency (draws plain MC needs for the same half-width, over the
draws made, pilots included).

    .venv/bin/python research/is_toy_efficiency.py --inputs screened --min-spread 0.7071 --seeds 6
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.sampling.importance import is_estimate
from pedsafe_sumo.sampling.stages import INPUT_MODES, cross_entropy_update

Z = 1.959964


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", choices=INPUT_MODES, default="screened")
    parser.add_argument("--min-spread", type=float, default=0.7071067811865476)
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--pilot-stages", type=int, default=3)
    parser.add_argument("--pilot", type=int, default=200)
    parser.add_argument("--final", type=int, default=2000)
    args = parser.parse_args(argv)
    if not (0.05 <= args.min_spread <= 1 and 1 <= args.seeds <= 1000 and 0 <= args.pilot_stages <= 10):
        print("error: --min-spread in 0.05..1, --seeds in 1..1000, --pilot-stages in 0..10", file=sys.stderr)
        return 2
    sys.path.insert(0, str(REPO_ROOT / "tests" / "sampling"))
    import test_stages as toy  # the toy's episode rows (_toy_rows) and its probability TOY_P

    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        current: dict = {}
        for _ in range(args.pilot_stages):
            rows = toy._toy_rows(rng, current, args.pilot)
            current = dict(
                cross_entropy_update(rows, current, args.inputs, args.min_spread).proposal.families
            )
        final = toy._toy_rows(rng, current, args.final)
        est = is_estimate(final["collision"].to_numpy(dtype=float), final["weight"].to_numpy(dtype=float))
        half = (est.high - est.low) / 2
        n = args.pilot_stages * args.pilot + args.final
        efficiency = est.mean * (1 - est.mean) * (Z / half) ** 2 / n if half > 0 else float("nan")
        print(
            f"{args.inputs} floor={args.min_spread:.4f} seed={seed} estimate={est.mean:.5f} "
            f"[{est.low:.5f}, {est.high:.5f}] holds_truth={est.low <= toy.TOY_P <= est.high} "
            f"ess={est.ess:.0f} mean_weight={final['weight'].mean():.3f} efficiency={efficiency:.1f} "
            f"proposed={sorted(current)}",
            flush=True,
        )
    print(f"truth {toy.TOY_P:.6f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
