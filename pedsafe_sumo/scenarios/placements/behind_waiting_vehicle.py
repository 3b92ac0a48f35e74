"""behind_waiting_vehicle (the background_blending scenario): a vehicle waits at the stop line in the kerb
lane (a right-turner yielding to the pedestrians on the crosswalk of the road it turns into, as in
crossing), the pedestrian, dressed in its colour, crosses behind it towards the median beside the
crosswalk while it shows red, so that seen from the ego the vehicle is right behind them.

Fixed staging: they stand in the kerb lane right behind its rear bumper, centred on it, closer to it
than the LiDAR can separate (`blend_gap_min_m`..`max_m`, 0 by default: the body circle touches it).

Approach staging (spec.staging "approach"). What a traffic engineer sees: the approach has green; in the
kerb lane a right-turner stands at the stop line, waiting for the pedestrians on the crosswalk it turns
across (its permissive green yields to that crosswalk's walk signal, shown in the same green), while the
approach's own crosswalk shows red to pedestrians. A pedestrian who means to cross anyway waits where
people wait, on the sidewalk at the kerb beside the vehicle's rear, and steps off to cross behind it, the
vehicle shielding them from the kerb lane, keeping a gap a person keeps from a vehicle body
(`kerb_gap_min_m`..`kerb_gap_max_m` between their body circle and the rear bumper's line). Staged: the
vehicle drove up the kerb lane before the episode's start and stopped at the red stop line, where SUMO
stops (VehicleSetup.formed, sim/queue.py: HEAD_BEFORE_STOP_LINE_M before it), and the gap is measured
from there. On a one-lane approach the vehicle stands parked at the kerb (the ego drives the only lane)
and they start on the sidewalk behind it, centred on its rear, at the same gap.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.geometry import Approach, Turn, lane_pos_to_offset_m, offset_to_lane_pos_m
from pedsafe_sumo.scenarios.placements.base import StagingInputs, StagingPoint
from pedsafe_sumo.scenarios.placements.midblock import (
    HEAD_BEFORE_STOP_LINE_M,
    formed_by_sumo,
    kerb_wait_offset_m,
    queue_formed_by_sumo,
)
from pedsafe_sumo.scenarios.placements.straight import (
    KerbRow,
    StraightPlacement,
    kerb_parking_offset_m,
    road_offsets_m,
)
from pedsafe_sumo.scenarios.road_users import PEDESTRIAN_RADIUS_M, VEHICLE_CLASSES, VehicleSize

if TYPE_CHECKING:
    # Annotations only: specs.py imports the placement registry to validate a spec's placement.
    from pedsafe_sumo.scenarios.specs import ScenarioSpec


#: The fixed staging, and a one-lane approach's car parked at the kerb: the waiting vehicle's front stands
#: this far before the stop line [m], as the crossing scenario's occluder (placements/crosswalk.py).
FIXED_BEFORE_STOP_LINE_M = 0.5


def head_before_stop_line_m(spec: ScenarioSpec, row: KerbRow) -> float:
    """How far before the stop line the waiting vehicle's front stands [m]: under approach staging in a
    kerb lane where SUMO stops it at the red (HEAD_BEFORE_STOP_LINE_M), else where the staging puts it."""
    if formed_in_kerb_lane(spec, one_lane=row.one_lane):
        return HEAD_BEFORE_STOP_LINE_M
    return FIXED_BEFORE_STOP_LINE_M


def formed_in_kerb_lane(spec: ScenarioSpec, one_lane: bool) -> bool:
    """Whether SUMO forms the waiting vehicle (approach staging, a kerb lane beside the ego's,
    ScenarioSpec.queue_staging "formed")."""
    return spec.staging == "approach" and not one_lane and queue_formed_by_sumo(spec)


class BehindWaitingVehicle(StraightPlacement):
    name = "behind_waiting_vehicle"

    def stage_row(self, inputs: StagingInputs, row: KerbRow) -> tuple[tuple, list[VehicleSetup], tuple]:
        spec = inputs.spec
        approach_staging = spec.staging == "approach"
        low_m, high_m = (
            (spec.kerb_gap_min_m, spec.kerb_gap_max_m)
            if approach_staging
            else (spec.blend_gap_min_m, spec.blend_gap_max_m)
        )
        gap_m = inputs.draws.uniform("blend_gap_m", low_m, high_m)
        formed = formed_in_kerb_lane(spec, one_lane=row.one_lane)
        waiting = row.random_vehicle("waiting_0", row.stop_line_pos_m - head_before_stop_line_m(spec, row))
        if spec.waiting_vehicle_class:
            waiting = dataclasses.replace(waiting, size=VEHICLE_CLASSES[spec.waiting_vehicle_class])
        if formed:
            # It drove up the kerb lane and stopped at the red stop line (sim/queue.py), where SUMO stops.
            (waiting,) = formed_by_sumo([waiting])
        cross_pos = waiting.front_pos_m - waiting.size.length_m - gap_m - PEDESTRIAN_RADIUS_M
        if approach_staging:
            # The gap as drawn on the road (the sensors' and the body rule's metres, the vehicle's body
            # its full length back from where SUMO draws its front), not in lane-length metres: on a lane
            # drawn shorter than its length it would come out up to a few centimetres short.
            shape, length_m = inputs.approach.lane_shapes[row.lane], inputs.approach.lane_lengths_m[row.lane]
            front_offset_m = lane_pos_to_offset_m(shape, length_m, waiting.front_pos_m)
            behind_m = waiting.size.length_m + gap_m + PEDESTRIAN_RADIUS_M
            cross_pos = offset_to_lane_pos_m(shape, length_m, front_offset_m - behind_m)
        # Fixed staging: they already stand right behind the vehicle, centred on its rear: seen from the
        # ego behind them, the vehicle's rear surrounds them on both sides from the first frame. (On its
        # kerb-side half the LiDAR finds the vehicle's returns on one side only and separates them at
        # the start in 3 of 30 episodes even at gap 0; from the sidewalk both onboard sensors see them
        # before they blend.)
        start_offset_m = 0.0
        if approach_staging:
            # On the sidewalk at the kerb, beside the vehicle's rear.
            start_offset_m = kerb_wait_offset_m(inputs.approach)
        if row.one_lane:
            # Behind the car parked at the kerb, centred on its rear as in the kerb lane.
            start_offset_m = -kerb_parking_offset_m(inputs.approach, waiting.size)
        path = inputs.approach.across(row.lane, cross_pos, start_offset_m, row.far_offset_m)
        # Dressed in the colour of the vehicle they stand behind.
        return path, [waiting], waiting.colour_rgb

    def kerb_classes(self, spec: ScenarioSpec) -> list[VehicleSize]:
        if spec.waiting_vehicle_class:
            return [VEHICLE_CLASSES[spec.waiting_vehicle_class]]
        return list(VEHICLE_CLASSES.values())

    def kerb_row_m(self, spec: ScenarioSpec, queue_m: float) -> float:
        # One vehicle at the stop line: no queue behind it. (A one-lane approach: parked at the kerb.)
        return FIXED_BEFORE_STOP_LINE_M + max(size.length_m for size in self.kerb_classes(spec))

    def staging_points(self, spec: ScenarioSpec, approach: Approach, turn: Turn | None) -> list[StagingPoint]:
        """Behind a car waiting at the stop line (a car's length, the gap and the body before it), then
        over each lane's centre; under approach staging from the kerb beside its rear."""
        offsets = road_offsets_m(approach)
        stop_line_m = approach.lane_lengths_m[0]
        gap_max_m = spec.kerb_gap_max_m if spec.staging == "approach" else spec.blend_gap_max_m
        before_m = (
            HEAD_BEFORE_STOP_LINE_M
            if formed_in_kerb_lane(spec, one_lane=len(approach.lane_ids) == 1)
            else FIXED_BEFORE_STOP_LINE_M
        )
        behind_m = before_m + VEHICLE_CLASSES["car"].length_m + gap_max_m + PEDESTRIAN_RADIUS_M
        if len(approach.lane_ids) == 1:
            # The car stands parked at the kerb beside the one lane (kerb_parking_offset_m): the
            # pedestrian starts behind it, then crosses the lane.
            offsets = [0.0, -kerb_parking_offset_m(approach, VEHICLE_CLASSES["car"]), 0.0]
        elif spec.staging == "approach":
            offsets = [0.0, kerb_wait_offset_m(approach), *offsets[1:]]
        return [
            StagingPoint(
                f"{behind_m:.1f} m before the stop line, {offset_m:+.1f} m",
                approach.across(0, stop_line_m - behind_m, offset_m, offset_m)[0],
                start=offset_m == offsets[1],
            )
            for offset_m in offsets[1:]
        ]
