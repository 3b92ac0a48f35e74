"""Run Euro NCAP cells through the episode engine and score them (one row per cell and condition).

Each cell is staged (staging.stage_cell) and run under SV and under V2I by the same EpisodeRunner, with
the same seed (the perception stream; the staging has no random draw). The per-step log of every run is
kept as a case, and the directory is also laid out as a run directory (episodes.parquet, run.json,
cases/) so that `python -m pedsafe_sumo.replay DIR --scenario CELL_ID --episode 0 --condition sv`
replays or exports (--export-fcd) any cell.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable
from functools import lru_cache
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.ncap.metrics import METRIC_COLUMNS, cell_metrics
from pedsafe_sumo.ncap.protocol import KMH_PER_MPS, Cell, Protocol
from pedsafe_sumo.ncap.robustness import ROBUSTNESS_COLUMNS, robustness_points
from pedsafe_sumo.ncap.scoring import band_colour, cell_score, points_of_test
from pedsafe_sumo.ncap.staging import StagedCell, spec_for, stage_cell
from pedsafe_sumo.sim.connection import SimulatorError
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sim.outcome import EpisodeResult
from pedsafe_sumo.sim.staging import SumoStaging
from pedsafe_sumo.sumo_net import read_net

#: The metrics of ncap_scores.csv over a test's cells run (NaN where no cell has the moment): the mean
#: TTC at brake onset and warning time over the cells that braked / warned, the mean speed reduction,
#: the largest peak deceleration.
SUMMARY_METRICS = (
    "mean_brake_onset_ttc_s",
    "mean_warning_time_s",
    "mean_speed_reduction_kmh",
    "max_peak_decel_mps2",
)
#: The columns of ncap.csv: the eight result columns (docs/ncap.md), then what explains them.
CELL_COLUMNS = (
    "test", "ego_speed_kmh", "impact_point_pct", "condition", "avoided", "impact_speed_kmh", "colour",
    "cell_score", "test_range", "turn", "variation", "lighting", "cell_id", "measured_impact_point_pct",
    "end_reason", "first_detection_distance_m", "detected_by", *METRIC_COLUMNS, "status", "error",
)  # fmt: skip
SCORE_COLUMNS = (
    "test", "lighting", "condition", "points", "points_kind", "points_standard", "points_extended",
    "max_points", "cells", "complete", *ROBUSTNESS_COLUMNS, *SUMMARY_METRICS,
)  # fmt: skip


class NcapStaging(SumoStaging):
    """The staging, with the ego's movement through the junction held green for the whole test.

    A Euro NCAP test has no signal: the ego drives its movement at the test speed. SUMO refuses to insert
    a vehicle at speed whose next link is never a prioritised green ('G'), which is the case of the
    permissive turns of Xueqing's signal program ('g' only); and a red could stop the ego's movement
    mid-test. Nothing else in the scene is signalled: there is no other traffic, and the dummy is moved
    by the test, not by SUMO.
    """

    def populate(self, api, setup, approach, start_s: float = 0.0) -> None:
        super().populate(api, setup, approach, start_s)
        link = ego_signal_link(str(self.site.file("net.xml")), setup.ego.lane_id, setup.ego_route[1])
        if link is not None:
            tls_id, index = link
            state = list(api.trafficlight.getRedYellowGreenState(tls_id))
            state[index] = "G"
            api.trafficlight.setRedYellowGreenState(tls_id, "".join(state))


class NcapRunner(EpisodeRunner):
    """The engine, staged for Euro NCAP tests (NcapStaging: the ego's movement held green)."""

    staging_class = NcapStaging


@lru_cache(maxsize=64)
def ego_signal_link(net_file: str, lane_id: str, next_edge_id: str) -> tuple[str, int] | None:
    """(traffic light id, link index) of the connection from `lane_id` to `next_edge_id`, or None."""
    net = read_net(net_file)
    for connection in net.getLane(lane_id).getOutgoing():
        if connection.getTo().getID() == next_edge_id and connection.getTLSID():
            return connection.getTLSID(), connection.getTLLinkIndex()
    return None


def impact_of(result: EpisodeResult, direction: tuple[float, float]) -> tuple[float, float]:
    """(relative impact speed km/h, impact point % of the ego's width from its nearside edge) of a run;
    (0, nan) without a collision. Relative speed: the ego's speed minus the dummy's velocity along the
    test's direction of travel (`direction`, the ego lane's at the dummy's path), at the first step of
    contact: the ego's speed for a crossing dummy, minus the dummy's speed for one walking ahead."""
    if result.end_reason != "collision":
        return 0.0, math.nan
    row = result.log.iloc[-1]
    along_mps = row["ped_vx_mps"] * direction[0] + row["ped_vy_mps"] * direction[1]
    speed_kmh = (row["ego_speed_mps"] - along_mps) * KMH_PER_MPS
    cos_yaw, sin_yaw = math.cos(row["ego_yaw_rad"]), math.sin(row["ego_yaw_rad"])
    left_m = -(row["ped_x_m"] - row["ego_x_m"]) * sin_yaw + (row["ped_y_m"] - row["ego_y_m"]) * cos_yaw
    point_pct = (left_m + row["ego_width_m"] / 2) / row["ego_width_m"] * 100
    return float(speed_kmh), float(point_pct)


def cell_row(
    protocol: Protocol, staged: StagedCell, condition: str, result: EpisodeResult, step_length_s: float
) -> dict[str, Any]:
    cell = staged.cell
    collided = result.end_reason == "collision"
    speed_kmh, point_pct = impact_of(result, staged.ego_direction)
    colour = band_colour(protocol, cell.ego_speed_kmh, speed_kmh if collided else 0.0, cell.test.criterion)
    return {
        "test": cell.test.name,
        "ego_speed_kmh": cell.ego_speed_kmh,
        "impact_point_pct": cell.impact_point_pct,
        "condition": condition,
        "avoided": not collided,
        "impact_speed_kmh": speed_kmh,
        "colour": colour,
        "cell_score": cell_score(protocol, colour, cell.test_range),
        "test_range": cell.test_range,
        "turn": cell.turn,
        "variation": cell.variation.name,
        "lighting": cell.lighting,
        "cell_id": cell.cell_id,
        "measured_impact_point_pct": point_pct,
        "end_reason": result.end_reason,
        "first_detection_distance_m": result.outcome["first_detection_distance_m"],
        "detected_by": result.outcome["detected_by"],
        **cell_metrics(
            result.log, step_length_s, cell.ego_speed_kmh, collided, protocol.brake_onset_decel_mps2
        ),
        "status": "ok",
        "error": "",
    }


def run_cells(
    runner: EpisodeRunner,
    protocol: Protocol,
    cells: Iterable[Cell],
    conditions: tuple[str, ...] = ("sv", "v2i"),
    seed: int = 0,
    on_result: Callable[[Cell, str, EpisodeResult, dict[str, Any]], None] | None = None,
) -> pd.DataFrame:
    """Stage and run every cell under every condition; one ncap.csv row per run, in cell order.

    V2I receives every roadside camera of the site. `on_result(cell, condition, result, row)` is called
    after each run (case writing, progress).
    """
    poles = tuple(runner.roadside_units)
    rows = []
    for cell in cells:
        staged = stage_cell(
            protocol, runner.approach, runner.site.file("net.xml"), cell, seed, runner.step_length_s
        )
        spec = spec_for(cell, poles, staged.setup.time_limit_s)
        for condition in conditions:
            try:
                result = runner.run(spec, condition, seed, setup=staged.setup)
            except SimulatorError:
                raise  # SUMO itself failed: nothing after this would run
            except Exception as exc:  # the AD stack under test failed: the cell has no result
                result, row = None, error_row(cell, condition, exc)
            else:
                row = cell_row(protocol, staged, condition, result, runner.step_length_s)
            rows.append(row)
            if on_result is not None:
                on_result(cell, condition, result, row)
    return pd.DataFrame(rows, columns=list(CELL_COLUMNS))


def error_row(cell: Cell, condition: str, exc: BaseException) -> dict[str, Any]:
    """The ncap.csv row of a run that raised: no colour, no score; its test is then not complete."""
    message = (str(exc).strip().splitlines() or [""])[0]
    return {
        "test": cell.test.name,
        "ego_speed_kmh": cell.ego_speed_kmh,
        "impact_point_pct": cell.impact_point_pct,
        "condition": condition,
        "avoided": False,
        "impact_speed_kmh": math.nan,
        "colour": "",
        "cell_score": math.nan,
        "test_range": cell.test_range,
        "turn": cell.turn,
        "variation": cell.variation.name,
        "lighting": cell.lighting,
        "cell_id": cell.cell_id,
        "measured_impact_point_pct": math.nan,
        "end_reason": "",
        "first_detection_distance_m": math.nan,
        "detected_by": "",
        **dict.fromkeys(METRIC_COLUMNS, math.nan),
        "status": "error",
        "error": f"{type(exc).__name__}: {message}",
    }


def score_tests(protocol: Protocol, table: pd.DataFrame) -> pd.DataFrame:
    """Points per test, lighting and condition from the nominal cells, the robustness points of a day
    load case from its variation runs (robustness.py; NaN when none was run), and an `overall` row per
    condition.

    `complete` says whether every cell of the test's grid was run without error; `points_kind` is
    "partial" where it was not: such points are the calculator's formula applied to the cells that were
    run, not a rating. The overall row is complete only when every test of the protocol was run, day and
    night (coverage.grid_summary lists what is missing).
    """
    rows = []
    nominal = table[(table["variation"] == "nominal") & (table["status"] == "ok")]
    varied = table[table["variation"] != "nominal"]
    for (name, lighting, condition), group in nominal.groupby(["test", "lighting", "condition"], sort=False):
        test = protocol.tests[name]
        runs = varied[(varied["test"] == name) & (varied["condition"] == condition)]
        robust = dict.fromkeys(ROBUSTNESS_COLUMNS, math.nan)
        if lighting == "day" and not runs.empty:
            robust = robustness_points(protocol, name, runs, group)
        points = points_of_test(
            test.points_standard,
            test.points_extended,
            zip(group["test_range"], group["cell_score"]),
        )
        grid = {(t, s, p) for t, s in test.rows for p in test.impact_points_pct}
        ran = set(zip(group["turn"].fillna(""), group["ego_speed_kmh"], group["impact_point_pct"]))
        rows.append(
            {
                "test": name,
                "lighting": lighting,
                "condition": condition,
                **points,
                "max_points": test.points_standard + test.points_extended,
                "cells": len(group),
                "complete": grid <= ran,
                **robust,
                **summary_metrics(group),
            }
        )
    scores = pd.DataFrame(rows, columns=[c for c in SCORE_COLUMNS if c != "points_kind"])
    if not scores.empty:
        load_cases = {
            (name, lighting) for name, test in protocol.tests.items() for lighting in test.lightings
        }
        totals = scores.groupby("condition", sort=False).agg(
            points=("points", "sum"),
            points_standard=("points_standard", "sum"),
            points_extended=("points_extended", "sum"),
            max_points=("max_points", "sum"),
            cells=("cells", "sum"),
            complete=("complete", "all"),
            robustness_layers_passed=("robustness_layers_passed", lambda v: v.sum(min_count=1)),
            robustness_layers_applicable=("robustness_layers_applicable", lambda v: v.sum(min_count=1)),
            points_robustness=("points_robustness", lambda v: v.sum(min_count=1)),
        )
        for condition, group in scores.groupby("condition", sort=False):
            if set(zip(group["test"], group["lighting"])) != load_cases:
                totals.loc[condition, "complete"] = False
        metrics = nominal.groupby("condition", sort=False)[list(METRIC_COLUMNS)].apply(summary_metrics_frame)
        totals = totals.join(metrics).reset_index().assign(test="overall", lighting="all")
        scores = pd.concat([scores, totals[scores.columns]], ignore_index=True)
    scores.insert(4, "points_kind", ["rating" if c else "partial" for c in scores["complete"]])
    return scores[list(SCORE_COLUMNS)]


def summary_metrics(cells: pd.DataFrame) -> dict[str, float]:
    """SUMMARY_METRICS over some cells' rows (finite values only: a cell that never braked has no onset)."""

    def finite(column: str) -> pd.Series:
        values = cells[column].astype(float)
        return values[np.isfinite(values)]

    return {
        "mean_brake_onset_ttc_s": float(finite("brake_onset_ttc_s").mean()),
        "mean_warning_time_s": float(finite("warning_time_s").mean()),
        "mean_speed_reduction_kmh": float(finite("speed_reduction_kmh").mean()),
        "max_peak_decel_mps2": float(finite("peak_decel_mps2").max()),
    }


def summary_metrics_frame(cells: pd.DataFrame) -> pd.Series:
    return pd.Series(summary_metrics(cells))


def spec_record(cell: Cell, runner: EpisodeRunner, protocol: Protocol, seed: int) -> dict[str, Any]:
    """The cell's scenario as run.json records scenarios (dataclasses.asdict of the ScenarioSpec)."""
    staged = stage_cell(
        protocol, runner.approach, runner.site.file("net.xml"), cell, seed, runner.step_length_s
    )
    return dataclasses.asdict(spec_for(cell, tuple(runner.roadside_units), staged.setup.time_limit_s))
