"""The AD interface in real SUMO: raw data and world feeds only on request, lane changes and paths
actuated in SUMO (and refused off the road), the traffic light as SUMO has it (over V2I with the
link's latency), the map from the network, unknown sensors refused in one line."""

from __future__ import annotations

import copy
import math
import subprocess
import sys

import numpy as np
import pytest
import sumolib

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.control.agent import KNOWN_SENSORS, AlgorithmLoadError, load_agent_class
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.perception.surfaces import KIND_PEDESTRIAN
from pedsafe_sumo.scenarios.specs import SCENARIOS
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sim.observation import ObservationFeeds
from pedsafe_sumo.sumo_net import read_net
from tests.sim.ad_agents import Recorder

SITE = get_site("xueqing")
PARAMS = load_params()
LIDAR_HEIGHT_M = PARAMS["perception"]["lidar"]["height_m"]


@pytest.fixture(scope="module")
def runner():
    runner = EpisodeRunner(SITE, PARAMS, Recorder)
    yield runner
    runner.close()


def _run(runner, wants, command=None, condition="sv", seed=1, scenario="crossing", hook=None):
    Recorder.wants = list(wants)
    Recorder.command = dict(command or {})
    result = runner.run(SCENARIOS[scenario], condition, seed, on_step=hook)
    return result, list(Recorder.observations)


# ------------------------------------------------------------------ refusing unknown sensors
def test_an_agent_asking_for_an_unknown_sensor_is_refused_in_one_line():
    with pytest.raises(AlgorithmLoadError) as err:
        load_agent_class("tests.sim.ad_agents:AsksForRadar")
    assert "onboard_radar" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("flags", "name"),
    [
        (["--algorithm", "tests.sim.ad_agents:AsksForRadar"], "onboard_radar"),
        (["--perception", "tests.sim.ad_agents:RadarPerception"], "front_radar"),
        (
            ["--perception", "no.such.module:Detector"],
            "cannot import module 'no.such.module' for --perception",
        ),
    ],
)
def test_the_episode_cli_refuses_unknown_sensors_and_bad_perception_in_one_line_exit_2(flags, name):
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.episode", "--scenario", "crossing", *flags],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and name in proc.stderr and "Traceback" not in proc.stderr


def test_a_stack_asking_for_the_detections_alone_gets_no_feeds_built():
    assert ObservationFeeds.for_agent(None, "ego", set(KNOWN_SENSORS), "v2i", None, None, {}) is None


def test_a_stack_asking_for_the_detections_alone_gets_what_it_got_before(runner):
    _, observations = _run(runner, KNOWN_SENSORS, condition="v2i")
    assert observations
    for o in observations:
        assert o.sensor_data == {} and o.vehicles == () and o.route is None
        assert o.road_map is None and o.traffic_light is None


# ------------------------------------------------------------------ raw data
@pytest.mark.slow
def test_raw_lidar_points_are_in_the_sensor_frame_and_the_labelled_pedestrian_returns_lie_on_her(runner):
    result, observations = _run(runner, ["onboard_lidar_points", "onboard_lidar_labels"])
    log = result.log
    radius = float(log.ped_radius_m.iloc[0])
    height_m = result.setup.pedestrian.height_m
    checked = 0
    for o, (_, row) in zip(observations, log.iterrows(), strict=True):
        assert set(o.sensor_data) == {"onboard_lidar_points", "onboard_lidar_labels"}
        points, labels = o.sensor_data["onboard_lidar_points"], o.sensor_data["onboard_lidar_labels"]
        assert points.ndim == 2 and points.shape[1] == 3 and labels.kind.shape == (points.shape[0],)
        # The flat ground near the vehicle lies one mount height below the sensor.
        assert np.any(np.isclose(points[:, 2], -LIDAR_HEIGHT_M, atol=1e-6))
        on_ped = labels.kind == KIND_PEDESTRIAN
        if not on_ped.any():
            continue
        # Sensor frame -> world by the ego's logged pose (the LiDAR sits over the box centre).
        c, s = math.cos(row.ego_yaw_rad), math.sin(row.ego_yaw_rad)
        x = row.ego_x_m + c * points[on_ped, 0] - s * points[on_ped, 1]
        y = row.ego_y_m + s * points[on_ped, 0] + c * points[on_ped, 1]
        # On her cylinder: its side (radius from her axis) or its top (her height, inside the radius).
        r = np.hypot(x - row.ped_x_m, y - row.ped_y_m)
        top = np.isclose(points[on_ped, 2], height_m - LIDAR_HEIGHT_M, atol=1e-6)
        assert np.all(np.isclose(r, radius, atol=1e-6) | (top & (r <= radius + 1e-6)))
        assert np.all(labels.object_id[on_ped] == "ped")
        checked += 1
    assert checked > 10


