"""turn (the right_turn and left_turn scenarios): a turning ego and a pedestrian on the crosswalk over
the road it turns into. The pedestrian walks from `ped_start_corner` with the walk signal (the signal
staging gives it), the ego turns on its green and must yield to them; a vehicle turning ahead of the ego
(turn_leader) or one coming the other way (oncoming_vehicle) hides them (docs/engine.md, "Turning
scenarios"). Under approach staging (`TurnPlacement.stage_approach`; docs/engine.md, "The turning
scenarios under approach staging") the pedestrian walks in along the sidewalk that reaches an end of that
crosswalk, and the leader and the oncoming vehicle drive from the start so that they pass where the fixed
staging has them at the same time before the conflict."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import sumolib

from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.sampling.draws import Draws
from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.geometry import (
    Approach,
    Turn,
    lane_pos_to_offset_m,
    load_turn,
    path_pos_m,
    turn_name,
)
from pedsafe_sumo.scenarios.oncoming import (
    OncomingPath,
    lane_position,
    oncoming_signal_problem,
    sight_line_pos_m,
)
from pedsafe_sumo.scenarios.placements.approach import stage_approach
from pedsafe_sumo.scenarios.placements.base import (
    Placement,
    StagedScene,
    StagingInputs,
    StagingPoint,
    first_crossing,
)
from pedsafe_sumo.scenarios.road_users import CAR_COLOURS_RGB, EGO_BLUE_RGB, VEHICLE_CLASSES
from pedsafe_sumo.scenarios.walkways import Walkway, reaching_sidewalk, towards

if TYPE_CHECKING:
    # Annotations only: specs.py imports the placement registry to validate a spec's placement.
    from pedsafe_sumo.scenarios.specs import ScenarioSpec

#: SUMO inserts a vehicle before a minor (yielding) link only if it could stop before it: even with the
#: ego's hard insertion decel (pedsafe_sumo/sim) it refuses fronts within 2 m of the stop line at
#: 2-8.3 m/s (measured on Xueqing's right and left turns); 3 m leaves a margin.
TURN_START_BEFORE_STOP_LINE_M = 3.0


class TurnPlacement(Placement):
    name = "turn"
    turning = True

    def load_turn(self, site: Site, spec: ScenarioSpec, arm: str | None) -> Turn | None:
        return load_turn(site, spec.turn, arm)

    def stage(self, inputs: StagingInputs) -> StagedScene:
        spec, approach, turn, draws = inputs.spec, inputs.approach, inputs.turn, inputs.draws
        if turn is None:
            raise ScenarioError(f"scenario '{spec.name}' needs the geometry of its {spec.turn} turn")
        ego_size = VEHICLE_CLASSES["car"]
        ego_speed_mps = inputs.ego_speed_mps
        # Drawn after the shared draws (and only when there is a leader), so the scenarios without one
        # keep their worlds seed for seed.
        leader_draws = draw_turn_leader(spec, draws) if spec.turn_leader else None
        oncoming_colour = (
            CAR_COLOURS_RGB[draws.index("oncoming_0.colour", len(CAR_COLOURS_RGB))]
            if spec.oncoming_vehicle
            else None
        )
        if spec.staging == "approach":
            return self.stage_approach(inputs, turn, leader_draws, oncoming_colour)
        near, far = turn.crosswalk_path
        start, end = (near, far) if spec.ped_start_corner == "near" else (far, near)
        # From 1 m back on the sidewalk to 1 m beyond the crosswalk's other end.
        length = math.dist(start, end)
        ux, uy = (end[0] - start[0]) / length, (end[1] - start[1]) / length
        path = ((start[0] - ux, start[1] - uy), (end[0] + ux, end[1] + uy))
        conflict_xy = crossing_with_polyline(turn.path_xy, path)
        walk_to_conflict_s = math.dist(path[0], conflict_xy) / inputs.traits["walking_speed_mps"]
        start_delay_s = spec.ped_start_delay_s
        # In SUMO's lane-length metres along the turn, which the ego's speed covers.
        ego_conflict_pos = path_pos_m(turn.lanes, conflict_xy)
        leader = None
        if leader_draws is not None:
            leader, clear_s = turn_leader(spec, turn, ego_conflict_pos, ego_speed_mps, *leader_draws)
            # They wait for it: they step off ped_start_delay_s after its rear has passed their body.
            start_delay_s += clear_s
        arrival_s = start_delay_s + walk_to_conflict_s + inputs.conflict_offset_s
        front_pos = ego_conflict_pos - ego_speed_mps * arrival_s
        # The ego starts on the approach lane with its whole body on it, TURN_START_BEFORE_STOP_LINE_M
        # before the stop line at the latest.
        latest_m = turn.approach_length_m - TURN_START_BEFORE_STOP_LINE_M
        if front_pos > latest_m:
            # The pedestrian would reach the conflict before the ego could come from the stop line: they
            # wait longer on the kerb instead.
            start_delay_s += (front_pos - latest_m) / ego_speed_mps
            front_pos = latest_m
        if front_pos < ego_size.length_m:
            start_delay_s += (ego_size.length_m - front_pos) / ego_speed_mps
            front_pos = ego_size.length_m
        ego = VehicleSetup(
            "ego", approach.lane_ids[turn.lane_index], front_pos, ego_speed_mps, EGO_BLUE_RGB, ego_size
        )
        others = [leader] if leader is not None else []
        if oncoming_colour is not None:
            if inputs.oncoming is None:
                raise ScenarioError(
                    f"scenario '{spec.name}' needs the oncoming through movement of its approach"
                )
            others.append(oncoming_vehicle(spec, turn, ego, path[0], inputs.oncoming, oncoming_colour))
        return StagedScene(
            ego=ego,
            ego_route=turn.route,
            path=path,
            clothing_rgb=inputs.clothing_rgb,
            start_delay_s=start_delay_s,
            parked=tuple(others),
            conflict_xy=conflict_xy,
            conflict_time_s=(ego_conflict_pos - front_pos) / ego_speed_mps,
            ped_crossing_id=turn.crosswalk_id,
            ego_start_distance_m=ego_conflict_pos - front_pos,
        )

    def stage_approach(self, inputs: StagingInputs, turn: Turn, leader_draws, oncoming_colour) -> StagedScene:
        """The scene under approach staging (placements/approach.py, docs/engine.md "Approach staging"):
        the ego starts `ego_start_distance_m` before the conflict point along its turning path; the
        pedestrian walks in along the sidewalk that reaches the kerb end of the crosswalk turned into
        (`approach_kerb_end`), waits, crosses on walk and walks on. The leader and the oncoming vehicle
        drive at the ego's speed from the start, placed so that they pass where the fixed staging has
        them at the same time before the conflict: the leader's rear passes the pedestrian's path (by
        their radius) when they reach the kerb, `ped_start_delay_s` before they step off; the oncoming
        vehicle's centre crosses the line of sight from the ego to them at that moment, which under
        `oncoming_moment` "stop_line" comes no later than when the ego's front is
        TURN_START_BEFORE_STOP_LINE_M before its stop line (`oncoming_kerb_wait_s`)."""
        spec, approach = inputs.spec, inputs.approach
        ego_size = VEHICLE_CLASSES["car"]
        ego_mps = inputs.ego_speed_mps
        ends = approach_kerb_end(spec, turn, approach)
        if ends is None:
            raise ScenarioError(approach_kerb_problem(spec, turn))
        start, end, walkway = ends
        length = math.dist(start, end)
        ux, uy = (end[0] - start[0]) / length, (end[1] - start[1]) / length
        path = ((start[0] - ux, start[1] - uy), (end[0] + ux, end[1] + uy))
        conflict_xy = crossing_with_polyline(turn.path_xy, path)
        conflict_pos = path_pos_m(turn.lanes, conflict_xy)
        walk_to_conflict_s = math.dist(path[0], conflict_xy) / inputs.traits["walking_speed_mps"]
        latest_m = turn.approach_length_m - TURN_START_BEFORE_STOP_LINE_M
        kerb_wait_s = spec.ped_start_delay_s
        if oncoming_colour is not None and spec.oncoming_moment == "stop_line":
            kerb_wait_s = oncoming_kerb_wait_s(spec, inputs, conflict_pos, walk_to_conflict_s, latest_m)
        timing = stage_approach(
            inputs,
            path,
            conflict_pos,
            walk_to_conflict_s,
            # The ego's front on its lane at least TURN_START_BEFORE_STOP_LINE_M before the stop line, its
            # whole body on it.
            (max(conflict_pos - latest_m, 0.0), conflict_pos - ego_size.length_m),
            walkway=Walkway(walkway.lane_id, towards(walkway.shape, start), walkway.width_m),
            kerb_wait_s=kerb_wait_s,
        )
        ego = VehicleSetup(
            "ego", approach.lane_ids[turn.lane_index], timing.front_pos_m, ego_mps, EGO_BLUE_RGB, ego_size
        )
        # When the pedestrian reaches the kerb (the scene the fixed staging starts with): the conflict
        # comes the conflict offset, the walk to it and the wait later.
        lead_s = inputs.conflict_offset_s + walk_to_conflict_s + kerb_wait_s
        at_kerb_s = timing.start_distance_m / ego_mps - lead_s
        others: list[VehicleSetup] = []
        fallbacks = list(timing.fallbacks)
        if leader_draws is not None:
            others.append(approach_leader(spec, turn, ego, conflict_pos, at_kerb_s, leader_draws[0]))
        if oncoming_colour is not None:
            if inputs.oncoming is None:
                raise ScenarioError(
                    f"scenario '{spec.name}' needs the oncoming through movement of its approach"
                )
            # The ego's box centre (the roof LiDAR) when the pedestrian reaches the kerb.
            eye_xy = path_point(turn.lanes, conflict_pos - ego_mps * lead_s - ego_size.length_m / 2)
            oncoming, late = approach_oncoming(
                spec, inputs.oncoming, eye_xy, path[0], ego_mps, at_kerb_s, oncoming_colour
            )
            others.append(oncoming)
            if late:
                fallbacks.append("oncoming_late")
        return StagedScene(
            ego=ego,
            ego_route=turn.route,
            path=timing.path,
            clothing_rgb=inputs.clothing_rgb,
            start_delay_s=timing.start_delay_s,
            parked=tuple(others),
            conflict_xy=conflict_xy,
            conflict_time_s=(conflict_pos - timing.front_pos_m) / ego_mps,
            ped_crossing_id=turn.crosswalk_id,
            ego_start_distance_m=timing.start_distance_m,
            appear_time_s=timing.appear_time_s,
            kerb_index=timing.kerb_index,
            leaves_scene=True,
            approach_fallbacks=tuple(fallbacks),
        )

    def approach_staging_problem(
        self, spec: ScenarioSpec, approach: Approach, turn: Turn | None
    ) -> str | None:
        """Why `spec` cannot be staged under approach staging, or None: a sidewalk must reach a kerb end
        of the crosswalk turned into, and the ego's lane must hold a start `ego_start_min_m` before the
        conflict point there (its whole body on the lane)."""
        if turn is None:
            return f"scenario '{spec.name}' needs the geometry of its {spec.turn} turn"
        ends = approach_kerb_end(spec, turn, approach)
        if ends is None:
            return approach_kerb_problem(spec, turn)
        start, end, _ = ends
        conflict = first_crossing(turn.path_xy, (start, end))
        if conflict is None:
            return (
                f"approach staging: crosswalk {turn.crosswalk_id} does not cross the ego's "
                f"{turn_name(spec.turn, approach.keep_side)}"
            )
        room_m = path_pos_m(turn.lanes, conflict) - VEHICLE_CLASSES["car"].length_m
        if room_m < spec.ego_start_min_m:
            return (
                f"approach staging: lane {approach.lane_ids[turn.lane_index]} holds the ego at most "
                f"{room_m:.1f} m before the conflict point of its "
                f"{turn_name(spec.turn, approach.keep_side)}, less than "
                f"ego_start_min_m {spec.ego_start_min_m:g} m"
            )
        return None

    def staging_points(self, spec: ScenarioSpec, approach: Approach, turn: Turn | None) -> list[StagingPoint]:
        """Along the crosswalk over the road turned into (`turn`, geometry.load_turn), from the end the
        pedestrian starts at."""
        if turn is None:
            raise ScenarioError(f"scenario '{spec.name}' needs the geometry of its {spec.turn} turn")
        near, far = turn.crosswalk_path
        (ax, ay), (bx, by) = (near, far) if spec.ped_start_corner == "near" else (far, near)
        if spec.staging == "approach":
            ends = approach_kerb_end(spec, turn, approach)
            if ends is not None:
                (ax, ay), (bx, by) = ends[0], ends[1]
        return [
            StagingPoint(
                f"crosswalk {turn.crosswalk_id}, {f:.0%} across",
                (ax + f * (bx - ax), ay + f * (by - ay)),
                start=f == 0,
            )
            for f in np.linspace(0.0, 1.0, 5)
        ]

    def staging_problem(
        self, site: Site, spec: ScenarioSpec, approach: Approach, turn: Turn | None, arm: str
    ) -> str | None:
        if getattr(spec, "oncoming_vehicle", 0) and turn is not None:
            return oncoming_signal_problem(site, arm, approach.lane_ids[turn.lane_index], turn.route[-1])
        return None


def oncoming_kerb_wait_s(
    spec: ScenarioSpec,
    inputs: StagingInputs,
    conflict_pos_m: float,
    walk_to_conflict_s: float,
    latest_m: float,
) -> float:
    """How long the pedestrian waits at the kerb under `oncoming_moment` "stop_line": `ped_start_delay_s`,
    or longer when the ego's front would be past `latest_m` (SUMO distance along its path, 3 m before
    its stop line) as they reach the kerb: then they reach it when the ego's front is at `latest_m`, as
    the fixed staging starts them. Further on, a slow ego is too near the oncoming lane, or already past
    it, for a vehicle on it to pass between them (docs/decisions/2026-11-28-left-turn-sight-line-staging.md).
    """
    ego_mps = inputs.ego_speed_mps
    lead_s = inputs.conflict_offset_s + walk_to_conflict_s + spec.ped_start_delay_s
    front_at_kerb_m = conflict_pos_m - ego_mps * lead_s
    return spec.ped_start_delay_s + max(front_at_kerb_m - latest_m, 0.0) / ego_mps


def approach_kerb_end(spec: ScenarioSpec, turn: Turn, approach: Approach):
    """Under approach staging, (the step-off end, the other end, the sidewalk that reaches the step-off
    end) of the crosswalk turned into, or None when no sidewalk reaches either end. A pedestrian who
    crosses that road on walk comes from a sidewalk: from the end `ped_start_corner` names when a sidewalk
    reaches it (walkways.reaching_sidewalk), else from the other end (a median refuge, where the fixed
    staging may start them, is reached only over a crosswalk: on Xueqing right_turn's far end)."""
    near, far = turn.crosswalk_path
    order = [(near, far), (far, near)] if spec.ped_start_corner == "near" else [(far, near), (near, far)]
    for start, end in order:
        walkway = reaching_sidewalk(approach.walkways, start)
        if walkway is not None:
            return start, end, walkway
    return None


def approach_kerb_problem(spec: ScenarioSpec, turn: Turn) -> str:
    return (
        f"approach staging: no sidewalk reaches either end of crosswalk {turn.crosswalk_id}, which the "
        f"pedestrian of '{spec.name}' crosses"
    )


def path_point(lanes, pos_m: float) -> tuple[float, float]:
    """Where SUMO draws SUMO distance `pos_m` along a lane path (geometry.LanePath; clamped to it)."""
    done_m = 0.0
    for shape, length_m in lanes:
        if pos_m <= done_m + length_m or (shape, length_m) == lanes[-1]:
            on_lane_m = min(max(pos_m - done_m, 0.0), length_m)
            x_m, y_m = sumolib.geomhelper.positionAtShapeOffset(
                shape, lane_pos_to_offset_m(shape, length_m, on_lane_m)
            )[:2]
            return float(x_m), float(y_m)
        done_m += length_m
    raise ValueError("empty lane path")


def approach_leader(
    spec: ScenarioSpec, turn: Turn, ego: VehicleSetup, conflict_pos_m: float, at_kerb_s: float, colour
) -> VehicleSetup:
    """Approach staging's vehicle turning ahead of the ego (class `occluder_class`, at the ego's speed, on
    the ego's path): its rear passes the pedestrian's path by their radius (0.3 m) `at_kerb_s`, when they
    reach the kerb, `ped_start_delay_s` before they step off, as in the fixed staging (they step off that
    long after it has passed them). It starts on the ego's lane ahead of it (the ego's start distance is at
    least ego_start_min_m), or, where the timing puts it beyond the junction, on the road turned into;
    its green from when its front reaches the stop line (VehicleSetup.green_from_s)."""
    size = VEHICLE_CLASSES[spec.occluder_class]
    speed_mps = ego.speed_mps
    front_m = conflict_pos_m + 0.3 + size.length_m - speed_mps * at_kerb_s
    if front_m <= turn.approach_length_m:
        return VehicleSetup(
            "leader_0",
            ego.lane_id,
            front_m,
            speed_mps,
            colour,
            size,
            route=turn.route,
            green_from_s=(turn.approach_length_m - front_m) / speed_mps,
        )
    if front_m >= turn.exit_start_m:
        return VehicleSetup(
            "leader_0",
            turn.exit_lane_id,
            front_m - turn.exit_start_m,
            speed_mps,
            colour,
            size,
            route=(turn.route[-1],),
        )
    raise ScenarioError(
        f"scenario '{spec.name}': the vehicle turning ahead of the ego would start on the junction "
        f"({front_m - turn.approach_length_m:.1f} m past the stop line): the ego starts too close"
    )


def approach_oncoming(
    spec: ScenarioSpec, oncoming: OncomingPath, eye_xy, ped_xy, speed_mps: float, at_kerb_s: float, colour
) -> tuple[VehicleSetup, bool]:
    """Approach staging's oncoming through vehicle (class `occluder_class`, at the ego's speed): its centre
    crosses the line of sight from `eye_xy` (the ego's box centre then) to `ped_xy` (the pedestrian at the
    kerb) `at_kerb_s` after the start. It starts on its approach, or on the road before it (through the
    junctions before it: OncomingPath.extended) when its approach is shorter than that run; where that road
    too is shorter, at its start, crossing the line of sight later (True: `oncoming_late`). Its green from
    when its front reaches the stop line (VehicleSetup.green_from_s)."""
    size = VEHICLE_CLASSES[spec.occluder_class]
    path = oncoming.extended()
    crossing_m = sight_line_pos_m(path, eye_xy, ped_xy)
    if crossing_m is None:
        raise ScenarioError(
            f"scenario '{spec.name}': the oncoming path ({oncoming.lanes[0].lane_id} straight on) does not "
            "cross the line of sight from the ego to the pedestrian"
        )
    front_m = crossing_m + size.length_m / 2 - speed_mps * at_kerb_s
    late = front_m < size.length_m
    front_m = max(front_m, size.length_m)
    green_from_s = max(oncoming.stop_line_m() - front_m, 0.0) / speed_mps
    lane_id, pos_m = lane_position(path, front_m)
    edge_id = lane_id.rsplit("_", 1)[0]
    if edge_id in path.route:
        route = path.route[path.route.index(edge_id) :]
        return VehicleSetup(
            "oncoming_0", lane_id, pos_m, speed_mps, colour, size, route=route, green_from_s=green_from_s
        ), late
    # On a junction: inserted at the start of the path (clear of the junction), then moved.
    first = path.lanes[0]
    return VehicleSetup(
        "oncoming_0",
        first.lane_id,
        min(size.length_m + 1.0, first.length_m),
        speed_mps,
        colour,
        size,
        route=path.route,
        internal_lane_id=lane_id,
        internal_pos_m=pos_m,
        green_from_s=green_from_s,
    ), late


def draw_turn_leader(spec: ScenarioSpec, draws: Draws) -> tuple[tuple, float]:
    """The leader's colour and how far its front is onto the road turned into, in that order of draws
    (recorded by name, as every draw of the world)."""
    colour = CAR_COLOURS_RGB[draws.index("leader_0.colour", len(CAR_COLOURS_RGB))]
    front_m = draws.uniform("leader_0.front_m", spec.turn_leader_front_min_m, spec.turn_leader_front_max_m)
    return colour, front_m


def turn_leader(
    spec: ScenarioSpec, turn: Turn, conflict_pos_m: float, speed_mps: float, colour, front_m: float
) -> tuple[VehicleSetup, float]:
    """The vehicle turning ahead of the ego, on the ego's path at the ego's speed with its front `front_m`
    onto the road turned into, and the seconds until its rear has passed the pedestrian's body (0.3 m
    radius; 0 when it already has)."""
    size = VEHICLE_CLASSES[spec.occluder_class]
    rear_before_m = conflict_pos_m - (turn.exit_start_m + front_m - size.length_m)
    leader = VehicleSetup(
        "leader_0", turn.exit_lane_id, front_m, speed_mps, colour, size, route=(turn.route[-1],)
    )
    return leader, max(0.0, rear_before_m + 0.3) / speed_mps


def oncoming_vehicle(
    spec: ScenarioSpec, turn: Turn, ego: VehicleSetup, ped_xy, oncoming: OncomingPath, colour
) -> VehicleSetup:
    """The oncoming through vehicle (class `occluder_class`, at the ego's speed), its centre where its path
    crosses the line of sight from the ego's box centre (where the roof LiDAR is) to the pedestrian at the
    start."""
    size = VEHICLE_CLASSES[spec.occluder_class]
    (shape, length_m) = turn.lanes[0]
    centre_offset_m = lane_pos_to_offset_m(shape, length_m, ego.front_pos_m) - ego.size.length_m / 2
    eye_xy = tuple(sumolib.geomhelper.positionAtShapeOffset(shape, centre_offset_m))
    crossing_m = sight_line_pos_m(oncoming, eye_xy, ped_xy)
    if crossing_m is None:
        raise ScenarioError(
            f"scenario '{spec.name}': the oncoming path ({oncoming.lanes[0].lane_id} straight on) does not "
            "cross the line of sight from the ego to the pedestrian"
        )
    lane_id, pos_m = lane_position(oncoming, crossing_m + size.length_m / 2)
    first, last = oncoming.lanes[0], oncoming.lanes[-1]
    if lane_id == first.lane_id:
        return VehicleSetup("oncoming_0", lane_id, pos_m, ego.speed_mps, colour, size, route=oncoming.route)
    if lane_id == last.lane_id:
        return VehicleSetup(
            "oncoming_0", lane_id, pos_m, ego.speed_mps, colour, size, route=(oncoming.route[1],)
        )
    # On the junction: inserted at the start of its approach lane (clear of the stop line), then moved.
    return VehicleSetup(
        "oncoming_0",
        first.lane_id,
        min(size.length_m + 1.0, first.length_m),
        ego.speed_mps,
        colour,
        size,
        route=oncoming.route,
        internal_lane_id=lane_id,
        internal_pos_m=pos_m,
    )


def crossing_with_polyline(polyline, path) -> tuple[float, float]:
    """First intersection of the pedestrian's straight path with a polyline (the ego's turn path)."""
    crossing = first_crossing(polyline, path)
    if crossing is None:
        raise ScenarioError("the pedestrian's path does not cross the ego's turn")
    return crossing
