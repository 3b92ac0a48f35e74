"""Table I and the paired SV-versus-V2I comparison of a run, as DataFrames, text, Markdown and CSV.

The statistics are those of `pedsafe_sumo.safety.stats` (Wilson intervals, the two-part MOVER interval of
the mean injury, exact McNemar); this module only arranges and formats them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy import special

from pedsafe_sumo.report.staging_checks import collision_type_cells
from pedsafe_sumo.safety.conflict import conflict_without_collision
from pedsafe_sumo.safety.stats import FAILED_STATUSES, paired_mcnemar, table_one
from pedsafe_sumo.sampling.control_variate import ESTIMATOR_CV, ESTIMATOR_IS, condition_control, stage_control
from pedsafe_sumo.sampling.control_variate import MIN_ROWS as CV_MIN_ROWS
from pedsafe_sumo.sampling.importance import Estimate
from pedsafe_sumo.sampling.joint import GUARD_MIN_COLLISIONS
from pedsafe_sumo.sampling.pooling import StageRows, pooled_estimate, pooled_from_stage, stage_max_weight
from pedsafe_sumo.sampling.stages import DEFENSIVE_SHARE
from pedsafe_sumo.sampling.v2i_factor import V2I_ONLY_MIN_COLLISIONS

CONDITION_LABELS = {"sv": "SV", "v2i": "V2I"}
#: Outcomes of the paired test: column tested -> its name in the table. "table_conflict" is Table I's
#: conflict (a conflict in an episode without a collision), derived by `paired_of_run`.
PAIRED_OUTCOMES = {"collision": "collision", "table_conflict": "conflict"}
TABLE_FILES = ("table1.csv", "table1.md", "paired.csv", "paired.md")
#: An importance-sampling row is flagged when its final stage's mean weight lies further from 1 (its
#: expectation under any proposal) than this many of its standard errors: the weights' tail was then not
#: sampled, and the central-limit interval understates the spread (docs/sampling.md). 3 standard errors:
#: a false flag in about 1 row of 370 when the weights behave.
WEIGHT_CHECK_Z = 3.0
#: ... or when one episode carries more than this share of the collision estimate sum w_i f_i: the
#: estimate (and its interval) then rests on one draw. A quarter: with that share from one draw of
#: tens, the product's sample variance is dominated by it.
WEIGHT_CHECK_MAX_SHARE = 0.25


def condition_label(condition: str) -> str:
    return CONDITION_LABELS.get(condition, str(condition))


def is_weighted(episodes: pd.DataFrame) -> bool:
    """Whether the run is an importance-sampling one (--sampler is): it has sampler stages beyond 0."""
    return "sampler_stage" in episodes.columns and bool((episodes["sampler_stage"] > 0).any())


def table_one_weighted(
    episodes: pd.DataFrame,
    confidence: float = 0.95,
    proposals: Mapping[str, Sequence[str]] | None = None,
    first_stage: int | None = None,
) -> pd.DataFrame:
    """Table I of an importance-sampling run (docs/sampling.md): per scenario and condition, the unbiased
    weighted estimates of the collision indicator, the injury probability and the conflict-without-collision
    indicator with central-limit 95% intervals, from the episodes of stages `first_stage`..final (the final
    stage is the highest sampler_stage of the scenario; `first_stage` None, or above it: the final stage
    alone, (1/n) sum w_i f_i). Several stages are pooled by sampling.pooling.pooled_estimate: each stage's
    own estimate, weighted by its share of the episodes, and the table gains the column `stages` ("2-3").
    Also the effective sample size `ess` of the pooled weights, and `n_run`, every episode run under that
    condition, pilot stages and errors included (the cost). `n` and `n_error` count the pooled stages.

    `proposals` (run.json's sampler_proposals: scenario -> one JSON proposal per stage): each stage that
    drew from a joint proposal with a stored E_p[pi_hat] is estimated with its pi_hat as a control variate
    (sampling/control_variate.py; docs/sampling.md, "Control variate") and the table gains the column
    `estimator` ("is+cv", or "is" and which indexes kept the plain estimate in every stage). Without such a
    proposal in the table, the table is the plain weighted one, column for column.
    """
    rows, controlled, pooled = [], False, False
    for (scenario, condition), group in episodes.groupby(["scenario", "condition"], sort=False):
        final_stage = int(group["sampler_stage"].max())
        first = pooled_from_stage(first_stage, final_stage)
        pooled |= first < final_stage
        used = group[group["sampler_stage"] >= first]
        errors = used["status"].isin(FAILED_STATUSES).to_numpy()
        ok = used[~errors]
        weights = ok["weight"].to_numpy(dtype=float)
        collisions = _flags(ok["collision"])
        values = {
            "collision": collisions.astype(float),
            "injury": np.nan_to_num(ok["injury_probability"].to_numpy(dtype=float), nan=0.0),
            "conflict": conflict_without_collision(_flags(ok["conflict"]), collisions).astype(float),
        }
        stage_of_row = ok["sampler_stage"].to_numpy(dtype=int)
        stage_numbers = sorted(set(stage_of_row.tolist()))
        controls = {
            stage: _stage_control_values(
                ok, stage_of_row == stage, (proposals or {}).get(scenario), stage, str(condition)
            )
            for stage in stage_numbers
        }
        est, kept_plain = {}, []
        for index, v in values.items():
            stages = [
                StageRows(
                    v[stage_of_row == stage],
                    weights[stage_of_row == stage],
                    *controls[stage],
                    max_weight=stage_max_weight((proposals or {}).get(scenario), stage),
                )
                for stage in stage_numbers
            ]
            result = pooled_estimate(stages, confidence)
            est[index] = result.estimate
            if result.stages_with_control == 0:
                kept_plain.append(index)
        has_control = any(control[0] is not None for control in controls.values())
        controlled |= has_control
        rows.append(
            {
                "scenario": scenario,
                "condition": condition,
                "n": len(ok),
                "n_error": int(errors.sum()),
                "collision_rate": est["collision"].mean,
                "collision_low": max(0.0, est["collision"].low),
                "collision_high": est["collision"].high,
                "injury_mean": est["injury"].mean,
                "injury_low": max(0.0, est["injury"].low),
                "injury_high": est["injury"].high,
                "conflict_rate": est["conflict"].mean,
                "conflict_low": max(0.0, est["conflict"].low),
                "conflict_high": est["conflict"].high,
                "ess": est["collision"].ess,
                "n_run": len(group),
                **weight_check(weights, collisions.astype(float)),
                "estimator": _estimator_label(has_control and len(ok) > 0, kept_plain, list(values)),
                "stages": f"{first}-{final_stage}" if first < final_stage else str(final_stage),
            }
        )
    table = pd.DataFrame(rows)
    if not controlled:  # no control variate anywhere: no estimator column, the table of plain IS
        table = table.drop(columns="estimator", errors="ignore")
    if not pooled:  # the final stage alone everywhere (no --is-pool-from): no stages column
        table = table.drop(columns="stages", errors="ignore")
    return table


def _stage_control_values(
    rows: pd.DataFrame, in_stage: np.ndarray, proposals: Sequence[str] | None, stage: int, condition: str
) -> tuple[np.ndarray | None, float, float]:
    """The control at the stage's rows of `condition` with its nominal mean and that mean's standard
    error (condition_control: pi_hat, or pi_hat r for V2I under the V2I factor), where the stage drew from
    a joint proposal that can serve as a control variate (stage_control); else (None, nan, nan)."""
    control = stage_control(proposals, stage)
    if control is None or not in_stage.any():
        return None, math.nan, math.nan
    return condition_control(control, rows.loc[in_stage, "sampler_inputs"].tolist(), condition)


def _estimator_label(has_control: bool, kept_plain: list[str], indexes: list[str]) -> str:
    """The row's `estimator`: is+cv where every index used the control variate in some stage, is where
    none did (or no stage has a control), else is+cv with the indexes that kept the weighted mean."""
    if not has_control or len(kept_plain) == len(indexes):
        return ESTIMATOR_IS
    if not kept_plain:
        return ESTIMATOR_CV
    return f"{ESTIMATOR_CV} ({ESTIMATOR_IS}: {', '.join(kept_plain)})"


def weight_check(weights: np.ndarray, collisions: np.ndarray) -> dict[str, object]:
    """The final stage's mean weight (expectation 1 under any proposal), the largest share one episode has
    of the collision estimate, and `weight_note`: "" when both look sound, else why the central-limit
    interval should not be trusted (WEIGHT_CHECK_Z, WEIGHT_CHECK_MAX_SHARE)."""
    w = np.asarray(weights, dtype=float)
    if len(w) < 2:
        return {
            "mean_weight": float(np.mean(w)) if len(w) else math.nan,
            "max_share": math.nan,
            "weight_note": "",
        }
    mean_w = float(np.mean(w))
    se = float(np.std(w, ddof=1)) / math.sqrt(len(w))
    products = w * np.asarray(collisions, dtype=float)
    total = float(np.sum(products))
    max_share = float(np.max(products) / total) if total > 0 else math.nan
    notes = []
    if abs(mean_w - 1.0) > WEIGHT_CHECK_Z * se:
        notes.append(f"mean weight {mean_w:.3f} is more than {WEIGHT_CHECK_Z:g} SE from 1")
    if total > 0 and max_share > WEIGHT_CHECK_MAX_SHARE:
        notes.append(f"one episode carries {max_share:.0%} of the collision estimate")
    return {"mean_weight": mean_w, "max_share": max_share, "weight_note": "; ".join(notes)}


def table_one_of_run(
    episodes: pd.DataFrame,
    confidence: float = 0.95,
    proposals: Mapping[str, Sequence[str]] | None = None,
    first_stage: int | None = None,
) -> pd.DataFrame:
    """Table I (scenario x condition) of `table_one`, rows ordered by scenario then sv before v2i; for an
    importance-sampling run, `table_one_weighted` (with the columns ess and n_run; `proposals`, run.json's
    sampler_proposals, for the control variate of joint proposals; `first_stage`, the first stage pooled,
    batch.sampled.first_estimated_stage of run.json)."""
    table = (
        table_one_weighted(episodes, confidence, proposals, first_stage)
        if is_weighted(episodes)
        else table_one(episodes, confidence)
    )
    order = {c: i for i, c in enumerate(CONDITION_LABELS)}
    scenario_order = {s: i for i, s in enumerate(pd.unique(episodes["scenario"]))}
    key = table["scenario"].map(scenario_order) * 100 + table["condition"].map(order).fillna(99)
    return table.iloc[key.argsort(kind="stable")].reset_index(drop=True)


def _flags(column: pd.Series) -> np.ndarray:
    """A boolean column as a numpy bool array; missing values (an errored episode's) read as False."""
    return column.astype("boolean").fillna(False).to_numpy(dtype=bool)


def paired_of_run(episodes: pd.DataFrame, first_stage: int | None = None) -> pd.DataFrame:
    """Per scenario and outcome, the exact McNemar test of SV against V2I on pairs of the same episode.

    Outcomes: collisions, and Table I's conflict (a conflict in an episode without a collision).
    Columns: scenario, outcome, n_pairs, both, b (SV only), c (V2I only), neither, sv_rate, v2i_rate
    (shares of the pairs), p_value. A scenario run under one condition only has n_pairs = 0, p = 1.

    An importance-sampling run (is_weighted) drew its pairs from a proposal, so the counts and shares of
    the drawn pairs say nothing of the nominal population: there, over the stages Table I estimates from
    (`first_stage`, as in table_one_weighted), the counts are those drawn, `sv_rate` and `v2i_rate` the
    weighted estimates, and `p_value` the two-sided test of E_p[SV - V2I] = 0 on the weighted paired
    differences (their pooled estimate over its standard error, normal; 1 with no discordant pair), and
    the table gains the column `test` ("weighted z").
    """
    frame = episodes.copy()
    frame["table_conflict"] = conflict_without_collision(
        _flags(frame["conflict"]), _flags(frame["collision"])
    )
    if is_weighted(frame):
        frame = _estimated_stages(frame, first_stage)
    parts = []
    for column, name in PAIRED_OUTCOMES.items():
        test = paired_mcnemar(frame, outcome=column)
        test.insert(1, "outcome", name)
        parts.append(test)
    paired = pd.concat(parts, ignore_index=True).rename(columns={"sv_only": "b", "v2i_only": "c"})
    n = paired["n_pairs"].where(paired["n_pairs"] > 0)
    paired.insert(len(paired.columns) - 1, "sv_rate", (paired["both"] + paired["b"]) / n)
    paired.insert(len(paired.columns) - 1, "v2i_rate", (paired["both"] + paired["c"]) / n)
    if is_weighted(episodes):
        for i, row in paired.iterrows():
            column = next(c for c, name in PAIRED_OUTCOMES.items() if name == row["outcome"])
            sv_rate, v2i_rate, p_value = _weighted_paired_test(
                frame[frame["scenario"] == row["scenario"]], column
            )
            paired.loc[i, ["sv_rate", "v2i_rate", "p_value"]] = [sv_rate, v2i_rate, p_value]
        paired["test"] = WEIGHTED_PAIRED_TEST
    scenario_order = {s: i for i, s in enumerate(pd.unique(episodes["scenario"]))}
    return paired.sort_values(
        "scenario", key=lambda s: s.map(scenario_order), kind="stable", ignore_index=True
    )


#: The `test` column of an importance-sampling run's paired table (paired_of_run).
WEIGHTED_PAIRED_TEST = "weighted z"


def _estimated_stages(frame: pd.DataFrame, first_stage: int | None) -> pd.DataFrame:
    """The rows of the stages Table I estimates from, per scenario (table_one_weighted's choice)."""
    final = frame.groupby("scenario")["sampler_stage"].transform("max")
    first = final.map(lambda stage: pooled_from_stage(first_stage, int(stage)))
    return frame[frame["sampler_stage"] >= first]


def _weighted_paired_test(rows: pd.DataFrame, column: str) -> tuple[float, float, float]:
    """(SV estimate, V2I estimate, two-sided p of E_p[SV - V2I] = 0) from one scenario's weighted pairs,
    each stage's own mean weighted by its share (sampling.pooling.pooled_estimate, no control variate)."""
    ok = rows[~rows["status"].isin(FAILED_STATUSES)]
    sides = [ok[ok["condition"] == c].set_index("episode") for c in ("sv", "v2i")]
    pairs = sides[0][["weight", "sampler_stage", column]].merge(
        sides[1][[column]], left_index=True, right_index=True, suffixes=("", "_v2i")
    )
    if pairs.empty:
        return math.nan, math.nan, 1.0
    sv = _flags(pairs[column]).astype(float)
    v2i = _flags(pairs[f"{column}_v2i"]).astype(float)
    weights = pairs["weight"].to_numpy(dtype=float)
    stage = pairs["sampler_stage"].to_numpy(dtype=int)

    def pooled(values: np.ndarray) -> Estimate:
        stages = [StageRows(values[stage == s], weights[stage == s]) for s in sorted(set(stage.tolist()))]
        return pooled_estimate(stages).estimate

    difference = sv - v2i
    if not np.any(difference != 0):
        return pooled(sv).mean, pooled(v2i).mean, 1.0
    d = pooled(difference)
    se = (d.high - d.mean) / float(special.ndtri(0.975))
    p_value = float(2 * special.ndtr(-abs(d.mean) / se)) if se > 0 else 0.0
    return pooled(sv).mean, pooled(v2i).mean, p_value


# ---------------------------------------------------------------- formatting
def _num(value: float, digits: int = 4) -> str:
    return "n/a" if value is None or not math.isfinite(float(value)) else f"{value:.{digits}f}"


def _with_interval(value: float, low: float, high: float) -> str:
    interval = "" if not (math.isfinite(low) and math.isfinite(high)) else f" [{low:.4f}, {high:.4f}]"
    return _num(value) + interval


def _p(value: float) -> str:
    return "n/a" if not math.isfinite(value) else (f"{value:.4f}" if value >= 1e-4 else f"{value:.1e}")


def table_one_rows(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    """Header and formatted cells of Table I (rate or mean, then its 95% interval)."""
    header = [
        "scenario",
        "condition",
        "n",
        "errors",
        "collision rate [95% CI]",
        "injury P_I mean [95% CI]",
        "conflict rate [95% CI]",
    ]
    rows = [
        [
            str(r.scenario),
            condition_label(r.condition),
            str(r.n),
            str(r.n_error),
            _with_interval(r.collision_rate, r.collision_low, r.collision_high),
            _with_interval(r.injury_mean, r.injury_low, r.injury_high),
            _with_interval(r.conflict_rate, r.conflict_low, r.conflict_high),
        ]
        for r in table.itertuples(index=False)
    ]
    if "mais3f_mean" in table.columns:  # the second injury index (safety/injury_mais3.py)
        header.insert(6, "MAIS3+F risk mean [95% CI]")
        for cells, r in zip(rows, table.itertuples(index=False)):
            cells.insert(6, _with_interval(r.mais3f_mean, r.mais3f_low, r.mais3f_high))
    if "ess" in table.columns:  # importance sampling: the effective sample size and the episodes run
        header += ["ESS", "episodes run (pilots included)"]
        for cells, r in zip(rows, table.itertuples(index=False)):
            cells += [f"{r.ess:.1f}", str(r.n_run)]
        if "mean_weight" in table.columns:  # the weights' check (weight_check)
            header += ["mean weight", "check"]
            for cells, r in zip(rows, table.itertuples(index=False)):
                cells += [f"{r.mean_weight:.3f}", r.weight_note or "ok"]
        if "estimator" in table.columns:  # a joint proposal's control variate (table_one_weighted)
            header += ["estimator"]
            for cells, r in zip(rows, table.itertuples(index=False)):
                cells += [str(r.estimator)]
        if "stages" in table.columns:  # the stages pooled (--is-pool-from)
            header += ["stages"]
            for cells, r in zip(rows, table.itertuples(index=False)):
                cells += [str(r.stages)]
    types_header, types_cells = collision_type_cells(table)  # the collisions by type, where counted
    header += types_header
    for cells, extra in zip(rows, types_cells):
        cells += extra
    return header, rows


def paired_rows(paired: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    header = [
        "scenario",
        "outcome",
        "pairs",
        "both",
        "b (SV only)",
        "c (V2I only)",
        "neither",
        "SV",
        "V2I",
        "p",
    ]
    rows = [
        [
            str(r.scenario),
            str(r.outcome),
            str(r.n_pairs),
            str(r.both),
            str(r.b),
            str(r.c),
            str(r.neither),
            _num(r.sv_rate),
            _num(r.v2i_rate),
            _p(r.p_value),
        ]
        for r in paired.itertuples(index=False)
    ]
    return header, rows


def text_table(header: list[str], rows: list[list[str]]) -> str:
    """Columns padded to their widest cell; text left-aligned, the rest right-aligned."""
    widths = [max(len(h), *(len(row[i]) for row in rows)) if rows else len(h) for i, h in enumerate(header)]
    left = {0, 1}

    def line(cells: list[str]) -> str:
        return "  ".join(
            c.ljust(w) if i in left else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths))
        )

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(header), rule, *(line(r) for r in rows)])


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    aligns = ["---" if i < 2 else "---:" for i in range(len(header))]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(aligns) + " |"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


