"""One Euro NCAP cell staged on a site's real approach, as the engine's EpisodeSetup. No random draw.

Frame (SUMO network coordinates, metres): at the point C where the dummy's path meets the centreline of
the ego's lane, u is the lane's direction of travel and n its left normal. The ego is a car of
VEHICLE_CLASSES["car"] (width W) driving the lane at the test speed; its nearside (right, kerb) edge is
at lateral offset -W/2 from C, so impact point p % lies at lateral offset y_p = -W/2 + p/100 W.

- Crossing tests (CPNA nearside, CPFA farside, CPNCO nearside behind parked vehicles): the ego drives
  the median-side lane (the kerb lane is free, or holds CPNCO's parked vehicles); the dummy walks
  perpendicular to the lane through C, from the middle of the kerb-side sidewalk (nearside) or from the
  same distance on the far side (farside). C is on the approach's crosswalk (CPNA, CPFA) or
  `midblock_distance_m` before the stop line (CPNCO).
- Longitudinal test (CPLA): the ego drives the kerb lane; the dummy walks ahead of it in its direction,
  at y_p, and is at C (`midblock_distance_m` before the stop line) at the nominal impact.
- Turning tests (CPTA): the ego turns left (farside) or right (nearside) from the approach lane that has
  the movement; C is where its path crosses the main junction's crosswalk over the exit road, and the
  dummy walks that crosswalk (1 m onto the sidewalks at both ends) in the ego's initial direction
  ("same") or against it ("opposite"), at lateral offset y_p from the ego's path at the impact. A slow
  turn whose run-up would start inside the junction starts on the approach and the dummy later.
Timing: without braking the ego's front reaches the dummy's circle exactly when the dummy's centre is at
y_p (crossing) or at C (longitudinal); the test starts at least `start_ttc_s` before that. The engine
logs from SUMO's insertion step (time dt), when the ego's front is at its depart position and moves
speed x dt per step; a walker with start delay d (on the step grid, >= dt) has walked speed x (t - d).

A robustness variation changes the dummy (its speed, its heading, or where it starts on its path) and
keeps the cell on its collision course: without braking the ego still hits the dummy at the cell's
impact point at the test speed (see the variations block in stage_cell).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import sumolib

from pedsafe_sumo.ncap.protocol import KMH_PER_MPS, Cell, NcapError, Protocol
from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup, PedestrianSetup, VehicleSetup
from pedsafe_sumo.scenarios.geometry import Approach, lane_path_in, offset_to_lane_pos_m, shape_length_m
from pedsafe_sumo.scenarios.road_users import EGO_BLUE_RGB, VEHICLE_CLASSES
from pedsafe_sumo.scenarios.specs import ScenarioSpec
from pedsafe_sumo.sumo_net import read_net

#: How far the ego's front is past first touching the dummy at the nominal impact step [m].
CONTACT_OVERLAP_M = 0.001
#: The ego starts on its approach lane at least this far before the lane's end (the stop line) [m].
EGO_START_BEFORE_STOP_LINE_M = 1.0
#: Every walker in a test is unaware of the ego: the dummy of a test track keeps its speed and path.
DUMMY_RISK = "unaware"


@dataclass(frozen=True)
class StagedCell:
    cell: Cell
    setup: EpisodeSetup
    #: Time of the nominal impact in the engine's clock (SUMO time) [s].
    impact_time_s: float
    #: Distances of the ego's front along its path (SUMO lane-length metres) at the start and at the
    #: nominal impact [m]: the ego covers speed x time of them.
    ego_start_front_m: float
    ego_contact_front_m: float
    #: The ego's direction of travel at the dummy's path (unit vector): the test's frame, in which the
    #: relative impact speed is measured.
    ego_direction: tuple[float, float]


@lru_cache(maxsize=8)
def ego_path(net_file: str, lane_id: str, next_edge_id: str) -> tuple[tuple[tuple, float], ...]:
    """The lanes the ego drives, as (shape, SUMO length) each: its lane, the junction's internal lane(s)
    of the movement to `next_edge_id`, and the lane it reaches there. SUMO moves a vehicle by its speed
    in lane-length metres and draws it on the lane's shape, whose drawn length netconvert may make
    differ (Xueqing's median lane: 181.16 m drawn, 181.63 m long)."""
    net = read_net(net_file, withInternal=True)
    try:
        return lane_path_in(net, net.getLane(lane_id), next_edge_id)
    except ValueError as exc:
        raise NcapError(str(exc)) from None


def _locate(path, line=None, before_end_m: float = 0.0):
    """Where on the ego's path a test happens: (SUMO distance from the path's start, lane-length metres
    per drawn metre there, frame). Either where the path crosses the straight `line` (a crosswalk), or
    `before_end_m` drawn metres before the end of the first lane (the stop line)."""
    done_m = 0.0
    for shape, length in path:
        drawn = _shape_length(shape)
        if line is None:
            offset = drawn - before_end_m
        else:
            try:
                offset = _line_offset(shape, line)
            except NcapError:
                done_m += length
                continue
        return done_m + offset_to_lane_pos_m(shape, length, offset), length / drawn, _frame(shape, offset)
    raise NcapError("the crosswalk does not cross the ego's path")


@lru_cache(maxsize=16)
def turning_movement(net_file: str, approach: Approach, turn: str) -> tuple[int, str, tuple]:
    """(index of the approach lane, exit edge, the exit's crosswalk from end to end) of the farside turn
    (a left turn across the oncoming traffic, in right-hand traffic) or the nearside one (right turn).
    The crosswalk is the main junction's crossing over the exit edge."""
    wanted = {"farside": "l", "nearside": "r"}.get(turn)
    if wanted is None:
        raise NcapError(f"unknown turn '{turn}' (known: farside, nearside)")
    net = read_net(net_file, withInternal=True)
    for index, lane_id in enumerate(approach.lane_ids):
        for connection in net.getLane(lane_id).getOutgoing():
            if connection.getDirection() != wanted:
                continue
            exit_edge = connection.getTo()
            crossings = [
                c
                for c in net.getEdges(withInternal=True)
                if c.getFunction() == "crossing" and exit_edge in c._crossingEdges
            ]
            own = [c for c in crossings if c.getID().startswith(f":{approach.junction_id}_")]
            if own or crossings:
                shape = (own or crossings)[0].getLane(0).getShape()
                return index, exit_edge.getID(), (tuple(shape[0]), tuple(shape[-1]))
    raise NcapError(f"approach {approach.edge_id} has no {turn} turn into a road with a crosswalk")


def _unit(a, b) -> tuple[float, float]:
    length = math.dist(a, b)
    return ((b[0] - a[0]) / length, (b[1] - a[1]) / length)


def _frame(shape, offset_m: float):
    """(x, y), u, n of a polyline at a geometric offset: the point, the direction and its left normal."""

    x, y = sumolib.geomhelper.positionAtShapeOffset(shape, offset_m)
    heading = sumolib.geomhelper.rotationAtShapeOffset(shape, offset_m)
    u = (math.cos(heading), math.sin(heading))
    return (x, y), u, (-u[1], u[0])


def _shape_length(shape) -> float:
    return shape_length_m(shape)


def _line_offset(shape, line) -> float:
    """Geometric offset along `shape` where it crosses the straight line through the two points `line`."""
    (ax, ay), (bx, by) = line
    walked = 0.0
    for (px, py), (qx, qy) in zip(shape[:-1], shape[1:]):
        d1x, d1y, d2x, d2y = bx - ax, by - ay, qx - px, qy - py
        denom = d1x * d2y - d1y * d2x
        if abs(denom) > 1e-12:
            u = ((px - ax) * d1y - (py - ay) * d1x) / denom
            if 0.0 <= u <= 1.0:
                return walked + u * math.hypot(d2x, d2y)
        walked += math.hypot(d2x, d2y)
    raise NcapError("the crosswalk does not cross the ego's path")


def _at(origin, u, n, along_m: float, left_m: float) -> tuple[float, float]:
    return (origin[0] + along_m * u[0] + left_m * n[0], origin[1] + along_m * u[1] + left_m * n[1])


def _on_grid(time_s: float, step_s: float) -> float:
    """time_s rounded up to a whole number of steps (at least one step)."""
    return max(1, math.ceil(time_s / step_s - 1e-9)) * step_s


def spec_for(cell: Cell, roadside_units: tuple[str, ...], time_limit_s: float = 30.0) -> ScenarioSpec:
    """The engine's scenario for a cell: no background traffic; V2I receives the given roadside poles."""
    return ScenarioSpec(
        cell.cell_id,
        f"Euro NCAP {cell.test.name}: {cell.test.description}",
        # The protocol's placements (ncap/protocol.py, PLACEMENTS) are scenario placements of those names.
        placement=cell.test.placement,
        ego_speed_fit="intersection",
        background_traffic=0,
        time_limit_s=time_limit_s,
        roadside_units=",".join(roadside_units),
    )


def stage_cell(
    protocol: Protocol, approach: Approach, net_file: Path | str, cell: Cell, seed: int, step_length_s: float
) -> StagedCell:
    """The EpisodeSetup of one cell on `approach` of the network `net_file` (deterministic: a function of
    the cell and the site).

    The ego's timing is in SUMO's lane-length metres (see ego_path), the dummy's geometry in drawn ones.
    """
    test = cell.test
    dummy = test.dummy
    ego_size = VEHICLE_CLASSES["car"]
    lane_w = approach.lane_width_m
    n_lanes = len(approach.lane_ids)
    v_mps = cell.ego_speed_kmh / KMH_PER_MPS
    walk_mps = test.ped_speed_kmh / KMH_PER_MPS
    radius_m = dummy.radius_m
    y_p = -ego_size.width_m / 2 + cell.impact_point_pct / 100 * ego_size.width_m
    # CPLA: the kerb lane (a pedestrian walking along the road walks at its edge); crossings: the
    # median-side lane, the kerb lane free for CPNCO's parked vehicles.
    ego_lane = 0 if test.approach == "longitudinal" else n_lanes - 1
    ego_route = approach.through_route
    crosswalk = approach.crosswalk_path
    if test.approach == "turning":
        ego_lane, exit_edge, crosswalk = turning_movement(str(net_file), approach, cell.turn)
        ego_route = (approach.edge_id, exit_edge)
    path = ego_path(str(net_file), approach.lane_ids[ego_lane], ego_route[1])
    if test.placement == "crosswalk":
        c_sumo_m, per_drawn_m, (origin, u, n) = _locate(path, line=crosswalk)
    else:
        c_sumo_m, per_drawn_m, (origin, u, n) = _locate(path, before_end_m=protocol.midblock_distance_m)
    impact_xy = _at(origin, u, n, 0.0, y_p)
    parked: list[VehicleSetup] = []
    # How far along the ego's path (drawn metres) the dummy's centre is from C at the impact.
    along_c_m = 0.0

    if test.approach == "turning":
        # The dummy walks the exit's crosswalk, 1 m onto the sidewalk at both ends, in the ego's initial
        # direction ("same") or against it; it is at lateral offset y_p from the ego's path at impact.
        lane_shape = approach.lane_shapes[ego_lane]
        u0 = _unit(lane_shape[-2], lane_shape[-1])
        d = _unit(*crosswalk)
        if (d[0] * u0[0] + d[1] * u0[1] > 0) != (test.direction == "same"):
            d = (-d[0], -d[1])
        first, last = sorted(crosswalk, key=lambda p: p[0] * d[0] + p[1] * d[1])
        start = (first[0] - d[0], first[1] - d[1])
        end = (last[0] + d[0], last[1] + d[1])
        d_n = d[0] * n[0] + d[1] * n[1]
        if abs(d_n) < 0.3:
            raise NcapError(f"{cell.cell_id}: the exit crosswalk runs nearly along the ego's path")
        walk_to_impact_m = (y_p - ((start[0] - origin[0]) * n[0] + (start[1] - origin[1]) * n[1])) / d_n
        if not 0 <= walk_to_impact_m <= math.dist(start, end):
            raise NcapError(f"{cell.cell_id}: the impact point is off the exit crosswalk")
        impact_xy = (start[0] + walk_to_impact_m * d[0], start[1] + walk_to_impact_m * d[1])
        along_c_m = (impact_xy[0] - origin[0]) * u[0] + (impact_xy[1] - origin[1]) * u[1]
        direction = d
        walk_s = _on_grid(walk_to_impact_m / walk_mps, step_length_s)
        delay_s = _on_grid(max(protocol.start_ttc_s - walk_s, step_length_s), step_length_s)
        impact_time_s = delay_s + walk_s
        end_along = math.dist(impact_xy, end)
    elif test.approach == "longitudinal":
        # The dummy walks from the first step; the relative speed closes the gap in start_ttc_s.
        delay_s = step_length_s
        impact_time_s = delay_s + protocol.start_ttc_s
        direction = u
        end_along = walk_mps * protocol.time_after_impact_s
    else:
        # Lateral offsets from C: the middle of the kerb-side sidewalk, and its mirror on the far side.
        kerb_m = -((n_lanes - 1) * lane_w + lane_w / 2 + approach.sidewalk_width_m / 2)
        start_left, end_left = (kerb_m, -kerb_m) if test.approach == "nearside" else (-kerb_m, kerb_m)
        sign = 1.0 if end_left > start_left else -1.0
        direction = (sign * n[0], sign * n[1])
        # The walk to the impact position takes a whole number of steps: the start moves out by less
        # than one step of walking (< 0.12 m at 8 km/h), and the impact falls on a logged step.
        walk_s = _on_grid(abs(y_p - start_left) / walk_mps, step_length_s)
        delay_s = _on_grid(max(protocol.start_ttc_s - walk_s, step_length_s), step_length_s)
        impact_time_s = delay_s + walk_s
        end_along = abs(end_left - y_p)
        if test.obstructed:
            parked = _obstruction(protocol, approach, origin)

    # Robustness variations, still on a collision course: the dummy reaches the nominal impact position
    # at the nominal impact time. Speed: it starts farther or nearer for the same walking time. Start:
    # it starts start_offset_m farther back along its path (to a whole step of walking) and sets off
    # earlier; if that would be before the first step, the whole test starts later. Heading: its path is
    # turned about the impact position.
    ped_speed_mps = walk_mps
    variation = cell.variation
    walk_time_s = impact_time_s - delay_s
    if variation.speed_delta_kmh:
        ped_speed_mps = (test.ped_speed_kmh + variation.speed_delta_kmh) / KMH_PER_MPS
        if ped_speed_mps <= 0:
            raise NcapError(f"{cell.cell_id}: the varied dummy speed is not positive")
    if variation.start_share:  # the start a share of the walk nearer (the calculator's -25 %)
        walk_time_s = _on_grid(walk_time_s * (1 + variation.start_share), step_length_s)
        delay_s = impact_time_s - walk_time_s
    if variation.start_offset_m:
        walk_time_s = _on_grid(walk_time_s + variation.start_offset_m / ped_speed_mps, step_length_s)
        delay_s = impact_time_s - walk_time_s
        if delay_s < step_length_s:
            impact_time_s += step_length_s - delay_s
            delay_s = step_length_s
    start_along = -ped_speed_mps * walk_time_s
    if variation.heading_delta_deg:
        turn = math.radians(variation.heading_delta_deg)
        c, s = math.cos(turn), math.sin(turn)
        direction = (c * direction[0] - s * direction[1], s * direction[0] + c * direction[1])

    # The ego's front touches the dummy's circle at impact_time_s (a logged step; the first is at dt),
    # CONTACT_OVERLAP_M deep so that rounding cannot push the first contact to the step after.
    contact_m = c_sumo_m + (along_c_m - radius_m + CONTACT_OVERLAP_M) * per_drawn_m
    start_m = contact_m - v_mps * (impact_time_s - step_length_s)
    first_lane_m = path[0][1]
    if start_m > first_lane_m - EGO_START_BEFORE_STOP_LINE_M:
        # A slow turn: the ego would start inside the junction. It starts on the approach instead, and
        # the dummy sets off that much later.
        later_s = _on_grid((start_m - first_lane_m + EGO_START_BEFORE_STOP_LINE_M) / v_mps, step_length_s)
        impact_time_s += later_s
        delay_s += later_s
        start_m -= v_mps * later_s
    if start_m < ego_size.length_m:
        raise NcapError(
            f"{cell.cell_id}: the approach is too short for this cell ({start_m:.1f} m of lane before "
            f"the ego's front at the start, {ego_size.length_m} m needed)"
        )
    start_xy = (impact_xy[0] + start_along * direction[0], impact_xy[1] + start_along * direction[1])
    end_xy = (impact_xy[0] + end_along * direction[0], impact_xy[1] + end_along * direction[1])

    pedestrian = PedestrianSetup(
        path_xy=(start_xy, end_xy),
        start_delay_s=delay_s,
        age_years=dummy.age_years,
        gender="m",
        risk=DUMMY_RISK,
        walking_speed_mps=ped_speed_mps,
        clothing_rgb=dummy.clothing_rgb,
        radius_m=radius_m,
        height_m=dummy.height_m,
        avoids_vehicle_bodies=False,  # a dummy on its platform keeps its path into the car
    )
    ego = VehicleSetup("ego", approach.lane_ids[ego_lane], start_m, v_mps, EGO_BLUE_RGB, ego_size)
    setup = EpisodeSetup(
        scenario=cell.cell_id,
        seed=seed,
        ego=ego,
        ego_route=ego_route,
        pedestrian=pedestrian,
        parked=tuple(parked),
        conflict_xy=(float(impact_xy[0]), float(impact_xy[1])),
        conflict_offset_s=0.0,
        time_limit_s=round(impact_time_s + protocol.time_after_impact_s, 6),
    )
    return StagedCell(cell, setup, impact_time_s, start_m, contact_m, u)


def _obstruction(protocol: Protocol, approach: Approach, crossing_xy) -> list[VehicleSetup]:
    """CPNCO's two parked vehicles in the kerb lane, `gap_m` apart around the dummy's path."""
    spec = protocol.obstruction
    kerb_lane_id = approach.lane_ids[0]

    kerb_shape = approach.lane_shapes[0]
    geo_m = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(crossing_xy, kerb_shape)
    pos = offset_to_lane_pos_m(kerb_shape, approach.lane_lengths_m[0], geo_m)
    downstream = VEHICLE_CLASSES[spec["downstream_class"]]
    upstream = VEHICLE_CLASSES[spec["upstream_class"]]
    gap_m = float(spec["gap_m"])
    return [
        VehicleSetup(
            "obstruction_0",
            kerb_lane_id,
            pos + gap_m / 2 + downstream.length_m,
            0.0,
            tuple(spec["downstream_rgb"]),
            downstream,
        ),
        VehicleSetup(
            "obstruction_1", kerb_lane_id, pos - gap_m / 2, 0.0, tuple(spec["upstream_rgb"]), upstream
        ),
    ]
