"""The interactions that end at one FCD step are measured over their stacked steps: each one's measures
must be those of its own log, and the stacked logs must pass the log contract exactly when each log does."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import path_boxes_apart
from pedsafe_sumo.safety.interaction import (
    interaction_measures,
    measures_of_stacked_steps,
    measures_of_steps,
    step_measures_of_rows,
)
from pedsafe_sumo.safety.proximity import kinematic_arrays


def car_log(t0_s: float, n: int, ped_x_m: float, ped_y_m: float, ped_vy_mps: float) -> dict[str, np.ndarray]:
    """A car 4 m long, 2 m wide driving east along y = 0 at 10 m/s from x = 0; a pedestrian (radius 0.3 m)
    at (ped_x_m, ped_y_m) walking north at ped_vy_mps. One step every 0.1 s."""
    t = t0_s + 0.1 * np.arange(n)
    ped_y = ped_y_m + ped_vy_mps * (t - t0_s)
    return {
        steplog.TIME: t,
        steplog.EGO_X: 10.0 * (t - t0_s),
        steplog.EGO_Y: np.zeros(n),
        steplog.EGO_YAW: np.zeros(n),
        steplog.EGO_SPEED: np.full(n, 10.0),
        steplog.EGO_LENGTH: np.full(n, 4.0),
        steplog.EGO_WIDTH: np.full(n, 2.0),
        steplog.PED_X: np.full(n, ped_x_m),
        steplog.PED_Y: ped_y,
        steplog.PED_VX: np.zeros(n),
        steplog.PED_VY: np.full(n, ped_vy_mps),
        steplog.PED_RADIUS: np.full(n, 0.3),
    }


def stack(logs):
    columns = {name: np.concatenate([log[name] for log in logs]) for name in steplog.NUMERIC_COLUMNS}
    starts = np.cumsum([0] + [len(log[steplog.TIME]) for log in logs]).tolist()
    return columns, starts


def same(a, b) -> bool:
    return all(
        (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y)) or x == y
        for x, y in zip(dataclasses.astuple(a), dataclasses.astuple(b))
    )


def test_each_interaction_measured_over_the_stack_as_over_its_own_log():
    logs = [
        car_log(5.0, 30, 20.0, 2.0, 0.0),  # stands 2 m beside the lane: passed at 2 - 1 - 0.3 = 0.7 m
        car_log(0.0, 40, 20.0, -3.0, 1.5),  # walks into the car's path
        car_log(7.0, 1, 30.0, 5.0, 0.0),  # one step only
        car_log(2.0, 25, 12.0, 0.0, 0.0),  # stands in the lane: hit
    ]
    columns, starts = stack(logs)
    assert steplog.logs_pass(columns, starts[:-1])  # time falls from one log to the next: allowed
    steps = step_measures_of_rows(columns)
    for log, start, stop in zip(logs, starts[:-1], starts[1:]):
        part = {name: values[start:stop] for name, values in columns.items()}
        stacked = measures_of_steps(part, steps.part(start, stop))
        assert same(stacked, interaction_measures(log))
    beside = measures_of_steps({n: v[: starts[1]] for n, v in columns.items()}, steps.part(0, starts[1]))
    assert beside.min_clearance_m == pytest.approx(0.7) and not beside.collision
    hit = measures_of_steps({n: v[starts[3] :] for n, v in columns.items()}, steps.part(starts[3], None))
    # the car's front (x + 2) reaches the circle's edge (12 - 0.3) at x = 9.7: the step at x = 10
    assert hit.collision and hit.contact_step == 10 and hit.pet_s == 0.0


def standing_car_log(n: int, car_x_m: float, ped_x_m: float, ped_y_m: float, speed_mps) -> dict:
    """car_log's car standing with its centre at (car_x_m, 0) (speed_mps per step: it may pull away
    without moving in the log), a person standing at (ped_x_m, ped_y_m)."""
    log = car_log(0.0, n, ped_x_m, ped_y_m, 0.0)
    log[steplog.EGO_X] = np.full(n, car_x_m)
    log[steplog.EGO_SPEED] = np.asarray(speed_mps, dtype=float)
    return log


def test_the_reductions_over_the_stack_give_each_logs_own_measures():
    logs = [
        car_log(5.0, 30, 20.0, 2.0, 0.0),  # passes beside a standing person
        car_log(0.0, 40, 20.0, -3.0, 1.5),  # walks into the car's path: contact
        car_log(7.0, 1, 30.0, 5.0, 0.0),  # one step only
        car_log(2.0, 25, 12.0, 0.0, 0.0),  # stands in the lane: hit
        car_log(1.0, 20, 200.0, 40.0, 0.0),  # far off: the paths' boxes are apart
        car_log(0.0, 40, 25.0, -3.0, 3.0),  # crosses the car's path at x = 25 1.5 s before the car
        standing_car_log(12, 0.0, 20.0, 2.0, np.zeros(12)),  # nothing moves: every step ties
        # the car's front (x = 12) overlaps the circle (12.2, r 0.3) while it stands, creeps at 0.05 m/s
        # (below the 0.1 m/s of a collision), then moves at 1 m/s: the collision at step 8
        standing_car_log(12, 10.0, 12.2, 0.0, [0.0] * 5 + [0.05] * 3 + [1.0] * 4),
    ]
    columns, starts = stack(logs)
    stacked = measures_of_stacked_steps(columns, step_measures_of_rows(columns), starts[:-1])
    assert len(stacked) == len(logs)
    for log, measures in zip(logs, stacked):
        assert same(measures, interaction_measures(log))
    beside, walks_in, one_step, hit, far, crossing, still, creeping = stacked
    assert beside.min_clearance_m == pytest.approx(0.7) and not beside.collision
    assert hit.collision and hit.contact_step == 10 and hit.pet_s == 0.0
    assert walks_in.collision and one_step.min_clearance_step == 0
    assert far.path_crossing is None and math.isnan(far.pet_s) and not far.collision
    assert crossing.path_crossing == pytest.approx((25.0, 0.0)) and crossing.pet_s > 0.0
    # standing: the same clearance at every step (the first is reported), no TTC, no DRAC
    assert still.min_clearance_step == 0 and still.min_clearance_m == pytest.approx(
        math.hypot(18.0, 1.0) - 0.3
    )
    assert still.ttc_step is None and still.drac_step is None and not still.collision
    assert creeping.collision and creeping.contact_step == 8
    assert creeping.min_clearance_m == pytest.approx(-0.1)


def test_path_boxes_apart_only_where_no_crossing_can_be_found():
    # pairs of paths stacked: A then B of each pair share the rows
    ax = np.array([0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0])
    ay = np.zeros(8)
    bx = np.array([1.5, 1.5, 1.0, 1.0, 0.5, 0.5, math.nan, 0.5])
    by = np.array([-1.0, 1.0, -1.0, 1.0, 2.0, 3.0, -1.0, 1.0])
    apart = path_boxes_apart(ax, ay, bx, by, [0, 2, 4, 6])
    # right of A's box; touching it at A's end point; above it; a NaN (never called apart)
    assert apart.tolist() == [True, False, True, False]


@pytest.mark.parametrize(
    "column, index, value",
    [
        (steplog.PED_X, 3, math.nan),
        (steplog.EGO_Y, 35, math.inf),
        (steplog.EGO_SPEED, 12, -0.5),
        (steplog.PED_RADIUS, 40, -0.1),
        (steplog.EGO_LENGTH, 0, 0.0),
        (steplog.EGO_WIDTH, 49, -2.0),
        (steplog.TIME, 25, 5.05),  # second log (t from 5.0): back to its first step's neighbour
    ],
)
def test_stacked_logs_fail_exactly_when_one_log_breaks_the_contract(column, index, value):
    logs = [car_log(0.0, 20, 20.0, 2.0, 0.0), car_log(5.0, 30, 20.0, 2.0, 0.0)]
    columns, starts = stack(logs)
    columns[column][index] = value
    assert not steplog.logs_pass(columns, starts[:-1])
    broken = 0 if index < starts[1] else 1
    part = {name: values[starts[broken] : starts[broken + 1]] for name, values in columns.items()}
    with pytest.raises(steplog.LogError):
        kinematic_arrays(part)


def test_an_empty_log_in_the_stack_fails():
    columns, _ = stack([car_log(0.0, 20, 20.0, 2.0, 0.0)])
    assert not steplog.logs_pass(columns, [0, 20])
    assert not steplog.logs_pass(columns, [0, 5, 5])
