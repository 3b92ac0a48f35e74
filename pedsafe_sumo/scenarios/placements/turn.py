"""turn (the right_turn and left_turn scenarios): a turning ego and a pedestrian on the crosswalk over
the road it turns into. The pedestrian walks from `ped_start_corner` with the walk signal (the signal
staging gives it), the ego turns on its green and must yield to them; a vehicle turning ahead of the ego
(turn_leader) or one coming the other way (oncoming_vehicle) hides them (docs/engine.md, "Turning
scenarios")."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import sumolib

from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.sampling.draws import Draws
from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.geometry import Approach, Turn, lane_pos_to_offset_m, load_turn, path_pos_m
from pedsafe_sumo.scenarios.oncoming import (
    OncomingPath,
    lane_position,
    oncoming_signal_problem,
    sight_line_pos_m,
)
from pedsafe_sumo.scenarios.placements.base import (
    Placement,
    StagedScene,
    StagingInputs,
    StagingPoint,
    first_crossing,
)
from pedsafe_sumo.scenarios.road_users import CAR_COLOURS_RGB, EGO_BLUE_RGB, VEHICLE_CLASSES

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
        if spec.staging == "approach":
            raise ScenarioError(approach_refusal(spec))
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

    def staging_points(self, spec: ScenarioSpec, approach: Approach, turn: Turn | None) -> list[StagingPoint]:
        """Along the crosswalk over the road turned into (`turn`, geometry.load_turn), from the end the
        pedestrian starts at."""
        if turn is None:
            raise ScenarioError(f"scenario '{spec.name}' needs the geometry of its {spec.turn} turn")
        near, far = turn.crosswalk_path
        (ax, ay), (bx, by) = (near, far) if spec.ped_start_corner == "near" else (far, near)
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
        if spec.staging == "approach":
            return approach_refusal(spec)
        if getattr(spec, "oncoming_vehicle", 0) and turn is not None:
            return oncoming_signal_problem(site, arm, approach.lane_ids[turn.lane_index], turn.route[1])
        return None


def approach_refusal(spec: ScenarioSpec) -> str:
    """Why a turning scenario cannot be staged under approach staging (one line)."""
    return f"scenario '{spec.name}': the turn placement stages the fixed staging only (staging=fixed)"


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
        "leader_0", turn.exit_lane_id, front_m, speed_mps, colour, size, route=(turn.route[1],)
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
