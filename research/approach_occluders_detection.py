#!/usr/bin/env python3
"""What the onboard sensors see of the jaywalker and the blending pedestrian, fixed against approach
staging's occluders (scenarios/placements/midblock.py, behind_waiting_vehicle.py), under SV.

    PYTHONPATH=. nice -n 10 python research/approach_occluders_detection.py --seeds 10
    PYTHONPATH=. nice -n 10 python research/approach_occluders_detection.py --scenario jaywalking --seeds 10
    PYTHONPATH=. nice -n 10 python research/approach_occluders_detection.py --kerb-gap 0 --stagings approach

Per episode (Xueqing, reference stack, one seed per episode from 0): whether the onboard LiDAR and camera
detect the pedestrian at the step they step off (the last step they wait), and, for background blending,
in how many of the steps they walk behind the waiting vehicle (their centre within its half width of the
kerb lane's centre line) each sensor detects them; then the totals per staging. `--kerb-gap M` sets approach
staging's blending gap range to [M, M] (the spec fields kerb_gap_min_m and kerb_gap_max_m) to tell the gap's
part from the place's.

Used for docs/decisions/2026-11-27-approach-occluders.md.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pedsafe_sumo.control.reference import ReferenceStack  # noqa: E402
from pedsafe_sumo.network.sites import get_site  # noqa: E402
from pedsafe_sumo.params import load_params  # noqa: E402
from pedsafe_sumo.scenarios.geometry import load_approach  # noqa: E402
from pedsafe_sumo.scenarios.specs import get_scenario  # noqa: E402
from pedsafe_sumo.sim.episode import EpisodeRunner  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--scenario", default="background_blending", choices=("background_blending", "jaywalking")
    )
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--stagings", nargs="+", default=["fixed", "approach"], choices=("fixed", "approach"))
    parser.add_argument("--kerb-gap", type=float, default=None, help="approach staging's blending gap [m]")
    args = parser.parse_args()
    site = get_site("xueqing")
    approach = load_approach(site)
    runner = EpisodeRunner(site, load_params(), ReferenceStack)
    try:
        for staging in args.stagings:
            overrides: dict = {"staging": staging}
            if args.kerb_gap is not None:
                overrides |= {"kerb_gap_min_m": args.kerb_gap, "kerb_gap_max_m": args.kerb_gap}
            spec = get_scenario(args.scenario).with_overrides(overrides)
            totals = dict.fromkeys(("lidar", "camera", "behind_steps", "behind_lidar", "behind_camera"), 0)
            for seed in range(args.seeds):
                result = runner.run(spec, "sv", seed)
                log = result.log
                waiting = log[log["ped_state"] == "waiting"]
                step_off = waiting.iloc[-1] if len(waiting) else log.iloc[0]
                lidar, camera = (
                    bool(step_off["detected_onboard_lidar"]),
                    bool(step_off["detected_onboard_camera"]),
                )
                totals["lidar"] += lidar
                totals["camera"] += camera
                at = f"at step-off ({step_off['time_s']:.2f} s)"
                line = f"{staging} seed {seed}: {at} lidar {lidar} camera {camera}"
                if args.scenario == "background_blending":
                    vehicle = result.setup.parked[0]
                    x, y, heading = approach.pose(0, vehicle.front_pos_m)
                    left = (-math.sin(heading), math.cos(heading))
                    lateral = (log["ped_x_m"] - x) * left[0] + (log["ped_y_m"] - y) * left[1]
                    behind = log[
                        (lateral.abs() <= vehicle.size.width_m / 2) & (log["ped_state"] != "waiting")
                    ]
                    counts = (len(behind), int(behind["detected_onboard_lidar"].sum()))
                    counts += (int(behind["detected_onboard_camera"].sum()),)
                    for key, value in zip(
                        ("behind_steps", "behind_lidar", "behind_camera"), counts, strict=True
                    ):
                        totals[key] += value
                    line += f"; behind the vehicle {counts[0]} steps, lidar {counts[1]}, camera {counts[2]}"
                print(line, flush=True)
            print(f"{staging}: {totals} over {args.seeds} episodes", flush=True)
    finally:
        runner.close()


if __name__ == "__main__":
    main()
