"""What the placements on a straight-through approach share (crosswalk, midblock,
behind_waiting_vehicle): the kerb lane where the occluders stand, the queue behind them, and the ego's
timing on the lane next to it.

The occluders stand in the kerb lane; the pedestrian crosses from the kerb towards the median, so the
ego drives the lane next to the kerb lane on that side (lanes are listed kerb to median). On a one-lane
approach they stand parked at the kerb beside the lane instead, and the ego drives the lane itself, next
to them (VehicleSetup.kerb_offset_m); the draws are the same.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.geometry import Approach, Turn, path_pos_m, straight_staging_problem
from pedsafe_sumo.scenarios.placements.approach import stage_approach
from pedsafe_sumo.scenarios.placements.base import Placement, StagedScene, StagingInputs, first_crossing
from pedsafe_sumo.scenarios.road_users import (
    CAR_COLOURS_RGB,
    EGO_BLUE_RGB,
    QUEUE_CLASS_WEIGHTS,
    VEHICLE_CLASSES,
    VehicleSize,
)
from pedsafe_sumo.scenarios.upstream import UpstreamRoad, position_on
from pedsafe_sumo.scenarios.walkways import sidewalk_before_m

if TYPE_CHECKING:
    # Annotations only: specs.py imports the placement registry to validate a spec's placement.
    from pedsafe_sumo.scenarios.specs import ScenarioSpec

#: Approach staging: a sidewalk shorter than this upstream of the step-off point leads nowhere (a step;
#: the walk-in is at least walk_in_min_s, 2 s by default: about 3 m).
MIN_WALK_IN_SIDEWALK_M = 1.0


class KerbRow:
    """The kerb lane of one episode: where its occluders stand, and the draws of their classes,
    colours and gaps (each recorded by name, as every draw of the world)."""

    def __init__(self, inputs: StagingInputs) -> None:
        approach = inputs.approach
        self.spec = inputs.spec
        self.draws = inputs.draws
        self.lane = 0
        self.lane_id = approach.lane_ids[self.lane]
        self.one_lane = len(approach.lane_ids) == 1
        self.ego_lane = 0 if self.one_lane else adjacent_lane(self.lane, +1, len(approach.lane_ids))
        self.stop_line_pos_m = approach.lane_lengths_m[self.lane]
        lane_w = approach.lane_width_m
        # Across the road: from the middle of the sidewalk to 1 m beyond the ego lane's far edge.
        self.sidewalk_offset_m = -(lane_w / 2 + approach.sidewalk_width_m / 2)
        self.far_offset_m = (len(approach.lane_ids) - 1) * lane_w + lane_w / 2 + 1.0
        self._class_names = list(QUEUE_CLASS_WEIGHTS)
        self._class_p = np.array([QUEUE_CLASS_WEIGHTS[c] for c in self._class_names])

    def random_vehicle(self, vehicle_id: str, front_pos_m: float, colour=None) -> VehicleSetup:
        """A vehicle of a drawn class (and, unless given, a drawn colour) standing in the kerb lane."""
        draws = self.draws
        size = VEHICLE_CLASSES[self._class_names[draws.choice(f"{vehicle_id}.class", self._class_p)]]
        if colour is None:
            colour = CAR_COLOURS_RGB[draws.index(f"{vehicle_id}.colour", len(CAR_COLOURS_RGB))]
        return VehicleSetup(vehicle_id, self.lane_id, front_pos_m, 0.0, colour, size)

    def queue_behind(self, first: VehicleSetup, start_index: int) -> list[VehicleSetup]:
        """`queue_vehicles` vehicles queued upstream of `first`, bumper to bumper with small gaps."""
        spec = self.spec
        queue = []
        rear = first.front_pos_m - first.size.length_m
        for k in range(int(spec.queue_vehicles)):
            vehicle_id = f"queued_{start_index + k}"
            front = rear - self.draws.uniform(
                f"{vehicle_id}.gap_m", spec.queue_gap_min_m, spec.queue_gap_max_m
            )
            vehicle = self.random_vehicle(vehicle_id, front)
            queue.append(vehicle)
            rear = front - vehicle.size.length_m
        return queue


class StraightPlacement(Placement):
    """A placement on a straight-through approach: the subclass places the pedestrian's path and the
    vehicles in the kerb lane (stage_row); the ego's timing follows here."""

    def stage_row(self, inputs: StagingInputs, row: KerbRow) -> tuple[tuple, list[VehicleSetup], tuple]:
        """(the pedestrian's path, the vehicles in the kerb lane, the pedestrian's clothing)."""
        raise NotImplementedError

    def ped_crossing_id(self, approach: Approach) -> str:
        """The signalised crossing whose signal faces the pedestrian: at the stop line (on the crosswalk
        or just beside it) the crosswalk's; "" where none does."""
        return approach.crosswalk_id

    def kerb_classes(self, spec: ScenarioSpec) -> list[VehicleSize]:
        """The classes of the vehicles that may stand at the kerb (the widest needs room on a
        one-lane approach's sidewalk)."""
        return list(VEHICLE_CLASSES.values())

    def kerb_row_m(self, spec: ScenarioSpec, queue_m: float) -> float:
        """How far before the stop line the row of vehicles at the kerb may reach [m], with `queue_m`
        the longest queue the spec draws."""
        raise NotImplementedError

    def stage(self, inputs: StagingInputs) -> StagedScene:
        approach, spec = inputs.approach, inputs.spec
        row = KerbRow(inputs)
        path, parked, clothing = self.stage_row(inputs, row)
        if row.one_lane:
            parked = [
                dataclasses.replace(v, kerb_offset_m=kerb_parking_offset_m(approach, v.size)) for v in parked
            ]
        ego_size = VEHICLE_CLASSES["car"]
        ego_speed_mps = inputs.ego_speed_mps
        # Where the pedestrian's path meets the centre of the ego's lane, and when they get there.
        conflict_xy = crossing_with_lane(approach, row.ego_lane, path)
        walk_to_conflict_s = math.dist(path[0], conflict_xy) / inputs.traits["walking_speed_mps"]
        start_delay_s = spec.ped_start_delay_s
        ego_conflict_pos = lane_pos_of(approach, row.ego_lane, conflict_xy)
        if spec.staging == "approach":
            return self.stage_approach(inputs, row, path, parked, clothing, conflict_xy, ego_conflict_pos)
        arrival_s = start_delay_s + walk_to_conflict_s + inputs.conflict_offset_s
        front_pos = ego_conflict_pos - ego_speed_mps * arrival_s
        if front_pos < ego_size.length_m:
            # Not enough road behind the conflict point: hold the pedestrian back instead.
            start_delay_s += (ego_size.length_m - front_pos) / ego_speed_mps
            front_pos = ego_size.length_m
        ego = VehicleSetup(
            "ego", approach.lane_ids[row.ego_lane], front_pos, ego_speed_mps, EGO_BLUE_RGB, ego_size
        )
        return StagedScene(
            ego=ego,
            ego_route=approach.through_route,
            path=path,
            clothing_rgb=clothing,
            start_delay_s=start_delay_s,
            parked=tuple(parked),
            conflict_xy=conflict_xy,
            conflict_time_s=(ego_conflict_pos - front_pos) / ego_speed_mps,
            ped_crossing_id=self.ped_crossing_id(approach),
            ego_start_distance_m=ego_conflict_pos - front_pos,
        )

    def stage_approach(
        self, inputs: StagingInputs, row: KerbRow, path, parked, clothing, conflict_xy, conflict_pos_m: float
    ) -> StagedScene:
        """The scene under approach staging (placements/approach.py): the ego starts out of every
        sensor's reach, the pedestrian walks in along the sidewalk, crosses along `path` and walks on."""
        approach = inputs.approach
        ego_size = VEHICLE_CLASSES["car"]
        ego_mps = inputs.ego_speed_mps
        lane_length_m = approach.lane_lengths_m[row.ego_lane]
        upstream = ego_upstream(approach, row.ego_lane)
        timing = stage_approach(
            inputs,
            path,
            conflict_pos_m,
            math.dist(path[0], conflict_xy) / inputs.traits["walking_speed_mps"],
            # The ego's front before the junction, its whole body on the road: the approach lane and the
            # road before it.
            (
                max(conflict_pos_m - lane_length_m, 0.0),
                upstream.length_m + conflict_pos_m - ego_size.length_m,
            ),
        )
        ego, route = ego_start(approach, row.ego_lane, timing.front_pos_m, ego_mps)
        return StagedScene(
            ego=ego,
            ego_route=route,
            path=timing.path,
            clothing_rgb=clothing,
            start_delay_s=timing.start_delay_s,
            parked=tuple(parked),
            conflict_xy=conflict_xy,
            conflict_time_s=(conflict_pos_m - timing.front_pos_m) / ego_mps,
            ped_crossing_id=self.ped_crossing_id(approach),
            ego_start_distance_m=timing.start_distance_m,
            appear_time_s=timing.appear_time_s,
            kerb_index=timing.kerb_index,
            leaves_scene=True,
            approach_fallbacks=timing.fallbacks,
        )

    def staging_problem(
        self, site: Site, spec: ScenarioSpec, approach: Approach, turn: Turn | None, arm: str
    ) -> str | None:
        problem = straight_staging_problem(approach)
        if not problem and len(approach.lane_ids) == 1:
            problem = self.kerb_staging_problem(spec, approach)
        return problem

    def approach_staging_problem(
        self, spec: ScenarioSpec, approach: Approach, turn: Turn | None
    ) -> str | None:
        """Why `spec` cannot be staged under approach staging, or None: the ego's lane must hold a start
        `ego_start_min_m` before the nearest conflict point the placement stages (out of every onboard
        sensor's reach), its whole body on the lane, and a sidewalk must lead to the step-off point."""
        ego_lane = 0 if len(approach.lane_ids) == 1 else 1
        points = self.staging_points(spec, approach, None)
        upstream = ego_upstream(approach, ego_lane)
        room_m = (
            upstream.length_m
            + min(lane_pos_of(approach, ego_lane, p.xy) for p in points)
            - VEHICLE_CLASSES["car"].length_m
        )
        if room_m < spec.ego_start_min_m:
            road = f"lane {approach.lane_ids[ego_lane]}" + (
                f" and the road before it ({', '.join(upstream.edges)}) hold" if upstream.edges else " holds"
            )
            return (
                f"approach staging: {road} the ego at most {room_m:.1f} m before the nearest conflict "
                f"point, less than ego_start_min_m {spec.ego_start_min_m:g} m"
            )
        start = next(p for p in points if p.start)
        if spec.walk_in_max_s > 0 and (
            len(approach.sidewalk_shape) < 2
            or sidewalk_before_m(approach.sidewalk_shape, start.xy) < MIN_WALK_IN_SIDEWALK_M
        ):
            return (
                f"approach staging: no sidewalk of approach {approach.edge_id} leads to where the pedestrian "
                f"steps off ({start.where}) for their walk-in"
            )
        return None

    def kerb_staging_problem(self, spec: ScenarioSpec, approach: Approach) -> str | None:
        """Why `spec` cannot be staged with cars parked at the kerb of a one-lane approach, or None: the
        sidewalk must lie right beside the lane, hold the widest car the scenario draws, and the approach
        must hold the row of parked cars (SUMO inserts each on the lane before it parks: a car whose rear
        would stand before the lane's start cannot be inserted)."""
        widest = max(self.kerb_classes(spec), key=lambda size: size.width_m)
        if not approach.sidewalk_beside_lane:
            return (
                f"approach {approach.edge_id} has one vehicle lane and another lane between it and the "
                "sidewalk: no kerb beside the lane for a parked car to hide the pedestrian"
            )
        if approach.sidewalk_width_m < widest.width_m:
            return (
                f"approach {approach.edge_id} has one vehicle lane and a {approach.sidewalk_width_m:g} m "
                f"sidewalk: no room at the kerb for a parked car {widest.width_m:g} m wide to hide the "
                "pedestrian"
            )
        longest_m = max(size.length_m for size in VEHICLE_CLASSES.values())
        row_m = self.kerb_row_m(spec, spec.queue_vehicles * (spec.queue_gap_max_m + longest_m))
        if row_m > approach.lane_lengths_m[0]:
            return (
                f"approach {approach.edge_id} has one vehicle lane {approach.lane_lengths_m[0]:.1f} m long: "
                f"the cars parked at its kerb may need {row_m:.1f} m before the stop line"
            )
        return None


