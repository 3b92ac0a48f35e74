"""The pedestrian's staging in the loop, on the real Xueqing site: appearing late (nothing of them in SUMO,
the snapshot or the sensors before), walking on and leaving the scene, walking into the side of a moving
ego, and who struck whom (collision_type). Hand-built setups on the crossing scenario: an ego that never
brakes, held at 5 m/s, drives south along x ~ 199.5 and crosses the crosswalk, which the pedestrian walks
eastwards."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo.control.agent import load_agent_class
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params, with_overrides
from pedsafe_sumo.perception.surfaces import KIND_PEDESTRIAN
from pedsafe_sumo.protocol import VALUES_BEFORE
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim import loop as loop_module
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sim.staging import EGO_ID, PED_ID
from tests.sim.ad_agents import Recorder

SITE = get_site("xueqing")
SPEED_MPS = 5.0
SPEC = get_scenario("crossing").with_overrides(
    {"ego_speed_min_mps": SPEED_MPS, "ego_speed_max_mps": SPEED_MPS}
)
SEED = 0


def _runner(params=None):
    # Minimum clearance over every step with the pedestrian in the scene (proximity scope "episode"):
    # these tests follow the pedestrian after they cross, beside the ego's path.
    every_step = with_overrides(load_params(), {"safety.proximity_scope": "episode"})
    return EpisodeRunner(SITE, params or every_step, load_agent_class("tests.sim.plugin_agents:NeverBrakes"))


@pytest.fixture(scope="module")
def runner():
    runner = _runner()
    yield runner
    runner.close()


@pytest.fixture(scope="module")
def crossing(runner):
    """(setup, A, unit vector along the crosswalk, P, sin of the angle between ego path and crosswalk,
    time the ego's centre passes P): P is where the ego's centre path crosses the crosswalk line, from a
    probe run with the pedestrian idle on the sidewalk."""
    setup = runner.draw_setup(SPEC, SEED)
    idle = dataclasses.replace(setup.pedestrian, start_delay_s=1000.0, risk="unaware")
    probe = runner.run(SPEC, "sv", SEED, setup=dataclasses.replace(setup, pedestrian=idle)).log
    (ax, ay), (bx, by) = setup.pedestrian.path_xy
    length = math.hypot(bx - ax, by - ay)
    ux, uy = (bx - ax) / length, (by - ay) / length
    # Ego centre path (south-bound, nearly straight) against the crosswalk line: the crossing by the
    # sign change of the centre's side of the line.
    side = (probe["ego_x_m"] - ax) * uy - (probe["ego_y_m"] - ay) * ux
    k = int(np.flatnonzero(np.sign(side.to_numpy()) != np.sign(side.iloc[0]))[0])
    f = side.iloc[k - 1] / (side.iloc[k - 1] - side.iloc[k])
    px = probe["ego_x_m"].iloc[k - 1] + f * (probe["ego_x_m"].iloc[k] - probe["ego_x_m"].iloc[k - 1])
    py = probe["ego_y_m"].iloc[k - 1] + f * (probe["ego_y_m"].iloc[k] - probe["ego_y_m"].iloc[k - 1])
    t_p = probe["time_s"].iloc[k - 1] + f * (probe["time_s"].iloc[k] - probe["time_s"].iloc[k - 1])
    yaw = probe["ego_yaw_rad"].iloc[k]
    sin_angle = abs(math.cos(yaw) * uy - math.sin(yaw) * ux)
    return setup, (ax, ay), (ux, uy), (px, py), sin_angle, t_p


def _with_pedestrian(setup, **changes):
    return dataclasses.replace(setup, pedestrian=dataclasses.replace(setup.pedestrian, **changes))


def _in_sumo_hook(seen):
    def hook(api, row):
        seen.append((row["time_s"], PED_ID in api.person.getIDList(), row["ped_state"]))

    return hook


# ---------------------------------------------------------------------------------------------- (a)
def test_before_appearing_a_step_reads_the_ego_alone(runner, crossing, monkeypatch):
    """appear_time_s = 4 s, a stack that asks for no feed made from the snapshot: before 4 s no step reads
    the other vehicles from SUMO (getAllSubscriptionResults, once a step from 4 s on), and the ego's row
    is still its footprint centre: SUMO's front bumper moved half its length back along its heading (SUMO's
    angle clockwise from north), by hand from SUMO's getters at every step."""
    setup = _with_pedestrian(crossing[0], appear_time_s=4.0, risk="unaware")
    api = runner.session.api
    reads = []
    real_read = api.vehicle.getAllSubscriptionResults

    def counting_read():
        reads.append(api.simulation.getTime())
        return real_read()

    monkeypatch.setattr(api.vehicle, "getAllSubscriptionResults", counting_read)
    by_hand = []

    def hook(api, row):
        x, y = api.vehicle.getPosition(EGO_ID)
        yaw = math.radians(90.0 - api.vehicle.getAngle(EGO_ID))
        half_m = setup.ego.size.length_m / 2
        by_hand.append(
            ((x - half_m * math.cos(yaw), y - half_m * math.sin(yaw)), (row["ego_x_m"], row["ego_y_m"]))
        )

    log = runner.run(SPEC, "sv", SEED, setup=setup, on_step=hook).log
    assert (log["time_s"] < 4.0 - 1e-9).sum() == 79
    assert len(reads) == (log["time_s"] >= 4.0 - 1e-9).sum()
    assert len(by_hand) == len(log)
    for expected, logged in by_hand:
        assert logged == pytest.approx(expected, abs=1e-9)


