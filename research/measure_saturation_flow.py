#!/usr/bin/env python3
"""Measure SUMO's saturation flow for the demand's own vehicles: discharge headways of a queue at green.

    python research/measure_saturation_flow.py --seeds 1 2 3

A straight two-lane road (400 m to a signal, 300 m beyond, the fit's 16.67 m/s limit), a fixed-time signal
(green, yellow, red), and an oversaturating stream on both lanes (one vehicle per lane every
--insert-interval s, far above capacity, so a queue stands at every red). Each vehicle is the generator's:
the vType of pedsafe_sumo/demand/vehicles.py (length, minGap, sigma of defaults.toml [traffic], speedDev 0)
and its own speed factor = a draw from the generator's desired-speed law (traffic.desired_speed_law: the
non-intersection lognormal, or the calibrated one) / the limit. The time each vehicle
enters the downstream edge is recorded per lane; per green, the headways after the 4th vehicle (HCM: the
start-up lost time is in the first four) give the saturation headway, and 3600 / its mean the saturation
flow per lane. Greens of the first three cycles are ignored (the queue builds up).

Used for the Webster computation of networks/xueqing_dual_ring (its README).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pedsafe_sumo.demand.vehicles import desired_speed_distribution  # noqa: E402
from pedsafe_sumo.params import load_params  # noqa: E402
from pedsafe_sumo.sumo_binaries import sumo_binary  # noqa: E402

NODES = '<nodes><node id="A" x="0" y="0"/><node id="B" x="400" y="0" type="traffic_light"/>' + (
    '<node id="C" x="700" y="0"/></nodes>'
)
EDGES = (
    '<edges><edge id="AB" from="A" to="B" numLanes="2" speed="{v}"/>'
    '<edge id="BC" from="B" to="C" numLanes="2" speed="{v}"/></edges>'
)
TLL = (
    '<tlLogics><tlLogic id="B" type="static" programID="0" offset="0"><phase duration="{g}" state="GG"/>'
    '<phase duration="{y}" state="yy"/><phase duration="{r}" state="rr"/></tlLogic></tlLogics>'
)
#: HCM: the saturation headway is measured from the 5th vehicle of a queue on.
SKIP_FIRST = 4
WARMUP_CYCLES = 3


def measure(seed: int, args: argparse.Namespace, traffic: dict) -> tuple[float, float, int]:
    """(mean saturation headway s, saturation flow veh/h/lane, headways measured) for one seed."""
    import libsumo as ts

    limit = float(traffic["fit_speed_limit_mps"])
    speed_law = desired_speed_distribution(traffic)
    cycle = args.green + args.yellow + args.red
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "n.nod.xml").write_text(NODES)
        (d / "n.edg.xml").write_text(EDGES.format(v=limit))
        (d / "n.tll.xml").write_text(TLL.format(g=args.green, y=args.yellow, r=args.red))
        netconvert = [sumo_binary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml", "-i", "n.tll.xml"]
        subprocess.run(
            [*netconvert, "-o", "n.net.xml"],
            cwd=d,
            check=True,
            capture_output=True,
        )
        rng = np.random.default_rng(seed)
        ts.start(
            ["sumo", "-n", str(d / "n.net.xml"), "--step-length", "0.05", "--no-step-log", "--no-warnings"]
        )
        try:
            ts.vehicletype.copy("DEFAULT_VEHTYPE", "bg")
            ts.vehicletype.setLength("bg", float(traffic["vehicle_length_m"]))
            ts.vehicletype.setMinGap("bg", float(traffic["vehicle_min_gap_m"]))
            ts.vehicletype.setImperfection("bg", float(traffic["driver_imperfection_sigma"]))
            ts.vehicletype.setSpeedDeviation("bg", 0.0)
            ts.vehicletype.setMaxSpeed("bg", 55.6)
            ts.route.add("r", ["AB", "BC"])
            passed: dict[int, list[float]] = {0: [], 1: []}
            seen: set[str] = set()
            n = 0
            next_insert = 0.0
            while ts.simulation.getTime() < args.duration:
                if ts.simulation.getTime() >= next_insert - 1e-9:
                    next_insert += args.insert_interval
                    for lane in (0, 1):
                        desired = float(speed_law.sample(rng, 1)[0])
                        vid = f"v{n}"
                        n += 1
                        ts.vehicle.add(vid, "r", typeID="bg", departLane=str(lane), departSpeed="desired")
                        ts.vehicle.setSpeedFactor(vid, desired / limit)
                ts.simulationStep()
                t = ts.simulation.getTime()
                for vid in ts.edge.getLastStepVehicleIDs("BC"):
                    if vid not in seen:
                        seen.add(vid)
                        passed[ts.vehicle.getLaneIndex(vid)].append(t)
        finally:
            ts.close()
    headways: list[float] = []
    for times in passed.values():
        a = np.array(times)
        cycles = np.floor(a / cycle)
        for c in np.unique(cycles):
            if c < WARMUP_CYCLES:
                continue
            x = a[cycles == c]
            if x.size > SKIP_FIRST + 1:
                headways.extend(np.diff(x[SKIP_FIRST:]))
    h = float(np.mean(headways))
    return h, 3600.0 / h, len(headways)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--duration", type=float, default=3600.0, help="simulated s per seed")
    p.add_argument("--green", type=float, default=40.0)
    p.add_argument("--yellow", type=float, default=4.0)
    p.add_argument("--red", type=float, default=46.0)
    p.add_argument("--insert-interval", type=float, default=1.5, help="s between insertions per lane")
    p.add_argument("--params", help="parameter TOML laid over the defaults")
    args = p.parse_args(argv)
    traffic = load_params(args.params)["traffic"]
    flows = []
    for seed in args.seeds:
        h, s, n = measure(seed, args, traffic)
        flows.append(s)
        print(f"seed {seed}: mean saturation headway {h:.3f} s over {n} headways -> {s:.0f} veh/h/lane")
    print(f"mean over {len(flows)} seeds: {np.mean(flows):.0f} veh/h/lane")
    return 0


if __name__ == "__main__":
    sys.exit(main())
