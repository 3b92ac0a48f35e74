"""Cost of the perception layer per frame against the cost of one SUMO step of the same scene.

    python benchmarks/bench_perception.py [--steps 400] [--repeat 3] [--seed 1]

1. Runs the Xueqing network with libsumo (step 0.05 s) keeping 30 vehicles (routes of
   routes/xueqing.vehicles.rou.xml) and 5 walking persons in the network, and times
   ``simulationStep`` alone. After each timed step it reads the world (positions, angles, sizes,
   colours) into a :class:`WorldSnapshot` (not timed as SUMO cost; reported separately: it is the
   simulator layer's cost of building the snapshot).
2. Replays the recorded snapshots through the perception layer with all buildings of
   networks/xueqing/xueqing.poly.xml and the roadside camera of xueqing.rsu.add.xml. The ego is the
   vehicle nearest the main junction in each snapshot.
   * scene "sumo": the persons where SUMO put them (anywhere on the site);
   * scene "dense": the same vehicles, but the 5 pedestrians moved 8-40 m in front of the ego,
     inside the onboard camera's field of view (the expensive case for the onboard sensors);
   * scene "roadside_view": the 5 pedestrians moved 8-40 m in front of the roadside camera (the
     expensive case for the roadside camera);
   * scene "dense_one": as "dense" with a single pedestrian (what the episode engine passes).
   Per frame: each sensor alone (plan + cast + rule) and the whole layer (``perceive`` with the V2I
   link), in microseconds. ``--reference`` times the numpy reference path instead of the compiled
   kernels.
3. The start-up cost of the compiled kernels in a fresh process (what each batch worker pays):
   import plus the first ``perceive`` with an empty numba cache (JIT compile) and with a warm one.

The benchmark may import libsumo; the perception package never does.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import statistics
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from pedsafe_sumo.params import load_params  # noqa: E402
from pedsafe_sumo.perception import (  # noqa: E402
    EgoPose,
    Pedestrians,
    SensorSuite,
    V2ILink,
    VehicleBoxes,
    WorldSnapshot,
    load_roadside_units,
    load_static_occluders,
    perceive,
    sumo_angle_to_yaw_rad,
    sumo_front_to_centre,
)
from pedsafe_sumo.perception.pipeline import _cast_all, _sensors_compiled, perceive_reference  # noqa: E402
from pedsafe_sumo.perception.sensors import (  # noqa: E402
    finish_camera,
    finish_lidar,
    plan_camera,
    plan_lidar,
)

SITE = ROOT / "networks" / "xueqing"
N_VEHICLES = 30
N_PERSONS = 5


def run_sumo(steps: int, seed: int):
    """Run SUMO with 30 vehicles and 5 persons; return (per-step seconds, snapshots, snapshot seconds)."""
    import libsumo as ts

    from pedsafe_sumo.sumo_binaries import sumo_binary

    ts.start(
        [
            sumo_binary("sumo"),
            "-n", str(SITE / "xueqing.net.xml"),
            "--step-length", "0.05",
            "--pedestrian.model", "striping",
            "--collision.check-junctions", "true",
            "--no-step-log", "true",
            "--no-warnings", "true",
            "--seed", str(seed),
        ]
    )  # fmt: skip
    rnd = random.Random(seed)
    root = ET.parse(ROOT / "routes" / "xueqing.vehicles.rou.xml").getroot()
    routes = [r.get("edges").split() for r in root.iter("route")]
    for i, edges in enumerate(routes):
        ts.route.add(f"r{i}", edges)
    proot = ET.parse(ROOT / "routes" / "xueqing.pedestrians.rou.xml").getroot()
    walks = [(w.get("from"), w.get("to")) for w in proot.iter("walk")][:200]
    counter = {"veh": 0, "per": 0}

    def top_up():
        """Insert what is missing (counted once: additions show up only after the next step)."""
        for _ in range(N_VEHICLES - ts.vehicle.getIDCount() - len(ts.simulation.getPendingVehicles())):
            counter["veh"] += 1
            vid = f"v{counter['veh']}"
            ts.vehicle.add(vid, f"r{rnd.randrange(len(routes))}", departLane="best", departSpeed="max")
            ts.vehicle.setColor(vid, tuple(rnd.randrange(256) for _ in range(3)) + (255,))
        for _ in range(N_PERSONS - ts.person.getIDCount()):
            counter["per"] += 1
            a, b = walks[rnd.randrange(len(walks))]
            pid = f"p{counter['per']}"
            ts.person.add(pid, a, 0.0)
            ts.person.appendWalkingStage(pid, [a, b] if a != b else [a], -1)
            ts.person.setColor(pid, tuple(rnd.randrange(256) for _ in range(3)) + (255,))

    for k in range(400):  # warm-up: fill the network
        if k % 20 == 0:
            top_up()
        ts.simulationStep()
    step_s, snap_s, snaps = [], [], []
    for k in range(steps):
        if k % 20 == 0:  # every second of simulated time, outside the timed step
            top_up()
        t0 = time.perf_counter()
        ts.simulationStep()
        step_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        snaps.append(read_snapshot(ts))
        snap_s.append(time.perf_counter() - t0)
    ts.close()
    return step_s, snaps, snap_s


def read_snapshot(ts) -> tuple:
    vids = ts.vehicle.getIDList()
    v = []
    for vid in vids:
        x, y = ts.vehicle.getPosition(vid)
        yaw = float(sumo_angle_to_yaw_rad(ts.vehicle.getAngle(vid)))
        length = ts.vehicle.getLength(vid)
        cx, cy = sumo_front_to_centre(x, y, yaw, length)
        v.append((vid, float(cx), float(cy), yaw, length, ts.vehicle.getWidth(vid), ts.vehicle.getHeight(vid),
                  ts.vehicle.getColor(vid)[:3]))  # fmt: skip
    p = []
    for pid in ts.person.getIDList():
        x, y = ts.person.getPosition(pid)
        p.append((pid, x, y, 0.5 * ts.person.getWidth(pid), 1.75, ts.person.getColor(pid)[:3]))
    return ts.simulation.getTime(), v, p


def to_world(raw, static) -> WorldSnapshot:
    t, v, p = raw
    vb = VehicleBoxes.build(*[[row[k] for row in v] for k in range(8)]) if v else VehicleBoxes.empty()
    pb = Pedestrians.build(*[[row[k] for row in p] for k in range(6)]) if p else Pedestrians.empty()
    return WorldSnapshot(t, vb, pb, static)


def choose_ego(world: WorldSnapshot, junction_xy) -> EgoPose:
    veh = world.vehicles
    i = int(np.argmin(np.hypot(veh.x_m - junction_xy[0], veh.y_m - junction_xy[1])))
    return EgoPose(float(veh.x_m[i]), float(veh.y_m[i]), float(veh.yaw_rad[i]), veh.ids[i])


def densify(world: WorldSnapshot, x_m, y_m, yaw_rad, rng: np.random.Generator, m=N_PERSONS) -> WorldSnapshot:
    """Move the pedestrians 8-40 m ahead of (x_m, y_m), within +-35 deg of the heading yaw_rad."""
    dist = rng.uniform(8, 40, m)
    bearing = yaw_rad + np.radians(rng.uniform(-35, 35, m))
    peds = Pedestrians.build(
        [f"dense{k}" for k in range(m)],
        x_m + dist * np.cos(bearing),
        y_m + dist * np.sin(bearing),
        0.25,
        rng.uniform(1.5, 1.9, m),
        rng.integers(0, 256, (m, 3)),
    )
    return WorldSnapshot(world.time_s, world.vehicles, peds, world.static)


def time_frames(fn, frames, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        for args in frames:
            t0 = time.perf_counter()
            fn(*args)
            out.append(time.perf_counter() - t0)
    return out


def sensor_fns_compiled(suite: SensorSuite):
    def skip(world, ego):
        return world.vehicles.ids.index(ego.vehicle_id) if ego.vehicle_id in world.vehicles.ids else -1

    def camera(world, ego):
        _sensors_compiled(world, ego, suite, skip(world, ego), True, False, False)

    def lidar(world, ego):
        _sensors_compiled(world, ego, suite, skip(world, ego), False, True, False)

    def roadside(world, ego):
        _sensors_compiled(world, ego, suite, skip(world, ego), False, False, True)

    return {"onboard_camera": camera, "onboard_lidar": lidar, "roadside_camera": roadside}


def sensor_fns(suite: SensorSuite):
    """Per sensor through the numpy reference (plan, cast, rule)."""

    def skip(world, ego):
        return world.vehicles.ids.index(ego.vehicle_id) if ego.vehicle_id in world.vehicles.ids else -1

    def camera(world, ego):
        plan = plan_camera(suite.camera, suite.camera_mount.pose(ego), world.pedestrians)
        (hits,) = _cast_all(world, [plan], skip(world, ego))
        if hits is not None:
            finish_camera(suite.camera, plan, hits, world, suite.ground_rgb, suite.sky_rgb)

    def lidar(world, ego):
        plan = plan_lidar(suite.lidar, suite.lidar_mount.pose(ego), world.pedestrians)
        (hits,) = _cast_all(world, [plan], skip(world, ego))
        if hits is not None:
            finish_lidar(suite.lidar, plan, hits, world)

    def roadside(world, ego):
        for pose in suite.roadside_poses:
            plan = plan_camera(suite.roadside, pose, world.pedestrians)
            (hits,) = _cast_all(world, [plan], -1)
            if hits is not None:
                finish_camera(suite.roadside, plan, hits, world, suite.ground_rgb, suite.sky_rgb)

    return {"onboard_camera": camera, "onboard_lidar": lidar, "roadside_camera": roadside}


def summary_us(samples: list[float]) -> dict:
    us = sorted(s * 1e6 for s in samples)
    return {
        "mean_us": round(statistics.fmean(us), 1),
        "median_us": round(us[len(us) // 2], 1),
        "p95_us": round(us[int(0.95 * (len(us) - 1))], 1),
    }


_START_SCRIPT = """
import sys, time
t0 = time.perf_counter()
import numpy as np
from pedsafe_sumo.params import load_params
from pedsafe_sumo.perception import EgoPose, Pedestrians, SensorSuite, StaticOccluders, VehicleBoxes
from pedsafe_sumo.perception import WorldSnapshot, perceive
t1 = time.perf_counter()
suite = SensorSuite.from_params(load_params()["perception"])
snap = WorldSnapshot(0.0, VehicleBoxes.build(["ego"], [0.0], [0.0], [0.0], [4.5], [1.8], [1.5], [(9, 9, 9)]),
                     Pedestrians.build(["p"], [31.5], [0.0], [0.25], [1.75], [(200, 30, 30)]),
                     StaticOccluders.build([("b", "building", [(20, 5), (30, 5), (30, 15), (20, 15)], 0, 9,
                                             (90, 90, 90))]))