def test_before_appearing_the_pedestrian_is_nowhere(runner, crossing, monkeypatch):
    """appear_time_s = 4 s: the rows before 4 s have the pedestrian absent (NaN position, infinite
    clearance, nothing perceived or detected), perceive is not called, and SUMO has no person; from the
    row at 4.00 s on they stand at the start of their path, in SUMO, and the sensors run."""
    setup = _with_pedestrian(crossing[0], appear_time_s=4.0, risk="unaware")
    calls = []
    real_perceive = loop_module.perceive

    def counting_perceive(snapshot, ego_pose, sensors, rng, time_s, link):
        calls.append((time_s, len(snapshot.pedestrians)))
        return real_perceive(snapshot, ego_pose, sensors, rng, time_s, link)

    monkeypatch.setattr(loop_module, "perceive", counting_perceive)
    seen = []
    result = runner.run(SPEC, "sv", SEED, setup=setup, on_step=_in_sumo_hook(seen))
    log = result.log
    before = log[log["time_s"] < 4.0 - 1e-9]
    after = log[log["time_s"] >= 4.0 - 1e-9]
    assert len(before) == 79 and before["time_s"].iloc[-1] == pytest.approx(3.95)  # 0.05 .. 3.95 s
    assert (before["ped_state"] == "absent").all()
    assert before[["ped_x_m", "ped_y_m", "ped_vx_mps", "ped_vy_mps"]].isna().all().all()
    assert np.isinf(before["clearance_m"]).all()
    flags = [
        "detected_onboard_camera",
        "detected_onboard_lidar",
        "detected_roadside",
        "perceived",
        "roadside_raw",
    ]
    assert not before[flags].any().any()
    # perceive: never before 4 s, once at every step from then on, always with the pedestrian.
    assert min(t for t, _ in calls) == pytest.approx(4.0)
    assert len(calls) == len(after) and all(n == 1 for _, n in calls)
    # SUMO: no person before 4 s, the person at every step after.
    assert not any(present for t, present, _ in seen if t < 4.0 - 1e-9)
    assert all(present for t, present, _ in seen if t >= 4.0 - 1e-9)
    first = after.iloc[0]
    (ax, ay) = setup.pedestrian.path_xy[0]
    assert (first["ped_x_m"], first["ped_y_m"]) == pytest.approx((ax, ay)) and first["ped_state"] == "waiting"
    # The indexes are those of the present steps: the minimum clearance over them, detection at or after 4 s.
    assert result.outcome["min_clearance_m"] == pytest.approx(after["clearance_m"].min(), abs=1e-9)
    assert result.outcome["first_detection_time_s"] >= 4.0
    assert result.outcome["ped_appear_time_s"] == 4.0
    # The start delay runs from the appearance: the first step of the walk is the one of 4 + 1 = 5 s.
    walked = after[after["ped_state"] == "walking"]
    assert walked["time_s"].iloc[0] == pytest.approx(4.0 + setup.pedestrian.start_delay_s + 0.05)


