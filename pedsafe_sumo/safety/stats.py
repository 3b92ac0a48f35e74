"""Statistics for Table I: Wilson intervals for rates, a two-part (MOVER) interval for the mean injury,
and the exact McNemar test for the paired SV/V2I design. The binomial pieces are scipy's (`binomtest`)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import stats

from pedsafe_sumo.safety.conflict import conflict_without_collision
from pedsafe_sumo.safety.geometry import FloatOrArray

#: The second injury index (safety/injury_mais3.py) and its Table I columns (mean, 95% interval); a run
#: written before the column existed has a Table I without them.
SEVERE_INJURY_COLUMN = "injury_mais3f_probability"
SEVERE_INJURY_TABLE_COLUMNS = ("mais3f_mean", "mais3f_low", "mais3f_high")
TABLE_INPUT_COLUMNS = ("scenario", "condition", "collision", "injury_probability", "conflict", "status")
ERROR_STATUS = "error"
TIMEOUT_STATUS = "timeout"
#: Statuses of episodes that did not run to their end (an error, or an AD stack past its per-step time
#: limit): counted apart in n_error and left out of every rate and of the paired tests.
FAILED_STATUSES = (ERROR_STATUS, TIMEOUT_STATUS)


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (Wilson 1927); (NaN, NaN) when n = 0.

    scipy's `binomtest(successes, n).proportion_ci(method="wilson")` (no continuity correction): centre
    (p + z^2/(2n)) / (1 + z^2/n), half-width z sqrt(p(1-p)/n + z^2/(4n^2)) / (1 + z^2/n), p = successes/n.
    """
    if n < 0 or successes < 0 or successes > n:
        raise ValueError(f"need 0 <= successes <= n, got successes={successes}, n={n}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    if n == 0:
        return math.nan, math.nan
    ci = stats.binomtest(int(successes), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar test: scipy's two-sided binomial test of b successes in b + c discordant
    pairs at 1/2 (= min(1, 2 P(X <= min(b, c))), X ~ Binomial(b + c, 1/2)); 1.0 without a discordant pair.
    """
    if b < 0 or c < 0:
        raise ValueError(f"discordant counts must not be negative, got b={b}, c={c}")
    if b + c == 0:
        return 1.0
    return float(stats.binomtest(int(b), int(b + c), 0.5, alternative="two-sided").pvalue)


def zero_inflated_mean_interval(values: FloatOrArray, confidence: float = 0.95) -> tuple[float, float, float]:
    """Mean of values in [0, 1] that are mostly 0 (per-episode P_I), with an interval that holds there.

    A two-part model, mean = q m with q the share of positive values and m their mean, combined by MOVER
    (method of variance estimates recovery, Zou & Donner 2008, Stat. Med. 27:1693; for zero-inflated
    data Zou, Taleban & Huo 2009, Comput. Stat. Data Anal. 53:3755) on the log scale:
        log q: Wilson interval (l_q, u_q) of the k positives among n;
        log m: Student t interval (l_m, u_m) of the k positive values, clipped to [0, 1];
        low  = exp(log q m - sqrt((log q - log l_q)^2 + (log m - log l_m)^2)),
        high = exp(log q m + sqrt((log u_q - log q)^2 + (log u_m - log m)^2)).
    With k <= 1 the spread of the positives is unknown: (low, high) = (0, u_q), using m <= 1. All-zero
    data give (0, z^2 / (n + z^2)), about 3.84 / n: no event seen is not zero risk (cf. the rule of
    three, 3 / n). Returns (mean, low, high); NaN for no values, ValueError for a value outside [0, 1].
    Coverage by simulation: docs/safety_indexes.md and tests/safety/test_injury_interval.py.
    """
    x = np.asarray(values, dtype=float).reshape(-1)
    if not np.all((x >= 0.0) & (x <= 1.0)):  # NaN fails too
        raise ValueError("values must lie in [0, 1] (probabilities)")
    n = x.size
    if n == 0:
        return math.nan, math.nan, math.nan
    positive = x[x > 0.0]
    k = positive.size
    low_q, high_q = wilson_interval(k, n, confidence)
    mean = float(np.mean(x))
    if k <= 1:
        return mean, 0.0, high_q
    q, m = k / n, float(np.mean(positive))
    half = stats.t.ppf(0.5 + confidence / 2.0, k - 1) * float(np.std(positive, ddof=1)) / math.sqrt(k)
    low_m, high_m = max(0.0, m - half), min(1.0, m + half)
    with np.errstate(divide="ignore"):  # log 0 = -inf: a lower end at 0
        log_q, log_m = math.log(q), math.log(m)
        down = math.hypot(log_q - np.log(low_q), log_m - np.log(low_m))
        up = math.hypot(math.log(high_q) - log_q, math.log(high_m) - log_m)
    return mean, float(math.exp(log_q + log_m - down)), float(min(1.0, math.exp(log_q + log_m + up)))


def paired_counts(sv: FloatOrArray, v2i: FloatOrArray) -> tuple[int, int, int, int]:
    """Counts of a paired binary outcome: (both, sv only, v2i only, neither)."""
    sv, v2i = np.asarray(sv, dtype=bool), np.asarray(v2i, dtype=bool)
    if sv.shape != v2i.shape:
        raise ValueError(f"paired outcomes differ in shape: {sv.shape} and {v2i.shape}")
    return (
        int(np.sum(sv & v2i)),
        int(np.sum(sv & ~v2i)),
        int(np.sum(~sv & v2i)),
        int(np.sum(~sv & ~v2i)),
    )


def table_one(episodes: pd.DataFrame, confidence: float = 0.95) -> pd.DataFrame:
    """The paper's Table I, one row per scenario and condition (in order of first appearance).

    Columns: scenario, condition, n (episodes counted), n_error (episodes with status "error" or
    "timeout", left out), collision_rate with collision_low/high (Wilson), injury_mean with
    injury_low/high (`zero_inflated_mean_interval` of the per-episode P_I), conflict_rate with
    conflict_low/high (Wilson), where a conflict counts only in an episode without a collision; and
    when the episodes have values of `injury_mais3f_probability`, mais3f_mean with mais3f_low/high
    (as the injury; NaN in a row whose episodes lack some of them).
    """
    missing = [c for c in TABLE_INPUT_COLUMNS if c not in episodes.columns]
    if missing:
        raise ValueError(f"episodes lack column(s): {', '.join(missing)}")
    rows = []
    has_severe = SEVERE_INJURY_COLUMN in episodes.columns and bool(
        episodes[SEVERE_INJURY_COLUMN].notna().any()
    )
    for (scenario, condition), group in episodes.groupby(["scenario", "condition"], sort=False):
        errors = group["status"].isin(FAILED_STATUSES).to_numpy()
        ok = group[~errors]
        n = len(ok)
        collisions = ok["collision"].to_numpy(dtype=bool)
        conflicts = conflict_without_collision(ok["conflict"].to_numpy(dtype=bool), collisions)
        n_col, n_con = int(collisions.sum()), int(conflicts.sum())
        injury_mean, injury_low, injury_high = zero_inflated_mean_interval(
            ok["injury_probability"].to_numpy(dtype=float), confidence
        )
        # the second injury index, in runs that have it (NaN where a row lacks it: rows of older runs)
        severe = {}
        if has_severe:
            values = ok[SEVERE_INJURY_COLUMN].to_numpy(dtype=float)
            interval = zero_inflated_mean_interval(values, confidence) if not np.isnan(values).any() else None
            severe = dict(zip(SEVERE_INJURY_TABLE_COLUMNS, interval or (math.nan,) * 3))
        rows.append(
            {
                "scenario": scenario,
                "condition": condition,
                "n": n,
                "n_error": int(errors.sum()),
                "collision_rate": n_col / n if n else math.nan,
                "collision_low": wilson_interval(n_col, n, confidence)[0],
                "collision_high": wilson_interval(n_col, n, confidence)[1],
                "injury_mean": injury_mean,
                "injury_low": injury_low,
                "injury_high": injury_high,
                "conflict_rate": n_con / n if n else math.nan,
                "conflict_low": wilson_interval(n_con, n, confidence)[0],
                "conflict_high": wilson_interval(n_con, n, confidence)[1],
                **severe,
            }
        )
    return pd.DataFrame(rows)


def paired_mcnemar(episodes: pd.DataFrame, outcome: str = "collision") -> pd.DataFrame:
    """Per scenario, the exact McNemar test of a binary outcome between the paired sv and v2i episodes.

    Pairs are matched on (scenario, episode); a pair where either side has status "error" or "timeout"
    is dropped.
    Columns: scenario, n_pairs, both, sv_only, v2i_only, neither, p_value.
    """
    missing = [
        c for c in ("scenario", "condition", "episode", "status", outcome) if c not in episodes.columns
    ]
    if missing:
        raise ValueError(f"episodes lack column(s): {', '.join(missing)}")
    rows = []
    for scenario, group in episodes.groupby("scenario", sort=False):
        sides = {}
        for condition in ("sv", "v2i"):
            side = group[group["condition"] == condition].set_index("episode")
            if side.index.has_duplicates:
                raise ValueError(f"scenario {scenario}: episode numbers repeat under condition {condition}")
            sides[condition] = side
        pairs = sides["sv"][["status", outcome]].merge(
            sides["v2i"][["status", outcome]], left_index=True, right_index=True, suffixes=("_sv", "_v2i")
        )
        pairs = pairs[~pairs["status_sv"].isin(FAILED_STATUSES) & ~pairs["status_v2i"].isin(FAILED_STATUSES)]
        both, sv_only, v2i_only, neither = paired_counts(pairs[f"{outcome}_sv"], pairs[f"{outcome}_v2i"])
        rows.append(
            {
                "scenario": scenario,
                "n_pairs": len(pairs),
                "both": both,
                "sv_only": sv_only,
                "v2i_only": v2i_only,
                "neither": neither,
                "p_value": mcnemar_exact(sv_only, v2i_only),
            }
        )
    return pd.DataFrame(rows)
