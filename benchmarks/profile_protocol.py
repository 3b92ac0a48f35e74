"""Where a protocol's time goes: its actual mix of scenarios and conditions, in one process, per episode
and per step.

    .venv/bin/python benchmarks/profile_protocol.py --protocol protocols/paper-v7.toml --episodes 10
    .venv/bin/python benchmarks/profile_protocol.py ... --cprofile prof.out   # and a cProfile dump

Runs the worker side of a batch (`batch.runner.run_chunk`, the protocol's scenarios, conditions and
parameters) in this process, after one untimed pair per scenario (numba's kernels loaded). The phases
are timed by wrapping the functions that do them with a clock (no profiler: its overhead inflates Python
code several times over C): drawing the world (draw_setup, background traffic included), SUMO's `load`,
staging (adding vehicles and the pedestrian, the first step), SUMO's own `simulation.step`, the loop's
own timers (snapshot, perception, agent, logging), the indexes at the end, building the log's DataFrame;
the rest of an episode is the loop's glue. Writing (the driver's part files) is timed separately on the
chunk's rows. Times are wall clock and CPU time of this process.
"""

from __future__ import annotations

import argparse
import cProfile
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.batch import runner as batch_runner  # noqa: E402
from pedsafe_sumo.batch.__main__ import parse_args  # noqa: E402
from pedsafe_sumo.batch.chunks import plan_chunks  # noqa: E402
from pedsafe_sumo.batch.plan import prepare  # noqa: E402
from pedsafe_sumo.io.episodes import to_table  # noqa: E402
from pedsafe_sumo.sim import episode as episode_module  # noqa: E402
from pedsafe_sumo.sim import outcome as outcome_module  # noqa: E402
from pedsafe_sumo.sim import staging as staging_module  # noqa: E402
from pedsafe_sumo.sim.connection import SumoSession  # noqa: E402

TOTALS: dict[str, float] = defaultdict(float)
CPU_TOTALS: dict[str, float] = defaultdict(float)
CALLS: dict[str, int] = defaultdict(int)
#: The loop's own timers (EpisodeResult.timings_s), summed.
LOOP_TIMERS: dict[str, float] = defaultdict(float)


def timed(owner, name: str, label: str) -> None:
    """Replace owner.name by a wrapper adding its wall and CPU time to TOTALS[label]."""
    real = getattr(owner, name)
    clock, cpu = time.perf_counter, time.process_time

    def wrapper(*args, **kwargs):
        t, c = clock(), cpu()
        try:
            return real(*args, **kwargs)
        finally:
            TOTALS[label] += clock() - t
            CPU_TOTALS[label] += cpu() - c
            CALLS[label] += 1

    setattr(owner, name, wrapper)


SUMO_CALL_CPU: dict[str, float] = defaultdict(float)
SUMO_CALL_COUNT: dict[str, int] = defaultdict(int)
#: Timed elsewhere (simulation.step, SUMO load through SumoSession.run) or not per episode.
NOT_WRAPPED = {"simulation.step", "simulation.load", "simulation.start", "simulation.close"}


def wrap_sumo_calls(libsumo) -> None:
    """Every public function of libsumo's domains, with a CPU clock around it (SUMO_CALL_CPU)."""
    cpu = time.process_time
    for domain in ("vehicle", "person", "simulation", "trafficlight", "route", "vehicletype"):
        owner = getattr(libsumo, domain)
        for name in dir(owner):
            label = f"{domain}.{name}"
            real = getattr(owner, name)
            if name.startswith("_") or not callable(real) or label in NOT_WRAPPED:
                continue

            def wrapper(*args, _real=real, _label=label, **kwargs):
                c = cpu()
                try:
                    return _real(*args, **kwargs)
                finally:
                    SUMO_CALL_CPU[_label] += cpu() - c
                    SUMO_CALL_COUNT[_label] += 1

            setattr(owner, name, wrapper)


def wrapper_cost_s() -> float:
    """CPU seconds one wrapper adds around a call of nothing (its two clock reads and bookkeeping)."""
    cpu, totals, counts = time.process_time, defaultdict(float), defaultdict(int)

    def wrapper(*args, _real=lambda: None, _label="x", **kwargs):
        c = cpu()
        try:
            return _real(*args, **kwargs)
        finally:
            totals[_label] += cpu() - c
            counts[_label] += 1

    best = float("inf")
    for _ in range(5):
        c = cpu()
        for _ in range(20_000):
            wrapper()
        best = min(best, (cpu() - c) / 20_000)
    return best


