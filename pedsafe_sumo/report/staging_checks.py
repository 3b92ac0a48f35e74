"""Diagnostics of how the episodes were staged, per scenario and condition, with the targets they should meet.

A staging that sets the outcome betrays itself in the episode rows:

- the first detection distance follows the ego's start distance (the pedestrian seen from t = 0): the
  Pearson and Spearman correlation of first_detection_distance_m with ego_start_distance_m, over the
  episodes where both are finite; target |Pearson r| < CORRELATION_TARGET;
- the first detection falls in the episode's first second (first_detection_time_s <= FIRST_SECOND_S): its
  share of the episodes; target below FIRST_SECOND_SHARE_TARGET;
- the minimum clearance of the episodes without a collision piles up on one value (a pedestrian frozen at
  the end of its path): the share of the most common min_clearance_m rounded to CLEARANCE_BIN_M, with that
  value; target at most CLEARANCE_SHARE_TARGET.

And the collisions by `collision_type` beside Table I (`collision_type_columns`). Only status "ok" rows
count. Nothing here prints.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import stats

from pedsafe_sumo.safety.stats import wilson_interval

OK_STATUS = "ok"
#: A correlation needs at least this many episodes with both distances finite; fewer give "n/a".
MIN_CORRELATION_EPISODES = 10
#: |r| below 0.3 is a weak correlation by the usual convention: the start distance then explains less than
#: a tenth (r^2 < 0.09) of the spread of the first detection distance.
CORRELATION_TARGET = 0.3
#: The episode's first second, s: a detection by then is one the staging handed over at the start.
FIRST_SECOND_S = 1.0
#: Target: fewer than 5% of the episodes detect the pedestrian in their first second (an assumption: the
#: share one would accept of pedestrians already in sight when the episode starts).
FIRST_SECOND_SHARE_TARGET = 0.05
#: The clearances are compared rounded to 1 cm, well above the logged positions' rounding.
CLEARANCE_BIN_M = 0.01
#: Target: no single clearance value holds more than 5% of the episodes without a collision (an
#: assumption: a spread-out measure puts well under that in any 1 cm bin).
CLEARANCE_SHARE_TARGET = 0.05

STAGING_COLUMNS = (
    "scenario",
    "condition",
    "n",
    "correlation_n",
    "pearson_r",
    "spearman_r",
    "correlation_note",
    "correlation_target_met",
    "first_second_share",
    "first_second_target_met",
    "no_collision_n",
    "modal_clearance_m",
    "modal_clearance_share",
    "clearance_target_met",
)
#: collision_type values beside Table I (io/episodes.py COLLISION_TYPES without "none").
COLLISION_TYPE_LABELS = {
    "ego_strikes_pedestrian": "ego strikes pedestrian",
    "pedestrian_strikes_side": "pedestrian strikes side",
}


def _groups(episodes: pd.DataFrame):
    order = {"sv": 0, "v2i": 1}
    for scenario in pd.unique(episodes["scenario"]):
        rows = episodes[episodes["scenario"] == scenario]
        for condition in sorted(pd.unique(rows["condition"]), key=lambda c: (order.get(c, 2), str(c))):
            yield str(scenario), str(condition), rows[rows["condition"] == condition]


def detection_correlation(detection_m: np.ndarray, start_m: np.ndarray) -> tuple[int, float, float, str]:
    """(episodes used, Pearson r, Spearman rho, note): NaN and the reason in `note` where undefined."""
    both = np.isfinite(detection_m) & np.isfinite(start_m)
    n = int(both.sum())
    x, y = start_m[both], detection_m[both]
    if not np.isfinite(start_m).any():
        return 0, math.nan, math.nan, "n/a: no episode records ego_start_distance_m (fixed staging)"
    if n < MIN_CORRELATION_EPISODES:
        return n, math.nan, math.nan, f"n/a: {n} episode(s) with both distances finite, fewer than 10"
    if np.ptp(x) == 0:
        return n, math.nan, math.nan, f"n/a: ego_start_distance_m is constant ({x[0]:g} m)"
    if np.ptp(y) == 0:
        return n, math.nan, math.nan, f"n/a: first_detection_distance_m is constant ({y[0]:g} m)"
    return n, float(stats.pearsonr(x, y)[0]), float(stats.spearmanr(x, y)[0]), ""


def modal_clearance(clearance_m: np.ndarray) -> tuple[float, float]:
    """(the most common clearance rounded to CLEARANCE_BIN_M, its share of the finite values); the smallest
    value among equally common ones; (NaN, NaN) without a finite value."""
    values = clearance_m[np.isfinite(clearance_m)]
    if values.size == 0:
        return math.nan, math.nan
    bins = np.round(values / CLEARANCE_BIN_M).astype(np.int64)
    keys, counts = np.unique(bins, return_counts=True)  # keys ascending: argmax takes the smallest
    k = int(np.argmax(counts))
    return round(float(keys[k]) * CLEARANCE_BIN_M, 2), float(counts[k]) / values.size


def staging_diagnostics(episodes: pd.DataFrame) -> pd.DataFrame:
    """Per scenario and condition: the three diagnostics and whether each target is met (None: n/a)."""
    ok = episodes[episodes["status"] == OK_STATUS]
    rows = []
    for scenario, condition, group in _groups(ok):
        n = len(group)
        detection = group["first_detection_distance_m"].to_numpy(dtype=float)
        if "ego_start_distance_m" in group:
            start = group["ego_start_distance_m"].to_numpy(dtype=float)
            n_corr, pearson, spearman, note = detection_correlation(detection, start)
        else:
            n_corr, pearson, spearman = 0, math.nan, math.nan
            note = "n/a: no ego_start_distance_m in this run"
        first_time = group["first_detection_time_s"].to_numpy(dtype=float)
        with np.errstate(invalid="ignore"):
            first_second = float(np.mean(first_time <= FIRST_SECOND_S)) if n else math.nan
        free = ~group["collision"].astype("boolean").fillna(False).to_numpy(dtype=bool)
        if "min_clearance_m" in group:
            value, share = modal_clearance(group["min_clearance_m"].to_numpy(dtype=float)[free])
        else:
            value, share = math.nan, math.nan
        rows.append(
            {
                "scenario": scenario,
                "condition": condition,
                "n": n,
                "correlation_n": n_corr,
                "pearson_r": pearson,
                "spearman_r": spearman,
                "correlation_note": note,
                "correlation_target_met": None if math.isnan(pearson) else abs(pearson) < CORRELATION_TARGET,
                "first_second_share": first_second,
                "first_second_target_met": None
                if math.isnan(first_second)
                else first_second < FIRST_SECOND_SHARE_TARGET,
                "no_collision_n": int(free.sum()),
                "modal_clearance_m": value,
                "modal_clearance_share": share,
                "clearance_target_met": None if math.isnan(share) else share <= CLEARANCE_SHARE_TARGET,
            }
        )
    return pd.DataFrame(rows, columns=list(STAGING_COLUMNS))


def collision_type_columns(table: pd.DataFrame, episodes: pd.DataFrame) -> pd.DataFrame:
    """Table I with, per collision type, its count and rate over the row's n episodes (Wilson 95% interval)
    appended as `<type>` , `<type>_rate`, `<type>_low`, `<type>_high`; Table I's own columns untouched.
    An importance-sampling table (column `ess`) gets the counts as drawn over every stage only: their plain
    rate would not estimate the nominal one. The table unchanged when the run has no collision_type column."""
    if "collision_type" not in episodes.columns:
        return table
    ok = episodes[episodes["status"] == OK_STATUS]
    weighted = "ess" in table.columns
    out = table.copy()
    for kind in COLLISION_TYPE_LABELS:
        counts, rates, lows, highs = [], [], [], []
        for row in table.itertuples(index=False):
            group = ok[(ok["scenario"] == row.scenario) & (ok["condition"] == row.condition)]
            count = int((group["collision_type"] == kind).sum())
            n = int(row.n)
            low, high = wilson_interval(count, n) if n else (math.nan, math.nan)
            counts.append(count)
            rates.append(count / n if n and not weighted else math.nan)
            lows.append(low if not weighted else math.nan)
            highs.append(high if not weighted else math.nan)
        out[kind] = counts
        out[f"{kind}_rate"], out[f"{kind}_low"], out[f"{kind}_high"] = rates, lows, highs
    return out


# ---------------------------------------------------------------- formatting
STAGING_TITLE = (
    "Staging diagnostics (targets: |Pearson r| of first detection with start distance < "
    f"{CORRELATION_TARGET:g}; first detection in the first second < {FIRST_SECOND_SHARE_TARGET:.0%} "
    f"of episodes;\nthe most common minimum clearance (1 cm bins, episodes without a collision) <= "
    f"{CLEARANCE_SHARE_TARGET:.0%} of them)"
)


def _label(condition: str) -> str:
    return {"sv": "SV", "v2i": "V2I"}.get(condition, condition)


def _met(flag) -> str:
    return "n/a" if flag is None or pd.isna(flag) else ("met" if flag else "MISSED")


def _share(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{100 * value:.1f}%"


def staging_rows(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    header = [
        "scenario",
        "condition",
        "n",
        "r (Pearson / Spearman) of detection with start distance",
        "target |r| < 0.3",
        "first detection <= 1 s",
        "target < 5%",
        "most common min clearance",
        "target <= 5%",
    ]
    rows = []
    for r in table.to_dict("records"):
        correlation = (
            r["correlation_note"]
            if r["correlation_note"]
            else f"{r['pearson_r']:.3f} / {r['spearman_r']:.3f} (n={r['correlation_n']})"
        )
        clearance = (
            "n/a: no episode without a collision"
            if not math.isfinite(r["modal_clearance_share"])
            else f"{r['modal_clearance_m']:.2f} m in {_share(r['modal_clearance_share'])} of "
            f"{r['no_collision_n']}"
        )
        rows.append(
            [
                r["scenario"],
                _label(r["condition"]),
                str(r["n"]),
                correlation,
                _met(r["correlation_target_met"]),
                _share(r["first_second_share"]),
                _met(r["first_second_target_met"]),
                clearance,
                _met(r["clearance_target_met"]),
            ]
        )
    return header, rows


def collision_type_cells(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    """Header cells and per-row cells of the collision-type columns (empty without them)."""
    if not all(kind in table.columns for kind in COLLISION_TYPE_LABELS):
        return [], [[] for _ in range(len(table))]
    weighted = "ess" in table.columns
    header = [
        f"{label} {'(drawn, every stage)' if weighted else 'rate [95% CI]'}"
        for label in COLLISION_TYPE_LABELS.values()
    ]
    rows = []
    for r in table.to_dict("records"):
        cells = []
        for kind in COLLISION_TYPE_LABELS:
            if weighted or not math.isfinite(r[f"{kind}_rate"]):
                cells.append(str(r[kind]))
            else:
                cells.append(f"{r[f'{kind}_rate']:.4f} [{r[f'{kind}_low']:.4f}, {r[f'{kind}_high']:.4f}]")
        rows.append(cells)
    return header, rows
