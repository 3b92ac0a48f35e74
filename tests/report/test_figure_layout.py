"""The figures' layout rules: a mean per bin is a curve only through bins of two or more episodes (a bin
of one is a hollow marker, and one such bin is no curve); the injury figures have a panel per scenario
with a collision; the case figure's axis is the logged time in seconds."""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from report_runs import STANDARD_SV_CASE, case_log, standard_episodes

from pedsafe_sumo.report import figures
from pedsafe_sumo.report.summaries import case_trace


def _drawn(means: pd.DataFrame) -> list[tuple[str, int, str]]:
    """(line style, points, marker face) of every line `_binned_means` draws for `means`."""
    ax = Figure().subplots()
    figures._binned_means(ax, means, "sv", "SV")
    return [
        (line.get_linestyle(), len(line.get_xdata()), str(line.get_markerfacecolor())) for line in ax.lines
    ]


def test_a_bin_of_one_episode_is_a_marker_not_part_of_the_curve():
    means = pd.DataFrame({"x_mean": [1.0, 2.0, 3.0, 4.0], "mean": [0.1, 0.2, 0.3, 0.4], "n": [1, 5, 1, 4]})
    drawn = _drawn(means)
    assert [(style, points) for style, points, _ in drawn] == [("-", 2), ("None", 2)]
    assert drawn[1][2] == "none"  # hollow: the two bins of one episode


def test_one_collision_draws_no_curve_through_one_point():
    one = pd.DataFrame({"x_mean": [30.0], "mean": [0.4], "n": [1]})
    assert [(style, points) for style, points, _ in _drawn(one)] == [("None", 1)]
    single_bin = pd.DataFrame({"x_mean": [30.0], "mean": [0.4], "n": [7]})
    assert [(style, points) for style, points, _ in _drawn(single_bin)] == [("None", 1)]


def test_injury_panels_are_the_scenarios_with_a_collision():
    episodes = standard_episodes()
    assert figures.collision_scenarios(episodes) == ["crossing", "jaywalking"]
    no_crossing_collision = episodes.assign(
        collision=episodes["collision"].where(episodes["scenario"] != "crossing", False)
    )
    assert figures.collision_scenarios(no_crossing_collision) == ["jaywalking"]


def test_case_trace_times_are_the_logged_seconds():
    log = case_log(**STANDARD_SV_CASE)  # the log starts at 0.05 s, a step of 0.05 s; onboard from row 99
    trace = case_trace(log, "sv", collision=False)
    assert np.allclose(trace.time_s, log["time_s"])
    assert trace.first_onboard_frame == 100 and trace.time_of_frame(trace.first_onboard_frame) == 5.0
    assert trace.time_of_frame(None) is None
