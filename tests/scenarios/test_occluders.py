"""Where the occluders of jaywalking and background blending stand (scenarios/placements/midblock.py,
behind_waiting_vehicle.py), checked on Xueqing with geometry computed here from the network file.

Approach staging: the jaywalking queue starts at the stop line (its head a right-turner waiting there,
where SUMO stops a vehicle at the red: SUMO forms the queue, test_occluders_formed.py) and reaches back
past the mid-block crossing, the jaywalker crossing through the gap nearest the drawn
distance; the blending pedestrian waits on the sidewalk at the kerb and crosses behind the waiting vehicle
at a drawn gap, never touching it. Fixed staging: the positions protocol paper-v7 stages."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.draws import Draws
from pedsafe_sumo.scenarios.geometry import load_approach
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode
from pedsafe_sumo.sim.episode import EpisodeRunner

TRAITS = {"age_years": 35.0, "gender": "f", "risk": "unaware", "walking_speed_mps": 1.4}
SEEDS = range(12)
#: Xueqing's lanes carry no width attribute: netconvert's default, 3.2 m. Its sidewalk: 3.00 m (net file).
LANE_WIDTH_M = 3.2
SIDEWALK_WIDTH_M = 3.0
#: The range a person keeps from the vehicle they cross behind under approach staging (the module's
#: stated assumption, written out here by hand).
KERB_GAP_RANGE_M = (0.3, 1.0)
#: The spec's defaults, written out by hand: queue gaps, the jaywalker's gap, vehicles behind the gap's
#: upstream flank.
QUEUE_GAP_RANGE_M = (1.5, 3.0)
PARKED_GAP_RANGE_M = (1.2, 2.5)
QUEUE_BEHIND_FLANK = 3
PEDESTRIAN_RADIUS_M = 0.3
#: Where SUMO stops a vehicle's front before a red stop line [m]: its junction model's jmStoplineGap, 1 m
#: by default (SUMO's documentation, "Junction Model Parameters").
SUMO_STOPLINE_GAP_M = 1.0


@pytest.fixture(scope="module")
def approach():
    return load_approach(get_site("xueqing"))


@pytest.fixture(scope="module")
def kerb_lane(approach):
    """(drawn shape, SUMO length) of the kerb lane, read from the network file."""
    root = ET.parse(get_site("xueqing").file("net.xml")).getroot()
    lane = next(ln for ln in root.iter("lane") if ln.get("id") == approach.lane_ids[0])
    shape = [tuple(float(c) for c in point.split(",")) for point in lane.get("shape").split()]
    return shape, float(lane.get("length"))


def draw(name, seed, approach, staging):
    spec = get_scenario(name).with_overrides({"staging": staging})
    draws = Draws(np.random.default_rng(seed))
    setup = draw_episode(spec, approach, seed, TRAITS, 8.0, draws)
    return setup, draws.inputs


def crossing_segment(setup):
    """The pedestrian's crossing: from their step-off point to the next point of their path."""
    k = setup.pedestrian.kerb_index
    return setup.pedestrian.path_xy[k], setup.pedestrian.path_xy[k + 1]


# ------------------------------------------------------------------------------ plane geometry
def _closest_on_segment(p, a, b):
    (px, py), (ax, ay), (bx, by) = p, a, b
    dx, dy = bx - ax, by - ay
    norm2 = dx * dx + dy * dy
    t = max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / norm2)) if norm2 else 0.0
    return ax + t * dx, ay + t * dy, t


def distance_to_polyline(p, shape) -> float:
    return min(math.dist(p, _closest_on_segment(p, a, b)[:2]) for a, b in zip(shape[:-1], shape[1:]))


def drawn_offset(p, shape) -> float:
    """Offset along the drawn `shape` of the point nearest `p`."""
    best, done = (math.inf, 0.0), 0.0
    for a, b in zip(shape[:-1], shape[1:]):
        x, y, t = _closest_on_segment(p, a, b)
        if math.dist(p, (x, y)) < best[0]:
            best = (math.dist(p, (x, y)), done + t * math.dist(a, b))
        done += math.dist(a, b)
    return best[1]


def shape_length(shape) -> float:
    return sum(math.dist(a, b) for a, b in zip(shape[:-1], shape[1:]))


def lane_pos(p, kerb_lane) -> float:
    """SUMO lane position (lane-length metres) of the kerb lane's point nearest `p`."""
    shape, length_m = kerb_lane
    return drawn_offset(p, shape) * length_m / shape_length(shape)