@pytest.mark.slow
def test_the_camera_image_shows_the_clothing_colour_where_the_projection_puts_the_pedestrian(runner):
    result, observations = _run(runner, ["onboard_camera", "onboard_camera_image", "onboard_camera_depth"])
    clothing = tuple(int(v) for v in result.setup.pedestrian.clothing_rgb)
    cam = PARAMS["perception"]["camera"]
    raw = PARAMS["perception"]["raw"]
    w, h = raw["camera_image_width_px"], raw["camera_image_height_px"]
    f = w / (2 * math.tan(math.radians(cam["hfov_deg"]) / 2))
    hits = 0
    for o, (_, row) in zip(observations, result.log.iterrows(), strict=True):
        image = o.sensor_data["onboard_camera_image"]
        assert image.shape == (h, w, 3) and image.dtype == np.uint8
        assert o.sensor_data["onboard_camera_depth"].shape == (h, w)
        if not row.detected_onboard_camera:
            continue
        # Eq. 6 by hand: her box in the image, from her axis (ahead, left of the camera), her radius and
        # height. The camera sees at least 30 % of her, so her clothing shows, and only inside that box
        # (part of it may hide behind a parked car).
        c, s = math.cos(row.ego_yaw_rad), math.sin(row.ego_yaw_rad)
        cx, cy = row.ego_x_m + c * cam["forward_offset_m"], row.ego_y_m + s * cam["forward_offset_m"]
        dx, dy = row.ped_x_m - cx, row.ped_y_m - cy
        ahead, left = dx * c + dy * s, -dx * s + dy * c
        # Her outline: the circle of her footprint, at her feet and at her head, projected point by point.
        theta = np.linspace(0, 2 * np.pi, 721)
        x = ahead + row.ped_radius_m * np.cos(theta)
        u = w / 2 - f * (left + row.ped_radius_m * np.sin(theta)) / x
        u_lo, u_hi = u.min(), u.max()
        v_head = (h / 2 + f * (cam["height_m"] - result.setup.pedestrian.height_m) / x).min()
        v_feet = (h / 2 + f * cam["height_m"] / x).max()
        rows, cols = np.nonzero(np.all(image == np.array(clothing, dtype=np.uint8), axis=2))
        assert rows.size > 0
        assert np.all((cols + 1 >= u_lo) & (cols <= u_hi) & (rows + 1 >= v_head) & (rows <= v_feet))
        hits += 1
    assert hits > 5


def test_the_roadside_image_comes_over_v2i_only_with_the_link_latency(runner):
    _, sv = _run(runner, ["roadside_camera_image"], condition="sv")
    assert all("roadside_camera_image" not in o.sensor_data for o in sv)
    _, v2i = _run(runner, ["roadside_camera_image"], condition="v2i")
    latency_steps = round(PARAMS["perception"]["v2i"]["latency_s"] / 0.05)
    assert all("roadside_camera_image" not in o.sensor_data for o in v2i[:latency_steps])
    raw = PARAMS["perception"]["raw"]
    for o in v2i[latency_steps:]:
        images = o.sensor_data["roadside_camera_image"]
        assert set(images) == set(SCENARIOS["crossing"].roadside_unit_ids)
        for image in images.values():
            assert image.shape == (raw["roadside_image_height_px"], raw["roadside_image_width_px"], 3)


# ------------------------------------------------------------------ steering
def _lane_probe(api, seen):
    return lambda api_, row: seen.append(
        (api_.vehicle.getLaneID("ego"), api_.vehicle.getLateralLanePosition("ego"), row["command_refused"])
    )


