"""midblock (the jaywalking scenario): the pedestrian crosses mid-block, 30-45 m before the crosswalk (no
signal: ped_signal none), through the gap between vehicles queued or parked in the kerb lane; the ego
cruises at a stable speed on green.

Fixed staging: two vehicles flank the gap at the drawn distance, the queue of `queue_vehicles` behind
them, the kerb lane empty ahead of them.

Approach staging (spec.staging "approach"), on an approach with two or more lanes. What a traffic
engineer sees: the approach's green has just begun, the median lane's queue has driven off and the ego
comes down it, but the kerb lane stands still: its first vehicle, a right-turner, waits at the stop line
for the pedestrians walking the crosswalk it turns across (the program gives that crosswalk its walk
signal with the approach's green, and the right turn is a permissive green that yields to it), and the
queue that built up behind it during the red cannot get past it. A pedestrian who wants to cross the
block walks up the sidewalk, stops at the kerb beside a gap in the standing queue and steps through it.

Staged: the queue from the stop line back, bumper to bumper (gaps `queue_gap_min_m`..`max_m`), past the
mid-block crossing. Of its gaps, the one whose centre lies nearest the drawn mid-block distance is the
jaywalker's (drawn `parked_gap_min_m`..`max_m`): how many vehicles stand before it follows from the
distance; the upstream flank and `queue_vehicles` more stand behind it, as in the fixed staging. SUMO forms
it (VehicleSetup.formed, sim/queue.py): the vehicles drive up the kerb lane before the episode's start and
stop at the red stop line (the head, HEAD_BEFORE_STOP_LINE_M before it, where SUMO stops) and each behind
the one before it at its drawn gap (its SUMO minGap); a queue that does not stand where it was staged is
refused. The pedestrian waits at the kerb beside the gap and crosses through it. On a one-lane approach the
ego drives the only lane, so nothing queues beside it: the vehicles stand parked at the kerb, as in the
fixed staging.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.geometry import Approach, Turn
from pedsafe_sumo.scenarios.placements.base import StagingInputs, StagingPoint
from pedsafe_sumo.scenarios.placements.straight import KerbRow, StraightPlacement, road_offsets_m
from pedsafe_sumo.scenarios.road_users import PEDESTRIAN_RADIUS_M, VEHICLE_CLASSES

if TYPE_CHECKING:
    # Annotations only: specs.py imports the placement registry to validate a spec's placement.
    from pedsafe_sumo.scenarios.specs import ScenarioSpec

#: Approach staging: the queue's head vehicle (the right-turner) stands with its front this far before
#: the stop line [m]: where SUMO stops a vehicle at a red light (its junction model's `jmStoplineGap`,
#: 1 m by default; measured on Xueqing's kerb lane: 1.001 m), as SUMO forms the queue (sim/queue.py).
HEAD_BEFORE_STOP_LINE_M = 1.0
#: ScenarioSpec.queue_staging "placed": the head is added standing this far before the stop line [m], as
#: the crossing scenario's occluder (placements/crosswalk.py).
PLACED_HEAD_BEFORE_STOP_LINE_M = 0.5
#: SUMO's minGap of the head of a formed queue [m]: unused at the red (the stop line gap applies), the
#: staged vehicles' usual 0.5 m.
HEAD_MIN_GAP_M = 0.5


def formed_by_sumo(queue: list[VehicleSetup]) -> list[VehicleSetup]:
    """`queue` (its head first, standing bumper to bumper as staged) marked for SUMO to form before the
    episode's start (VehicleSetup.formed, sim/queue.py): each follower's minGap is its staged gap to the
    rear of the vehicle before it, so that SUMO's car-following stops it there."""
    formed = [dataclasses.replace(queue[0], formed=True, min_gap_m=HEAD_MIN_GAP_M)]
    for leader, follower in zip(queue[:-1], queue[1:]):
        gap_m = leader.front_pos_m - leader.size.length_m - follower.front_pos_m
        formed.append(dataclasses.replace(follower, formed=True, min_gap_m=gap_m))
    return formed


