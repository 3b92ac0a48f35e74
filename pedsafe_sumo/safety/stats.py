"""Statistics for Table I: Wilson intervals for rates, an exact McNemar test for the paired SV/V2I design."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import stats

from pedsafe_sumo.safety.conflict import conflict_without_collision
from pedsafe_sumo.safety.geometry import FloatOrArray

TABLE_INPUT_COLUMNS = ("scenario", "condition", "collision", "injury_probability", "conflict", "status")
ERROR_STATUS = "error"
TIMEOUT_STATUS = "timeout"
#: Statuses of episodes that did not run to their end (an error, or an AD stack past its per-step time
#: limit): counted apart in n_error and left out of every rate and of the paired tests.
FAILED_STATUSES = (ERROR_STATUS, TIMEOUT_STATUS)


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (Wilson 1927); (NaN, NaN) when n = 0.

    centre = (p + z^2/(2n)) / (1 + z^2/n), half-width = z sqrt(p(1-p)/n + z^2/(4n^2)) / (1 + z^2/n),
    with p = successes/n and z the two-sided normal quantile of `confidence`.
    """
    if n < 0 or successes < 0 or successes > n:
        raise ValueError(f"need 0 <= successes <= n, got successes={successes}, n={n}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    if n == 0:
        return math.nan, math.nan
    z = stats.norm.ppf(0.5 + confidence / 2.0)
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar test: the binomial test of b successes in b + c discordant pairs at 1/2.

    p = min(1, 2 * P(X <= min(b, c))), X ~ Binomial(b + c, 1/2); 1.0 when there is no discordant pair.
    """
    if b < 0 or c < 0:
        raise ValueError(f"discordant counts must not be negative, got b={b}, c={c}")
    if b + c == 0:
        return 1.0
    return float(min(1.0, 2.0 * stats.binom.cdf(min(b, c), b + c, 0.5)))


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


def _mean_interval(values: np.ndarray, confidence: float) -> tuple[float, float, float]:
    """Mean with a Student-t interval (clipped to [0, 1], as the values are probabilities)."""
    n = len(values)
    if n == 0:
        return math.nan, math.nan, math.nan
    mean = float(np.mean(values))
    if n == 1:
        return mean, math.nan, math.nan
    half = stats.t.ppf(0.5 + confidence / 2.0, n - 1) * float(np.std(values, ddof=1)) / math.sqrt(n)
    return mean, max(0.0, mean - half), min(1.0, mean + half)


def table_one(episodes: pd.DataFrame, confidence: float = 0.95) -> pd.DataFrame:
    """The paper's Table I, one row per scenario and condition (in order of first appearance).

    Columns: scenario, condition, n (episodes counted), n_error (episodes with status "error" or
    "timeout", left out), collision_rate with collision_low/high (Wilson), injury_mean with
    injury_low/high (Student t on the per-episode P_I), conflict_rate with conflict_low/high (Wilson),
    where a conflict counts only in an episode without a collision.
    """
    missing = [c for c in TABLE_INPUT_COLUMNS if c not in episodes.columns]
    if missing:
        raise ValueError(f"episodes lack column(s): {', '.join(missing)}")
    rows = []
    for (scenario, condition), group in episodes.groupby(["scenario", "condition"], sort=False):
        errors = group["status"].isin(FAILED_STATUSES).to_numpy()
        ok = group[~errors]
        n = len(ok)
        collisions = ok["collision"].to_numpy(dtype=bool)
        conflicts = conflict_without_collision(ok["conflict"].to_numpy(dtype=bool), collisions)
        n_col, n_con = int(collisions.sum()), int(conflicts.sum())
        injury_mean, injury_low, injury_high = _mean_interval(
            ok["injury_probability"].to_numpy(dtype=float), confidence
        )
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
