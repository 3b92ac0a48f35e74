"""The independent collision witness (safety/witness.py) on hand-built logs with answers worked out by hand,
and against the loop's own verdict on a small real batch."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import shapely
from safety_logs import make_log

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.safety.witness import CIRCLE_TOLERANCE_M, quad_segs_for, witness_collision

DT_S = 0.1
#: The ego of these logs: 4 m x 2 m, its centre from x = 0 along +x at 10 m/s; its front is 2 m ahead of
#: the centre, its sides 1 m either side.
SPEED_MPS, LENGTH_M, WIDTH_M, RADIUS_M = 10.0, 4.0, 2.0, 0.3


def rotate(x, y, angle_rad: float):
    """Points turned by `angle_rad` about the origin: a whole scene turned keeps its answers."""
    cos, sin = math.cos(angle_rad), math.sin(angle_rad)
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return cos * x - sin * y, sin * x + cos * y


def driving_log(ped_x_m: float, ped_y_m: float, angle_rad: float = 0.0, n_steps: int = 31, **columns):
    """The ego driving at SPEED_MPS towards a pedestrian standing at (ped_x_m, ped_y_m), the scene turned by
    `angle_rad` (the ego's yaw)."""
    t = np.arange(n_steps) * DT_S
    ex, ey = rotate(SPEED_MPS * t, np.zeros_like(t), angle_rad)
    px, py = rotate(np.full_like(t, ped_x_m), np.full_like(t, ped_y_m), angle_rad)
    values = dict(
        ego_x_m=ex,
        ego_y_m=ey,
        ego_yaw_rad=angle_rad,
        ego_speed_mps=SPEED_MPS,
        ego_length_m=LENGTH_M,
        ego_width_m=WIDTH_M,
        ped_x_m=px,
        ped_y_m=py,
        ped_radius_m=RADIUS_M,
    )
    values.update(columns)
    return make_log(t, **values)


@pytest.mark.parametrize("angle_rad", [0.0, 0.7, -2.5])
def test_front_reaches_a_standing_pedestrian_at_the_step_worked_out_by_hand(angle_rad):
    # The front (centre + 2 m) is at 10 t + 2. At t = 1.8 s it is at 20 m: a pedestrian at x = 20.298 m
    # (circle from 19.998 m) overlaps it by 2 mm there, at 1.7 s (front at 19 m) it is 1 m short.
    hit = witness_collision(driving_log(20.298, 0.5, angle_rad))
    assert hit.collided and hit.step == 18 and hit.time_s == pytest.approx(1.8)
    # 4 mm further (circle from 20.002 m): 2 mm short at 1.8 s, so the first contact is at 1.9 s.
    later = witness_collision(driving_log(20.302, 0.5, angle_rad))
    assert later.collided and later.step == 19 and later.time_s == pytest.approx(1.9)


@pytest.mark.parametrize("angle_rad", [0.0, 1.1])
def test_a_pass_at_one_centimetre_is_no_collision_and_one_centimetre_over_is(angle_rad):
    # The side is at y = 1 m: a circle centred at y = 1.31 m stays 1 cm off it the whole way past.
    assert not witness_collision(driving_log(20.0, 1.0 + RADIUS_M + 0.01, angle_rad, n_steps=41)).collided
    # Centred at y = 1.29 m the circle dips 1 cm below the side over x = 20 +- sqrt(0.3^2 - 0.29^2)
    # = 20 +- 0.0768 m: the front corner (10 t + 2) gets there after t = 1.7923 s, the step of 1.8 s.
    hit = witness_collision(driving_log(20.0, 1.0 + RADIUS_M - 0.01, angle_rad, n_steps=41))
    assert hit.collided and hit.time_s == pytest.approx(1.8)


def test_contact_with_a_standing_ego_is_no_collision_and_the_threshold_speed_is_one():
    # The pedestrian's circle overlaps the front by 10 cm at every step.
    t = np.arange(5) * DT_S
    common = dict(ego_length_m=LENGTH_M, ego_width_m=WIDTH_M, ped_x_m=2.2, ped_y_m=0.0, ped_radius_m=0.3)
    assert not witness_collision(make_log(t, ego_speed_mps=0.099, **common)).collided
    moving = witness_collision(make_log(t, ego_speed_mps=0.1, **common))
    assert moving.collided and moving.step == 0
    # Standing for the first two steps, creeping from the third: the collision is the third step's.
    creeping = witness_collision(make_log(t, ego_speed_mps=[0.0, 0.05, 0.5, 0.5, 0.5], **common))
    assert creeping.collided and creeping.step == 2 and creeping.time_s == pytest.approx(0.2)


@pytest.mark.parametrize("gap_m, touches", [(-0.001, True), (0.001, False)])
def test_a_corner_graze(gap_m, touches):
    # The front-left corner of an ego turned by 0.5 rad and centred at (3, -1); the pedestrian's centre lies
    # on the corner's outer diagonal, radius + gap from it: only that corner can touch, and it does when the
    # gap is negative (1 mm overlap), not when positive.
    yaw, cx, cy = 0.5, 3.0, -1.0
    d = RADIUS_M + gap_m
    lx, ly = LENGTH_M / 2 + d / math.sqrt(2), WIDTH_M / 2 + d / math.sqrt(2)
    px, py = rotate(lx, ly, yaw)
    log = make_log(
        [0.0],
        ego_x_m=cx,
        ego_y_m=cy,
        ego_yaw_rad=yaw,
        ego_speed_mps=5.0,
        ego_length_m=LENGTH_M,
        ego_width_m=WIDTH_M,
        ped_x_m=cx + float(px),
        ped_y_m=cy + float(py),
        ped_radius_m=RADIUS_M,
    )
    assert witness_collision(log).collided is touches


def test_steps_without_the_pedestrian_are_skipped():
    # The approach staging logs NaN where the pedestrian is not in the scene yet. A pedestrian standing at
    # x = 2.2 m (circle 1.9-2.5 m) is inside the footprint (rear 10 t - 2, front 10 t + 2) up to t = 0.4 s,
    # clear of it from 0.5 s (rear at 3 m). Absent for steps 0-2, the first contact is step 3; absent for
    # steps 0-4, there is none.
    log = driving_log(2.2, 0.0, n_steps=10)
    log.loc[:2, ["ped_x_m", "ped_y_m"]] = np.nan
    hit = witness_collision(log)
    assert hit.collided and hit.step == 3 and hit.time_s == pytest.approx(0.3)
    log.loc[:4, ["ped_x_m", "ped_y_m"]] = np.nan
    assert not witness_collision(log).collided
    only_radius_missing = driving_log(2.2, 0.0, n_steps=3)
    only_radius_missing["ped_radius_m"] = [np.nan, np.nan, 0.3]
    assert witness_collision(only_radius_missing).step == 2
    never = driving_log(2.2, 0.0, n_steps=3)
    never[["ped_x_m", "ped_y_m"]] = np.nan
    verdict = witness_collision(never)
    assert not verdict.collided and math.isnan(verdict.time_s) and verdict.step is None


def test_the_circle_polygon_lies_within_the_stated_tolerance():
    for radius in (0.2, 0.3, 0.5, 1.0):
        body = shapely.Point(0.0, 0.0).buffer(radius, quad_segs=quad_segs_for(radius))
        # The polygon is inscribed: its vertices on the circle, its edges' middles the furthest inside.
        inside_by = radius - shapely.Point(0.0, 0.0).distance(body.exterior)
        assert 0.0 < inside_by <= CIRCLE_TOLERANCE_M <= 1e-3
        vertices = np.asarray(body.exterior.coords)
        assert np.allclose(np.hypot(vertices[:, 0], vertices[:, 1]), radius)


def test_a_log_without_the_needed_columns_is_refused():
    with pytest.raises(KeyError, match="ped_radius_m"):
        witness_collision(pd.DataFrame({"time_s": [0.0]}))


@pytest.mark.slow
def test_the_witness_agrees_with_the_loop_on_a_small_real_batch(tmp_path):
    """Two episodes each of crossing and jaywalking under both conditions, every log kept, once with the
    default stack and once with one that never brakes (every episode collides): the witness's verdict on
    each episode's step log, and the columns the batch wrote, match the loop's collision, at the same step."""
    from pedsafe_sumo.safety.collision import detect_collision  # the loop's verdict, for the comparison

    for algorithm in (None, "tests.sim.plugin_agents:NeverBrakes"):
        out = tmp_path / ("never_brakes" if algorithm else "default")
        command = [sys.executable, "-m", "pedsafe_sumo.batch", "--scenario", "crossing,jaywalking"]
        command += ["--episodes", "2", "--workers", "1", "--keep-logs", "all", "--out", str(out)]
        command += ["--algorithm", algorithm] if algorithm else []
        batch = subprocess.run(command, capture_output=True, text=True, cwd=REPO_ROOT, timeout=900)
        assert batch.returncode == 0, batch.stderr[-2000:]
        episodes = pd.read_parquet(out / "episodes.parquet")
        steps = pd.concat(pd.read_parquet(p) for p in sorted((out / "steplogs").glob("*.parquet")))
        assert len(episodes) == 8 and (episodes["status"] == "ok").all()
        for row in episodes.itertuples(index=False):
            log = steps[
                (steps["scenario"] == row.scenario)
                & (steps["condition"] == row.condition)
                & (steps["episode"] == row.episode)
            ].reset_index(drop=True)
            loop, witness = detect_collision(log), witness_collision(log)
            assert witness.collided == loop.collided == row.collision == row.witness_collision
            if loop.collided:
                assert witness.step == loop.step
                assert row.witness_collision_time_s == loop.time_s
            else:
                assert math.isnan(row.witness_collision_time_s)
        if algorithm:
            assert episodes["collision"].all()