def footprint(vehicle, kerb_lane):
    """Corners of a vehicle standing in the kerb lane: its front where SUMO draws its lane position, its
    body its full length back along the heading there (as the engine turns a front into a footprint)."""
    shape, length_m = kerb_lane
    offset_m = vehicle.front_pos_m * shape_length(shape) / length_m
    for a, b in zip(shape[:-1], shape[1:]):
        seg = math.dist(a, b)
        if offset_m <= seg:
            break
        offset_m -= seg
    ux, uy = (b[0] - a[0]) / seg, (b[1] - a[1]) / seg
    fx, fy = a[0] + offset_m * ux, a[1] + offset_m * uy
    rx, ry = fx - vehicle.size.length_m * ux, fy - vehicle.size.length_m * uy
    lx, ly, half = -uy, ux, vehicle.size.width_m / 2
    return [
        (fx + half * lx, fy + half * ly),
        (fx - half * lx, fy - half * ly),
        (rx - half * lx, ry - half * ly),
        (rx + half * lx, ry + half * ly),
    ]


def _crosses(p, q, a, b) -> bool:
    def orient(u, v, w):
        return (v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0])

    return orient(p, q, a) * orient(p, q, b) < 0 and orient(a, b, p) * orient(a, b, q) < 0


def segment_to_polygon_m(p, q, corners) -> float:
    """Distance from segment pq to a convex polygon's boundary (0 if it cuts an edge)."""
    edges = list(zip(corners, corners[1:] + corners[:1]))
    if any(_crosses(p, q, a, b) for a, b in edges):
        return 0.0
    return min(
        *(distance_to_polyline(point, [a, b]) for point in (p, q) for a, b in edges),
        *(distance_to_polyline(corner, [p, q]) for corner in corners),
    )


# ------------------------------------------------------------------------------ approach staging
@pytest.mark.parametrize("seed", SEEDS)
def test_jaywalking_queue_starts_at_the_stop_line_and_the_jaywalker_crosses_through_its_gap(
    seed, approach, kerb_lane
):
    setup, inputs = draw("jaywalking", seed, approach, "approach")
    stop_line_m = kerb_lane[1]
    queue = list(setup.parked)
    assert all(v.lane_id == approach.lane_ids[0] for v in queue)
    assert all(v.speed_mps == 0.0 for v in queue)
    # The head (the right-turner) where SUMO stops a vehicle at a red stop line.
    assert stop_line_m - queue[0].front_pos_m == pytest.approx(SUMO_STOPLINE_GAP_M, abs=1e-9)
    # Bumper to bumper from the head back, in SUMO's lane metres.
    gaps = [a.front_pos_m - a.size.length_m - b.front_pos_m for a, b in zip(queue[:-1], queue[1:])]
    # SUMO forms it: each follower stops its minGap behind the one before it, and that is the staged gap.
    assert all(v.formed for v in queue)
    assert [v.min_gap_m for v in queue[1:]] == pytest.approx(gaps, abs=1e-9)
    # The crossing line meets the kerb lane's centreline inside one gap.
    start, end = crossing_segment(setup)
    cross_m = lane_pos(start, kerb_lane)
    assert lane_pos(end, kerb_lane) == pytest.approx(cross_m, abs=0.01)  # straight across the lane
    inside = [
        k
        for k, (a, b) in enumerate(zip(queue[:-1], queue[1:]))
        if b.front_pos_m < cross_m < a.front_pos_m - a.size.length_m
    ]
    assert len(inside) == 1, f"crossing at {cross_m:.2f} m: gaps {gaps}"
    j = inside[0]
    # ... its middle, and that gap is the drawn one, in the parked-gap range; every other gap a queue gap.
    assert cross_m == pytest.approx(queue[j].front_pos_m - queue[j].size.length_m - gaps[j] / 2, abs=1e-9)
    assert gaps[j] == pytest.approx(inputs["parked_gap_m"], abs=1e-9)
    assert PARKED_GAP_RANGE_M[0] <= gaps[j] <= PARKED_GAP_RANGE_M[1]
    for k, gap in enumerate(gaps):
        if k != j:
            assert QUEUE_GAP_RANGE_M[0] - 1e-9 <= gap <= QUEUE_GAP_RANGE_M[1] + 1e-9, (k, gaps)
    # The gap nearest the drawn line lies within half the longest spacing (a 3.0 m gap and a 5.0 m van).
    assert abs(cross_m - (stop_line_m - inputs["midblock_distance_m"])) <= (3.0 + 5.0) / 2
    # The queue goes on past the crossing: its upstream flank and three more.
    assert len(queue) - (j + 1) == 1 + QUEUE_BEHIND_FLANK
    assert queue[-1].front_pos_m - queue[-1].size.length_m > 0.0
    # They wait on the sidewalk at the kerb, beside the gap.
    kerb_distance_m = distance_to_polyline(start, kerb_lane[0])
    assert LANE_WIDTH_M / 2 < kerb_distance_m < LANE_WIDTH_M / 2 + SIDEWALK_WIDTH_M
    # Their body clears both flanks of the gap all the way across.
    for vehicle in (queue[j], queue[j + 1]):
        clearance_m = segment_to_polygon_m(start, end, footprint(vehicle, kerb_lane)) - PEDESTRIAN_RADIUS_M
        assert clearance_m > 0.0