t2 = time.perf_counter()
perceive(snap, EgoPose(0.0, 0.0, 0.0, "ego"), suite, np.random.default_rng(0))
t3 = time.perf_counter()
print(t1 - t0, t3 - t2)
"""


def jit_start_s() -> dict:
    """Import time and first-frame time in fresh processes, with an empty then a warm numba cache."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
        for label in ("cold_cache", "warm_cache"):
            res = subprocess.run([sys.executable, "-c", _START_SCRIPT], env=env, cwd=ROOT, check=True,
                                 capture_output=True, text=True)  # fmt: skip
            imp, first = (float(v) for v in res.stdout.split())
            out[label] = {"import_s": round(imp, 3), "first_frame_s": round(first, 3)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", type=Path, help="also write the numbers to this file")
    ap.add_argument("--reference", action="store_true", help="time the numpy reference path instead")
    ap.add_argument("--no-jit-start", action="store_true", help="skip the fresh-process start-up timing")
    args = ap.parse_args(argv)
    layer = perceive_reference if args.reference else perceive

    params = load_params()["perception"]
    t0 = time.perf_counter()
    static = load_static_occluders(SITE / "xueqing.poly.xml", params["occluders"])
    load_s = time.perf_counter() - t0
    units = load_roadside_units(
        SITE / "xueqing.rsu.add.xml",
        params["roadside_camera"]["default_height_m"],
        params["roadside_camera"]["default_pitch_down_deg"],
    )
    suite = SensorSuite.from_params(params, units)
    junction = json.loads((SITE / "xueqing.site.json").read_text())["main_junction_xy"]

    step_s, raws, snap_s = run_sumo(args.steps, args.seed)
    worlds = [to_world(r, static) for r in raws]
    egos = [choose_ego(w, junction) for w in worlds]
    rng = np.random.default_rng(args.seed)
    scenes = {
        "sumo": list(zip(worlds, egos, strict=True)),
        "dense": [(densify(w, e.x_m, e.y_m, e.yaw_rad, rng), e) for w, e in zip(worlds, egos, strict=True)],
    }
    if units:
        u = units[0]
        scenes["roadside_view"] = [
            (densify(w, u.x_m, u.y_m, u.yaw_rad, rng), e) for w, e in zip(worlds, egos, strict=True)
        ]
    scenes["dense_one"] = [
        (densify(w, e.x_m, e.y_m, e.yaw_rad, rng, m=1), e) for w, e in zip(worlds, egos, strict=True)
    ]
    results = {
        "machine": f"{platform.machine()}, {platform.processor() or 'cpu'}, 2 cores shared",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "path": "numpy reference" if args.reference else "compiled (numba)",
        "static": {
            "buildings_and_blocks": len(static.poly_ids),
            "wall_edges": static.n_edges,
            "tree_cylinders": static.n_cylinders,
            "load_ms": round(load_s * 1e3, 2),
        },  # fmt: skip
        "sumo_step": summary_us(step_s),
        "snapshot_read_libsumo": summary_us(snap_s),
        "mean_vehicles": statistics.fmean(len(w.vehicles) for w in worlds),
        "mean_persons": statistics.fmean(len(w.pedestrians) for w in worlds),
    }
    fns = sensor_fns(suite) if args.reference else sensor_fns_compiled(suite)
    for w, e in scenes["dense"][:3]:  # compile (or load the cached kernels) outside the timings
        perceive(w, e, suite, np.random.default_rng(0), w.time_s, V2ILink(suite.v2i))
        for fn in fns.values():
            fn(w, e)
    for name, frames in scenes.items():
        per = {}
        for sensor, fn in fns.items():
            per[sensor] = summary_us(time_frames(fn, frames, args.repeat))

        samples = []
        for _ in range(args.repeat):  # a fresh link per pass: its queue must see time move forward
            link = V2ILink(suite.v2i)
            gen = np.random.default_rng(args.seed)
            for w, e in frames:
                t0 = time.perf_counter()
                layer(w, e, suite, gen, w.time_s, link)
                samples.append(time.perf_counter() - t0)
        per["whole_layer"] = summary_us(samples)
        # Medians: the machine is shared, and a preempted frame would dominate a mean.
        per["whole_over_sumo_step_median"] = round(
            per["whole_layer"]["median_us"] / results["sumo_step"]["median_us"], 2
        )
        link = V2ILink(suite.v2i)
        gen = np.random.default_rng(args.seed)
        dets = [layer(w, e, suite, gen, w.time_s, link) for w, e in frames]
        per["mean_detected"] = {
            "onboard_camera": statistics.fmean(len(d.camera) for d in dets),
            "onboard_lidar": statistics.fmean(len(d.lidar) for d in dets),
            "roadside_camera": statistics.fmean(len(d.roadside) for d in dets),
            "v2i_received": statistics.fmean(len(d.v2i_received) for d in dets),
        }
        results[f"scene_{name}"] = per
    if not args.reference and not args.no_jit_start:
        results["jit_start"] = jit_start_s()
    text = json.dumps(results, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
