"""Table I of a batch's rows, printed at the end of the run: Wilson intervals for plain Monte Carlo, the
weighted estimates of the pooled stages for importance sampling, one table per approach under
--approach all. The report (python -m pedsafe_sumo.report) writes the same table with more columns.
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from pedsafe_sumo.batch.sampled import PROPOSALS_KEY
from pedsafe_sumo.report.tables import is_weighted, table_one_of_run, v2i_only_note
from pedsafe_sumo.safety.stats import table_one
from pedsafe_sumo.sampling.pooling import first_estimated_stage


def print_table(table: pd.DataFrame, run_info: dict[str, Any] | None = None) -> None:
    """Table I of the rows; `run_info` (run.json) for an importance-sampling run's stages pooled and the
    control variates of joint proposals (report/tables.py: table_one_weighted)."""
    proposals = (run_info or {}).get(PROPOSALS_KEY)
    first_stage = first_estimated_stage(run_info)

    def summarise(rows: pd.DataFrame) -> pd.DataFrame:
        if not is_weighted(rows):
            return table_one(rows)
        return table_one_of_run(rows, proposals=proposals, first_stage=first_stage)

    summary = summarise(table)
    if is_weighted(table):
        which = "the final stage" if first_stage is None else f"stages {first_stage}..final, pooled"
        print(
            f"Table I (importance sampling: weighted estimates of {which}, 95% central-limit "
            "intervals; see tables/table1.csv for ess and the episodes run, pilots included):"
        )
    else:
        print(
            "Table I (95% Wilson intervals; n counts the episodes that ran, errors are left out of the "
            "rates):"
        )
    _print_rows(summary)
    note = v2i_only_note(run_info) if is_weighted(table) else ""
    if note:
        print(note)
    arms = [arm for arm in table["approach"].unique() if arm] if "approach" in table else []
    if len(arms) > 1:  # --approach all: the same table per approach
        for arm in arms:
            print(f"Table I on approach {arm}:")
            _print_rows(summarise(table[table["approach"] == arm]))


def _print_rows(summary: pd.DataFrame) -> None:
    for _, row in summary.iterrows():
        print(
            f"  {row['scenario']:20s} {row['condition']:4s} n={int(row['n']):5d} "
            f"(errors {int(row['n_error'])})  collision {row['collision_rate']:.4f} "
            f"[{row['collision_low']:.4f}, {row['collision_high']:.4f}]  "
            f"injury {row['injury_mean']:.4f} [{row['injury_low']:.4f}, {row['injury_high']:.4f}]  "
            f"conflict {row['conflict_rate']:.4f} [{row['conflict_low']:.4f}, {row['conflict_high']:.4f}]"
            + (f"  ({row['estimator']})" if "estimator" in summary.columns else "")
        )
