"""RSS of the conflicts tool (`python -m pedsafe_sumo.conflicts`) along an FCD file: the tool's own loop
(read_fcd -> InteractionTracker -> TableWriter, with the site's net for places and its route files for
sizes), printing RSS, open interactions and interactions finished every 400 timesteps.

    .venv/bin/python benchmarks/bench_conflicts_memory.py FCD.xml.gz OUT.parquet
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from pedsafe_sumo.conflicts.fcd import read_fcd
from pedsafe_sumo.conflicts.interactions import InteractionTracker
from pedsafe_sumo.conflicts.output import TableWriter
from pedsafe_sumo.conflicts.places import PlaceFinder
from pedsafe_sumo.conflicts.sizes import SizeBook
from pedsafe_sumo.params import load_params

ROOT = Path(__file__).resolve().parents[1]


def rss_mb() -> float:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main(fcd: str, out: str, every: int = 400) -> None:
    section = load_params(None)["conflicts"]
    routes = [ROOT / "routes/xueqing.vehicles.rou.xml", ROOT / "routes/xueqing.pedestrians.rou.xml"]
    sizes = SizeBook.from_params(section, routes)
    place = PlaceFinder(ROOT / "networks/xueqing/xueqing.net.xml")
    table = TableWriter(Path(out))
    tracker = InteractionTracker(section["interaction_radius_m"], sizes, table.write, place)
    started = time.process_time()
    print(f"start: RSS {rss_mb():.1f} MB", flush=True)
    for step in read_fcd(fcd):
        tracker.step(step)
        if tracker.steps % every == 0:
            print(
                f"t={step.time_s:6.0f} s  RSS {rss_mb():6.1f} MB  open {tracker.open_interactions:5d}  "
                f"finished {tracker.interactions:6d}  CPU {time.process_time() - started:6.0f} s",
                flush=True,
            )
    tracker.finish()
    table.close()
    print(f"end: RSS {rss_mb():.1f} MB, {tracker.interactions} interactions", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
