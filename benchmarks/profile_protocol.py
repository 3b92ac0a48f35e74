"""Where a protocol's time goes: its actual mix of scenarios and conditions, in one process, per episode
and per step.

    .venv/bin/python benchmarks/profile_protocol.py --protocol protocols/paper-v7.toml --episodes 10
    .venv/bin/python benchmarks/profile_protocol.py ... --cprofile prof.out   # and a cProfile dump
    .venv/bin/python benchmarks/profile_protocol.py --protocol protocols/approach-v2.toml --phases

Runs the worker side of a batch (`batch.runner.run_chunk`, the protocol's scenarios, conditions and
parameters) in this process, after one untimed pair per scenario (numba's kernels loaded). The phases
are timed by wrapping the functions that do them with a clock (no profiler: its overhead inflates Python
code several times over C): drawing the world (draw_setup, background traffic included), SUMO's `load`,
staging (adding vehicles and the pedestrian, the first step), SUMO's own `simulation.step`, the loop's
own timers (snapshot, perception, agent, logging), the indexes at the end, building the log's DataFrame;
the rest of an episode is the loop's glue. Writing (the driver's part files) is timed separately on the
chunk's rows. Times are wall clock and CPU time of this process.

`--phases` (instead of the phase timers above) splits the CPU time of the loop's steps by whether the
pedestrian is in the scene (before they appear, in the scene, after they left; staging and judging
apart) and by part: SUMO's `simulation.step`, every other libsumo call, perception (`perceive`), the
stack's feeds (route, map, signals, raw data: `ObservationFeeds.step`), the pedestrian model
(`PedestrianWalker.step`, sight rays included), the AD stack (`run_step`); each part's own time (a part
inside another counts once, in the inner one), "loop" is the rest of the step (the snapshot, the row, the
loop's own lines, the clock reads of the wrappers). A step runs from the end of one `simulation.step` to
the end of the next and belongs to the phase at its start. The last line is the overhead ratio of each
phase: (step CPU - simulation.step) / simulation.step.
"""

from __future__ import annotations

import argparse
import cProfile
import math
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
from pedsafe_sumo.behaviour import pedestrian as pedestrian_module  # noqa: E402
from pedsafe_sumo.io.episodes import to_table  # noqa: E402
from pedsafe_sumo.sim import episode as episode_module  # noqa: E402
from pedsafe_sumo.sim import observation as observation_module  # noqa: E402
from pedsafe_sumo.sim import outcome as outcome_module  # noqa: E402
from pedsafe_sumo.sim import staging as staging_module  # noqa: E402
from pedsafe_sumo.sim.connection import SumoSession  # noqa: E402

try:  # the loop's module; in commits before it, the loop is sim/episode.py's _drive (before/after runs)
    from pedsafe_sumo.sim import loop as loop_module  # noqa: E402
except ImportError:
    loop_module = episode_module
DRIVE = "drive" if hasattr(episode_module, "drive") else "_drive"

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


