#!/usr/bin/env python3
"""Where SUMO's measured approach speeds fall below the desired ones (docs/demand_validation.md, "Calibrated
desired speeds", the diagnosis): the validation's loops joined by vehicle id with each vehicle's desired
speed, SUMO's tripinfo (insertion delay and speed) and lane-change output.

    research/demand_compression.py --seed 1 [--net tests/demand/data/straight.net.xml] [--duration 3600]
        [--pedestrians] [--no-lane-changes] [--set traffic.KEY=VALUE ...] [--work DIR]

Vehicles only unless --pedestrians (the straight test road has no sidewalks: SUMO walks them on the lanes).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from pedsafe_sumo import NETWORKS_DIR  # noqa: E402
from pedsafe_sumo.demand.generate import generate_demand  # noqa: E402
from pedsafe_sumo.demand.site import SiteError, load_site  # noqa: E402
from pedsafe_sumo.demand.validate import FALLBACK_OPTIONS, detector_lines, measure, place_detectors  # noqa: E402
from pedsafe_sumo.params import ParameterError, load_params, with_overrides  # noqa: E402
from pedsafe_sumo.sumo_binaries import sumo_binary  # noqa: E402

#: Desired-speed classes (m/s at the loop's road) of the deficit table.
CLASSES_MPS = ((0, 3), (3, 5), (5, 7), (7, 10), (10, 99))


def parse_value(text: str):
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text, text)


def run(args, work: Path) -> None:
    overrides = {}
    for item in args.set:
        key, _, value = item.partition("=")
        overrides[key] = parse_value(value)
    params = with_overrides(load_params(), overrides)
    demand = generate_demand("diag", args.duration, args.seed, work, net_file=args.net, params=params)
    if args.no_lane_changes:  # strategic lane changes stay possible; speed gain and keep-right are off
        text = demand.vehicles_file.read_text(encoding="utf-8")
        text = text.replace("<vType ", '<vType lcSpeedGain="0" lcKeepRight="0" ', 1)
        demand.vehicles_file.write_text(text, encoding="utf-8")
    site = load_site("diag", NETWORKS_DIR, args.net)
    detectors = place_detectors(site)
    (work / "det.add.xml").write_text("\n".join(detector_lines(detectors, "det.out.xml")) + "\n")
    routes = [demand.vehicles_file] + ([demand.pedestrians_file] if args.pedestrians else [])
    cmd = [sumo_binary("sumo"), *FALLBACK_OPTIONS, "--net-file", str(args.net),
           "--route-files", ",".join(map(str, routes)), "--additional-files", str(work / "det.add.xml"),
           "--end", f"{args.duration:g}", "--no-step-log", "true", "--duration-log.statistics", "true",
           "--seed", "1", "--tripinfo-output", str(work / "trip.xml"),
           "--lanechange-output", str(work / "lc.xml"), "--log", str(work / "sumo.log")]  # fmt: skip
    subprocess.run(cmd, check=True, capture_output=True)

    vehicles = ET.parse(demand.vehicles_file).getroot().iter("vehicle")
    factor = {v.get("id"): float(v.get("speedFactor")) for v in vehicles}
    trips = {t.get("id"): t for t in ET.parse(work / "trip.xml").getroot().iter("tripinfo")}
    changes = [c for c in ET.parse(work / "lc.xml").getroot().iter("change")]
    limit = {d.detector_id: d.speed_limit_mps for d in detectors}
    kind_of = {d.detector_id: d.kind for d in detectors}
    records: dict[str, list[tuple[float, float]]] = {}
    rows: dict[str, list[tuple[str, float, float]]] = {"midblock": [], "midlane": []}
    for el in ET.parse(work / "det.out.xml").getroot().iter("instantOut"):
        if el.get("state") != "enter":
            continue
        det, t_s, v = el.get("id"), float(el.get("time")), float(el.get("speed"))
        records.setdefault(det, []).append((t_s, v))
        if t_s >= args.warmup and kind_of[det] in rows:
            rows[kind_of[det]].append((el.get("vehID"), v, factor[el.get("vehID")] * limit[det]))

    stats = [line.strip() for line in (work / "sumo.log").read_text().splitlines()]
    print("SUMO:", "; ".join(s for s in stats if s.split(":")[0] in ("Inserted", "Waiting", "DepartDelay")))
    for comp in measure(records, detectors, params["traffic"], args.warmup)[:2]:
        print(f"{comp.name}: KS {comp.ks_distance:.3f} (n {comp.n}), median {comp.measured_median:.2f} "
              f"(fit {comp.fitted_median:.2f})")  # fmt: skip
    for kind, kind_rows in rows.items():
        measured = np.array([r[1] for r in kind_rows])
        desired = np.array([r[2] for r in kind_rows])
        ratio = measured / desired
        shares = " / ".join(f"{np.mean(ratio < x):.3f}" for x in (0.95, 0.8, 0.5))
        print(f"{kind} loops, {len(kind_rows)} records: share below 95% / 80% / 50% of desired {shares}")
        for low, high in CLASSES_MPS:
            sel = (desired >= low) & (desired < high)
            if sel.any():
                deficit_mps = np.mean(desired[sel] - measured[sel])
                print(f"  desired {low}-{high} m/s: n {sel.sum()}, median measured/desired "
                      f"{np.median(ratio[sel]):.3f}, mean deficit {deficit_mps:.2f} m/s")  # fmt: skip
        ids = [r[0] for r in kind_rows if r[0] in trips]
        delay = np.array([float(trips[i].get("departDelay")) for i in ids])
        depart_ratio = np.array([float(trips[i].get("departSpeed")) for i in ids]) / np.array(
            [r[2] for r in kind_rows if r[0] in trips]
        )
        print(f"  insertion (vehicles that finished): delay median {np.median(delay):.1f} s, mean "
              f"{np.mean(delay):.1f} s, over 5 s {np.mean(delay > 5):.3f}, "
              f"over 60 s {np.mean(delay > 60):.3f}; "
              f"departSpeed/desired median {np.median(depart_ratio):.3f}, "
              f"below 0.95 {np.mean(depart_ratio < 0.95):.3f}")  # fmt: skip
    changers = {c.get("id") for c in changes}
    reasons: dict[str, int] = {}
    for c in changes:
        reasons[c.get("reason")] = reasons.get(c.get("reason"), 0) + 1
    positions = np.array([float(c.get("pos")) for c in changes])
    print(f"lane changes: {len(changes)} by {len(changers)} of {len(factor)} vehicles; reasons {reasons}; "
          f"10% / 50% of them within {np.quantile(positions, 0.1):.0f} / {np.quantile(positions, 0.5):.0f} m "
          "of their edge's start" if changes else "lane changes: none")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--net", type=Path, default=REPO / "tests" / "demand" / "data" / "straight.net.xml")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration", type=float, default=3600.0)
    parser.add_argument("--warmup", type=float, default=300.0)
    parser.add_argument("--pedestrians", action="store_true", help="add the generated pedestrians")
    parser.add_argument("--no-lane-changes", action="store_true", help="lcSpeedGain = lcKeepRight = 0")
    parser.add_argument("--set", action="append", default=[], metavar="traffic.KEY=VALUE")
    parser.add_argument("--work", type=Path, help="keep the files here")
    args = parser.parse_args(argv)
    if not args.duration > args.warmup >= 0:
        parser.exit(2, f"{parser.prog}: error: need --duration > --warmup >= 0\n")
    try:
        with tempfile.TemporaryDirectory(prefix="pedsafe_compression_") as tmp:
            work = args.work or Path(tmp)
            work.mkdir(parents=True, exist_ok=True)
            run(args, work)
    except (SiteError, ParameterError, OSError, ValueError, subprocess.CalledProcessError) as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
