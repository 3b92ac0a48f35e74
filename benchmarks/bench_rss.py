"""Memory of a batch's worker processes over a run: does a worker's RSS stay flat?

    nice .venv/bin/python benchmarks/bench_rss.py --out OUT -- \
        --protocol protocols/paper-v7.toml --episodes 300 --workers 2

Starts `python -m pedsafe_sumo.batch <arguments after -->` with `--out OUT/run`, and every `--every`
seconds reads the resident set size (VmRSS of /proc/<pid>/status) of the driver and of every process
below it (the pool's workers, each with its own libsumo). Writes OUT/rss.csv (elapsed_s, pid, role,
rss_mib, episodes done so far from the run's manifest), OUT/rss.png (one line per process), and prints
per worker its RSS at the first sample after the warm-up (`--warmup-fraction` of the run's samples,
default the first 10 %), at the end, the growth between them and the linear trend over the rest, in
MiB per 1000 episodes. Linux only (/proc).
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def rss_mib(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def children(pid: int) -> list[int]:
    """Every process below `pid` (the pool's workers and anything they start)."""
    out, todo = [], [pid]
    while todo:
        parent = todo.pop()
        try:
            kids = Path(f"/proc/{parent}/task/{parent}/children").read_text().split()
        except OSError:
            continue
        for kid in map(int, kids):
            out.append(kid)
            todo.append(kid)
    return out


def episodes_done(run: Path) -> int:
    """Rows written so far: the manifest's chunks (pedsafe_sumo.io.run_store), 0 before the first."""
    for name in ("manifest.json", "parts/manifest.json"):
        path = run / name
        if path.is_file():
            try:
                data = json.loads(path.read_text())
            except (OSError, ValueError):
                return -1
            chunks = data.get("chunks", data) if isinstance(data, dict) else data
            items = chunks.values() if isinstance(chunks, dict) else chunks
            return sum(int(c.get("rows", 0)) for c in items if isinstance(c, dict))
    return 0


def main() -> int:
    argv = sys.argv[1:]
    if "--" not in argv:
        print("error: give the batch's arguments after --", file=sys.stderr)
        return 2
    split = argv.index("--")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--every", type=float, default=2.0, help="seconds between samples")
    parser.add_argument("--warmup-fraction", type=float, default=0.1)
    args = parser.parse_args(argv[:split])
    batch_args = argv[split + 1 :]
    args.out.mkdir(parents=True, exist_ok=True)
    run = args.out / "run"
    command = [sys.executable, "-m", "pedsafe_sumo.batch", *batch_args, "--out", str(run)]
    started = time.perf_counter()
    driver = subprocess.Popen(command, stdout=subprocess.DEVNULL)
    samples: list[tuple[float, int, str, float, int]] = []
    while driver.poll() is None:
        elapsed = time.perf_counter() - started
        done = episodes_done(run)
        for pid, role in [(driver.pid, "driver")] + [(p, "worker") for p in children(driver.pid)]:
            rss = rss_mib(pid)
            if rss is not None:
                samples.append((round(elapsed, 2), pid, role, round(rss, 2), done))
        time.sleep(args.every)
    wall_s = time.perf_counter() - started
    with open(args.out / "rss.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["elapsed_s", "pid", "role", "rss_mib", "episodes_done"])
        writer.writerows(samples)
    print(
        f"batch exit {driver.returncode}, wall {wall_s:.1f} s, {len(samples)} samples -> {args.out}/rss.csv"
    )
    workers = sorted({pid for _, pid, role, _, _ in samples if role == "worker"})
    total_episodes = max((s[4] for s in samples), default=0)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for pid in [driver.pid, *workers]:
        series = [(t, r) for t, p, _, r, _ in samples if p == pid]
        if len(series) < 2:
            continue
        t, r = np.array(series).T
        role = "driver" if pid == driver.pid else "worker"
        ax.plot(t, r, label=f"{role} {pid}")
        k0 = int(len(t) * args.warmup_fraction)
        slope_per_s = np.polyfit(t[k0:], r[k0:], 1)[0] if len(t) - k0 >= 3 else float("nan")
        per_1000 = slope_per_s * wall_s / max(total_episodes, 1) * 1000
        print(
            f"{role} {pid}: {r[k0]:.1f} MiB after warm-up (t={t[k0]:.0f} s), {r[-1]:.1f} MiB at the end, "
            f"max {r.max():.1f}; growth {r[-1] - r[k0]:+.1f} MiB, trend {per_1000:+.2f} MiB per 1000 episodes"
        )
    ax.set_xlabel("elapsed [s]")
    ax.set_ylabel("RSS [MiB]")
    ax.set_title(f"RSS of the batch's processes ({total_episodes} episodes, {wall_s:.0f} s)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out / "rss.png", dpi=100)
    return driver.returncode


if __name__ == "__main__":
    sys.exit(main())