def ego_upstream(approach: Approach, lane_index: int) -> UpstreamRoad:
    """The road before vehicle lane `lane_index` of the approach (none where it begins at the network's
    edge, at a signalised junction or at a link that yields: upstream.free_through)."""
    return approach.upstream_roads[lane_index] if approach.upstream_roads else UpstreamRoad()


def ego_start(
    approach: Approach, lane_index: int, front_pos_m: float, speed_mps: float
) -> tuple[VehicleSetup, tuple[str, ...]]:
    """The ego at the start and its route, its front `front_pos_m` SUMO metres from the start of vehicle
    lane `lane_index` of the approach; negative: that far before it, on the road before it
    (`ego_upstream`), its route from there. SUMO inserts on edges only: a front on a junction's internal
    lane is inserted at the end of the lane before it and moved there before the first step
    (VehicleSetup.internal_lane_id)."""
    size = VEHICLE_CLASSES["car"]
    lane_id = approach.lane_ids[lane_index]
    if front_pos_m >= 0.0:
        ego = VehicleSetup("ego", lane_id, front_pos_m, speed_mps, EGO_BLUE_RGB, size)
        return ego, approach.through_route
    upstream = ego_upstream(approach, lane_index)
    on_id, on_pos_m = position_on(upstream.lanes, upstream.length_m + front_pos_m)
    internal_id, internal_pos_m = "", 0.0
    if on_id.startswith(":"):
        index = next(k for k, lane in enumerate(upstream.lanes) if lane.lane_id == on_id)
        before = next(lane for lane in reversed(upstream.lanes[:index]) if not lane.lane_id.startswith(":"))
        internal_id, internal_pos_m = on_id, on_pos_m
        on_id, on_pos_m = before.lane_id, before.length_m
    edge_id = on_id.rsplit("_", 1)[0]
    ego = VehicleSetup(
        "ego",
        on_id,
        on_pos_m,
        speed_mps,
        EGO_BLUE_RGB,
        size,
        internal_lane_id=internal_id,
        internal_pos_m=internal_pos_m,
        approach_lane_id=lane_id,
    )
    return ego, (*upstream.edges[upstream.edges.index(edge_id) :], *approach.through_route)