# ---------------------------------------------------------------------------------------------- (b)
def _walk_on_setup(crossing, delay_s, leaves):
    """The ego 40 m further back (it passes P about 8 s later, after the pedestrian crossed); the
    pedestrian unaware, with the walk-on: 5 m beyond the crosswalk's end, straight on, away from the road."""
    setup, _, (ux, uy), *_ = crossing
    (ax, ay), (bx, by) = setup.pedestrian.path_xy
    ego = dataclasses.replace(setup.ego, front_pos_m=setup.ego.front_pos_m - 40.0)
    path = ((ax, ay), (bx, by), (bx + 5.0 * ux, by + 5.0 * uy)) if leaves else ((ax, ay), (bx, by))
    ped = dataclasses.replace(
        setup.pedestrian, path_xy=path, start_delay_s=delay_s, risk="unaware", leaves_scene=leaves
    )
    return dataclasses.replace(setup, ego=ego, pedestrian=ped)


def test_walking_on_the_pedestrian_leaves_and_the_minimum_clearance_follows_the_timing(runner, crossing):
    """Standing at the crosswalk's end (the fixed staging) the pedestrian's minimum clearance to the ego
    passing later is the geometry's constant whatever their start delay; walking on 5 m and leaving,
    it depends on the delay. The pedestrian leaves the scene (state "left", gone from SUMO) the step
    after reaching the end of their path, (|AB| + 5 m) / speed after the delay."""
    clearances = {}
    for leaves in (False, True):
        for delay_s in (0.5, 1.5):
            seen = []
            setup = _walk_on_setup(crossing, delay_s, leaves)
            result = runner.run(SPEC, "sv", SEED, setup=setup, on_step=_in_sumo_hook(seen))
            assert result.end_reason == "both_cleared" and not result.outcome["collision"]
            clearances[leaves, delay_s] = result.outcome["min_clearance_m"]
            log = result.log
            if not leaves:
                assert "left" not in set(log["ped_state"])
                continue
            ped = setup.pedestrian
            (ax, ay), (bx, by), _ = ped.path_xy
            walk_s = (math.hypot(bx - ax, by - ay) + 5.0) / ped.walking_speed_mps
            left = log[log["ped_state"] == "left"]
            # Reached the end at the first step at or after delay + walk; "left" from the step after.
            assert left["time_s"].iloc[0] == pytest.approx(delay_s + walk_s + 0.05, abs=0.05 + 1e-9)
            assert left[["ped_x_m", "ped_y_m"]].isna().all().all() and np.isinf(left["clearance_m"]).all()
            assert not any(present for t, present, _ in seen if t >= left["time_s"].iloc[0] - 1e-9)
            last = log[log["ped_state"] != "left"].iloc[-1]
            assert (last["ped_x_m"], last["ped_y_m"]) == pytest.approx(ped.path_xy[-1], abs=1e-6)
    assert clearances[False, 0.5] == pytest.approx(clearances[False, 1.5], abs=0.02)
    assert abs(clearances[True, 0.5] - clearances[True, 1.5]) > 0.5
    assert min(clearances[True, 0.5], clearances[True, 1.5]) > clearances[False, 0.5] + 0.5


# ---------------------------------------------------------------------------------------------- (c)
def _walking_into_the_lane(crossing, flank_at_s):
    """The pedestrian (unaware) walks the crosswalk from A, timed so that their body reaches the line of
    the ego's near (west) flank at `flank_at_s`."""
    setup, (ax, ay), _, (px, py), sin_angle, _ = crossing
    ped = setup.pedestrian
    to_flank_m = math.hypot(px - ax, py - ay) - (setup.ego.size.width_m / 2 + ped.radius_m) / sin_angle
    return _with_pedestrian(
        setup, risk="unaware", start_delay_s=flank_at_s - to_flank_m / ped.walking_speed_mps
    )


def _ego_frame(row):
    cos, sin = math.cos(row["ego_yaw_rad"]), math.sin(row["ego_yaw_rad"])
    dx, dy = row["ped_x_m"] - row["ego_x_m"], row["ped_y_m"] - row["ego_y_m"]
    return cos * dx + sin * dy, -sin * dx + cos * dy


