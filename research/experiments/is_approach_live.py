"""Run `python -m pedsafe_sumo.batch` with `--sampler is` on an approach-staged protocol, the refusal lifted
for this process only: the live measurement a decision to lift it needs (docs/decisions/
2026-11-28-is-under-approach-staging-measured.md). The product refuses the same command in one line.

    python research/experiments/is_approach_live.py --protocol protocols/paper-v10-xueqing.toml --sampler is \
        --is-pilot-stages 2 --is-pilot-episodes 100 --episodes 200 --workers 2 --out IS_RUN
    python research/is_validation.py IS_RUN MC_RUN --markdown

Every argument is batch's; `--resume --out IS_RUN` continues a stopped run through this script again. The
refusal is a check in the planning step of the main process only (batch/plan.py); the workers run the
package unchanged.
"""

from __future__ import annotations

import sys

from pedsafe_sumo.batch import plan
from pedsafe_sumo.batch.__main__ import main


def _no_staging_check(arguments, specs) -> None:
    return None


if __name__ == "__main__":
    plan.check_sampler_staging = _no_staging_check
    sys.exit(main(sys.argv[1:]))
