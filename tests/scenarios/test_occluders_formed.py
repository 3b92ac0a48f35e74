"""The kerb lane's queue formed by SUMO under approach staging (sim/queue.py), checked against SUMO's own
positions: a hand-built queue at a red light with a known answer, the jaywalker's step-off point in a gap
of the queue SUMO formed, the blending pedestrian's gap measured from where the waiting vehicle stopped,
and real batches of both scenarios (no error rows; the same rows on one and two workers)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.road_users import VehicleSize
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim.connection import SumoSession
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sim.queue import form_queue
from pedsafe_sumo.sim.staging import add_vehicle, sumo_args

#: Xueqing's southbound approach and its kerb lane (SUMO index 1: the sidewalk is lane 0).
EDGE_ID = "177353854#0"
KERB_LANE_ID = f"{EDGE_ID}_1"
#: Where SUMO stops a vehicle's front before a red stop line [m]: its junction model's jmStoplineGap, 1 m
#: by default (SUMO's documentation, "Junction Model Parameters").
SUMO_STOPLINE_GAP_M = 1.0
#: SUMO stops a vehicle up to this much further back than its stop-line gap or minGap says [m] (its
#: numerical margin: 1 mm, measured); the k-th vehicle from the head may stand up to k + 1 times this back.
FOLLOWER_MARGIN_M = 0.002
PEDESTRIAN_RADIUS_M = 0.3
#: The blending pedestrian's gap to the waiting vehicle under approach staging (the spec's kerb_gap_min_m,
#: kerb_gap_max_m, written out by hand).
KERB_GAP_RANGE_M = (0.3, 1.0)


def kerb_lane_length_m() -> float:
    """The kerb lane's SUMO length, read from the network file: its end is the stop line."""
    root = ET.parse(get_site("xueqing").file("net.xml")).getroot()
    return float(next(ln for ln in root.iter("lane") if ln.get("id") == KERB_LANE_ID).get("length"))


def add_upstream(api, vehicle, route_id, depart):
    add_vehicle(api, vehicle, route_id, True, depart, upstream=True)


def hand_built_queue(lengths_m, min_gaps_m, stop_line_m, shift_m=0.0):
    """A queue whose staged fronts are where SUMO should stop it: the head SUMO_STOPLINE_GAP_M before the
    stop line, each follower its length + minGap behind the one before it (`shift_m` moves them all)."""
    queue, front_m = [], stop_line_m - SUMO_STOPLINE_GAP_M + shift_m
    for k, (length_m, gap_m) in enumerate(zip(lengths_m, min_gaps_m, strict=True)):
        if k:
            front_m -= lengths_m[k - 1] + gap_m
        size = VehicleSize(length_m, 1.8, 1.5)
        queue.append(
            VehicleSetup(
                f"q{k}", KERB_LANE_ID, front_m, 0.0, (90, 90, 90), size, formed=True, min_gap_m=gap_m
            )
        )
    return tuple(queue)


@pytest.fixture(scope="module")
def session():
    with SumoSession() as sumo:
        yield sumo


def test_a_queue_forms_at_the_red_where_the_formula_puts_it(session):
    # Six vehicles of known lengths (a 12 m bus among them) and minGaps, behind the red stop line.
    lengths_m = [4.6, 4.8, 12.0, 4.6, 5.0, 4.6]
    min_gaps_m = [0.5, 1.5, 3.0, 2.2, 1.2, 2.5]
    stop_line_m = kerb_lane_length_m()
    session.run(sumo_args(get_site("xueqing"), 0.05, 7))
    api = session.api
    (tls,) = api.trafficlight.getIDList()
    program = api.trafficlight.getProgram(tls)
    queue = hand_built_queue(lengths_m, min_gaps_m, stop_line_m)
    form_queue(api, queue, add_upstream)
    # The k-th front: the stop line, SUMO's stop-line gap, then k times (length + minGap) of those before.
    for k in range(len(queue)):
        expected_m = stop_line_m - SUMO_STOPLINE_GAP_M - sum(lengths_m[:k]) - sum(min_gaps_m[1 : k + 1])
        assert api.vehicle.getLaneID(f"q{k}") == KERB_LANE_ID
        assert api.vehicle.getSpeed(f"q{k}") == 0.0
        assert api.vehicle.getLanePosition(f"q{k}") == pytest.approx(
            expected_m, abs=(k + 1) * FOLLOWER_MARGIN_M
        )
    # The red held the lane only while the queue formed: the junction runs its program again.
    assert api.trafficlight.getProgram(tls) == program
    # The head turns right where the lane allows it (Xueqing's kerb lane: its link 0 onto 121510222#1).
    assert api.vehicle.getRoute("q0") == (EDGE_ID, "121510222#1")
    assert api.vehicle.getRoute("q1")[1] == "1270646950#1"