@pytest.mark.parametrize("seed", SEEDS)
def test_blending_pedestrian_waits_at_the_kerb_and_crosses_behind_the_vehicle_at_the_drawn_gap(
    seed, approach, kerb_lane
):
    setup, inputs = draw("background_blending", seed, approach, "approach")
    (waiting,) = setup.parked
    assert waiting.lane_id == approach.lane_ids[0]
    # It drives up and stops at the red stop line, where SUMO stops it.
    assert waiting.formed
    assert kerb_lane[1] - waiting.front_pos_m == pytest.approx(SUMO_STOPLINE_GAP_M, abs=1e-9)
    gap_m = inputs["blend_gap_m"]
    assert KERB_GAP_RANGE_M[0] <= gap_m <= KERB_GAP_RANGE_M[1]
    start, end = crossing_segment(setup)
    # Off the vehicle lane: on the sidewalk at the kerb.
    kerb_distance_m = distance_to_polyline(start, kerb_lane[0])
    assert LANE_WIDTH_M / 2 < kerb_distance_m < LANE_WIDTH_M / 2 + SIDEWALK_WIDTH_M
    body = footprint(waiting, kerb_lane)
    # Where they wait, their body is more than the drawn gap from the vehicle (beside and behind it) ...
    assert segment_to_polygon_m(start, start, body) - PEDESTRIAN_RADIUS_M > gap_m
    # ... and crossing behind it they pass its rear bumper at the drawn gap, on the road as drawn.
    assert segment_to_polygon_m(start, end, body) - PEDESTRIAN_RADIUS_M == pytest.approx(gap_m, abs=1e-6)
    # Behind it: the crossing line lies upstream of its rear.
    assert lane_pos(start, kerb_lane) < waiting.front_pos_m - waiting.size.length_m
    assert setup.pedestrian.clothing_rgb == waiting.colour_rgb


@pytest.mark.slow
def test_in_sumo_the_blending_pedestrian_steps_off_clear_of_the_waiting_vehicle():
    """SUMO's own position of the waiting vehicle at the step where the pedestrian steps off: their body
    is at least the drawn gap from its body. Prints whether the onboard sensors detect them then (SV),
    under both stagings (`pytest -s -k steps_off_clear`)."""
    runner = EpisodeRunner(get_site("xueqing"), load_params(), ReferenceStack)
    seen = {}
    try:
        for staging in ("fixed", "approach"):
            spec = get_scenario("background_blending").with_overrides({"staging": staging})
            seen[staging] = []
            for seed in range(3):
                waiting_steps = []

                def on_step(api, row, waiting_steps=waiting_steps):
                    if row["ped_state"] == "waiting":
                        angle_deg = api.vehicle.getAngle("waiting_0")
                        waiting_steps.append((row, api.vehicle.getPosition("waiting_0"), angle_deg))

                result = runner.run(spec, "sv", seed, on_step=on_step)
                row, (fx, fy), angle_deg = waiting_steps[-1]  # the step they step off at
                (waiting,) = result.setup.parked
                # SUMO's front bumper and heading (degrees clockwise from north), the body its full
                # length back.
                ux, uy = math.sin(math.radians(angle_deg)), math.cos(math.radians(angle_deg))
                rear = (fx - waiting.size.length_m * ux, fy - waiting.size.length_m * uy)
                lx, ly, half = -uy, ux, waiting.size.width_m / 2
                body = [
                    (fx + half * lx, fy + half * ly),
                    (fx - half * lx, fy - half * ly),
                    (rear[0] - half * lx, rear[1] - half * ly),
                    (rear[0] + half * lx, rear[1] + half * ly),
                ]
                centre = (row["ped_x_m"], row["ped_y_m"])
                gap_m = segment_to_polygon_m(centre, centre, body) - PEDESTRIAN_RADIUS_M
                drawn_m = KERB_GAP_RANGE_M[0] if staging == "approach" else 0.0
                assert gap_m >= drawn_m - 1e-3, (staging, seed, gap_m)
                seen[staging].append((row["detected_onboard_lidar"], row["detected_onboard_camera"]))
    finally:
        runner.close()
    for staging, flags in seen.items():
        print(
            f"{staging}: at step-off the LiDAR detects {sum(bool(li) for li, _ in flags)} of {len(flags)}, "
            f"the camera {sum(bool(ca) for _, ca in flags)}"
        )


