"""Time per episode, split into SUMO (load, insertion, stepping), snapshot, perception, AD stack and
logging; plus the cost of starting SUMO against reloading it (issue 5, items 1 and 10).

    .venv/bin/python benchmarks/bench_episode.py --episodes 10
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.control.reference import ReferenceStack  # noqa: E402
from pedsafe_sumo.network.sites import get_site  # noqa: E402
from pedsafe_sumo.params import load_params  # noqa: E402
from pedsafe_sumo.scenarios.registry import SCENARIOS, get_scenario  # noqa: E402
from pedsafe_sumo.sim.connection import SumoSession  # noqa: E402
from pedsafe_sumo.sim.episode import EpisodeRunner  # noqa: E402

PARTS = ("sumo_s", "snapshot_s", "perception_s", "agent_s", "logging_s")


def start_versus_load(site, repeats: int = 20) -> tuple[float, float]:
    args = ["-n", str(site.file("net.xml")), "--step-length", "0.05", "--no-step-log", "true"]
    starts, loads = [], []
    for _ in range(3):
        session = SumoSession()
        t = time.perf_counter()
        session.run(args)
        starts.append(time.perf_counter() - t)
        for _ in range(repeats):
            t = time.perf_counter()
            session.run(args)
            loads.append(time.perf_counter() - t)
        session.close()
    return statistics.median(starts), statistics.median(loads)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10, help="episodes per scenario and condition")
    args = parser.parse_args()
    site = get_site("xueqing")
    start_s, load_s = start_versus_load(site)
    print(f"machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}")
    print(f"libsumo start {start_s * 1e3:.1f} ms, load (reuse) {load_s * 1e3:.1f} ms (median)")

    runner = EpisodeRunner(site, load_params(), ReferenceStack)
    print(
        f"{'scenario':20s} {'cond':4s} {'ep/s':>6s} {'steps':>6s} "
        + " ".join(f"{p[:-2]:>11s}" for p in PARTS)
        + "   (ms per episode; us per step in brackets)"
    )
    grand_steps, grand_wall = 0, 0.0
    for name in SCENARIOS:
        for condition in ("sv", "v2i"):
            totals = dict.fromkeys(PARTS, 0.0)
            steps = 0
            t = time.perf_counter()
            for seed in range(args.episodes):
                result = runner.run(get_scenario(name), condition, seed)
                steps += len(result.log)
                for part in PARTS:
                    totals[part] += result.timings_s[part]
            wall = time.perf_counter() - t
            grand_steps += steps
            grand_wall += wall
            cells = " ".join(
                f"{totals[p] / args.episodes * 1e3:5.1f}({totals[p] / steps * 1e6:4.0f})" for p in PARTS
            )
            print(
                f"{name:20s} {condition:4s} {args.episodes / wall:6.2f} {steps / args.episodes:6.0f} {cells}"
            )
    runner.close()
    print(
        f"overall: {grand_steps / grand_wall:.0f} steps/s, {grand_wall / grand_steps * 1e6:.0f} us per step"
    )


if __name__ == "__main__":
    main()