class PhaseProfile:
    """CPU time of the loop's steps by phase (pedestrian absent, in the scene, gone) and by part, each
    part's own time (a wrapped call inside another is taken off the outer one)."""

    SETUP, ABSENT, PRESENT, LEFT, JUDGING = (
        "staging",
        "before appearing",
        "in scene",
        "after leaving",
        "judging",
    )

    def __init__(self) -> None:
        self.phase = self.step_phase = self.SETUP
        self.mark = time.process_time()
        self.inner: list[float] = []  # time of wrapped calls inside the open ones
        self.own: dict[tuple[str, str], float] = defaultdict(float)
        self.calls: dict[tuple[str, str], int] = defaultdict(int)
        self.total: dict[str, float] = defaultdict(float)
        self.steps: dict[str, int] = defaultdict(int)

    def wrap(self, owner, name: str, label: str, after=None) -> None:
        """Time owner.name as `label`; `after(result, args)` runs after each call (phase changes)."""
        real, cpu, inner = getattr(owner, name), time.process_time, self.inner

        def wrapper(*args, **kwargs):
            c = cpu()
            inner.append(0.0)
            try:
                result = real(*args, **kwargs)
            finally:
                spent = cpu() - c
                key = (self.step_phase, label)
                self.own[key] += spent - inner.pop()
                self.calls[key] += 1
                if inner:
                    inner[-1] += spent
            if after is not None:
                after(result, args, kwargs)
            return result

        setattr(owner, name, wrapper)

    def end_step(self, *_) -> None:
        """A step ends with simulation.step: its CPU time since the last one goes to its phase."""
        now = time.process_time()
        self.total[self.step_phase] += now - self.mark
        self.steps[self.step_phase] += 1
        self.mark, self.step_phase = now, self.phase

    def enter(self, phase: str) -> None:
        """Close the current stretch (staging, or the episode's last row) and start `phase` now."""
        now = time.process_time()
        self.total[self.step_phase] += now - self.mark
        self.mark, self.phase, self.step_phase = now, phase, phase

    def install(self, libsumo) -> None:
        runner_cls = episode_module.EpisodeRunner
        real_drive, real_guard = getattr(episode_module, DRIVE), episode_module.guard_step

        def drive(pose, *args, **kwargs):
            from_start = loop_module.in_scene_from_start(kwargs["setup"].pedestrian)
            self.enter(self.PRESENT if from_start else self.ABSENT)
            try:
                return real_drive(pose, *args, **kwargs)
            finally:
                self.enter(self.JUDGING)

        def guard(step, timeout_s):
            holder = type("StackStep", (), {"run_step": staticmethod(step)})
            self.wrap(holder, "run_step", "AD stack (run_step)")
            return real_guard(holder.run_step, timeout_s)

        setattr(episode_module, DRIVE, drive)
        episode_module.guard_step = guard
        self.wrap(runner_cls, "run", "staging, judging", after=lambda *_: self.enter(self.SETUP))
        self.wrap(libsumo.simulation, "step", "simulation.step", after=self.end_step)
        for domain in ("vehicle", "person", "simulation", "trafficlight", "route", "vehicletype", "lane"):
            owner = getattr(libsumo, domain)
            for name in dir(owner):
                label = f"{domain}.{name}"
                if name.startswith("_") or not callable(getattr(owner, name)) or label in NOT_WRAPPED:
                    continue
                self.wrap(owner, name, "libsumo " + label)
        self.wrap(episode_module.SumoStaging, "add_pedestrian_now", "libsumo person.add (glue)")
        real_add = episode_module.SumoStaging.add_pedestrian_now

        def add_now(*args, **kwargs):
            result = real_add(*args, **kwargs)
            self.phase = self.PRESENT  # from the step that SUMO now makes on
            return result

        episode_module.SumoStaging.add_pedestrian_now = add_now
        real_remove = libsumo.person.remove

        def remove(*args, **kwargs):
            result = real_remove(*args, **kwargs)
            if self.step_phase == self.PRESENT:
                self.phase = self.LEFT
            return result

        libsumo.person.remove = remove
        self.wrap(loop_module, "perceive", "perception (perceive)")
        self.wrap(observation_module.ObservationFeeds, "step", "stack's feeds (ObservationFeeds.step)")
        self.wrap(pedestrian_module.PedestrianWalker, "step", "pedestrian model (walker.step)")

    def report(self) -> None:
        cost = wrapper_cost_s()
        for phase in (self.ABSENT, self.PRESENT, self.LEFT):
            steps = self.steps[phase]
            if not steps:
                continue
            parts = {label: s for (p, label), s in self.own.items() if p == phase}
            calls = sum(n for (p, _), n in self.calls.items() if p == phase)
            step_s = parts.get("simulation.step", 0.0)
            print(f"{phase}: {steps} steps, {self.total[phase] / steps * 1e6:.0f} us CPU per step")
            libsumo = {k: v for k, v in parts.items() if k.startswith("libsumo ")}
            rows = {k: v for k, v in parts.items() if k not in libsumo and k != "staging, judging"}
            rows["other libsumo calls"] = sum(libsumo.values())
            # The loop's own lines (snapshot, row, glue), less the wrappers' clock reads.
            rows["loop (snapshot, row, glue)"] = self.total[phase] - sum(parts.values()) - calls * cost
            for label, seconds in sorted(rows.items(), key=lambda kv: -kv[1]):
                ratio = seconds / step_s if step_s else math.nan
                print(f"  {label:44s} {seconds / steps * 1e6:8.1f} us/step {ratio:6.2f} x step")
            for label, seconds in sorted(libsumo.items(), key=lambda kv: -kv[1])[:8]:
                n = self.calls[(phase, label)]
                print(f"    {label[8:]:42s} {seconds / steps * 1e6:8.1f} us/step {n / steps:5.2f} calls/step")
        ratios, engine = [], []
        for phase in (self.ABSENT, self.PRESENT, self.LEFT):
            step_s = self.own.get((phase, "simulation.step"), 0.0)
            if step_s:
                calls = sum(n for (p, _), n in self.calls.items() if p == phase)
                ours = self.total[phase] - step_s - calls * cost
                stack = self.own.get((phase, "AD stack (run_step)"), 0.0)
                ratios.append(f"{phase} {ours / step_s:.2f}")
                engine.append(f"{phase} {(ours - stack) / step_s:.2f}")
        print(
            "overhead ratio (CPU: a step besides simulation.step, per simulation.step): " + ", ".join(ratios)
        )
        print("  of it without the AD stack's run_step (the engine's own):", ", ".join(engine))


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
    parser.add_argument(
        "--phases",
        action="store_true",
        help="split the loop's CPU time by phase (pedestrian absent, in the scene, gone) and part instead",
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

    if args.phases:
        phases = PhaseProfile()
        phases.install(libsumo)
        cpu = time.process_time()
        for chunk in chunks:
            batch_runner.run_chunk(plan.config, chunk.key, chunk.tasks)
        print(f"{len(chunks) * 2 * args.episodes} episodes, CPU {time.process_time() - cpu:.1f} s")
        phases.report()
        return

    runner_cls = episode_module.EpisodeRunner
    timed(runner_cls, "draw_setup", "draw world (draw_setup)")
    timed(episode_module, "draw_background", "  of it: background traffic")
    timed(SumoSession, "run", "SUMO load")
    timed(staging_module, "populate", "staging: add vehicles, person")
    timed(staging_module, "start_signals", "staging: signals")
    timed(outcome_module, "episode_indexes", "indexes at the end")
    timed(loop_module.pd, "DataFrame", "log DataFrame")
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
    timed(loop_module, "perceive", "perceive")
    timed(loop_module, "ego_in_sight", "pedestrian sight rays")
    timed(loop_module, "move_pedestrian", "person.moveToXY")

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