def test_a_queue_staged_where_sumo_does_not_stop_it_is_refused(session):
    session.run(sumo_args(get_site("xueqing"), 0.05, 7))
    queue = hand_built_queue([4.6, 4.6], [0.5, 2.0], kerb_lane_length_m(), shift_m=0.5)
    with pytest.raises(RuntimeError, match="did not form where it was staged") as error:
        form_queue(session.api, queue, add_upstream)
    assert "\n" not in str(error.value)


def sumo_body(api, vehicle_id: str, size: VehicleSize):
    """Corners of a vehicle's footprint from SUMO's front position and heading (degrees clockwise from
    north), the body its full length back."""
    (fx, fy), angle_deg = api.vehicle.getPosition(vehicle_id), api.vehicle.getAngle(vehicle_id)
    ux, uy = math.sin(math.radians(angle_deg)), math.cos(math.radians(angle_deg))
    rx, ry = fx - size.length_m * ux, fy - size.length_m * uy
    lx, ly, half = -uy, ux, size.width_m / 2
    return [(fx + half * lx, fy + half * ly), (fx - half * lx, fy - half * ly),
            (rx - half * lx, ry - half * ly), (rx + half * lx, ry + half * ly)]  # fmt: skip


def point_to_segment_m(p, a, b) -> float:
    (px, py), (ax, ay), (bx, by) = p, a, b
    dx, dy = bx - ax, by - ay
    t = max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy)))
    return math.dist(p, (ax + t * dx, ay + t * dy))


def segment_to_body_m(p, q, corners) -> float:
    """Distance from segment pq to a convex footprint (0 when pq cuts one of its edges)."""

    def orient(u, v, w):
        return (v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0])

    edges = list(zip(corners, corners[1:] + corners[:1]))
    if any(orient(p, q, a) * orient(p, q, b) < 0 and orient(a, b, p) * orient(a, b, q) < 0 for a, b in edges):
        return 0.0
    return min(
        *(point_to_segment_m(x, a, b) for x in (p, q) for a, b in edges),
        *(point_to_segment_m(c, p, q) for c in corners),
    )


def staged_in_sumo(runner: EpisodeRunner, name: str, seed: int):
    """The approach-staged episode `seed` of `name`, put into SUMO as the runner does before its first
    step: (setup, its draws by name, api)."""
    spec = get_scenario(name).with_overrides({"staging": "approach"})
    setup, draws = runner.draw_setup_sampled(spec, seed)
    runner.staging.stage(runner.session, setup, seed, runner.approach, runner.signals.program)
    return setup, draws.inputs, runner.session.api


@pytest.fixture(scope="module")
def runner():
    episode_runner = EpisodeRunner(get_site("xueqing"), load_params(), ReferenceStack)
    yield episode_runner
    episode_runner.close()


@pytest.mark.parametrize("seed", range(6))
def test_the_jaywalker_steps_off_into_a_gap_of_the_queue_sumo_formed(runner, seed):
    setup, _, api = staged_in_sumo(runner, "jaywalking", seed)
    ped = setup.pedestrian
    start, end = ped.path_xy[ped.kerb_index], ped.path_xy[ped.kerb_index + 1]
    # Where SUMO's queue stands (SUMO's positions and headings), and how far the crossing is from each body.
    clearances_m = [
        segment_to_body_m(start, end, sumo_body(api, v.vehicle_id, v.size)) - PEDESTRIAN_RADIUS_M
        for v in setup.parked
    ]
    # Their body clears every vehicle of the queue all the way across the kerb lane ...
    assert min(clearances_m) > 0.0, clearances_m
    # ... and the crossing lies in a gap: between two vehicles, each within the largest jaywalker's gap
    # (2.5 m) of the body.
    nearest = sorted(range(len(clearances_m)), key=clearances_m.__getitem__)[:2]
    assert abs(nearest[0] - nearest[1]) == 1
    assert max(clearances_m[k] for k in nearest) < 2.5
    # SUMO formed it: the vehicles stand still; they entered upstream one every 2 s before the episode's
    # clock started, so it starts after the last one entered.
    assert all(api.vehicle.getSpeed(v.vehicle_id) == 0.0 for v in setup.parked)
    assert api.simulation.getTime() > (len(setup.parked) - 1) * 2.0


