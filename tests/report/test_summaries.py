"""What the figures show: binned means, the 90% detection distance, the case pair and its detection frames."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from report_runs import (
    STANDARD_SV_CASE,
    STANDARD_V2I_CASE,
    case_log,
    standard_episodes,
    write_case,
    write_run,
    write_standard_run,
)

from pedsafe_sumo.report.rundir import load_run
from pedsafe_sumo.report.summaries import (
    binned_mean,
    case_trace,
    choose_case_pair,
    detection_summaries,
    distance_detected_by_share,
    frames_of,
    load_case_traces,
    quantile_edges,
)


def test_distance_detected_by_90_percent():
    # 10 episodes at 1..10 m: 9 of 10 (90 %) detect at 2 m or farther, not 10 of 10 at anything above 1
    assert distance_detected_by_share(np.arange(1.0, 11.0)) == 2.0
    # 20 episodes at 1..20 m: 18 of 20 at 3 m or farther
    assert distance_detected_by_share(np.arange(20.0, 0.0, -1.0)) == 3.0
    # one never-detected of 10 still leaves 9 of 10 detecting, all at 2 m or farther
    assert distance_detected_by_share([np.nan, *range(2, 11)]) == 2.0
    # two never-detected of 10: fewer than 90 % ever detect
    assert distance_detected_by_share([np.nan, np.nan, *range(3, 11)]) == -math.inf
    assert math.isnan(distance_detected_by_share([]))


def test_detection_summaries_count_never_detected():
    summaries = {(s.scenario, s.condition): s for s in detection_summaries(standard_episodes())}
    assert list(summaries) == [
        ("crossing", "sv"),
        ("crossing", "v2i"),
        ("jaywalking", "sv"),
        ("jaywalking", "v2i"),
    ]
    sv = summaries[("jaywalking", "sv")]
    assert (sv.n, sv.n_never, sv.distances_m.size) == (11, 1, 10)
    # 11 episodes, k = floor(11 * 10 / 100) = 1 -> second smallest of (-inf, 1, 2, ...) = 1 m: 10 of 11 >= 1 m
    assert sv.distance_90_m == 1.0
    v2i = summaries[("jaywalking", "v2i")]  # the errored episode is left out
    assert (v2i.n, v2i.n_never, v2i.distance_90_m) == (10, 0, 20.0)


def test_quantile_edges_and_binned_mean():
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0])
    y = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0])
    edges = quantile_edges(x, 2)
    assert edges.tolist() == [1.0, 4.5, 8.0]
    means = binned_mean(x, y, edges)
    assert means["n"].tolist() == [4, 4]
    assert means["x_mean"].tolist() == [2.5, 6.5] and means["mean"].tolist() == [0.25, 0.75]
    # NaNs are left out; an empty bin is left out
    means = binned_mean([1.0, 1.5, np.nan, 9.0], [1.0, 0.0, 1.0, 0.5], [0.0, 2.0, 4.0, 10.0])
    assert means["x_mean"].tolist() == [1.25, 9.0] and means["mean"].tolist() == [0.5, 0.5]
    # all values equal: one bin around them
    assert quantile_edges([30.0, 30.0], 8).tolist() == [29.5, 30.5]


def test_frames_from_log_time():
    assert frames_of([0.05, 0.1, 0.15, 0.2]).tolist() == [1, 2, 3, 4]
    assert frames_of(np.arange(0, 200) * 0.05).tolist() == list(range(200))
    assert frames_of([0.4]).tolist() == [0]


def test_case_trace_detection_frames_and_speed_in_kmh():
    trace = case_trace(case_log(**STANDARD_V2I_CASE), "v2i", collision=False)
    assert (trace.first_onboard_frame, trace.first_roadside_frame) == (80, 35)
    assert trace.frame[0] == 1 and trace.speed_kmh[0] == pytest.approx(36.0)
    sv = case_trace(case_log(**STANDARD_SV_CASE), "sv", collision=True)
    assert (sv.first_onboard_frame, sv.first_roadside_frame) == (100, None)
    never = case_trace(case_log(50, None, None), "sv", collision=False)
    assert never.first_onboard_frame is None


def test_case_pair_prefers_jaywalking_and_largest_detection_gap(tmp_path):
    run = load_run(write_standard_run(tmp_path / "run"))
    pair = choose_case_pair(run)
    # jaywalking pairs with both case files: episodes 0 (gap 2 s) and 3 (gap 4.5 s); episode 4 has SV only
    assert (pair.scenario, pair.episode, pair.seed) == ("jaywalking", 3, 103)
    assert (pair.sv_first_detection_s, pair.v2i_first_detection_s) == (5.0, 0.5)
    traces = load_case_traces(run, pair)
    assert [t.condition for t in traces] == ["sv", "v2i"]
    assert (traces[0].first_onboard_frame, traces[1].first_roadside_frame) == (100, 35)


def test_case_pair_never_seen_under_sv_beats_any_finite_gap(tmp_path):
    episodes = standard_episodes()
    never = (
        (episodes["scenario"] == "jaywalking") & (episodes["condition"] == "sv") & (episodes["episode"] == 4)
    )
    episodes.loc[never, ["first_detection_time_s", "first_detection_distance_m"]] = math.nan
    directory = write_run(tmp_path / "run", episodes)
    for episode in (3, 4):
        for condition, spec in (("sv", STANDARD_SV_CASE), ("v2i", STANDARD_V2I_CASE)):
            write_case(directory / "cases", "jaywalking", condition, 100 + episode, case_log(**spec))
    pair = choose_case_pair(load_run(directory))
    assert (pair.episode, pair.gap_s) == (4, math.inf)


def test_case_pair_ties_go_to_the_smallest_episode(tmp_path):
    directory = write_run(tmp_path / "run", standard_episodes())
    for episode in (2, 1):  # same gap (SV 3.0 s, V2I 1.0 s)
        for condition in ("sv", "v2i"):
            write_case(directory / "cases", "jaywalking", condition, 100 + episode, case_log(30, 5, None))
    assert choose_case_pair(load_run(directory)).episode == 1


def test_case_pair_falls_back_to_another_scenario_or_none(tmp_path):
    directory = write_run(tmp_path / "run", standard_episodes())
    assert choose_case_pair(load_run(directory)) is None  # no cases directory at all
    for condition in ("sv", "v2i"):
        write_case(directory / "cases", "crossing", condition, 107, case_log(30, 5, None))
    pair = choose_case_pair(load_run(directory))
    assert (pair.scenario, pair.episode) == ("crossing", 7)


def test_case_pair_skips_errored_pairs_and_unpaired_files(tmp_path):
    directory = write_run(tmp_path / "run", standard_episodes())
    for condition in ("sv", "v2i"):  # jaywalking episode 10: V2I errored
        write_case(directory / "cases", "jaywalking", condition, 110, case_log(30, 5, None))
    write_case(directory / "cases", "jaywalking", "sv", 105, case_log(30, 5, None))
    assert choose_case_pair(load_run(directory)) is None


def test_case_pair_needs_the_same_seed_on_both_sides(tmp_path):
    episodes = standard_episodes()
    odd = (episodes["scenario"] == "crossing") & (episodes["condition"] == "v2i") & (episodes["episode"] == 7)
    episodes.loc[odd, "seed"] = 999
    directory = write_run(tmp_path / "run", pd.DataFrame(episodes))
    for condition, seed in (("sv", 107), ("v2i", 999), ("v2i", 107)):
        write_case(directory / "cases", "crossing", condition, seed, case_log(30, 5, None))
    assert choose_case_pair(load_run(directory)) is None
