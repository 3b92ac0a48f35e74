"""CPU per interaction of the conflicts tool (`python -m pedsafe_sumo.conflicts`), whole command.

    .venv/bin/python benchmarks/bench_conflicts_cpu.py FCD.xml [--net NET.xml] [--types FILE ...] [--repeat 3]

Runs the tool's `main` (CSV and SSM XML written to a temporary folder, `--quiet`) `--repeat` times after one
warm-up run (imports, the network's first read) and prints, per run, the CPU time of the process
(`time.process_time`: user + system, not wall time, which another job on the machine would inflate) and
that time divided by the interactions found; then the machine (CPU model, cores) and the load average.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import pandas as pd

from pedsafe_sumo.conflicts.__main__ import main as conflicts_main


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def run_once(fcd: Path, extra: list[str], folder: Path, k: int) -> float:
    out, ssm = folder / f"run{k}.csv", folder / f"run{k}.ssm.xml"
    started = time.process_time()
    status = conflicts_main([str(fcd), "--out", str(out), "--ssm", str(ssm), "--quiet", *extra])
    spent = time.process_time() - started
    if status != 0:
        raise SystemExit(f"the conflicts tool failed on {fcd}")
    return spent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fcd", type=Path)
    parser.add_argument("--net", type=Path)
    parser.add_argument("--types", type=Path, action="append", default=[])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    extra = (["--net", str(args.net)] if args.net else []) + [
        a for t in args.types for a in ("--types", str(t))
    ]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        run_once(args.fcd, extra, folder, 0)
        interactions = len(pd.read_csv(folder / "run0.csv", usecols=["vehicle_id"]))
        print(f"{args.fcd}: {interactions} interactions")
        for k in range(1, args.repeat + 1):
            load = os.getloadavg()[0]
            spent = run_once(args.fcd, extra, folder, k)
            per_ms = 1e3 * spent / interactions
            print(f"run {k}: CPU {spent:.2f} s, {per_ms:.3f} ms per interaction (load {load:.1f})")
    print(f"machine: {cpu_model()}, {os.cpu_count()} logical cores, load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
