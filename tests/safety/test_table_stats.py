"""Table I statistics: Wilson intervals, the exact McNemar test, paired counts, and the table itself."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from pedsafe_sumo.safety.stats import mcnemar_exact, paired_counts, paired_mcnemar, table_one, wilson_interval

Z = 1.959964  # two-sided 95 % normal quantile


def test_wilson_23_of_100():
    # p = 0.23, z^2 = 3.841459, 1 + z^2/n = 1.038415
    # centre = (0.23 + 3.841459 / 200) / 1.038415 = 0.249207 / 1.038415 = 0.239988
    # half = z sqrt(0.23 * 0.77 / 100 + 3.841459 / 40000) / 1.038415
    #      = 1.959964 * sqrt(0.001771 + 0.000096) / 1.038415 = 1.959964 * 0.043209 / 1.038415 = 0.081556
    # -> (0.158432, 0.321544)
    low, high = wilson_interval(23, 100)
    assert low == pytest.approx(0.158432, abs=2e-6) and high == pytest.approx(0.321544, abs=2e-6)


def test_wilson_with_no_successes_starts_at_zero():
    # p = 0: centre = half = (z^2 / 20) / (1 + z^2 / 10), so high = 2 * centre = z^2 / (n + z^2)
    #       = 3.841459 / 13.841459 = 0.277533, low = 0
    low, high = wilson_interval(0, 10)
    assert low == 0.0 and high == pytest.approx(0.277533, abs=2e-6)


def test_wilson_bad_input():
    assert all(math.isnan(v) for v in wilson_interval(0, 0))
    with pytest.raises(ValueError):
        wilson_interval(5, 3)
    with pytest.raises(ValueError):
        wilson_interval(1, 3, confidence=1.5)


def test_mcnemar_exact_10_against_2():
    # 2 * P(X <= 2), X ~ Bin(12, 1/2) = 2 * (1 + 12 + 66) / 4096 = 158 / 4096 = 0.0385742
    assert mcnemar_exact(10, 2) == pytest.approx(158 / 4096)
    assert mcnemar_exact(2, 10) == pytest.approx(0.0385742, abs=1e-7)


def test_mcnemar_exact_against_the_binomial_sum():
    # b = 30, c = 12: p = 2 * sum_{i <= 12} C(42, i) / 2^42, summed with integers
    tail = sum(math.comb(42, i) for i in range(13)) / 2**42
    assert mcnemar_exact(30, 12) == pytest.approx(2 * tail, rel=1e-9)
    assert mcnemar_exact(12, 30) == pytest.approx(2 * tail, rel=1e-9)


def test_wilson_agrees_with_the_closed_form_on_many_inputs():
    for k, n in ((0, 1), (1, 1), (1, 4), (7, 9), (17, 150), (2, 2000), (1999, 2000)):
        p, denom = k / n, 1 + Z * Z / n
        centre = (p + Z * Z / (2 * n)) / denom
        half = Z * math.sqrt(p * (1 - p) / n + Z * Z / (4 * n * n)) / denom
        assert wilson_interval(k, n) == pytest.approx(
            (max(0.0, centre - half), min(1.0, centre + half)), abs=1e-6
        )


def test_mcnemar_exact_degenerate_cases():
    assert mcnemar_exact(0, 0) == 1.0
    # b = c = 3: 2 * (1 + 6 + 15 + 20) / 64 = 1.3125, capped at 1
    assert mcnemar_exact(3, 3) == 1.0
    # b = 5, c = 0: 2 * (1 / 32) = 0.0625
    assert mcnemar_exact(5, 0) == pytest.approx(0.0625)


def test_paired_counts():
    sv = [True, True, False, False, True]
    v2i = [True, False, True, False, False]
    assert paired_counts(sv, v2i) == (1, 2, 1, 1)
    with pytest.raises(ValueError, match="differ in shape"):
        paired_counts([True], [True, False])


def _episodes() -> pd.DataFrame:
    rows = [
        # crossing/sv: 4 counted episodes, 1 collision (P_I 0.4), 2 conflicts of which 1 with the collision,
        # plus one error episode that must not count (its collision included)
        ("crossing", "sv", 0, True, 0.4, True, "ok"),
        ("crossing", "sv", 1, False, 0.0, True, "ok"),
        ("crossing", "sv", 2, False, 0.0, False, "ok"),
        ("crossing", "sv", 3, False, 0.0, False, "ok"),
        ("crossing", "sv", 4, True, 0.9, False, "error"),
        ("crossing", "v2i", 0, False, 0.0, False, "ok"),
        ("crossing", "v2i", 1, False, 0.0, False, "ok"),
        ("crossing", "v2i", 2, False, 0.0, False, "ok"),
        ("crossing", "v2i", 3, True, 0.2, False, "ok"),
        ("crossing", "v2i", 4, False, 0.0, False, "ok"),
    ]
    cols = ["scenario", "condition", "episode", "collision", "injury_probability", "conflict", "status"]
    return pd.DataFrame(rows, columns=cols)


def test_table_one_by_hand():
    table = table_one(_episodes())
    assert list(table["condition"]) == ["sv", "v2i"]
    sv = table.iloc[0]
    assert (sv["n"], sv["n_error"]) == (4, 1)
    # collision 1/4; Wilson: 1 + z^2/4 = 1.960365, centre = (0.25 + 0.480182) / 1.960365 = 0.372473,
    # half = z sqrt(0.25 * 0.75 / 4 + 3.841459 / 64) / 1.960365 = 1.959964 * 0.326953 / 1.960365 = 0.326885
    assert sv["collision_rate"] == 0.25
    assert (sv["collision_low"], sv["collision_high"]) == pytest.approx((0.045588, 0.699358), abs=2e-6)
    # conflict without collision: only episode 1 -> 1/4, same interval
    assert sv["conflict_rate"] == 0.25
    assert (sv["conflict_low"], sv["conflict_high"]) == pytest.approx((0.045588, 0.699358), abs=2e-6)
    # injury: mean of (0.4, 0, 0, 0) = 0.1; one positive value, so the two-part interval is
    # (0, Wilson upper of 1 of 4) = (0, 0.699358) (zero_inflated_mean_interval: m <= 1)
    assert sv["injury_mean"] == pytest.approx(0.1)
    assert (sv["injury_low"], sv["injury_high"]) == pytest.approx((0.0, 0.699358), abs=1e-6)
    v2i = table.iloc[1]
    assert (v2i["n"], v2i["n_error"], v2i["collision_rate"], v2i["conflict_rate"]) == (5, 0, 0.2, 0.0)
    assert v2i["conflict_low"] == 0.0


def test_table_one_needs_its_columns():
    with pytest.raises(ValueError, match="lack column.*status"):
        table_one(_episodes().drop(columns="status"))


def test_paired_mcnemar_drops_pairs_with_an_error():
    # pairs 0-3 (pair 4 has an error under sv): collisions sv (T, F, F, F), v2i (F, F, F, T)
    # -> both 0, sv only 1, v2i only 1, neither 2; p = min(1, 2 * P(X <= 1 | n = 2)) = min(1, 2 * 0.75) = 1
    got = paired_mcnemar(_episodes()).iloc[0]
    assert (got["n_pairs"], got["both"], got["sv_only"], got["v2i_only"], got["neither"]) == (4, 0, 1, 1, 2)
    assert got["p_value"] == 1.0


def test_timeout_rows_are_counted_apart_like_errors():
    """An episode whose AD stack exceeded --agent-timeout (status "timeout") is out of every rate and
    every pair, exactly like an error: the table equals the one without that row, plus one in n_error."""
    episodes = _episodes()
    timed_out = episodes.iloc[[0]].assign(
        condition="v2i", episode=99, collision=True, injury_probability=1.0, conflict=True, status="timeout"
    )
    with_timeout = table_one(pd.concat([episodes, timed_out], ignore_index=True))
    without = table_one(episodes)
    assert list(with_timeout["n_error"]) == [1, 1] and list(without["n_error"]) == [1, 0]
    pd.testing.assert_frame_equal(with_timeout.drop(columns="n_error"), without.drop(columns="n_error"))
    # A pair with a timeout on either side is dropped from the paired test.
    paired = episodes.copy()
    paired.loc[(paired["episode"] == 0) & (paired["condition"] == "v2i"), "status"] = "timeout"
    assert paired_mcnemar(paired).iloc[0]["n_pairs"] == paired_mcnemar(episodes).iloc[0]["n_pairs"] - 1
