"""Per-frame cost of the AD interface's raw data and world feeds, in the episode loop.

    python benchmarks/bench_raw_sensors.py [--episodes 3] [--scenario crossing] [--condition v2i]

Runs the same episodes (seeds 1..N, after one warm-up episode that compiles the kernels) with an agent
that asks for one thing at a time (and with one asking for the reference stack's three detection
sources alone: the baseline) and reports the loop's perception time per step (the loop builds the
observation's extras inside its perception timer), so ``feed - baseline`` is what asking for the feed
costs per frame (one frame per 0.05 s step). The agents hold their initial speed, so every variant
drives the same episodes.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from pedsafe_sumo.control.agent import Agent, Command  # noqa: E402
from pedsafe_sumo.network.sites import get_site  # noqa: E402
from pedsafe_sumo.params import load_params  # noqa: E402
from pedsafe_sumo.scenarios.specs import SCENARIOS  # noqa: E402
from pedsafe_sumo.sim.episode import EpisodeRunner  # noqa: E402

VARIANTS = {
    "baseline (onboard_camera, onboard_lidar, v2i)": ["onboard_camera", "onboard_lidar", "v2i"],
    "onboard_lidar_points": ["onboard_lidar_points"],
    "onboard_lidar_points + labels": ["onboard_lidar_points", "onboard_lidar_labels"],
    "onboard_camera_image": ["onboard_camera_image"],
    "onboard_camera_image + depth": ["onboard_camera_image", "onboard_camera_depth"],
    "roadside_camera_image": ["roadside_camera_image"],
    "vehicles": ["vehicles"],
    "route + road_map + traffic_light": ["route", "road_map", "traffic_light"],
}


def agent_for(names):
    class Holds(Agent):
        def sensors(self):
            return list(names)

        def setup(self, config):
            self.speed_mps = config["initial_speed_mps"]

        def run_step(self, observation, time_s):
            return Command(self.speed_mps)

    return Holds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--scenario", default="crossing", choices=sorted(SCENARIOS))
    parser.add_argument("--condition", default="v2i", choices=("sv", "v2i"))
    args = parser.parse_args()
    params = load_params()
    site = get_site("xueqing")
    spec = SCENARIOS[args.scenario]
    rows = {}
    for label, names in VARIANTS.items():
        runner = EpisodeRunner(site, params, agent_for(names))
        runner.run(spec, args.condition, 1000)  # warm-up: kernels compiled or loaded from the cache
        perception_s, steps = 0.0, 0
        started = time.perf_counter()
        for seed in range(1, args.episodes + 1):
            result = runner.run(spec, args.condition, seed)
            perception_s += result.timings_s["perception_s"]
            steps += len(result.log)
        wall_s = time.perf_counter() - started
        runner.close()
        rows[label] = {
            "perception_ms_per_step": 1000 * perception_s / steps,
            "steps": steps,
            "wall_s": wall_s,
        }
    base = rows[next(iter(VARIANTS))]["perception_ms_per_step"]
    raw = params["perception"]["raw"]
    machine = platform.processor() or platform.machine()
    print(f"{args.scenario} / {args.condition}, {args.episodes} episodes, {machine}")
    print(f"camera image {raw['camera_image_width_px']}x{raw['camera_image_height_px']} px, roadside "
          f"{raw['roadside_image_width_px']}x{raw['roadside_image_height_px']} px")  # fmt: skip
    print(f"{'asks for':48s} {'ms/step':>9s} {'extra ms/frame':>15s} {'steps':>6s}")
    for label, row in rows.items():
        extra = row["perception_ms_per_step"] - base
        print(f"{label:48s} {row['perception_ms_per_step']:9.2f} {extra:15.2f} {row['steps']:6d}")
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
