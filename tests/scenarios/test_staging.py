"""The scenario table (scenarios/specs.py): frozen specs and validated overrides; and the episodes drawn
from them (scenarios/staging.py, scenarios/placements/) on the real network, which have the property each
scenario is about (checked with independent geometry)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.geometry import load_approach, load_turn
from pedsafe_sumo.scenarios.oncoming import load_oncoming
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.specs import SCENARIOS, get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode

TRAITS = {"age_years": 35.0, "gender": "f", "risk": "unaware", "walking_speed_mps": 1.4}


@pytest.fixture(scope="module")
def approach():
    return load_approach(get_site("xueqing"))


def draw(name, seed, approach, speed=8.0, traits=TRAITS):
    spec = get_scenario(name)
    turn = placement_of(spec).load_turn(get_site("xueqing"), spec, None)
    # Xueqing's geometry (its program cannot stage left_turn's oncoming vehicle; drawing needs no signals).
    oncoming = load_oncoming(get_site("xueqing")) if spec.oncoming_vehicle else None
    return draw_episode(spec, approach, seed, traits, speed, np.random.default_rng(seed), turn, oncoming)


def _segments_intersect(p, q, a, b):
    def orient(u, v, w):
        return (v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0])

    return orient(p, q, a) * orient(p, q, b) < 0 and orient(a, b, p) * orient(a, b, q) < 0


def _footprint(approach, lane_id, front_pos_m, length_m, width_m):
    """Corners of a vehicle whose front is at `front_pos_m` on a lane (straight over its length)."""
    index = approach.lane_ids.index(lane_id)
    fx, fy, heading = approach.pose(index, front_pos_m)
    ux, uy = math.cos(heading), math.sin(heading)
    lx, ly = -uy, ux
    rx, ry = fx - length_m * ux, fy - length_m * uy
    half = width_m / 2
    return [
        (fx + half * lx, fy + half * ly),
        (fx - half * lx, fy - half * ly),
        (rx - half * lx, ry - half * ly),
        (rx + half * lx, ry + half * ly),
    ]


def test_the_table_holds_the_scenarios_of_the_paper():
    assert sorted(SCENARIOS) == ["background_blending", "crossing", "jaywalking", "left_turn", "right_turn"]
    with pytest.raises(ScenarioError, match="unknown scenario 'parking'"):
        get_scenario("parking")


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"no_such_key": 1}, "unknown scenario parameter 'no_such_key'"),
        ({"time_limit_s": -5}, "time_limit_s > 0"),
        (
            {"conflict_offset_min_s": 3, "conflict_offset_max_s": 1},
            "conflict_offset_min_s <= conflict_offset_max_s",
        ),
        ({"ego_speed_min_mps": "fast"}, "must be a number"),
        ({"midblock_distance_min_m": "nan"}, "must be finite"),
    ],
)
def test_overrides_are_validated(overrides, message):
    with pytest.raises(ScenarioError, match=message):
        get_scenario("jaywalking").with_overrides(overrides)


def test_override_changes_only_that_field():
    spec = get_scenario("jaywalking").with_overrides({"time_limit_s": "12.5"})
    assert spec.time_limit_s == 12.5 and spec.midblock_distance_min_m == 30.0


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_same_seed_same_world_other_seed_other_world(name, approach):
    assert draw(name, 7, approach) == draw(name, 7, approach)
    assert draw(name, 7, approach) != draw(name, 8, approach)


@pytest.mark.parametrize("name", sorted(n for n, s in SCENARIOS.items() if not placement_of(s).turning))
def test_ego_reaches_the_conflict_point_at_the_drawn_offset(name, approach):
    setup = draw(name, 11, approach)
    ped = setup.pedestrian
    walk_s = math.dist(ped.path_xy[0], setup.conflict_xy) / ped.walking_speed_mps
    # Ego front travels (distance to conflict) / speed; SUMO lane positions are of the front.
    index = approach.lane_ids.index(setup.ego.lane_id)
    fx, fy, _ = approach.pose(index, setup.ego.front_pos_m)
    ego_s = math.dist((fx, fy), setup.conflict_xy) / setup.ego.speed_mps
    assert ego_s == pytest.approx(ped.start_delay_s + walk_s + setup.conflict_offset_s, abs=0.05)
    # The path starts at the kerb lane's centre (blending: behind the waiting vehicle) or on its kerb
    # side, at least a lane width from the ego lane's centre.
    kerb_x, kerb_y, _ = approach.pose(0, approach.lane_lengths_m[0] - 5)
    assert math.dist(ped.path_xy[0], setup.conflict_xy) >= approach.lane_width_m - 0.01


@pytest.mark.parametrize("name", ["right_turn", "left_turn"])
def test_turning_ego_reaches_the_crosswalk_conflict_at_the_drawn_offset(name, approach):
    """Along the turn's lanes (walked here segment by segment, each lane's drawn metres scaled to its SUMO
    length, as SUMO moves vehicles), the ego's front reaches the point where the pedestrian's path
    crosses it when the pedestrian does, plus the drawn offset; the point lies on the crosswalk over the
    road turned into, and the ego starts on the approach before the stop line."""
    turn = load_turn(get_site("xueqing"), get_scenario(name).turn)
    for seed in range(5):
        setup = draw(name, seed, approach, speed=5.0)
        ped = setup.pedestrian
        # SUMO distance along the lanes to the conflict point: the lane and segment it lies on.
        cx, cy = setup.conflict_xy
        conflict_along = None
        lanes_before_m = 0.0
        for shape, length_m in turn.lanes:
            path = np.array(shape)
            seg = np.hypot(*np.diff(path, axis=0).T)
            along = np.concatenate([[0.0], np.cumsum(seg)])
            for i in range(len(path) - 1):
                a, b = path[i], path[i + 1]
                t = np.dot((cx - a[0], cy - a[1]), b - a) / seg[i] ** 2
                if -1e-6 <= t <= 1 + 1e-6 and math.dist(a + t * (b - a), (cx, cy)) < 1e-6:
                    conflict_along = lanes_before_m + (along[i] + t * seg[i]) * length_m / along[-1]
                    break
            if conflict_along is not None:
                break
            lanes_before_m += length_m
        else:
            raise AssertionError("the conflict point is not on the turn path")
        ego_s = (conflict_along - setup.ego.front_pos_m) / setup.ego.speed_mps
        walk_s = math.dist(ped.path_xy[0], setup.conflict_xy) / ped.walking_speed_mps
        assert ego_s == pytest.approx(ped.start_delay_s + walk_s + setup.conflict_offset_s, abs=1e-6)
        assert setup.conflict_time_s == pytest.approx(ego_s)
        assert setup.ego_route == turn.route and setup.ped_crossing_id == turn.crosswalk_id
        assert 4.6 <= setup.ego.front_pos_m <= turn.approach_length_m - 3.0
        # The crosswalk's line passes through the conflict point (collinear within a centimetre).
        (ax, ay), (bx, by) = turn.crosswalk_path
        cross = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        assert abs(cross) / math.dist((ax, ay), (bx, by)) < 0.01


def test_jaywalker_crosses_30_to_45_m_before_the_crosswalk_between_parked_vehicles(approach):
    for seed in range(20):
        setup = draw("jaywalking", seed, approach)
        crosswalk_mid = np.mean(approach.crosswalk_path, axis=0)
        assert 30.0 - 3.0 <= math.dist(setup.conflict_xy, crosswalk_mid) <= 45.0 + 3.0
        downstream, upstream = setup.parked[0], setup.parked[1]
        gap_start = upstream.front_pos_m
        gap_end = downstream.front_pos_m - downstream.size.length_m
        crossing_pos = approach.lane_lengths_m[0] - (approach.lane_lengths_m[0] - (gap_start + gap_end) / 2)
        assert gap_start < crossing_pos < gap_end
        assert 1.2 <= gap_end - gap_start <= 2.5


@pytest.mark.parametrize("name", ["crossing", "jaywalking"])
def test_queued_vehicles_hide_the_waiting_pedestrian_from_the_ego(name, approach):
    """When the pedestrian steps off the kerb, the 2D sight line from the ego's front to them crosses a
    queued vehicle's footprint, for every seed where the ego is then within 50 m (further out, where
    the approach bends, the sight line can pass along the kerb side of the queue, as it would in reality)."""
    checked = 0
    for seed in range(30):
        setup = draw(name, seed, approach)
        ego_index = approach.lane_ids.index(setup.ego.lane_id)
        ego_front = setup.ego.front_pos_m + setup.ego.speed_mps * setup.pedestrian.start_delay_s
        camera = approach.pose(ego_index, ego_front)[:2]
        start = setup.pedestrian.path_xy[0]
        if math.dist(camera, start) > 50.0:
            continue
        checked += 1
        hidden = False
        for vehicle in setup.parked:
            corners = _footprint(
                approach, vehicle.lane_id, vehicle.front_pos_m, vehicle.size.length_m, vehicle.size.width_m
            )
            edges = list(zip(corners, corners[1:] + corners[:1]))
            hidden |= any(_segments_intersect(camera, start, a, b) for a, b in edges)
        assert hidden, f"seed {seed}: the pedestrian's start is in plain view of the ego"
    assert checked >= 10


def test_blending_pedestrian_passes_within_the_lidar_cluster_tolerance_of_the_vehicle_rear(approach):
    for seed in range(20):
        setup = draw("background_blending", seed, approach)
        waiting = setup.parked[0]
        rear_pos = waiting.front_pos_m - waiting.size.length_m
        rear_x, rear_y, _ = approach.pose(0, rear_pos)
        (ax, ay), (bx, by) = setup.pedestrian.path_xy
        # Distance from the rear-centre point to the path line, minus the pedestrian's radius.
        dist_to_line = abs((bx - ax) * (ay - rear_y) - (ax - rear_x) * (by - ay)) / math.dist(
            (ax, ay), (bx, by)
        )
        gap = dist_to_line - setup.pedestrian.radius_m
        spec = get_scenario("background_blending")
        # The gap is laid out in lane metres, which the kerb lane draws 0.005 % longer (181.64 m drawn,
        # 181.63 m long): 0.3 m of them are 0.30002 m drawn.
        assert spec.blend_gap_min_m - 1e-4 <= gap <= spec.blend_gap_max_m + 1e-4
        assert setup.pedestrian.clothing_rgb == waiting.colour_rgb
        # They start centred on the vehicle's rear (on the kerb lane's centreline), facing the median.
        assert math.dist(setup.pedestrian.path_xy[0], (rear_x, rear_y)) == pytest.approx(
            setup.pedestrian.radius_m + gap, abs=1e-4
        )


def test_blending_pedestrian_starts_in_front_of_the_vehicle_rear_as_seen_from_the_ego(approach):
    """The sight line from the ego's front to the pedestrian's start, continued 1 m past them, ends
    inside the waiting vehicle's footprint: its rear is what stands behind them in the image."""
    for seed in range(20):
        setup = draw("background_blending", seed, approach)
        waiting = setup.parked[0]
        corners = _footprint(
            approach, waiting.lane_id, waiting.front_pos_m, waiting.size.length_m, waiting.size.width_m
        )
        ego_index = approach.lane_ids.index(setup.ego.lane_id)
        camera = approach.pose(ego_index, setup.ego.front_pos_m)[:2]
        start = setup.pedestrian.path_xy[0]
        d = math.dist(camera, start)
        beyond = (start[0] + (start[0] - camera[0]) / d * 1.0, start[1] + (start[1] - camera[1]) / d * 1.0)
        edges = list(zip(corners, corners[1:] + corners[:1]))
        assert any(_segments_intersect(start, beyond, a, b) for a, b in edges), f"seed {seed}"


