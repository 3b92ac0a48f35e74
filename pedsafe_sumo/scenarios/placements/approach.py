"""Approach staging (ScenarioSpec.staging "approach"; docs/engine.md, "Approach staging"): the ego
starts on its approach out of every sensor's reach of the conflict point; the pedestrian enters the
scene later on the sidewalk, walks along it to their step-off point, waits there, crosses, and walks on
off the scene. The placement decides where the pedestrian crosses and where the conflict point is (as
in the fixed staging); this module decides when and from where everyone comes.

The draws follow every draw of the placement, in this order: the ego's start distance
(`ego_start_distance_m`), then the walk-in (`walk_in_s`). Timing: the ego reaches the conflict point at
T = start distance / initial speed; the pedestrian reaches the centre of the ego's lane
`conflict_offset_s` before it (as in the fixed staging), so they appear at
A = T - conflict_offset_s - walk_to_conflict_s - the kerb wait (ped_start_delay_s, or the longer one
the placement gives) - walk-in time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pedsafe_sumo.scenarios.placements.base import StagingInputs
from pedsafe_sumo.scenarios.walkways import (
    ON_CENTRELINE_M,
    Walkway,
    point_at,
    polyline_length_m,
    shape_between,
    sidewalk_before_m,
    sidewalk_offset_m,
    walk_in,
    walk_on,
)

#: The fallbacks the timing may take, in the order it tries them (StagedScene.approach_fallbacks).
FALLBACKS = {
    "start_clipped": "the road (with the road before the approach) holds less than the drawn start distance: "
    "the ego starts where it begins",
    "sidewalk_short": "the sidewalk upstream of the step-off point is shorter than the drawn walk-in",
    "walk_in_shortened": "the pedestrian would appear before ped_appear_min_s: the walk-in is shortened",
    "start_lengthened": "still before ped_appear_min_s: the ego starts farther back, within the road",
    "appears_early": "still before ped_appear_min_s: the pedestrian appears when the timing says",
    "on_way_at_start": "the timing says before t = 0: at t = 0 the pedestrian is already on their way",
    # The turning scenarios' (placements/turn.py):
    "oncoming_late": "the road before the oncoming vehicle is shorter than its run: it starts at its start",
}


@dataclass(frozen=True)
class ApproachTiming:
    """Where the ego starts and the pedestrian's whole walk, under approach staging."""

    #: The ego's front at the start, SUMO metres from the start of its approach lane (negative: before it,
    #: on the road before the approach; placements/straight.py, ego_start).
    front_pos_m: float
    start_distance_m: float
    #: Walk-in, step-off point (at kerb_index), the crossing, the walk-on.
    path: tuple[tuple[float, float], ...]
    kerb_index: int
    start_delay_s: float
    appear_time_s: float
    fallbacks: tuple[str, ...]