@pytest.mark.parametrize("seed", range(6))
def test_the_blending_pedestrian_keeps_the_drawn_gap_from_where_the_vehicle_stopped(runner, seed):
    setup, drawn, api = staged_in_sumo(runner, "background_blending", seed)
    (waiting,) = setup.parked
    assert waiting.formed
    ped = setup.pedestrian
    start, end = ped.path_xy[ped.kerb_index], ped.path_xy[ped.kerb_index + 1]
    gap_m = (
        segment_to_body_m(start, end, sumo_body(api, waiting.vehicle_id, waiting.size)) - PEDESTRIAN_RADIUS_M
    )
    # SUMO stopped it at the red stop line, 1 m before it (+1 mm), a vehicle length ahead of the crossing.
    assert kerb_lane_length_m() - api.vehicle.getLanePosition(waiting.vehicle_id) == pytest.approx(
        SUMO_STOPLINE_GAP_M, abs=FOLLOWER_MARGIN_M
    )
    # Their crossing passes its rear at the drawn gap, measured from where SUMO stopped it (1 mm off).
    assert KERB_GAP_RANGE_M[0] <= drawn["blend_gap_m"] <= KERB_GAP_RANGE_M[1]
    assert gap_m == pytest.approx(drawn["blend_gap_m"], abs=FOLLOWER_MARGIN_M)


def run_batch(out, workers: str) -> pd.DataFrame:
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--scenario", "jaywalking,background_blending",
         "--set", "staging=approach", "--episodes", "2", "--seed", "3", "--chunk-size", "1",
         "--workers", workers, "--out", str(out)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=600, env=dict(os.environ),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    return pd.read_parquet(out / "episodes.parquet")


@pytest.mark.slow
def test_approach_jaywalking_and_blending_run_without_errors_the_same_on_one_and_two_workers(tmp_path):
    one = run_batch(tmp_path / "one", "1")
    assert len(one) == 8  # 2 episodes x 2 scenarios x SV and V2I
    assert (one["status"] == "ok").all(), one[["scenario", "seed", "status", "error"]]
    assert (one["ped_appear_time_s"] > 0).all()
    two = run_batch(tmp_path / "two", "2")
    pd.testing.assert_frame_equal(one, two)


@pytest.mark.parametrize("name", ["crossing", "jaywalking", "background_blending"])
def test_queue_staging_placed_adds_them_standing_half_a_metre_before_the_line(runner, name):
    # queue_staging "placed" (protocol approach-v1's value): SUMO forms nothing; the head's front stands
    # 0.5 m before the stop line (the kerb lane's length, read from the network file, minus 0.5), every
    # staged vehicle with SUMO's minGap 0.5 m; the world's draws are those of "formed" but the head's
    # position.
    stop_line_m = kerb_lane_length_m()
    spec = get_scenario(name).with_overrides({"staging": "approach", "queue_staging": "placed"})
    placed, placed_draws = runner.draw_setup_sampled(spec, 3)
    formed, formed_draws = runner.draw_setup_sampled(spec.with_overrides({"queue_staging": "formed"}), 3)
    kerb_placed = [v for v in placed.parked if v.lane_id == KERB_LANE_ID]
    assert kerb_placed and not any(v.formed for v in kerb_placed)
    assert {v.min_gap_m for v in kerb_placed} == {0.5}
    assert max(v.front_pos_m for v in kerb_placed) == pytest.approx(stop_line_m - 0.5, abs=1e-9)
    kerb_formed = [v for v in formed.parked if v.lane_id == KERB_LANE_ID]
    assert all(v.formed for v in kerb_formed)
    assert max(v.front_pos_m for v in kerb_formed) == pytest.approx(stop_line_m - 1.0, abs=1e-9)
    assert list(placed_draws.inputs) == list(formed_draws.inputs)