def _inside(point, corners):
    """Point in a convex polygon given counter- or clockwise."""
    signs = []
    for (ax, ay), (bx, by) in zip(corners, corners[1:] + corners[:1]):
        signs.append((bx - ax) * (point[1] - ay) - (by - ay) * (point[0] - ax) > 0)
    return all(signs) or not any(signs)


def _hidden_share(pole_xyz, ped_xy, ped_height_m, corners, vehicle_height_m):
    """Share of sight lines from the pole to points up the pedestrian's axis (10-90% of their height)
    that pass through the vehicle's box, sampled every 2 cm."""
    hidden = 0
    heights = [f * ped_height_m for f in (0.1, 0.26, 0.42, 0.58, 0.74, 0.9)]
    for z in heights:
        n = int(math.dist(pole_xyz[:2], ped_xy) / 0.02)
        for i in range(1, n):
            t = i / n
            x = pole_xyz[0] + t * (ped_xy[0] - pole_xyz[0])
            y = pole_xyz[1] + t * (ped_xy[1] - pole_xyz[1])
            if pole_xyz[2] + t * (z - pole_xyz[2]) < vehicle_height_m and _inside((x, y), corners):
                hidden += 1
                break
    return hidden / len(heights)


def test_blending_pedestrian_walking_out_is_hidden_from_the_corner_pole_not_from_the_far_pole(approach):
    """Why background blending has a second pole: while the pedestrian walks out behind the waiting
    vehicle (the first 1.5 m of their path, every 0.25 m), the vehicle stands between the corner pole
    and them; from the far-side pole no sight line to them crosses it. Poles from the built site
    (site.json), geometry by hand."""
    import json

    info = json.loads(get_site("xueqing").file("site.json").read_text())
    poles = {u["id"]: (u["x"], u["y"], u["height_m"]) for u in info["roadside_units"]}
    assert get_scenario("background_blending").roadside_unit_ids == ("rsu_camera_0", "rsu_camera_1")
    assert (
        get_scenario("crossing").roadside_unit_ids
        == get_scenario("jaywalking").roadside_unit_ids
        == ("rsu_camera_0",)
    )
    corner_hidden, far_hidden = [], []
    for seed in range(20):
        setup = draw("background_blending", seed, approach)
        waiting = setup.parked[0]
        corners = _footprint(
            approach, waiting.lane_id, waiting.front_pos_m, waiting.size.length_m, waiting.size.width_m
        )
        (ax, ay), (bx, by) = setup.pedestrian.path_xy
        length = math.dist((ax, ay), (bx, by))
        for walked_m in np.arange(0.0, 1.51, 0.25):
            at = (ax + (bx - ax) * walked_m / length, ay + (by - ay) * walked_m / length)
            args = (at, setup.pedestrian.height_m, corners, waiting.size.height_m)
            corner_hidden.append(_hidden_share(poles["rsu_camera_0"], *args))
            far_hidden.append(_hidden_share(poles["rsu_camera_1"], *args))
    assert np.mean(corner_hidden) >= 0.5, np.mean(corner_hidden)
    assert max(far_hidden) == 0.0, far_hidden