def report_sumo_calls(episodes: int, steps: int) -> None:
    overhead = wrapper_cost_s()
    calls = sum(SUMO_CALL_COUNT.values())
    total = sum(SUMO_CALL_CPU.values()) - calls * overhead
    print(
        f"other libsumo calls (CPU, less {overhead * 1e6:.2f} us of wrapper per call): {calls / steps:.1f} "
        f"per step, {total / episodes * 1e3:.2f} ms per episode, {total / steps * 1e6:.1f} us per step"
    )
    for label in sorted(SUMO_CALL_CPU, key=SUMO_CALL_CPU.get, reverse=True)[:10]:
        own = SUMO_CALL_CPU[label] - SUMO_CALL_COUNT[label] * overhead
        per_step = SUMO_CALL_COUNT[label] / steps
        print(f"  {label:40s} {per_step:5.2f} per step {own / steps * 1e6:8.1f} us per step")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol", default="protocols/paper-v7.toml")
    parser.add_argument("--episodes", type=int, default=10, help="pairs per scenario")
    parser.add_argument("--cprofile", help="also profile with cProfile and write the stats here")
    parser.add_argument(
        "--sumo-calls",
        action="store_true",
        help="also time every other libsumo call (vehicle, person, simulation, trafficlight, route, "
        "vehicletype), the wrapper's own cost subtracted: what SUMO costs outside its step and load",
    )
    args = parser.parse_args()
    # prepare() writes nothing: --out is only a name the parser requires.
    plan = prepare(
        parse_args(["--protocol", args.protocol, "--episodes", str(args.episodes), "--out", "never-written"])
    )
    chunks = plan_chunks(
        plan.scenarios, plan.conditions, args.episodes, plan.arguments["seed"], args.episodes
    )

    # Warm-up: one pair per scenario (kernels loaded, caches filled), untimed.
    for chunk in chunks:
        batch_runner.run_chunk(plan.config, "warm", chunk.tasks[-1:])

    import libsumo

    runner_cls = episode_module.EpisodeRunner
    timed(runner_cls, "draw_setup", "draw world (draw_setup)")
    timed(episode_module, "draw_background", "  of it: background traffic")
    timed(SumoSession, "run", "SUMO load")
    timed(staging_module, "populate", "staging: add vehicles, person")
    timed(staging_module, "start_signals", "staging: signals")
    timed(outcome_module, "episode_indexes", "indexes at the end")
    timed(episode_module.pd, "DataFrame", "log DataFrame")
    timed(libsumo.simulation, "step", "simulation.step (all)")
    timed(runner_cls, "run", "episode (run)")
    real_run = runner_cls.run

    def run_keeping_timings(self, *a, **k):
        result = real_run(self, *a, **k)
        for part, seconds in result.timings_s.items():
            LOOP_TIMERS[part] += seconds
        LOOP_TIMERS["logged steps"] += len(result.log)
        return result

    runner_cls.run = run_keeping_timings
    timed(episode_module, "perceive", "perceive")
    timed(episode_module, "ego_in_sight", "pedestrian sight rays")
    timed(episode_module, "move_pedestrian", "person.moveToXY")

    if args.sumo_calls:
        wrap_sumo_calls(libsumo)
    profiler = cProfile.Profile() if args.cprofile else None
    rows, steps = [], 0
    wall, cpu = time.perf_counter(), time.process_time()
    if profiler:
        profiler.enable()
    for chunk in chunks:
        out = batch_runner.run_chunk(plan.config, chunk.key, chunk.tasks)
        rows += out.rows
    if profiler:
        profiler.disable()
        profiler.dump_stats(args.cprofile)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    # The step count and the loop's own timers: rerun nothing; the EpisodeResults are not returned by
    # run_chunk, so count steps through the wrapped simulation.step (one per logged step but the last,
    # plus the inserting step of each episode).
    episodes = len(rows)
    steps = CALLS["simulation.step (all)"]
    t = time.perf_counter()
    table = to_table(rows)
    with tempfile.TemporaryDirectory() as folder:
        table.to_parquet(Path(folder) / "rows.parquet")
    write_s = time.perf_counter() - t
    print(
        f"{episodes} episodes, {steps} SUMO steps ({steps / episodes:.0f} per episode), "
        f"wall {wall:.1f} s, CPU {cpu:.1f} s"
    )
    print(f"{episodes / wall:.1f} episodes/s wall, {episodes / cpu:.1f} episodes/s CPU (one process)")
    print(f"{'phase':40s} {'ms/episode':>10s} {'us/step':>8s} {'CPU ms/ep':>10s} {'share':>6s}")
    for label in TOTALS:
        print(
            f"{label:40s} {TOTALS[label] / episodes * 1e3:10.2f} {TOTALS[label] / steps * 1e6:8.1f} "
            f"{CPU_TOTALS[label] / episodes * 1e3:10.2f} {TOTALS[label] / wall:6.1%}"
        )
    print(f"{'writing rows (to_table + parquet)':40s} {write_s / episodes * 1e3:10.2f}")
    if args.sumo_calls:
        report_sumo_calls(episodes, steps)
    print(f"the loop's own timers ({LOOP_TIMERS['logged steps']:.0f} logged steps):")
    for part, seconds in LOOP_TIMERS.items():
        if part != "logged steps":
            print(f"  {part:38s} {seconds / episodes * 1e3:10.2f} {seconds / steps * 1e6:8.1f}")


if __name__ == "__main__":
    main()