def test_a_queue_the_kerb_lane_cannot_hold_is_a_staging_problem(approach):
    site = get_site("xueqing")
    spec = get_scenario("jaywalking").with_overrides({"staging": "approach"})
    placement = placement_of(spec)
    assert placement.staging_problem(site, spec, approach, None, "N") is None
    # 160-170 m out, then the flank and three vehicles behind: more than the 181.6 m lane holds.
    far = spec.with_overrides({"midblock_distance_min_m": 160, "midblock_distance_max_m": 170})
    problem = placement.staging_problem(site, far, approach, None, "N")
    assert problem is not None and "\n" not in problem
    assert "181.6 m" in problem
    # The fixed staging's row from the same distances is not the queue from the stop line.
    fixed = far.with_overrides({"staging": "fixed"})
    assert placement.staging_problem(site, fixed, approach, None, "N") is None


def test_the_hosting_points_start_where_the_pedestrian_waits(approach, kerb_lane):
    for name in ("jaywalking", "background_blending"):
        spec = get_scenario(name).with_overrides({"staging": "approach"})
        starts = [p for p in placement_of(spec).staging_points(spec, approach, None) if p.start]
        assert starts
        for point in starts:
            assert LANE_WIDTH_M / 2 < distance_to_polyline(point.xy, kerb_lane[0]) < LANE_WIDTH_M


# ------------------------------------------------------------------------------ fixed staging
#: The fixed staging's kerb-lane vehicles (id, front lane position) for seeds 0 and 1 at 8 m/s with
#: TRAITS: the positions protocol paper-v7's staging gives these draws.
FIXED_JAYWALKING = {
    0: [
        ("occluder_0", 156.42614010405063),
        ("occluder_1", 150.40465417786353),
        ("queued_2", 142.81040933638755),
        ("queued_3", 135.3078007007059),
        ("queued_4", 127.72169428582454),
    ],
    1: [
        ("occluder_0", 155.28422794984468),
        ("occluder_1", 148.25098366856628),
        ("queued_2", 141.53718496401254),
        ("queued_3", 135.39584629414793),
        ("queued_4", 128.60124871939928),
    ],
}


@pytest.mark.parametrize("seed", [0, 1])
def test_fixed_jaywalking_row_is_unchanged(seed, approach, kerb_lane):
    setup, inputs = draw("jaywalking", seed, approach, "fixed")
    assert [(v.vehicle_id, v.front_pos_m) for v in setup.parked] == FIXED_JAYWALKING[seed]
    # The gap flanks the drawn line, centred on it; the path starts on the sidewalk's middle.
    line_m = kerb_lane[1] - inputs["midblock_distance_m"]
    downstream, upstream = setup.parked[:2]
    assert downstream.front_pos_m - downstream.size.length_m == pytest.approx(
        line_m + inputs["parked_gap_m"] / 2, abs=1e-9
    )
    assert upstream.front_pos_m == pytest.approx(line_m - inputs["parked_gap_m"] / 2, abs=1e-9)
    start = setup.pedestrian.path_xy[0]
    assert distance_to_polyline(start, kerb_lane[0]) == pytest.approx(
        LANE_WIDTH_M / 2 + SIDEWALK_WIDTH_M / 2, abs=0.01
    )


@pytest.mark.parametrize("seed", [0, 1])
def test_fixed_blending_pedestrian_touches_the_rear_in_the_kerb_lane(seed, approach, kerb_lane):
    setup, inputs = draw("background_blending", seed, approach, "fixed")
    (waiting,) = setup.parked
    assert (waiting.vehicle_id, waiting.front_pos_m) == ("waiting_0", 181.13)
    assert inputs["blend_gap_m"] == 0.0
    start = setup.pedestrian.path_xy[0]
    # Centred on the rear, in the kerb lane, the body circle's centre one radius behind the rear in lane
    # metres.
    assert distance_to_polyline(start, kerb_lane[0]) < 0.01
    assert lane_pos(start, kerb_lane) == pytest.approx(
        waiting.front_pos_m - waiting.size.length_m - PEDESTRIAN_RADIUS_M, abs=1e-6
    )
