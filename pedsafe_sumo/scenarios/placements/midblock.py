"""midblock (the jaywalking scenario): the pedestrian crosses mid-block, 30-45 m before the crosswalk (no
signal: ped_signal none), through the gap between vehicles queued or parked in the kerb lane; the ego
cruises at a stable speed on green."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.geometry import Approach, Turn
from pedsafe_sumo.scenarios.placements.base import StagingInputs, StagingPoint
from pedsafe_sumo.scenarios.placements.straight import KerbRow, StraightPlacement, road_offsets_m
from pedsafe_sumo.scenarios.road_users import VEHICLE_CLASSES

if TYPE_CHECKING:
    # Annotations only: specs.py imports the placement registry to validate a spec's placement.
    from pedsafe_sumo.scenarios.specs import ScenarioSpec


class Midblock(StraightPlacement):
    name = "midblock"

    def stage_row(self, inputs: StagingInputs, row: KerbRow) -> tuple[tuple, list[VehicleSetup], tuple]:
        spec, draws = inputs.spec, inputs.draws
        distance_m = draws.uniform(
            "midblock_distance_m", spec.midblock_distance_min_m, spec.midblock_distance_max_m
        )
        gap_m = draws.uniform("parked_gap_m", spec.parked_gap_min_m, spec.parked_gap_max_m)
        cross_pos = row.stop_line_pos_m - distance_m
        path = inputs.approach.across(row.lane, cross_pos, row.sidewalk_offset_m, row.far_offset_m)
        # Downstream vehicle: its rear gap/2 past the line; upstream: the queue, its head gap/2 before it.
        downstream = row.random_vehicle("occluder_0", 0.0)
        downstream = dataclasses.replace(
            downstream, front_pos_m=cross_pos + gap_m / 2 + downstream.size.length_m
        )
        upstream = row.random_vehicle("occluder_1", cross_pos - gap_m / 2)
        return path, [downstream, upstream, *row.queue_behind(upstream, 2)], inputs.clothing_rgb

    def ped_crossing_id(self, approach: Approach) -> str:
        # Mid-block no signal faces the pedestrian.
        return ""

    def kerb_row_m(self, spec: ScenarioSpec, queue_m: float) -> float:
        longest_m = max(size.length_m for size in VEHICLE_CLASSES.values())
        return spec.midblock_distance_max_m + spec.parked_gap_max_m / 2 + longest_m + queue_m

    def staging_points(self, spec: ScenarioSpec, approach: Approach, turn: Turn | None) -> list[StagingPoint]:
        """Across the road at the nearest and the farthest mid-block distance, from the sidewalk's middle
        over each lane's centre."""
        offsets = road_offsets_m(approach)
        stop_line_m = approach.lane_lengths_m[0]
        points = []
        for distance_m in (spec.midblock_distance_min_m, spec.midblock_distance_max_m):
            line = approach.across(0, stop_line_m - distance_m, offsets[0], offsets[-1])
            for offset_m in offsets:
                start, end = line
                f = (offset_m - offsets[0]) / (offsets[-1] - offsets[0]) if offsets[-1] != offsets[0] else 0.0
                xy = (start[0] + f * (end[0] - start[0]), start[1] + f * (end[1] - start[1]))
                where = f"{distance_m:g} m before the stop line, {offset_m:+.1f} m"
                points.append(StagingPoint(where, xy, start=offset_m == offsets[0]))
        return points
