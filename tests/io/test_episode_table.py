"""episodes.parquet's flags: stated in every row, or the row is refused (never a guessed True or False);
sumo_collision alone may be unknown (null)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo.io.episodes import BOOL_COLUMNS, RAN_BOOL_COLUMNS, EpisodeRowError, to_table


def row(episode: int, condition: str = "sv", **values):
    base = {
        "scenario": "crossing",
        "condition": condition,
        "episode": episode,
        "seed": 100 + episode,
        "collision": False,
        "conflict": False,
        "close_pass": False,
        "contact_stationary": False,
        "witness_collision": False,
        "sumo_collision": None,
        "status": "ok",
    }
    base.update(values)
    return base


def test_flags_keep_their_values_and_dtype():
    table = to_table(
        [
            row(1, collision=True, conflict=np.bool_(True), sumo_collision=True),
            row(0, close_pass=True, contact_stationary=np.bool_(False), sumo_collision=False),
            row(0, "v2i"),
        ]
    )
    assert [str(table[c].dtype) for c in BOOL_COLUMNS] == ["bool"] * 4
    # Sorted by episode, then sv before v2i.
    assert table["episode"].tolist() == [0, 0, 1] and table["condition"].tolist() == ["sv", "v2i", "sv"]
    assert table["collision"].tolist() == [False, False, True]
    assert table["conflict"].tolist() == [False, False, True]
    assert table["close_pass"].tolist() == [True, False, False]
    assert str(table["sumo_collision"].dtype) == "boolean"
    assert table["sumo_collision"].isna().tolist() == [False, True, False]
    assert not table["sumo_collision"].iloc[0] and table["sumo_collision"].iloc[2]


@pytest.mark.parametrize("column", BOOL_COLUMNS)
@pytest.mark.parametrize("value", [None, math.nan, pd.NA, "False", 1, "missing key"])
def test_a_flag_missing_or_not_a_boolean_is_refused_naming_the_row(column, value):
    bad = row(7, "v2i")
    if isinstance(value, str) and value == "missing key":
        del bad[column]
    else:
        bad[column] = value
    with pytest.raises(EpisodeRowError, match=f"crossing/7/v2i: {column} is") as info:
        to_table([row(1), bad])
    assert "\n" not in str(info.value)


def test_unknown_sumo_verdict_stays_unknown_but_text_is_refused():
    table = to_table([row(0, sumo_collision=math.nan), row(1, sumo_collision=pd.NA), row(2)])
    assert table["sumo_collision"].isna().all()
    with pytest.raises(EpisodeRowError, match="sumo_collision is 'yes'"):
        to_table([row(0, sumo_collision="yes")])


@pytest.mark.parametrize("column", RAN_BOOL_COLUMNS)
def test_a_flag_of_a_row_that_ran_may_be_left_out_of_an_errored_row_only(column):
    errored = row(2, status="error")
    del errored[column]
    table = to_table([row(1, **{column: True}), errored])
    assert str(table[column].dtype) == "bool" and table[column].tolist() == [True, False]
    ran = row(3)
    del ran[column]
    with pytest.raises(EpisodeRowError, match=f"crossing/3/sv: {column} is"):
        to_table([ran])