TABLE_ONE_TITLE = (
    "Table I: collision rate, mean injury probability P_I, conflict rate (conflict without collision)\n"
    "95% intervals: Wilson for the rates, two-part (share injured x mean P_I of the injured, MOVER) for the "
    "mean P_I; n = episodes counted, "
    "errors = episodes with status 'error' or 'timeout' (left out)"
)
#: Under Table I when a row has the column `estimator` (table_one_weighted with a joint proposal).
ESTIMATOR_NOTE = (
    "estimator: is = the weighted mean (1/n) sum w_i f_i over the final stage (or over each stage of "
    "`stages`); is+cv = with pi_hat of the joint proposal as a control variate (regression estimator, "
    "docs/sampling.md); in brackets the indexes that kept the weighted mean (no event in the stages); a "
    f"stage of fewer than {CV_MIN_ROWS} episodes, or a constant control, keeps it for every index"
)
#: Under Table I when a row has the column `stages` (table_one_weighted with --is-pool-from).
STAGES_NOTE = (
    "stages: the sampler stages estimated from (--is-pool-from, fixed with the run): each stage's own "
    "estimate (with its own pi_hat as control variate where it has one), weighted by its share of the "
    "episodes (docs/sampling.md, 'Pooling the stages'); n counts their episodes"
)