def kerb_wait_offset_m(approach: Approach) -> float:
    """Where a pedestrian waiting at the kerb stands, towards the median from the kerb lane's centre
    (Approach.across) [m]: on the sidewalk, their body circle touching the kerb line (the lane's kerb-side
    edge) from the sidewalk side."""
    return -(approach.lane_width_m / 2 + PEDESTRIAN_RADIUS_M)


def queue_formed_by_sumo(spec: ScenarioSpec) -> bool:
    """Whether SUMO forms the approach staging's kerb-lane vehicles (ScenarioSpec.queue_staging)."""
    return spec.queue_staging == "formed"


def head_before_stop_line_m(spec: ScenarioSpec) -> float:
    """How far before the stop line the kerb lane's first vehicle stands under approach staging [m]."""
    return HEAD_BEFORE_STOP_LINE_M if queue_formed_by_sumo(spec) else PLACED_HEAD_BEFORE_STOP_LINE_M


def queued_from_stop_line(spec: ScenarioSpec, approach: Approach) -> bool:
    """Whether the kerb-lane vehicles queue from the stop line (approach staging, two or more lanes)."""
    return spec.staging == "approach" and len(approach.lane_ids) > 1


def crossing_reach_m(spec: ScenarioSpec) -> tuple[float, float]:
    """(nearest, farthest) distance before the stop line of the queue gap the jaywalker crosses through,
    when the queue starts at the stop line [m]: the gap nearest the drawn distance lies within half a
    spacing (a queue gap and a vehicle) of it, and the first gap lies behind the head vehicle."""
    shortest_m = min(size.length_m for size in VEHICLE_CLASSES.values())
    longest_m = max(size.length_m for size in VEHICLE_CLASSES.values())
    half_spacing_m = (spec.queue_gap_max_m + longest_m) / 2
    first_gap_m = head_before_stop_line_m(spec) + shortest_m + spec.parked_gap_min_m / 2
    return (
        max(spec.midblock_distance_min_m - half_spacing_m, first_gap_m),
        max(spec.midblock_distance_max_m + half_spacing_m, first_gap_m),
    )