def road_offsets_m(approach: Approach) -> list[float]:
    """Offsets towards the median from the kerb lane's centre (Approach.across) [m]: the sidewalk's
    middle, then each lane's centre."""
    lane_w = approach.lane_width_m
    lanes = len(approach.lane_ids)
    return [-(lane_w / 2 + approach.sidewalk_width_m / 2)] + [k * lane_w for k in range(lanes)]


def kerb_parking_offset_m(approach: Approach, size: VehicleSize) -> float:
    """How far towards the kerb from the centre of a one-lane approach's lane a car parked at the kerb
    stands (its centre) [m]: on the sidewalk, its road-side flank on the kerb line (the lane's kerb-side
    edge).
    Standing in the lane, or across the kerb, it would overlap the ego driving the lane's centre: a 1.8 m
    car in a 3.2 m lane leaves 0.7 m to the kerb line, and every class is wider than that (docs/sites.md)."""
    return approach.lane_width_m / 2 + size.width_m / 2


def adjacent_lane(occluder_lane: int, towards: int, n_lanes: int) -> int:
    """The lane next to `occluder_lane` in the direction the pedestrian crosses (+1: towards the
    median, lanes counted from the kerb), where the ego drives."""
    lane = occluder_lane + towards
    if not 0 <= lane < n_lanes:
        raise ScenarioError(
            f"the approach has {n_lanes} vehicle lane(s): no lane next to lane {occluder_lane} on the side "
            "the pedestrian crosses towards"
        )
    return lane


