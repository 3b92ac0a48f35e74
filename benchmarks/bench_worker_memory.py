"""Where a batch worker's memory creep comes from: one process, many episodes.

    nice .venv/bin/python benchmarks/bench_worker_memory.py --mode full --pairs 100 --every 10
    nice .venv/bin/python benchmarks/bench_worker_memory.py --mode full --pairs 100 --tracemalloc
    nice .venv/bin/python benchmarks/bench_worker_memory.py --mode sumo --pairs 100 --every 10

--mode full runs the worker side of a batch (`batch.runner.run_chunk`, the protocol's scenarios in
turn, one pair per call) in this process, as a pool worker does; --mode sumo runs only SUMO: the same
`load` arguments an episode gives (captured from one real pair per scenario, each episode with its own
--seed), then as many `simulation.step` calls as that episode had, and nothing of ours (no vehicles
added, no subscriptions, no perception). Every `--every` pairs it prints VmRSS (/proc/self/status) and,
with --tracemalloc, the Python heap traced by tracemalloc (started after the warm-up pair per scenario);
at the end, the tracemalloc allocation sites that grew most. If the Python heap stays flat while RSS
grows, the growth is native (SUMO, numba, pyarrow, the allocator's fragmentation).
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import sys
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.batch import runner as batch_runner  # noqa: E402
from pedsafe_sumo.batch.__main__ import parse_args  # noqa: E402
from pedsafe_sumo.batch.chunks import plan_chunks  # noqa: E402
from pedsafe_sumo.batch.plan import prepare  # noqa: E402
from pedsafe_sumo.sim.connection import SumoSession  # noqa: E402


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
                     "fordblks", "keepcost")
    ]  # fmt: skip


def malloc_mib() -> tuple[float, float]:
    """glibc's malloc: (bytes in use, incl. mmapped blocks; bytes free inside its heap) in MiB. Covers
    SUMO's C++ allocations and numpy's buffers; Python's small objects live in pymalloc's own arenas."""
    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype = _MallInfo2
    info = libc.mallinfo2()
    return (info.uordblks + info.hblkhd) / 2**20, info.fordblks / 2**20


def rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol", default="protocols/paper-v7.toml")
    parser.add_argument("--mode", choices=("full", "sumo"), default="full")
    parser.add_argument("--pairs", type=int, default=100, help="pairs in all (both conditions each)")
    parser.add_argument("--every", type=int, default=10, help="print every N pairs")
    parser.add_argument("--tracemalloc", action="store_true", help="trace the Python heap as well")
    args = parser.parse_args()
    per_scenario = max(1, -(-args.pairs // 4))
    # prepare() writes nothing: --out is only a name the parser requires.
    plan = prepare(
        parse_args(["--protocol", args.protocol, "--episodes", str(per_scenario), "--out", "never-written"])
    )
    chunks = plan_chunks(plan.scenarios, plan.conditions, per_scenario, plan.arguments["seed"], 1)
    # Round-robin over the scenarios, one pair per chunk, as a protocol's workers meet them.
    by_scenario: dict[str, list] = {}
    for chunk in chunks:
        by_scenario.setdefault(chunk.scenario, []).append(chunk)
    order = [c for group in zip(*by_scenario.values(), strict=False) for c in group][: args.pairs]

    # Warm-up, and the SUMO arguments and step counts of real episodes (for --mode sumo).
    captured: list[tuple[list[str], int]] = []
    real_run = SumoSession.run
    import libsumo

    real_step = libsumo.simulation.step
    steps = [0]

    def counting_step(*a, **k):
        steps[0] += 1
        return real_step(*a, **k)

    def capture(self, sumo_args):
        if captured:
            captured[-1] = (captured[-1][0], steps[0])
        steps[0] = 0
        captured.append((list(sumo_args), 0))
        return real_run(self, sumo_args)

    SumoSession.run = capture
    libsumo.simulation.step = counting_step
    for group in by_scenario.values():
        batch_runner.run_chunk(plan.config, "warm", group[-1].tasks)
    captured[-1] = (captured[-1][0], steps[0])
    SumoSession.run = real_run
    libsumo.simulation.step = real_step

    if args.tracemalloc:
        tracemalloc.start(8)
        first = tracemalloc.take_snapshot()
    start = time.perf_counter()
    print(f"mode {args.mode}: after warm-up RSS {rss_mib():.1f} MiB", flush=True)
    if args.mode == "sumo":
        batch_runner._close_runner()
        libsumo.start(["sumo", *captured[0][0]])
    for index, chunk in enumerate(order, 1):
        if args.mode == "full":
            batch_runner.run_chunk(plan.config, chunk.key, chunk.tasks)
        else:
            for condition_index in range(2):
                sumo_args, n_steps = captured[(index * 2 + condition_index) % len(captured)]
                seed_at = sumo_args.index("--seed") + 1
                sumo_args = [
                    *sumo_args[:seed_at],
                    str((chunk.tasks[0].seed + condition_index) % 2_147_483_647),
                    *sumo_args[seed_at + 1 :],
                ]
                libsumo.load(sumo_args)
                for _ in range(n_steps):
                    libsumo.simulation.step()
        if index % args.every == 0 or index == len(order):
            heap = ""
            if args.tracemalloc:
                current, _ = tracemalloc.get_traced_memory()
                heap = f", traced Python heap {current / 2**20:.2f} MiB"
            in_use, free = malloc_mib()
            heap += (
                f", malloc in use {in_use:.1f} MiB, free in heap {free:.1f} MiB, "
                f"Python blocks {sys.getallocatedblocks()}, objects {len(gc.get_objects())}"
            )
            print(
                f"{index:5d} pairs ({2 * index} episodes), {time.perf_counter() - start:7.1f} s: "
                f"RSS {rss_mib():.1f} MiB{heap}",
                flush=True,
            )
    if args.tracemalloc:
        last = tracemalloc.take_snapshot()
        print("largest growth by allocation site (tracemalloc, 8 frames):")
        for stat in last.compare_to(first, "traceback")[:8]:
            print(f"  {stat.size_diff / 1024:+8.1f} KiB {stat.count_diff:+6d} blocks  {stat.traceback[-1]}")


if __name__ == "__main__":
    main()
