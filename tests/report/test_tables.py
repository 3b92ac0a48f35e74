"""Table I and the paired tests of the report, against numbers worked out by hand (see report_runs)."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from report_runs import episode_row, standard_episodes, write_standard_run

from pedsafe_sumo.report.tables import (
    markdown_table,
    paired_of_run,
    table_one_of_run,
    table_one_rows,
    text_table,
    write_tables,
)

# Wilson 95 % for 3 of 10, by the closed form: z = 1.959964, z^2 = 3.841459, 1 + z^2/n = 1.3841459
# centre = (0.3 + 3.841459 / 20) / 1.3841459 = 0.4920729 / 1.3841459 = 0.3555066
# half = z sqrt(0.3 * 0.7 / 10 + 3.841459 / 400) / 1.3841459 = 1.959964 * 0.1749390 / 1.3841459 = 0.2477153
WILSON_3_OF_10 = (0.1077913, 0.6032219)


def _row(table: pd.DataFrame, scenario: str, condition: str) -> pd.Series:
    rows = table[(table["scenario"] == scenario) & (table["condition"] == condition)]
    assert len(rows) == 1
    return rows.iloc[0]


def test_closed_form_wilson_constant_is_right():
    z = 1.959964
    p, n = 0.3, 10
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    assert (centre - half, centre + half) == pytest.approx(WILSON_3_OF_10, abs=1e-6)


def test_table_one_rates_and_intervals():
    table = table_one_of_run(standard_episodes())
    assert list(zip(table["scenario"], table["condition"])) == [
        ("crossing", "sv"),
        ("crossing", "v2i"),
        ("jaywalking", "sv"),
        ("jaywalking", "v2i"),
    ]
    sv = _row(table, "crossing", "sv")
    assert sv["n"] == 10 and sv["n_error"] == 0
    assert sv["collision_rate"] == pytest.approx(0.3)
    assert (sv["collision_low"], sv["collision_high"]) == pytest.approx(WILSON_3_OF_10, abs=1e-6)
    # conflict raw in {2, 3, 4}, episode 2 collided: Table I counts 2 of 10
    assert sv["conflict_rate"] == pytest.approx(0.2)
    # mean P_I = (0.2 + 0.4 + 0.6) / 10 = 0.12 = q m with q = 3/10, m = 0.4 (two-part MOVER interval):
    # Wilson(3, 10) for q; t interval of (0.2, 0.4, 0.6): sd 0.2, t(0.975, 2) = 4.302653,
    # half = 4.302653 * 0.2 / sqrt(3) = 0.4968276 -> (0 (clipped), 0.8968276), so low = 0;
    # up = hypot(ln(0.6032219 / 0.3), ln(0.8968276 / 0.4)) = hypot(0.6985026, 0.8073991) = 1.0676138,
    # high = 0.12 exp(1.0676138) = 0.3490117
    assert sv["injury_mean"] == pytest.approx(0.12)
    assert (sv["injury_low"], sv["injury_high"]) == pytest.approx((0.0, 0.3490117), abs=1e-6)

    v2i = _row(table, "crossing", "v2i")
    assert v2i["collision_rate"] == 0.0 and v2i["collision_low"] == 0.0
    # Wilson upper bound at 0 of 10: z^2 / (n + z^2) = 3.841459 / 13.841459
    assert v2i["collision_high"] == pytest.approx(0.2775328, abs=1e-6)
    assert v2i["conflict_rate"] == pytest.approx(0.1)


def test_table_one_leaves_errors_out_and_counts_them():
    table = table_one_of_run(standard_episodes())
    sv, v2i = _row(table, "jaywalking", "sv"), _row(table, "jaywalking", "v2i")
    assert (sv["n"], sv["n_error"], sv["collision_rate"]) == (11, 0, pytest.approx(6 / 11))
    assert (v2i["n"], v2i["n_error"], v2i["collision_rate"]) == (10, 1, pytest.approx(0.1))


def test_paired_discordant_counts_and_exact_p():
    paired = paired_of_run(standard_episodes()).set_index(["scenario", "outcome"])
    crossing = paired.loc[("crossing", "collision")]
    assert (crossing["n_pairs"], crossing["both"], crossing["b"], crossing["c"]) == (10, 0, 3, 0)
    assert crossing["p_value"] == pytest.approx(0.25)  # 2 * (1/2)^3
    assert (crossing["sv_rate"], crossing["v2i_rate"]) == (pytest.approx(0.3), 0.0)
    conflict = paired.loc[("crossing", "conflict")]
    assert (conflict["both"], conflict["b"], conflict["c"], conflict["neither"]) == (0, 2, 1, 7)
    assert conflict["p_value"] == 1.0  # 2 * (1 + 3) / 8 = 1, capped
    jay = paired.loc[("jaywalking", "collision")]
    assert (jay["n_pairs"], jay["both"], jay["b"], jay["c"]) == (10, 1, 5, 0)  # episode 10 errored
    assert jay["p_value"] == pytest.approx(0.0625)  # 2 * (1/2)^5
    assert list(paired.index.get_level_values("outcome")[:2]) == ["collision", "conflict"]


def test_paired_with_one_condition_only_has_no_pairs():
    episodes = pd.DataFrame([episode_row("crossing", "sv", e, collision=e < 2) for e in range(4)])
    paired = paired_of_run(episodes)
    assert list(paired["n_pairs"]) == [0, 0] and list(paired["p_value"]) == [1.0, 1.0]
    assert paired["sv_rate"].isna().all()


def test_formatted_cells_carry_rate_and_interval():
    table = table_one_of_run(standard_episodes())
    header, rows = table_one_rows(table)
    assert header[4].startswith("collision rate")
    assert rows[0][:4] == ["crossing", "SV", "10", "0"]
    assert rows[0][4] == "0.3000 [0.1078, 0.6032]"
    text = text_table(header, rows)
    lines = text.splitlines()
    assert len(lines) == 2 + len(rows) and len({len(line.rstrip()) for line in lines[2:]}) >= 1
    assert "0.3000 [0.1078, 0.6032]" in lines[2]
    md = markdown_table(header, rows).splitlines()
    assert md[1].startswith("| --- | --- | ---:") and md[2].startswith("| crossing | SV | 10 | 0 |")


def test_single_episode_injury_interval_is_uninformative():
    episodes = pd.DataFrame([episode_row("crossing", "sv", 0, collision=True, injury_probability=0.3)])
    _, rows = table_one_rows(table_one_of_run(episodes))
    # one positive value of one: (0, Wilson upper of 1 of 1) = (0, 1), the honest answer from one episode
    assert rows[0][5] == "0.3000 [0.0000, 1.0000]"


def test_tables_written_as_csv_and_markdown(tmp_path):
    run = write_standard_run(tmp_path / "run")
    episodes = pd.read_parquet(run / "episodes.parquet")
    table, paired = table_one_of_run(episodes), paired_of_run(episodes)
    paths = write_tables(table, paired, tmp_path / "tables")
    assert [p.name for p in paths] == ["table1.csv", "table1.md", "paired.csv", "paired.md"]
    pd.testing.assert_frame_equal(pd.read_csv(paths[0]), table, check_dtype=False)
    back = pd.read_csv(paths[2])
    assert list(back["b"]) == list(paired["b"]) and back["p_value"].tolist() == pytest.approx(
        paired["p_value"]
    )
    assert "| crossing | SV | 10 | 0 | 0.3000 [0.1078, 0.6032] |" in paths[1].read_text()
    assert "| jaywalking | collision | 10 | 1 | 5 | 0 | 4 |" in paths[3].read_text()


def test_nullable_boolean_columns_give_the_same_tables():
    episodes = standard_episodes()
    nullable = episodes.astype({"collision": "boolean", "conflict": "boolean", "sumo_collision": "boolean"})
    assert nullable["collision"].isna().sum() == 1  # the errored episode
    pd.testing.assert_frame_equal(table_one_of_run(nullable), table_one_of_run(episodes))
    pd.testing.assert_frame_equal(paired_of_run(nullable), paired_of_run(episodes))
