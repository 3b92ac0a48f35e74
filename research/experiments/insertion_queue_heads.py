#!/usr/bin/env python3
"""Is a site's backlog capacity, or one vehicle that can never be inserted blocking its lane?

    python research/experiments/insertion_queue_heads.py xueqing OUT [--duration 3600] [--seed 1]

Generates the site's demand (the generator, the run seed), runs it in libsumo with the site's own
.sumocfg for the duration, and prints per entering lane (first edge, departLane) how many vehicles still
wait to be inserted at the end, the vehicle at the head of that queue (its due time and desired speed)
and when the lane last inserted a vehicle. A lane blocked by a vehicle SUMO can never insert (with
departSpeed="desired", a very fast draw needs a gap it never finds) stops inserting early and has that
vehicle at its head; a lane at capacity inserts until the end.
"""

from __future__ import annotations

import argparse
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from pedsafe_sumo.demand.generate import generate_demand  # noqa: E402
from pedsafe_sumo.demand.site import load_site  # noqa: E402
from pedsafe_sumo.demand.validate import _site_config  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("site")
    parser.add_argument("work", type=Path)
    parser.add_argument("--duration", type=float, default=3600.0)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    import libsumo as ts

    args.work.mkdir(parents=True, exist_ok=True)
    files = generate_demand(args.site, args.duration, args.seed, args.work)
    site = load_site(args.site)
    lane_speed = {lane.lane_id: lane.speed_limit_mps for lane in site.entering_lanes}
    root = ET.parse(files.vehicles_file).getroot()
    first_edge = {r.get("id"): r.get("edges").split()[0] for r in root.iter("route")}
    vehicles = {
        v.get("id"): (float(v.get("depart")), f"{first_edge[v.get('route')]}_{v.get('departLane')}",
                      float(v.get("speedFactor")))
        for v in root.iter("vehicle")
    }  # fmt: skip
    cfg, additionals = _site_config(site)
    ts.start(
        ["sumo", *(["-c", str(cfg)] if cfg else []), "--net-file", str(site.files.net_file),
         "--route-files", f"{files.vehicles_file},{files.pedestrians_file}",
         "--additional-files", ",".join(additionals), "--end", f"{args.duration:g}", "--no-step-log", "true",
         "--seed", "1", "--no-warnings", "true"]
    )  # fmt: skip
    last_insertion: dict[str, float] = {}
    while ts.simulation.getTime() < args.duration:
        ts.simulationStep()
        for vid in ts.simulation.getDepartedIDList():
            if vid in vehicles:
                last_insertion[vehicles[vid][1]] = ts.simulation.getTime()
    pending = [vid for vid in ts.simulation.getPendingVehicles() if vid in vehicles]
    ts.close()
    queues: dict[str, list[tuple[float, str, float]]] = {}
    for vid in pending:
        due_s, lane, factor = vehicles[vid]
        queues.setdefault(lane, []).append((due_s, vid, factor))
    print(
        f"{args.site}: {len(pending)} of {len(vehicles)} vehicles still wait to be inserted "
        f"at {args.duration:g} s"
    )
    for lane in sorted(set(lane_speed) | set(queues)):
        waiting = sorted(queues.get(lane, []))
        if not waiting:
            print(f"  {lane}: none waiting; last insertion at {last_insertion.get(lane, float('nan')):.0f} s")
            continue
        due_s, vid, factor = waiting[0]
        print(
            f"  {lane}: {len(waiting)} waiting; head {vid} due at {due_s:.0f} s, desired speed "
            f"{factor * lane_speed.get(lane, float('nan')):.1f} m/s; last insertion at "
            f"{last_insertion.get(lane, float('nan')):.0f} s"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