def test_a_lane_change_moves_the_ego_to_the_next_lane_in_sumo(runner):
    net = read_net(str(SITE.file("net.xml")))
    seen: list = []

    class Once(Recorder):
        def run_step(self, observation, time_s):
            command = super().run_step(observation, time_s)
            type(self).command = {}  # ask once
            return command

    runner.agent_class = Once
    try:
        Recorder.wants, Recorder.command = ["route"], {"lane_change": -1}
        result = runner.run(SCENARIOS["crossing"], "sv", 1, on_step=_lane_probe(None, seen))
    finally:
        runner.agent_class = Recorder
    start_lane, next_lane = seen[0][0], seen[1][0]
    edge, index = start_lane.rsplit("_", 1)
    assert next_lane == f"{edge}_{int(index) - 1}"
    # The ego's centre now lies on the new lane's centreline (sumolib's geometry, not ours).
    row = result.log.iloc[2]
    shape = net.getLane(next_lane).getShape()
    dist = sumolib.geomhelper.distancePointToPolygon((row.ego_x_m, row.ego_y_m), shape)
    assert dist < 0.05
    assert all(refused == "" for *_, refused in seen)


@pytest.mark.parametrize(("change", "lane"), [(+1, 3), (-2, 0)])
def test_a_lane_change_off_the_road_is_refused_and_logged(runner, change, lane):
    seen: list = []
    _run(runner, ["route"], {"lane_change": change}, hook=_lane_probe(None, seen))
    first_lane = seen[0][0]
    assert all(s[0] == first_lane for s in seen[:20])  # still on its lane
    assert seen[0][2] == f"lane change {change:+d} refused: lane {lane} of edge 177353854#0 is not road"


def test_a_lateral_offset_is_held_by_sumo_and_one_off_the_road_is_refused(runner):
    seen: list = []
    _run(runner, [], {"lateral_offset_m": 0.5}, hook=_lane_probe(None, seen))
    # Metres left of the lane centre, as SUMO has it (the offset path is drawn from our lane polyline).
    assert [s[1] for s in seen[1:20]] == pytest.approx([0.5] * 19, abs=0.01)
    seen.clear()
    _run(runner, [], {"lateral_offset_m": 4.0}, hook=_lane_probe(None, seen))
    assert all(s[1] == 0.0 for s in seen[:20])
    assert seen[0][2].startswith("lateral offset +4.00 m refused") and "leaves the road" in seen[0][2]


# ------------------------------------------------------------------ world feeds
def test_the_traffic_light_is_sumos_onboard_and_arrives_with_the_latency_over_v2i():
    params = copy.deepcopy(PARAMS)
    params["perception"]["v2i"]["signal_source"] = "spat"
    runner = EpisodeRunner(SITE, params, Recorder)
    try:
        _check_signal_feed_spat(runner)
    finally:
        runner.close()


def test_under_v2i_the_camera_reads_the_light_now_and_spat_gives_its_timing(runner):
    # signal_source "fresher" (the default): within the camera's reach the state is SUMO's at this very
    # step, the time to the switch SUMO's own (getNextSwitch) while the SPaT message, 0.1 s old, tells the
    # same state, NaN on the step a change has been seen but not yet sent.
    states: dict[float, str] = {}
    switch_in: dict[float, float] = {}

    def probe(api, row):
        upcoming = api.vehicle.getNextTLS("ego")
        if upcoming:
            tls, index, _, _ = upcoming[0]
            t = round(row["time_s"], 2)
            states[t] = api.trafficlight.getRedYellowGreenState(tls)[index]
            switch_in[t] = api.trafficlight.getNextSwitch(tls) - row["time_s"]

    _, observations = _run(runner, ["traffic_light"], condition="v2i", hook=probe)
    reach_m = PARAMS["perception"]["raw"]["signal_visibility_m"]
    # Observation k is of the k-th step the probe saw (as in the test above).
    now = sorted(states)[2 : len(states)]
    delivered = [(t, o.traffic_light) for t, o in zip(now, observations[2 : len(states)], strict=True)]
    assert sum(light.distance_m <= reach_m for _, light in delivered) > 20
    for time_s, light in delivered:
        if light.distance_m > reach_m:  # beyond the camera's reach: SPaT, 0.1 s old
            assert light.source == "v2i" and round(light.measured_at_s, 2) == round(time_s - 0.1, 2)
            continue
        t = round(light.measured_at_s, 2)
        assert light.source == "onboard_camera+v2i" and t == time_s
        assert light.state == states[t]
        if states.get(round(t - 0.1, 2)) == states[t]:
            assert light.time_to_switch_s == pytest.approx(switch_in[t], abs=1e-6)
        else:
            assert math.isnan(light.time_to_switch_s)


