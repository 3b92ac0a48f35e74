"""Batch throughput: episodes per second with 1 and 2 workers (scaling), and the projected wall time
of the paper's protocol (3 scenarios x 2 conditions x 10,000 episodes) on this machine.

    .venv/bin/python benchmarks/bench_batch.py --episodes 40
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PROTOCOL_EPISODES = 3 * 2 * 10_000


def run_batch(workers: int, episodes: int, out: Path) -> dict:
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pedsafe_sumo.batch",
            "--scenario",
            "all",
            "--episodes",
            str(episodes),
            "--workers",
            str(workers),
            "--seed",
            "11",
            "--out",
            str(out),
        ],
        cwd=REPO,
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads((out / "run.json").read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=40, help="episodes per scenario (x2 conditions)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    print(
        f"machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}"
    )
    base = None
    tmp = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    try:
        for workers in args.workers:
            info = run_batch(workers, args.episodes, tmp / f"w{workers}")
            rate = info["episodes_per_s"]
            base = base or rate
            protocol_min = PROTOCOL_EPISODES / rate / 60
            print(
                f"{workers} worker(s): {3 * 2 * args.episodes} episodes in {info['wall_time_s']:.1f} s = "
                f"{rate:.2f} episodes/s ({rate / workers:.2f} per worker, speed-up {rate / base:.2f}); "
                f"protocol of {PROTOCOL_EPISODES} episodes: {protocol_min:.0f} min"
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
