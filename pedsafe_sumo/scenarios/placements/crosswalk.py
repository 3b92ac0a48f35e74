"""crosswalk (the crossing scenario): the pedestrian crosses on the crosswalk at the stop line against
the red (red-light running by pedestrians, Zhu et al. 2021), stepping out in front of a black vehicle
stopped at the stop line in the kerb lane (the head of a short queue), which hides them from the ego (the
"multiple threat" crosswalk crash). The kerb lane carries the right turn: its head vehicle waits at the
stop line on green, as right-turners do, for the pedestrians on the crosswalk of the road it turns into
(the program gives that crosswalk its walk signal with the approach's green); the queue waits behind it.

Under approach staging (ScenarioSpec.queue_staging "formed", two or more lanes) SUMO forms that queue
before the episode's start: the vehicles drive up the kerb lane and stop at its red (sim/queue.py), the
head where SUMO stops a vehicle at a red stop line (HEAD_BEFORE_STOP_LINE_M before it), each follower
behind it at its drawn gap. Otherwise the head is added standing 0.5 m before the line.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.geometry import Approach, Turn
from pedsafe_sumo.scenarios.placements.base import StagingInputs, StagingPoint
from pedsafe_sumo.scenarios.placements.behind_waiting_vehicle import formed_in_kerb_lane
from pedsafe_sumo.scenarios.placements.midblock import HEAD_BEFORE_STOP_LINE_M, formed_by_sumo
from pedsafe_sumo.scenarios.placements.straight import KerbRow, StraightPlacement
from pedsafe_sumo.scenarios.road_users import OCCLUDER_BLACK_RGB, VEHICLE_CLASSES, VehicleSize

if TYPE_CHECKING:
    # Annotations only: specs.py imports the placement registry to validate a spec's placement.
    from pedsafe_sumo.scenarios.specs import ScenarioSpec


class Crosswalk(StraightPlacement):
    name = "crosswalk"

    def stage_row(self, inputs: StagingInputs, row: KerbRow) -> tuple[tuple, list[VehicleSetup], tuple]:
        path = inputs.approach.crosswalk_path
        # Extend from the crosswalk's kerb end back onto the sidewalk so the pedestrian starts off the road.
        (ax, ay), (bx, by) = path
        ux, uy = (bx - ax) / math.dist(path[0], path[1]), (by - ay) / math.dist(path[0], path[1])
        path = ((ax - ux * 1.0, ay - uy * 1.0), (bx + ux * 1.0, by + uy * 1.0))
        formed = formed_in_kerb_lane(inputs.spec, one_lane=row.one_lane)
        occluder = VehicleSetup(
            "occluder_0",
            row.lane_id,
            row.stop_line_pos_m - (HEAD_BEFORE_STOP_LINE_M if formed else 0.5),
            0.0,
            OCCLUDER_BLACK_RGB,
            VEHICLE_CLASSES[inputs.spec.occluder_class],
        )
        queue = [occluder, *row.queue_behind(occluder, 1)]
        return path, formed_by_sumo(queue) if formed else queue, inputs.clothing_rgb

    def kerb_classes(self, spec: ScenarioSpec) -> list[VehicleSize]:
        return [*VEHICLE_CLASSES.values(), VEHICLE_CLASSES[spec.occluder_class]]

    def kerb_row_m(self, spec: ScenarioSpec, queue_m: float) -> float:
        formed = spec.staging == "approach" and spec.queue_staging == "formed"
        head_m = HEAD_BEFORE_STOP_LINE_M if formed else 0.5
        return head_m + VEHICLE_CLASSES[spec.occluder_class].length_m + queue_m

    def staging_points(self, spec: ScenarioSpec, approach: Approach, turn: Turn | None) -> list[StagingPoint]:
        """Along the crosswalk, from its kerb end to the middle of the approach's farthest lane."""
        lanes = len(approach.lane_ids)
        (ax, ay), (bx, by) = approach.crosswalk_path
        width = math.dist((ax, ay), (bx, by))
        road_m = approach.sidewalk_width_m / 2 + lanes * approach.lane_width_m
        reach = min(1.0, road_m / width) if width else 1.0
        return [
            StagingPoint(
                f"crosswalk {approach.crosswalk_id}, {f * reach:.0%} across",
                (ax + f * reach * (bx - ax), ay + f * reach * (by - ay)),
                start=f == 0.0,
            )
            for f in np.linspace(0.0, 1.0, 5)
        ]