def _check_signal_feed_spat(runner):
    for condition in ("sv", "v2i"):
        states: dict[float, str] = {}

        def probe(api, row, states=states):
            upcoming = api.vehicle.getNextTLS("ego")
            if upcoming:  # none once the ego is past the junction's stop line
                tls, index, _, _ = upcoming[0]
                states[round(row["time_s"], 2)] = api.trafficlight.getRedYellowGreenState(tls)[index]

        _, observations = _run(runner, ["traffic_light"], condition=condition, hook=probe)
        delivered = [o.traffic_light for o in observations if o.traffic_light is not None]
        assert len(delivered) > 20
        for light in delivered:
            assert light.state == states[round(light.measured_at_s, 2)]
            if condition == "sv":
                assert light.source == "onboard_camera" and math.isnan(light.time_to_switch_s)
        if condition == "v2i":
            times = [round(o.traffic_light.measured_at_s, 2) for o in observations[2 : len(states)]]
            now = [round(t, 2) for t in sorted(states)[2 : len(states)]]
            assert times == [round(t - 0.1, 2) for t in now]
            # Before the first SPaT message arrives, the camera reads the light.
            assert [o.traffic_light.source for o in observations[:2]] == ["onboard_camera"] * 2
            assert all(light.source == "v2i" and light.time_to_switch_s >= 0 for light in delivered[2:])


def test_route_and_map_come_from_the_network(runner):
    lanes_seen: list = []
    _, observations = _run(
        runner, ["route", "road_map"], hook=lambda api, row: lanes_seen.append(api.vehicle.getLaneID("ego"))
    )
    net = read_net(str(SITE.file("net.xml")), withInternal=True)
    crossings = [e for e in net.getEdges(withInternal=True) if e.getFunction() == "crossing"]
    road_map = observations[0].road_map
    assert len(road_map.crosswalks) == len(crossings)
    for cw in road_map.crosswalks:
        lane = net.getEdge(cw.crossing_id).getLanes()[0]
        mid = np.mean(np.asarray(lane.getShape()), axis=0)
        assert np.mean(np.asarray(cw.polygon_xy_m), axis=0) == pytest.approx(mid, abs=1e-6)
    for o, lane_id in zip(observations, lanes_seen, strict=True):
        assert o.route.current_lane_id == lane_id
        assert lane_id in {lane.lane_id for lane in o.route.lanes}
    ego_lane = lanes_seen[0]
    stop = next(s for s in road_map.stop_lines if s.lane_id == ego_lane)
    end = net.getLane(ego_lane).getShape()[-1]
    assert np.mean([stop.start_xy_m, stop.end_xy_m], axis=0) == pytest.approx(end, abs=1e-6)
    assert math.dist(stop.start_xy_m, stop.end_xy_m) == pytest.approx(net.getLane(ego_lane).getWidth())


def test_a_path_of_points_is_followed_in_sumo(runner):
    """A path drawn by hand 0.8 m left of the ego's lane (each segment of SUMO's lane shape shifted
    along its own left normal): SUMO puts the ego 0.8 m left of its lane centre, at the commanded speed."""
    net = read_net(str(SITE.file("net.xml")))
    shape = net.getLane("177353854#0_2").getShape()
    path = []
    for (x0, y0), (x1, y1) in zip(shape, shape[1:]):
        length = math.hypot(x1 - x0, y1 - y0)
        nx, ny = -(y1 - y0) / length * 0.8, (x1 - x0) / length * 0.8
        path += [(x0 + nx, y0 + ny), (x1 + nx, y1 + ny)]
    seen: list = []
    result, _ = _run(runner, [], {"path_xy_m": tuple(path)}, hook=_lane_probe(None, seen))
    assert seen[0][0] == "177353854#0_2"
    assert [s[1] for s in seen[1:15]] == pytest.approx([0.8] * 14, abs=0.01)
    assert all(s[2] == "" for s in seen[:15])
    # Advanced by speed x step along the lane: 0.05 s at the initial speed each step.
    log = result.log
    step_m = np.hypot(np.diff(log.ego_x_m[1:15]), np.diff(log.ego_y_m[1:15]))
    assert step_m == pytest.approx(log.ego_speed_mps.iloc[0] * 0.05, rel=0.02)


def test_the_batch_refuses_an_unknown_sensor_of_a_perception_plugin_in_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--scenario", "crossing", "--episodes", "1",
         "--out", str(out), "--perception", "tests.sim.ad_agents:RadarPerception"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "front_radar" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()
