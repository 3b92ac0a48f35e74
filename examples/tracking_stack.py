"""A user AD stack: the reference pedestrian braking, with object permanence. A pedestrian it stops
perceiving stays in its world for `coast_s` (2 s), moved on at the velocity last tracked.

Why (research/EXPERIMENTS.md, "zhixin's V2I collisions are the reference stack forgetting the
pedestrian"): the reference stack forgets a pedestrian as soon as no detection comes. After `clear_hold_s`
(0.5 s) without one it drives back to its cruise speed, and when the pedestrian is seen again its reaction
time starts over. Under V2I the roadside camera sees the pedestrian from far off but loses them behind the
queued vehicles. The reference stack then first brakes gently, forgets, speeds up again, and meets the
pedestrian late. On the zhixin junction, holding a lost threat for 2 s removes all 46 of V2I's jaywalking
collisions in 10,000 pairs; this stack removes 24 of 26 in 5,000 there and 8 of 11 on Xueqing, and adds at
most one.

    python -m pedsafe_sumo.batch --scenario jaywalking --condition v2i \
        --algorithm examples.tracking_stack:TrackingStack
"""

from __future__ import annotations

import dataclasses
from typing import Any

from pedsafe_sumo.control.agent import Command, Observation, PerceivedPedestrian
from pedsafe_sumo.control.reference import ReferenceStack, TrackedPedestrian, Tracker

#: How long a pedestrian no longer perceived is kept, moved on at constant velocity [s]. 2 s: about the
#: longest the roadside camera loses a jaywalker behind the queue on zhixin (median 0.9 s, 90% 1.7 s),
#: chosen before any run of this stack.
COAST_S = 2.0
#: The source given to a pedestrian kept from memory (the reference stack does not read it).
COASTED_SOURCE = "track"


class RememberingTracker(Tracker):
    """The reference tracker, which also keeps each pedestrian's last tracked state."""

    def __init__(self, window_s: float) -> None:
        super().__init__(window_s)
        self.last: dict[str, tuple[float, TrackedPedestrian]] = {}

    def update(self, pedestrians, time_s: float) -> list[TrackedPedestrian]:
        tracked = super().update(pedestrians, time_s)
        for ped, track in zip(pedestrians, tracked):
            if ped.source != COASTED_SOURCE:
                self.last[track.ped_id] = (time_s, track)
        return tracked


class TrackingStack(ReferenceStack):
    def setup(self, config: dict[str, Any]) -> None:
        super().setup(config)
        self.coast_s = float(config.get("coast_s", COAST_S))
        self.tracker = RememberingTracker(self.tracker.window_s)

    def coasted(self, observation: Observation, time_s: float) -> list[PerceivedPedestrian]:
        """The pedestrians perceived within the last `coast_s` but not now, where they would be by now."""
        seen = {ped.ped_id for ped in observation.pedestrians}
        kept = []
        for ped_id, (seen_s, track) in list(self.tracker.last.items()):
            if ped_id in seen:
                continue
            elapsed_s = time_s - seen_s
            if elapsed_s > self.coast_s + 1e-9:
                del self.tracker.last[ped_id]
                continue
            x_m = track.x_m + track.vx_mps * elapsed_s
            y_m = track.y_m + track.vy_mps * elapsed_s
            kept.append(PerceivedPedestrian(ped_id, x_m, y_m, COASTED_SOURCE))
        return kept

    def run_step(self, observation: Observation, time_s: float) -> Command:
        kept = self.coasted(observation, time_s)
        if kept:
            observation = dataclasses.replace(observation, pedestrians=(*observation.pedestrians, *kept))
        return super().run_step(observation, time_s)