def extended_shape(approach: Approach, lane_index: int, beyond_m: float = 20.0):
    """The centreline the ego drives from the lane over the crosswalk into the junction: its straight-
    through path as SUMO draws it (the junction's internal lane need not continue the lane straight:
    0.12-0.15 m aside at Xueqing's crosswalk), or the lane continued straight where it has none."""
    lanes = approach.through_paths[lane_index] if approach.through_paths else ()
    if len(lanes) > 1:
        drawn = [tuple(p) for shape, _ in lanes for p in shape]
        return [p for k, p in enumerate(drawn) if k == 0 or math.dist(p, drawn[k - 1]) > 1e-6]
    shape = list(approach.lane_shapes[lane_index])
    (px, py), (qx, qy) = shape[-2], shape[-1]
    norm = math.hypot(qx - px, qy - py)
    shape.append((qx + beyond_m * (qx - px) / norm, qy + beyond_m * (qy - py) / norm))
    return shape


def lane_pos_of(approach: Approach, lane_index: int, xy: tuple[float, float]) -> float:
    """SUMO distance (lane-length metres) from the start of the lane to the point of its straight-through
    path (the lane, the junction, the road beyond) nearest `xy`: where a front placed by it is drawn
    (see scenarios/geometry.py on lane positions)."""
    return path_pos_m(approach.through_paths[lane_index], xy)


def crossing_with_lane(approach: Approach, lane_index: int, path) -> tuple[float, float]:
    """Intersection of the pedestrian's straight path with the centreline of a lane."""
    crossing = first_crossing(extended_shape(approach, lane_index), path)
    if crossing is None:
        raise ValueError("the pedestrian's path does not cross the ego's lane")
    return crossing
