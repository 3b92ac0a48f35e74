"""Streaming and real SUMO output.

- Memory stays flat: the Python memory the tool holds at its peak (tracemalloc) is the same for a file
  ten times longer with the same traffic in it. CSV output, which writes each row as it comes: the
  Parquet writer holds up to one row group (4096 rows) by design, which a short file never fills. The
  tracker measures the interactions that have ended a batch at a time (FLUSH_INTERACTIONS): the batch is
  made small here (8), so that the short file already fills it three times.
- A real SUMO run of the site's whole demand (routes/, vehicles and persons) with `--fcd-output`: the
  interactions the tool finds are exactly the runs of consecutive timesteps at which a vehicle's centre
  is within the radius of a person, counted here by an independent pass over the file with sumolib's
  parser, and each one's minimum clearance is the smallest footprint-circle distance over its steps up
  to the first contact.
"""

from __future__ import annotations

import subprocess
import tracemalloc
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import sumolib

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.conflicts import interactions
from pedsafe_sumo.conflicts.__main__ import main
from pedsafe_sumo.safety.geometry import rectangle_circle_distance_m
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre

SITE = REPO_ROOT / "networks" / "xueqing"
ROUTES = REPO_ROOT / "routes"


def write_repeating_fcd(path: Path, cycles: int) -> Path:
    """`cycles` times the same encounter, 20 steps of 0.5 s each: a new car drives east past a new walker
    crossing its lane. Only one pair is ever open at once."""
    with open(path, "w") as out:
        out.write("<fcd-export>\n")
        for c in range(cycles):
            for k in range(20):
                t = (c * 20 + k) * 0.5
                out.write(f'<timestep time="{t:.2f}">\n')
                out.write(f'<vehicle id="car{c}" x="{k * 5.0:.2f}" y="0" angle="90" type="t" speed="10"/>\n')
                out.write(
                    f'<person id="ped{c}" x="50" y="{-5 + k * 0.5:.2f}" angle="0" type="p" speed="1"/>\n'
                )
                out.write("</timestep>\n")
        out.write("</fcd-export>\n")
    return path


def peak_traced_bytes(fcd: Path, out: Path) -> int:
    tracemalloc.start()
    try:
        assert main([str(fcd), "--out", str(out), "--quiet"]) == 0
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.slow
def test_memory_does_not_grow_with_the_length_of_the_file(tmp_path, monkeypatch):
    monkeypatch.setattr(interactions, "FLUSH_INTERACTIONS", 8)
    cycles = 25
    short = write_repeating_fcd(tmp_path / "short.fcd.xml", cycles)
    long = write_repeating_fcd(tmp_path / "long.fcd.xml", 10 * cycles)
    assert main([str(short), "--out", str(tmp_path / "warm.csv"), "--quiet"]) == 0  # imports done untraced
    peak_bytes = peak_traced_bytes(short, tmp_path / "short.csv")
    peak_long_bytes = peak_traced_bytes(long, tmp_path / "long.csv")
    assert len(pd.read_csv(tmp_path / "long.csv")) == 10 * cycles
    # Ten times the file: the same peak, give or take allocator noise (nothing is kept per timestep).
    assert peak_long_bytes < 1.2 * peak_bytes + 200_000, (peak_bytes, peak_long_bytes)


@pytest.fixture(scope="module")
def site_fcd(tmp_path_factory) -> Path:
    """90 s of the site's demand, from t = 60 s (the first pedestrians are out), FCD every 0.5 s."""
    fcd = tmp_path_factory.mktemp("site") / "site.fcd.xml"
    routes = f"{ROUTES / 'xueqing.vehicles.rou.xml'},{ROUTES / 'xueqing.pedestrians.rou.xml'}"
    proc = subprocess.run(
        [sumo_binary("sumo"), "-c", str(SITE / "xueqing.sumocfg"), "-r", routes, "--end", "150"]
        + ["--step-length", "0.1", "--device.fcd.begin", "60", "--device.fcd.period", "0.5"]
        + ["--fcd-output", str(fcd), "--no-step-log", "--no-warnings"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return fcd


def independent_runs(fcd: Path, radius_m: float, lengths: dict, widths: dict, person_width_m: float):
    """{(vehicle, person): [[clearances of run 1], [run 2], ...]} by a separate pass with sumolib."""
    vehicles, persons = defaultdict(dict), defaultdict(dict)
    for step, v in sumolib.xml.parse_fast_nested(
        str(fcd), "timestep", ["time"], "vehicle", ["id", "x", "y", "angle", "type"]
    ):
        vehicles[float(step.time)][v.id] = (float(v.x), float(v.y), float(v.angle), v.type)
    for step, p in sumolib.xml.parse_fast_nested(str(fcd), "timestep", ["time"], "person", ["id", "x", "y"]):
        persons[float(step.time)][p.id] = (float(p.x), float(p.y))
    runs: dict = defaultdict(list)
    open_pairs: set = set()
    for time_s in sorted(set(vehicles) | set(persons)):
        near = set()
        for vid, (x, y, angle, vtype) in vehicles[time_s].items():
            yaw = float(sumo_angle_to_yaw_rad(angle))
            length, width = lengths.get(vtype, 5.0), widths.get(vtype, 1.8)
            cx, cy = (float(c) for c in sumo_front_to_centre(x, y, yaw, length))
            for pid, (px, py) in persons[time_s].items():
                if np.hypot(px - cx, py - cy) <= radius_m:
                    near.add((vid, pid))
                    if (vid, pid) not in open_pairs:
                        runs[(vid, pid)].append([])
                    clearance = rectangle_circle_distance_m(
                        cx, cy, yaw, length, width, px, py, person_width_m / 2
                    )
                    runs[(vid, pid)][-1].append(float(clearance))
        open_pairs = near
    return runs


@pytest.mark.slow
def test_site_demand_interactions_match_an_independent_pass(site_fcd, tmp_path):
    out = tmp_path / "site.parquet"
    types = [ROUTES / "xueqing.vehicles.rou.xml", ROUTES / "xueqing.pedestrians.rou.xml"]
    args = [str(site_fcd), "--out", str(out), "--net", str(SITE / "xueqing.net.xml"), "--quiet"]
    assert main(args + [a for t in types for a in ("--types", str(t))]) == 0
    table = pd.read_parquet(out)
    # routes/: vType bg_passenger length 5 (SUMO's default width 1.8), bg_pedestrian with SUMO's 0.48 m
    runs = independent_runs(site_fcd, 50.0, {"bg_passenger": 5.0}, {"bg_passenger": 1.8}, 0.48)
    assert len(table) == sum(len(r) for r in runs.values()) > 50
    got = table.sort_values(["vehicle_id", "person_id", "begin_s"]).groupby(["vehicle_id", "person_id"])
    for (vid, pid), rows in got:
        # up to and including the first contact, as the episode indexes take it
        want = [
            min(run[: next((k + 1 for k, c in enumerate(run) if c <= 0), len(run))])
            for run in runs[(vid, pid)]
        ]
        assert rows["min_clearance_m"].to_numpy() == pytest.approx(want, abs=1e-9)
    # the place: the nearest lane to every minimum-clearance point, crossings named by their edge
    assert (table["lane_id"] != "").mean() > 0.9
    on_crossing = table[table["crossing_id"] != ""]
    assert all(
        lane.startswith(cross + "_")
        for lane, cross in zip(on_crossing["lane_id"], on_crossing["crossing_id"])
    )