def estimator_note(table: pd.DataFrame) -> str:
    """ESTIMATOR_NOTE where the table says which estimator each row used, STAGES_NOTE where it pools
    stages (both, one per line), else ""."""
    notes = [ESTIMATOR_NOTE] if "estimator" in table.columns else []
    if "stages" in table.columns:
        notes.append(STAGES_NOTE)
    return "\n\n".join(notes)


def v2i_only_note(run_info: Mapping[str, Any] | None) -> str:
    """One line per scenario of an importance-sampling run whose final proposal does not aim at V2I's
    collisions where SV does not collide although its pilots drew some (run.json's sampler_levels: the
    last stage's `v2i_only_pilot_collisions` > 0 without `v2i_only_terms`): V2I's interval may then be
    too narrow (docs/sampling.md, Limits, "Another junction"); "" otherwise, and for a run.json without
    the count."""
    levels = (run_info or {}).get("sampler_levels") or {}
    notes = []
    for scenario, stages in levels.items():
        last = stages[-1] if stages else {}
        seen = int(last.get("v2i_only_pilot_collisions", 0) or 0)
        if seen > 0 and not last.get("v2i_only_terms"):
            notes.append(
                f"note: {scenario}: V2I collided where SV did not in {seen} pilot pair(s), too few for the "
                f"proposal to aim there ({GUARD_MIN_COLLISIONS}, or {V2I_ONLY_MIN_COLLISIONS} making up "
                f"{DEFENSIVE_SHARE:g} of the pilots' V2I collisions): V2I's interval may be too narrow; "
                "check it against a plain MC run (docs/sampling.md, Limits)"
            )
    return "\n".join(notes)


