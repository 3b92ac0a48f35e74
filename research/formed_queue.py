"""Where SUMO forms the kerb lane's queue of jaywalking and background blending under approach staging
(sim/queue.py), against where the staging puts it and where the placement stood it when it added the
vehicles standing (the same draws, the head 0.5 m before the stop line instead of SUMO's 1 m).

For each seed, as the runner draws it: the queue's vehicles enter the kerb lane upstream while its signal
is red and SUMO's car-following stops them; then their fronts are read back from SUMO. Printed per seed:
how many vehicles, the head's front and the tail's rear before the stop line (SUMO's, staged, placed
standing), the largest difference of a front from its staged place, the SUMO time the queue took to stand,
and for jaywalking the gap the pedestrian crosses through as SUMO formed it (its length, and the clearance
of the pedestrian's body circle, centred on their crossing line, to each vehicle).

    python research/formed_queue.py [--seeds 20]
"""

from __future__ import annotations

import argparse
import statistics

from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.geometry import path_pos_m
from pedsafe_sumo.scenarios.placements import behind_waiting_vehicle, midblock
from pedsafe_sumo.scenarios.road_users import PEDESTRIAN_RADIUS_M
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sim.queue import form_queue, formed_positions_m, formed_queue
from pedsafe_sumo.sim.staging import add_vehicle, sumo_args

#: The head's front before the stop line when the placement added the queue standing [m].
PLACED_HEAD_BEFORE_STOP_LINE_M = 0.5


def placed_setup(runner: EpisodeRunner, spec, seed: int):
    """The episode's world as the placement stood it (the head 0.5 m before the stop line)."""
    formed_m = midblock.HEAD_BEFORE_STOP_LINE_M
    for module in (midblock, behind_waiting_vehicle):
        module.HEAD_BEFORE_STOP_LINE_M = PLACED_HEAD_BEFORE_STOP_LINE_M
    try:
        return runner.draw_setup(spec, seed)
    finally:
        for module in (midblock, behind_waiting_vehicle):
            module.HEAD_BEFORE_STOP_LINE_M = formed_m


def extent_m(fronts_m, queue, stop_line_m: float) -> tuple[float, float]:
    """(the head's front, the tail's rear) before the stop line [m]."""
    return stop_line_m - fronts_m[0], stop_line_m - (fronts_m[-1] - queue[-1].size.length_m)


def crossing_gap(fronts_m, queue, cross_m: float) -> tuple[float, float, float]:
    """(the gap's length, the body's clearance to the vehicle ahead's rear, to the one behind's front) of
    the gap around lane position `cross_m` [m]."""
    for k in range(len(queue) - 1):
        rear_m = fronts_m[k] - queue[k].size.length_m
        if fronts_m[k + 1] <= cross_m <= rear_m:
            return (
                rear_m - fronts_m[k + 1],
                rear_m - cross_m - PEDESTRIAN_RADIUS_M,
                cross_m - fronts_m[k + 1] - PEDESTRIAN_RADIUS_M,
            )
    return (float("nan"),) * 3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    site = get_site("xueqing")
    runner = EpisodeRunner(site, load_params(None), ReferenceStack)
    approach = runner.approach
    stop_line_m = approach.lane_lengths_m[0]
    for name in ("jaywalking", "background_blending"):
        spec = get_scenario(name).with_overrides({"staging": "approach"})
        print(
            f"{name}: n | head before the stop line: SUMO / staged / placed | tail: SUMO / staged / placed "
            "| max |SUMO - staged| | formed after"
            + (" | crossing gap, clearances" if name == "jaywalking" else "")
        )
        errors, tails, counts = [], [], []
        for seed in range(args.seeds):
            setup = runner.draw_setup(spec, seed)
            queue = formed_queue(setup)
            placed = placed_setup(runner, spec, seed).parked
            runner.session.run(sumo_args(site, runner.step_length_s, seed))
            api = runner.session.api
            try:
                form_queue(api, queue, lambda a, v, r, d: add_vehicle(a, v, r, True, d, upstream=True))
                refused = ""
            except RuntimeError as exc:
                refused = f" REFUSED: {exc}"
            fronts_m = formed_positions_m(api, queue)
            staged_m = [v.front_pos_m for v in queue]
            error_m = max(abs(a - b) for a, b in zip(fronts_m, staged_m, strict=True))
            sumo = extent_m(fronts_m, queue, stop_line_m)
            staged = extent_m(staged_m, queue, stop_line_m)
            was = extent_m([v.front_pos_m for v in placed], placed, stop_line_m)
            errors.append(error_m)
            tails.append(sumo[1])
            counts.append(len(queue))
            line = (
                f"  seed {seed:2d}: {len(queue):2d} ({len(placed):2d} placed) | {sumo[0]:.3f} / "
                f"{staged[0]:.3f} / {was[0]:.3f} | {sumo[1]:.3f} / {staged[1]:.3f} / {was[1]:.3f} | "
                f"{error_m * 1000:.1f} mm | "
                f"{api.simulation.getTime():.1f} s"
            )
            if name == "jaywalking":
                ped = setup.pedestrian
                cross_m = path_pos_m(approach.through_paths[0], ped.path_xy[ped.kerb_index])
                gap = crossing_gap(fronts_m, queue, cross_m)
                line += f" | {gap[0]:.3f} m, {gap[1]:.3f} / {gap[2]:.3f} m"
            print(line + refused)
        print(
            f"  {name}: {min(counts)}-{max(counts)} vehicles, tail {min(tails):.2f}-{max(tails):.2f} m "
            f"(median {statistics.median(tails):.2f}), fronts within {max(errors) * 1000:.1f} mm of the "
            "staging"
        )
    runner.close()


if __name__ == "__main__":
    main()