def stage_approach(
    inputs: StagingInputs,
    crossing: tuple,
    conflict_pos_m: float,
    walk_to_conflict_s: float,
    start_range_m: tuple[float, float],
    walkway: Walkway | None = None,
    kerb_wait_s: float | None = None,
) -> ApproachTiming:
    """The approach staging of a scene whose pedestrian crosses along `crossing` (its first point the
    step-off point, its last the far end) and meets the ego at SUMO distance `conflict_pos_m` from the
    start of the ego's lane, `walk_to_conflict_s` after stepping off. `start_range_m`: the shortest and
    the longest start distance the road holds (the ego's front on it, its whole body behind it; the road
    may include the road before the approach lane).
    `walkway`: the sidewalk the pedestrian walks in along, its shape running towards the step-off point (None:
    the approach's own). `kerb_wait_s`: how long they wait at the step-off point (None: the spec's
    `ped_start_delay_s`)."""
    spec, draws, approach = inputs.spec, inputs.draws, inputs.approach
    if walkway is None:
        walkway = Walkway(approach.sidewalk_lane_id, approach.sidewalk_shape, approach.sidewalk_width_m)
    ego_mps, walk_mps = inputs.ego_speed_mps, float(inputs.traits["walking_speed_mps"])
    fewest_m, most_m = start_range_m
    wait_s = spec.ped_start_delay_s if kerb_wait_s is None else kerb_wait_s
    fallbacks: list[str] = []
    start_m = draws.uniform("ego_start_distance_m", spec.ego_start_min_m, spec.ego_start_max_m)
    walk_in_s = draws.uniform("walk_in_s", spec.walk_in_min_s, spec.walk_in_max_s)
    if start_m > most_m:
        start_m = most_m
        fallbacks.append("start_clipped")
    start_m = max(start_m, fewest_m)

    step_off = (float(crossing[0][0]), float(crossing[0][1]))
    sidewalk_lane_id, sidewalk = walkway.lane_id, walkway.shape
    # From the sidewalk's centreline to the step-off point (the kerb end of a crosswalk, behind a waiting
    # car): walked whatever the walk-in; the drawn walk-in is the whole walk to the step-off point.
    beside = point_at(sidewalk, sidewalk_offset_m(sidewalk, step_off))
    leg_m = math.dist(beside, step_off)
    if leg_m < ON_CENTRELINE_M:
        leg_m = 0.0  # the walk-in goes straight to it (walkways.walk_in)
    along_m = max(walk_in_s * walk_mps - leg_m, 0.0)
    available_m = sidewalk_before_m(sidewalk, step_off)
    if along_m > available_m:
        along_m = available_m
        fallbacks.append("sidewalk_short")
    # From the end of the walk-in to the ego's arrival at the conflict point.
    lead_s = inputs.conflict_offset_s + walk_to_conflict_s + wait_s

    def appear_s() -> float:
        return start_m / ego_mps - lead_s - (along_m + leg_m) / walk_mps

    def early() -> bool:
        # Within rounding of the minimum is on it (the fallbacks below set A to it exactly).
        return appear_s() < spec.ped_appear_min_s - 1e-9

    if early() and along_m > 0:
        along_m = max(along_m - (spec.ped_appear_min_s - appear_s()) * walk_mps, 0.0)
        fallbacks.append("walk_in_shortened")
    if early() and start_m < most_m:
        start_m = min(ego_mps * (spec.ped_appear_min_s + lead_s + (along_m + leg_m) / walk_mps), most_m)
        fallbacks.append("start_lengthened")
    if early():
        fallbacks.append("appears_early")

    walk = walk_in(sidewalk, step_off, along_m)
    appear = start_m / ego_mps - lead_s - polyline_length_m([*walk, step_off]) / walk_mps
    if appear < spec.ped_appear_min_s and not early() and walk:
        # A step-off point within ON_CENTRELINE_M of the centreline is walked to straight from the point
        # before it, up to that much longer than along_m: the walk-in starts that much further on.
        before = [*walk, step_off]
        length_m = polyline_length_m(before)
        excess_m = min((spec.ped_appear_min_s - appear) * walk_mps, length_m)
        walk = tuple(shape_between(before, excess_m, length_m)[:-1])
        appear = start_m / ego_mps - lead_s - polyline_length_m([*walk, step_off]) / walk_mps
    (px, py), (qx, qy) = crossing[-2], crossing[-1]
    norm = math.hypot(qx - px, qy - py)
    onward = walk_on(
        (float(qx), float(qy)),
        ((qx - px) / norm, (qy - py) / norm),
        spec.walk_on_m,
        approach.walkways,
        approach.junction_xy,
        exclude=sidewalk_lane_id,
    )
    crossing_on = [step_off, *((float(x), float(y)) for x, y in crossing[1:]), *onward]
    delay_s = wait_s
    if appear < 0:
        fallbacks.append("on_way_at_start")
        walk, delay_s, crossing_on = _on_way(walk, step_off, crossing_on, -appear, walk_mps, delay_s)
        appear = 0.0
    return ApproachTiming(
        front_pos_m=conflict_pos_m - start_m,
        start_distance_m=start_m,
        path=(*walk, *crossing_on),
        kerb_index=len(walk),
        start_delay_s=delay_s,
        appear_time_s=appear,
        fallbacks=tuple(fallbacks),
    )


def _on_way(walk, step_off, crossing_on, elapsed_s: float, walk_mps: float, delay_s: float):
    """Where the pedestrian is `elapsed_s` after appearing (walk-in `walk` to `step_off`, the wait
    `delay_s`, then `crossing_on` from the step-off point): (the rest of the walk-in, the rest of the
    wait, the rest of the crossing), so that the conflict keeps its time."""
    walked_m = elapsed_s * walk_mps
    before = [*walk, step_off]
    walk_in_m = polyline_length_m(before)
    if walked_m < walk_in_m:
        rest = shape_between(before, walked_m, walk_in_m)
        return tuple(rest[:-1]), delay_s, crossing_on
    waited_s = elapsed_s - walk_in_m / walk_mps
    if waited_s < delay_s:
        return (), delay_s - waited_s, crossing_on
    crossed_m = (waited_s - delay_s) * walk_mps
    return (), 0.0, shape_between(crossing_on, crossed_m, polyline_length_m(crossing_on))
