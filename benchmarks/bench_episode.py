"""Time per episode, split into SUMO (load, insertion, stepping), snapshot, perception, AD stack and
logging; plus the cost of starting SUMO against reloading it.

    .venv/bin/python benchmarks/bench_episode.py --episodes 10

The column `step` is the time inside SUMO's own `simulation.step` alone (timed by wrapping libsumo's
function; no setSpeed, moveToXY or load in it). The last line, `overhead ratio: X`, is everything else
an episode costs per step (loading SUMO, staging, the snapshot, perception, the AD stack, logging, the
indexes, the loop's Python) divided by the time inside `simulation.step`, over all scenarios and
conditions.
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
from pedsafe_sumo.scenarios.hosting import site_hosting  # noqa: E402
from pedsafe_sumo.scenarios.specs import SCENARIOS, get_scenario  # noqa: E402
from pedsafe_sumo.sim.connection import SumoSession  # noqa: E402
from pedsafe_sumo.sim.episode import EpisodeRunner  # noqa: E402

PARTS = ("sumo_s", "snapshot_s", "perception_s", "agent_s", "logging_s")


class StepTimer:
    """Wraps libsumo's simulation.step and adds up the time spent inside it."""

    def __init__(self) -> None:
        import libsumo

        self._simulation = libsumo.simulation
        self._real_step = libsumo.simulation.step
        self.inside_s = 0.0
        self.inside_cpu_s = 0.0
        self.calls = 0

    def __enter__(self) -> StepTimer:
        real_step, clock, cpu_clock = self._real_step, time.perf_counter, time.process_time

        def timed_step(*args, **kwargs):
            started, started_cpu = clock(), cpu_clock()
            try:
                return real_step(*args, **kwargs)
            finally:
                self.inside_s += clock() - started
                self.inside_cpu_s += cpu_clock() - started_cpu
                self.calls += 1

        self._simulation.step = timed_step
        return self

    def __exit__(self, *exc_info) -> None:
        self._simulation.step = self._real_step


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
    # Scenarios the site cannot stage (left_turn on Xueqing's split phasing) are skipped.
    problems = site_hosting(site, dict(SCENARIOS), load_params())
    names = [name for name in SCENARIOS if not (problems[name] or "").startswith("cannot be staged")]
    for name in sorted(set(SCENARIOS) - set(names)):
        print(f"{name}: skipped, {problems[name]}")
    # Untimed: one episode per scenario first, so that loading the compiled kernels (numba's cache, or
    # their first compile) is not counted as a cost of the first timed row.
    for name in names:
        runner.run(get_scenario(name), "v2i", 10_000)
    print(
        f"{'scenario':20s} {'cond':4s} {'ep/s':>6s} {'steps':>6s} "
        + " ".join(f"{p[:-2]:>11s}" for p in (*PARTS, "step_s"))
        + "   (ms per episode; us per step in brackets)"
    )
    grand_steps, grand_wall, grand_inside = 0, 0.0, 0.0
    # CPU time as well: on a shared machine the wall clock also counts waiting for a core.
    grand_cpu, grand_inside_cpu = 0.0, 0.0
    for name in names:
        for condition in ("sv", "v2i"):
            totals = dict.fromkeys((*PARTS, "step_s"), 0.0)
            steps = 0
            with StepTimer() as step_timer:
                t, t_cpu = time.perf_counter(), time.process_time()
                for seed in range(args.episodes):
                    result = runner.run(get_scenario(name), condition, seed)
                    steps += len(result.log)
                    for part in PARTS:
                        totals[part] += result.timings_s[part]
                wall = time.perf_counter() - t
                grand_cpu += time.process_time() - t_cpu
            grand_inside_cpu += step_timer.inside_cpu_s
            totals["step_s"] = step_timer.inside_s
            grand_steps += steps
            grand_wall += wall
            grand_inside += step_timer.inside_s
            cells = " ".join(
                f"{totals[p] / args.episodes * 1e3:5.1f}({totals[p] / steps * 1e6:4.0f})"
                for p in (*PARTS, "step_s")
            )
            print(
                f"{name:20s} {condition:4s} {args.episodes / wall:6.2f} {steps / args.episodes:6.0f} {cells}"
            )
    runner.close()
    print(
        f"overall: {grand_steps / grand_wall:.0f} steps/s, {grand_wall / grand_steps * 1e6:.0f} us per step, "
        f"{grand_inside / grand_steps * 1e6:.0f} us of it inside simulation.step"
    )
    print(f"overhead ratio in CPU time: {(grand_cpu - grand_inside_cpu) / grand_inside_cpu:.2f}")
    # Everything an episode costs besides SUMO's own step, per unit of that step.
    print(f"overhead ratio: {(grand_wall - grand_inside) / grand_inside:.2f}")


if __name__ == "__main__":
    main()