class Midblock(StraightPlacement):
    name = "midblock"

    def stage_row(self, inputs: StagingInputs, row: KerbRow) -> tuple[tuple, list[VehicleSetup], tuple]:
        if queued_from_stop_line(inputs.spec, inputs.approach):
            return self.queue_from_stop_line(inputs, row)
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

    def queue_from_stop_line(
        self, inputs: StagingInputs, row: KerbRow
    ) -> tuple[tuple, list[VehicleSetup], tuple]:
        """The kerb lane's queue from the stop line back past the crossing, and the pedestrian's path
        through its gap nearest the drawn distance (module docstring). Draws: the distance and the gap
        (as in the fixed staging), then vehicle by vehicle from the head its gap ahead, class and colour
        (`queued_<k>`, k from 0 at the head)."""
        spec, draws = inputs.spec, inputs.draws
        distance_m = draws.uniform(
            "midblock_distance_m", spec.midblock_distance_min_m, spec.midblock_distance_max_m
        )
        gap_m = draws.uniform("parked_gap_m", spec.parked_gap_min_m, spec.parked_gap_max_m)
        line_pos_m = row.stop_line_pos_m - distance_m
        queue = [row.random_vehicle("queued_0", row.stop_line_pos_m - head_before_stop_line_m(spec))]
        while True:
            rear_m = queue[-1].front_pos_m - queue[-1].size.length_m
            # The crossing line if the gap opens behind the last vehicle, and if it opens behind the next.
            here_m = rear_m - gap_m / 2
            follower_id = f"queued_{len(queue)}"
            queue_gap_m = draws.uniform(f"{follower_id}.gap_m", spec.queue_gap_min_m, spec.queue_gap_max_m)
            follower = row.random_vehicle(follower_id, rear_m - queue_gap_m)
            next_m = rear_m - queue_gap_m - follower.size.length_m - gap_m / 2
            if abs(here_m - line_pos_m) <= abs(next_m - line_pos_m):
                # The crossing lines behind the queue come further from the drawn one: the gap opens
                # here, and the follower (its drawn queue gap unused) stands behind it.
                queue.append(dataclasses.replace(follower, front_pos_m=rear_m - gap_m))
                cross_pos = here_m
                break
            queue.append(follower)
        queue += row.queue_behind(queue[-1], len(queue))
        last = queue[-1]
        if last.front_pos_m - last.size.length_m < 0:
            raise ScenarioError(
                f"the kerb lane {row.lane_id} ({row.stop_line_pos_m:.1f} m) does not hold the queue from its "
                f"stop line past the mid-block crossing {distance_m:.1f} m before it"
            )
        path = inputs.approach.across(
            row.lane, cross_pos, kerb_wait_offset_m(inputs.approach), row.far_offset_m
        )
        return path, formed_by_sumo(queue) if queue_formed_by_sumo(spec) else queue, inputs.clothing_rgb

    def ped_crossing_id(self, approach: Approach) -> str:
        # Mid-block no signal faces the pedestrian.
        return ""

    def kerb_row_m(self, spec: ScenarioSpec, queue_m: float) -> float:
        longest_m = max(size.length_m for size in VEHICLE_CLASSES.values())
        return spec.midblock_distance_max_m + spec.parked_gap_max_m / 2 + longest_m + queue_m

    def queue_row_m(self, spec: ScenarioSpec) -> float:
        """How far before the stop line the queue from the stop line may reach [m]: to the farthest
        crossing gap, then the upstream flank and `queue_vehicles` more, each at the longest class and
        gap."""
        longest_m = max(size.length_m for size in VEHICLE_CLASSES.values())
        behind_m = longest_m + spec.queue_vehicles * (spec.queue_gap_max_m + longest_m)
        return crossing_reach_m(spec)[1] + spec.parked_gap_max_m / 2 + behind_m

    def staging_problem(
        self, site: Site, spec: ScenarioSpec, approach: Approach, turn: Turn | None, arm: str
    ) -> str | None:
        problem = super().staging_problem(site, spec, approach, turn, arm)
        if problem or not queued_from_stop_line(spec, approach):
            return problem
        row_m = self.queue_row_m(spec)
        if row_m > approach.lane_lengths_m[0]:
            return (
                f"approach {approach.edge_id} has a kerb lane {approach.lane_lengths_m[0]:.1f} m long: the "
                f"queue from its stop line past the mid-block crossing may need {row_m:.1f} m"
            )
        return None

    def staging_points(self, spec: ScenarioSpec, approach: Approach, turn: Turn | None) -> list[StagingPoint]:
        """Across the road at the nearest and the farthest mid-block distance, from where the pedestrian
        waits (the sidewalk's middle; under approach staging the kerb, at the nearest and farthest
        queue gap) over each lane's centre."""
        offsets = road_offsets_m(approach)
        distances_m = (spec.midblock_distance_min_m, spec.midblock_distance_max_m)
        if queued_from_stop_line(spec, approach):
            offsets[0] = kerb_wait_offset_m(approach)
            distances_m = crossing_reach_m(spec)
        stop_line_m = approach.lane_lengths_m[0]
        points = []
        for distance_m in distances_m:
            line = approach.across(0, stop_line_m - distance_m, offsets[0], offsets[-1])
            for offset_m in offsets:
                start, end = line
                f = (offset_m - offsets[0]) / (offsets[-1] - offsets[0]) if offsets[-1] != offsets[0] else 0.0
                xy = (start[0] + f * (end[0] - start[0]), start[1] + f * (end[1] - start[1]))
                where = f"{distance_m:g} m before the stop line, {offset_m:+.1f} m"
                points.append(StagingPoint(where, xy, start=offset_m == offsets[0]))
        return points