PAIRED_TITLE = (
    "Paired SV vs V2I (same episode, same seed): exact McNemar test on the discordant pairs\n"
    "b = event under SV only, c = event under V2I only; SV, V2I = event rate over the pairs"
)
#: The paired table of an importance-sampling run (paired_of_run with the column `test`).
PAIRED_WEIGHTED_TITLE = (
    "Paired SV vs V2I (same episode, same draw), importance sampling: pairs drawn from the proposal\n"
    "both, b (SV only), c (V2I only), neither = pairs as drawn, of the stages Table I estimates from; "
    "SV, V2I = weighted estimates of the event rate (no control variate); p = two-sided normal test of "
    "E[SV - V2I] = 0 on the weighted paired differences (test: weighted z), not McNemar's; a normal "
    "approximation, which needs more than a handful of discordant pairs (b + c)"
)


def paired_title(paired: pd.DataFrame) -> str:
    """The title of the paired table: PAIRED_WEIGHTED_TITLE for an importance-sampling run's."""
    return PAIRED_WEIGHTED_TITLE if "test" in paired.columns else PAIRED_TITLE


def _md_title(title: str) -> str:
    first, _, rest = title.partition("\n")
    return f"**{first}**\n\n{rest}" if rest else f"**{first}**"


def write_tables(table: pd.DataFrame, paired: pd.DataFrame, directory: Path, banner: str = "") -> list[Path]:
    """DIR/tables/table1.csv, table1.md, paired.csv, paired.md; returns the paths written. A `banner`
    (an unfinished run) opens each Markdown table."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = [directory / name for name in TABLE_FILES]
    head = f"**{banner}**\n\n" if banner else ""
    table.to_csv(paths[0], index=False)
    note = f"\n{estimator_note(table)}\n" if estimator_note(table) else ""
    paths[1].write_text(
        f"{head}{_md_title(TABLE_ONE_TITLE)}\n\n{markdown_table(*table_one_rows(table))}\n{note}",
        encoding="utf-8",
    )
    paired.to_csv(paths[2], index=False)
    paths[3].write_text(
        f"{head}{_md_title(paired_title(paired))}\n\n{markdown_table(*paired_rows(paired))}\n",
        encoding="utf-8",
    )
    return paths


def interval_cell(value: float, low: float, high: float) -> str:
    """A rate or mean with its interval, as Table I's cells show it ("0.3000 [0.1078, 0.6032]")."""
    return _with_interval(value, low, high)