def test_an_unaware_pedestrian_walks_into_the_side_of_the_moving_ego(runner, crossing):
    """Their body reaches the flank line as the ego's centre passes P: they walk into its side, while
    the front is already more than 2 m past them. collision_type pedestrian_strikes_side. Under the rule of
    paper-v7 (VALUES_BEFORE: body_rule_needs_notice off) the same pedestrian stops 0.1 m short."""
    *_, t_p = crossing
    setup = _walking_into_the_lane(crossing, t_p)
    result = runner.run(SPEC, "sv", SEED, setup=setup)
    assert result.outcome["collision"] and result.end_reason == "collision"
    contact = result.log.iloc[-1]
    lon, lat = _ego_frame(contact)
    assert abs(lon) < 1.0 and lat < 0  # beside the middle of the box, on its right (west) flank
    assert contact["ped_state"] == "walking" and contact["ped_vx_mps"] > 1.0  # eastwards, into the side
    assert result.outcome["collision_type"] == "pedestrian_strikes_side"

    params = load_params()
    for dotted, value in VALUES_BEFORE["parameters"].items():
        *tables, key = dotted.split(".")
        section = params
        for table in tables:
            section = section[table]
        section[key] = value
    before = _runner(params)
    try:
        old = before.run(SPEC, "sv", SEED, setup=setup)
    finally:
        before.close()
    assert not old.outcome["collision"] and old.outcome["collision_type"] == "none"
    assert "blocked" in set(old.log["ped_state"])
    assert old.outcome["min_clearance_m"] == pytest.approx(0.1, abs=0.08)


def test_the_ego_front_striking_a_pedestrian_in_its_lane(runner, crossing):
    """Their body reaches the flank line 0.75 s before the ego's centre reaches P: 0.45 s before the front
    does, so they are 0.5 m into the lane when it arrives; the front strikes them: ego_strikes_pedestrian."""
    *_, t_p = crossing
    setup = _walking_into_the_lane(crossing, t_p - 0.75)
    result = runner.run(SPEC, "sv", SEED, setup=setup)
    assert result.outcome["collision"]
    lon, _ = _ego_frame(result.log.iloc[-1])
    assert lon > setup.ego.size.length_m / 2  # ahead of the front face
    assert result.outcome["collision_type"] == "ego_strikes_pedestrian"


# ---------------------------------------------------------------------------------------------- (e)
def test_the_same_seed_gives_the_same_rows(runner, crossing):
    """A late-appearing pedestrian who walks in along a sidewalk leg, crosses and walks on: twice in one
    runner, once in a new one, the same rows."""
    setup, _, (ux, uy), *_ = crossing
    (ax, ay), (bx, by) = setup.pedestrian.path_xy
    path = ((ax - 4.0 * uy, ay + 4.0 * ux), (ax, ay), (bx, by), (bx + 5.0 * ux, by + 5.0 * uy))
    staged = _with_pedestrian(setup, path_xy=path, kerb_index=1, appear_time_s=2.0, leaves_scene=True)
    first = runner.run(SPEC, "v2i", SEED, setup=staged)
    second = runner.run(SPEC, "v2i", SEED, setup=staged)
    fresh = _runner()
    try:
        third = fresh.run(SPEC, "v2i", SEED, setup=staged)
    finally:
        fresh.close()
    assert {"absent", "walking_in", "waiting"} <= set(first.log["ped_state"])
    pd.testing.assert_frame_equal(first.log, second.log)
    pd.testing.assert_frame_equal(first.log, third.log)
    assert first.outcome.keys() == third.outcome.keys()
    for key, value in first.outcome.items():
        other = third.outcome[key]
        assert value == other or (isinstance(value, float) and math.isnan(value) and math.isnan(other)), key


def test_raw_lidar_data_before_the_pedestrian_appears(crossing):
    """A stack that asks for the raw LiDAR points and labels gets them at every step, before the
    pedestrian appears too: no pedestrian then, no return labelled as one, but the ground and the scene."""
    Recorder.wants, Recorder.command = ["onboard_lidar_points", "onboard_lidar_labels"], {}
    runner = EpisodeRunner(SITE, load_params(), Recorder)
    try:
        result = runner.run(SPEC, "sv", SEED, setup=_with_pedestrian(crossing[0], appear_time_s=4.0))
    finally:
        runner.close()
    observations = list(Recorder.observations)
    assert len(observations) == len(result.log)
    absent = result.log["ped_state"].to_numpy() == "absent"
    assert absent.sum() == 79
    for observation, nobody in zip(observations, absent, strict=True):
        points = observation.sensor_data["onboard_lidar_points"]
        labels = observation.sensor_data["onboard_lidar_labels"]
        assert points.ndim == 2 and points.shape[0] > 0 and labels.kind.shape == (points.shape[0],)
        if nobody:
            assert observation.pedestrians == () and not (labels.kind == KIND_PEDESTRIAN).any()
