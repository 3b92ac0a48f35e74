"""Crossing, jaywalking and background blending on one-lane approaches, on the zhixin clip
(tests/network/data/osm, ODbL) whose north and south approaches have one 3.2 m vehicle lane and a 3.0 m
sidewalk each.

The vehicles that hide the pedestrian stand parked at the kerb: on the sidewalk, their road-side flank on
the kerb line (scenarios.placements.straight.kerb_parking_offset_m), each in a SUMO parking space of its own
(sim/kerb.py); the ego drives the one lane beside them. Checked here in real SUMO: where SUMO reports the
parked cars (against the lane's shape and width, by hand), that SUMO's FCD output puts them there too, that
they hide the pedestrian from the ego at the start, that every scenario runs under both conditions with the
roadside camera detecting the pedestrian under V2I, and what the hosting check refuses.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.sumo_net import read_net

STRAIGHT = ("crossing", "jaywalking", "background_blending")


@pytest.fixture(scope="module")
def runner(zhixin):
    from pedsafe_sumo.control.reference import ReferenceStack
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.sim.episode import EpisodeRunner

    runner = EpisodeRunner(resolve_site(str(zhixin)), load_params(None), ReferenceStack)
    yield runner
    runner.close()


def _spec(name: str, arm: str):
    from pedsafe_sumo.scenarios.specs import get_scenario

    return get_scenario(name).with_overrides({"approach": arm})


def _right_of(shape, point) -> tuple[float, float]:
    """(distance of `point` to the polyline `shape`, +1 when it lies right of the driving direction, -1
    left), from the nearest segment: plain vector algebra, none of the project's geometry."""
    best = (math.inf, 0.0)
    for (ax, ay), (bx, by) in zip(shape[:-1], shape[1:]):
        dx, dy = bx - ax, by - ay
        t = min(1.0, max(0.0, ((point[0] - ax) * dx + (point[1] - ay) * dy) / (dx * dx + dy * dy)))
        px, py = ax + t * dx, ay + t * dy
        gap = math.dist((px, py), point)
        if gap < best[0]:
            cross = dx * (point[1] - ay) - dy * (point[0] - ax)
            best = (gap, -1.0 if cross > 0 else 1.0)
    return best


@pytest.mark.slow
@pytest.mark.parametrize("arm", ["N", "S"])
def test_sumo_reports_the_parked_cars_at_the_kerb(zhixin, runner, arm):
    """SUMO's own position of every parked car (vehicle.getPosition: its front) lies on the sidewalk side of
    the one lane, lane width / 2 + car width / 2 from the lane's centreline (its flank on the kerb line),
    at its staged lane position, parked, with SUMO's angle that of the lane; the ego drives the lane."""
    import sumolib

    site = resolve_site(str(zhixin))
    net = read_net(site.file("net.xml"))
    seen: dict[str, tuple] = {}

    def first_step(api, row) -> None:
        if not seen:
            for vid in api.vehicle.getIDList():
                seen[vid] = (api.vehicle.getPosition(vid), api.vehicle.getAngle(vid))
            seen["parked"] = tuple(v for v in api.vehicle.getIDList() if api.vehicle.isStoppedParking(v))
            seen["time_s"] = row["time_s"]

    checked = 0
    for name in STRAIGHT:
        for seed in (3, 4):
            seen.clear()
            result = runner.run(_spec(name, arm), "sv", seed, on_step=first_step)
            setup = result.setup
            lane = net.getLane(setup.ego.lane_id)
            assert [ln.getID() for ln in lane.getEdge().getLanes() if ln.allows("passenger")] == [
                lane.getID()
            ]
            # The episode's clock starts when the cars already stand parked: its first step is 0.05 s.
            assert seen["time_s"] == pytest.approx(0.05)
            lane_w = lane.getWidth()  # 3.2 m, read from the network
            shape = lane.getShape()
            scale = sumolib.geomhelper.polyLength(shape) / lane.getLength()
            for vehicle in setup.parked:
                assert vehicle.vehicle_id in seen["parked"]
                assert vehicle.lane_id == lane.getID()
                (x, y), angle = seen[vehicle.vehicle_id]
                gap_m, side = _right_of(shape, (x, y))
                assert side == 1.0, vehicle.vehicle_id
                # Hand rule: 1.6 m to the kerb line plus half the car's width (0.9-0.975 m). 1 cm: SUMO
                # writes the space's position with its own precision; a bend of the lane between the car's
                # front and the nearest segment would show as more.
                assert gap_m == pytest.approx(lane_w / 2 + vehicle.size.width_m / 2, abs=0.01), vehicle
                # Along the lane: where SUMO draws the front's lane position (scaled to the drawn shape).
                along_m = sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint((x, y), shape)
                assert along_m == pytest.approx(vehicle.front_pos_m * scale, abs=0.05)
                heading = math.degrees(sumolib.geomhelper.rotationAtShapeOffset(shape, along_m))
                assert (angle - (90.0 - heading) + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=0.01)
                checked += 1
            # The ego in the lane's centre (within SUMO's precision), behind the cars' reach of its path.
            (ex, ey), _ = seen["ego"]
            assert _right_of(shape, (ex, ey))[0] < 0.01
    assert checked >= 6 * 2


@pytest.mark.slow
def test_sumo_fcd_output_puts_a_parked_car_where_getposition_does(zhixin, tmp_path):
    """SUMO's FCD output (what sumo-gui's replay and the FCD export read) has the parked car at its space."""
    script = textwrap.dedent(
        """
        import sys
        import libsumo as api
        from pedsafe_sumo.network.sites import resolve_site
        from pedsafe_sumo.scenarios.geometry import load_approach
        from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
        from pedsafe_sumo.scenarios.placements.straight import kerb_parking_offset_m
        from pedsafe_sumo.scenarios.road_users import VEHICLE_CLASSES
        from pedsafe_sumo.sim.kerb import check_parked, park_at_kerb, parking_xml, space_pose
        site = resolve_site(sys.argv[1])
        approach = load_approach(site, "N")
        size = VEHICLE_CLASSES["suv"]
        car = VehicleSetup("parked", approach.lane_ids[0], 60.0, 0.0, (20, 20, 20), size,
                           kerb_offset_m=kerb_parking_offset_m(approach, size))
        add = sys.argv[2] + "/parking.add.xml"
        open(add, "w").write(parking_xml(approach, (car,)))
        api.start(["sumo", "-n", str(site.file("net.xml")), "-a", add, "--step-length", "0.05",
                   "--fcd-output", sys.argv[2] + "/fcd.xml", "--no-step-log"])
        def add_vehicle(api_, vehicle, route_id):
            api_.vehicle.add(vehicle.vehicle_id, route_id, depart="0", departLane="1",
                             departPos=repr(vehicle.front_pos_m), departSpeed="0")
        park_at_kerb(api, (car,), add_vehicle)
        api.simulationStep()
        check_parked(api, (car,))
        x, y, _ = space_pose(approach, car)
        print("space", x, y)
        print("getPosition", *api.vehicle.getPosition("parked"))
        for _ in range(3):
            api.simulationStep()
        api.close()
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script, str(zhixin), str(tmp_path)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    values = {line.split()[0]: tuple(map(float, line.split()[1:])) for line in proc.stdout.splitlines()}
    assert values["getPosition"] == pytest.approx(values["space"], abs=0.005)
    fcd = [
        (float(v.get("x")), float(v.get("y")), float(t.get("time")))
        for t in ET.parse(tmp_path / "fcd.xml").getroot()
        for v in t
        if v.get("id") == "parked"
    ]
    # From the step it parked on, every FCD record has it at its space.
    parked = [(x, y) for x, y, time_s in fcd if time_s >= 0.05]
    assert len(parked) >= 3
    for xy in parked:
        assert xy == pytest.approx(values["space"], abs=0.005)


def _world_at_start(result, seen, runner, with_parked: bool):
    """The perception layer's world at the episode's first step, from SUMO's positions (`seen`)."""
    from pedsafe_sumo.perception import Pedestrians, VehicleBoxes, WorldSnapshot
    from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre

    setup = result.setup
    vehicles = [setup.ego, *(setup.parked if with_parked else ())]
    front = np.array([seen[v.vehicle_id][0] for v in vehicles])
    yaw = sumo_angle_to_yaw_rad([seen[v.vehicle_id][1] for v in vehicles])
    lengths = np.array([v.size.length_m for v in vehicles])
    cx, cy = sumo_front_to_centre(front[:, 0], front[:, 1], yaw, lengths)
    boxes = VehicleBoxes.build(
        [v.vehicle_id for v in vehicles], cx, cy, yaw, lengths,
        [v.size.width_m for v in vehicles], [v.size.height_m for v in vehicles],
        [v.colour_rgb for v in vehicles],
    )  # fmt: skip
    first = result.log.iloc[0]
    ped = setup.pedestrian
    peds = Pedestrians.build(
        ["ped"], [first["ped_x_m"]], [first["ped_y_m"]], [ped.radius_m], [ped.height_m], [ped.clothing_rgb]
    )
    return WorldSnapshot(0.0, boxes, peds, runner.static), (float(cx[0]), float(cy[0]), float(yaw[0]))


def _segment_hits_box(p, q, centre, yaw, length_m, width_m) -> bool:
    """Whether the segment p-q crosses the rectangle (hand geometry: the box's frame, slab test)."""
    c, s = math.cos(yaw), math.sin(yaw)

    def local(point):
        dx, dy = point[0] - centre[0], point[1] - centre[1]
        return dx * c + dy * s, -dx * s + dy * c

    (px, py), (qx, qy) = local(p), local(q)
    t0, t1 = 0.0, 1.0
    for start, delta, half in ((px, qx - px, length_m / 2), (py, qy - py, width_m / 2)):
        if abs(delta) < 1e-12:
            if abs(start) > half:
                return False
            continue
        a, b = (-half - start) / delta, (half - start) / delta
        t0, t1 = max(t0, min(a, b)), min(t1, max(a, b))
        if t0 > t1:
            return False
    return True


@pytest.mark.slow
def test_the_parked_car_hides_the_pedestrian_from_the_ego_at_the_start(zhixin, runner):
    """Under SV, at the first step: the ego's onboard camera and LiDAR (the perception layer's own rules) do
    not detect the pedestrian in most episodes; in crossing and jaywalking the camera sees them once the
    parked cars are taken out of the same world (visible fraction and height, the camera's own rules), and
    the straight line from the camera to the pedestrian's centre crosses a parked car's footprint (hand
    geometry). Measured on the north approach, 10 seeds (hidden, by the cars, line blocked): crossing
    9/9/10, jaywalking 7/10/10, background blending 10/0/0."""
    from pedsafe_sumo.perception import EgoPose
    from pedsafe_sumo.perception.pipeline import _sensors_numpy

    sensors = runner.sensors_for(_spec("crossing", "N"))
    counts = {}
    for name in STRAIGHT:
        hidden = by_parked = line_blocked = 0
        for seed in range(10):
            seen: dict[str, tuple] = {}

            def first_step(api, row, seen=seen) -> None:
                if not seen:
                    seen.update({vid: (api.vehicle.getPosition(vid), api.vehicle.getAngle(vid))
                                 for vid in api.vehicle.getIDList()})  # fmt: skip

            result = runner.run(_spec(name, "N"), "sv", seed, on_step=first_step)
            first = result.log.iloc[0]
            if not (first["detected_onboard_camera"] or first["detected_onboard_lidar"]):
                hidden += 1
            world, (ex, ey, eyaw) = _world_at_start(result, seen, runner, with_parked=True)
            bare, _ = _world_at_start(result, seen, runner, with_parked=False)
            ego = EgoPose(ex, ey, eyaw, "ego")
            visible = []
            for snapshot in (world, bare):
                camera, _, _ = _sensors_numpy(snapshot, ego, sensors, 0)
                visible.append(
                    camera.visible_fraction[0] >= sensors.camera.min_visible_fraction
                    and camera.height_px[0] >= sensors.camera.min_height_px
                )
            if not visible[0] and visible[1]:
                by_parked += 1
            eye = sensors.camera_mount.pose(ego).position_m[:2]
            ped_xy = (first["ped_x_m"], first["ped_y_m"])
            if any(
                _segment_hits_box(eye, ped_xy, (cx, cy), yaw, length, width)
                for cx, cy, yaw, length, width in zip(
                    world.vehicles.x_m[1:],
                    world.vehicles.y_m[1:],
                    world.vehicles.yaw_rad[1:],
                    world.vehicles.length_m[1:],
                    world.vehicles.width_m[1:],
                )  # fmt: skip
            ):
                line_blocked += 1
        counts[name] = (hidden, by_parked, line_blocked)
    print("hidden at the start of 10 (not detected, hidden by the parked cars, sight line blocked):", counts)
    for name, (hidden, by_parked, line_blocked) in counts.items():
        assert hidden >= 6, (name, counts)
        if name == "background_blending":
            # They stand in front of the parked car as the ego sees it, dressed in its colour, against its
            # rear: the car does not hide them, it is what they blend into (neither sensor separates them).
            assert by_parked == 0 and line_blocked == 0, counts
        else:
            assert by_parked >= 6, (name, counts)
            assert line_blocked >= 6, (name, counts)


@pytest.mark.slow
def test_every_straight_scenario_runs_on_the_one_lane_approaches_with_roadside_detections(zhixin, tmp_path):
    """A batch on the south approach, as a user runs it (hosting checked at its start), then the north one
    in-process: every scenario under both conditions, ok, the ego in the one lane, and under V2I the
    approach's roadside camera detects the pedestrian."""
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--scenario", "all", "--approach", "S",
         "--episodes", "2", "--workers", "1", "--site", str(zhixin), "--out", str(out), "--keep-logs", "all"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    episodes = pd.read_parquet(out / "episodes.parquet")
    steps = pd.concat([pd.read_parquet(f) for f in sorted((out / "steplogs").glob("*.parquet"))])
    for name in STRAIGHT:
        rows = episodes[episodes["scenario"] == name]
        assert sorted(rows["condition"]) == ["sv", "sv", "v2i", "v2i"], name
        assert (rows["status"] == "ok").all() and (rows["approach"] == "S").all(), rows["error"].tolist()
        v2i = steps[(steps["scenario"] == name) & (steps["condition"] == "v2i")]
        assert v2i.groupby("episode")["detected_roadside"].any().all(), name


@pytest.mark.slow
def test_the_north_approach_runs_each_scenario_under_both_conditions(zhixin, runner):
    from pedsafe_sumo.scenarios.geometry import load_approach

    lane_ids = load_approach(resolve_site(str(zhixin)), "N").lane_ids
    assert len(lane_ids) == 1
    for name in STRAIGHT:
        for condition in ("sv", "v2i"):
            result = runner.run(_spec(name, "N"), condition, 2)
            assert result.outcome["status"] == "ok" and result.outcome["approach"] == "N"
            assert result.setup.ego.lane_id == lane_ids[0]
            assert all(v.kerb_offset_m > 0 for v in result.setup.parked)
            if condition == "v2i":
                assert result.log["detected_roadside"].any(), name


def test_hosting_refuses_in_one_line_what_cannot_be_staged_at_the_kerb(zhixin):
    """No room at the kerb (a sidewalk narrower than the car), no kerb beside the lane, an approach too
    short for the row of parked cars: refused with the reason; two-lane approaches are not asked."""
    from pedsafe_sumo.scenarios.geometry import load_approach
    from pedsafe_sumo.scenarios.placements import placement_of
    from pedsafe_sumo.scenarios.specs import get_scenario

    def kerb_staging_problem(spec, approach):
        return placement_of(spec).kerb_staging_problem(spec, approach)

    approach = load_approach(resolve_site(str(zhixin)), "N")
    assert approach.sidewalk_width_m == 3.0 and approach.sidewalk_beside_lane
    for name in STRAIGHT:
        assert kerb_staging_problem(get_scenario(name), approach) is None
    narrow = dataclasses.replace(approach, sidewalk_width_m=1.5)
    problem = kerb_staging_problem(get_scenario("crossing"), narrow)
    assert "1.5 m sidewalk: no room at the kerb for a parked car 1.95 m wide" in problem
    apart = dataclasses.replace(approach, sidewalk_beside_lane=False)
    assert "another lane between it and the sidewalk" in kerb_staging_problem(
        get_scenario("jaywalking"), apart
    )
    # 106.45 m of lane: 45 m + 1.25 m + 5 m + 3 x (3 m + 5 m) = 75.25 m fit; 8 queued cars do not.
    long_queue = get_scenario("jaywalking").with_overrides({"queue_vehicles": 8})
    assert "the cars parked at its kerb may need 115.2 m" in kerb_staging_problem(long_queue, approach)


@pytest.mark.slow
def test_a_batch_refuses_in_one_line_a_row_of_parked_cars_the_approach_cannot_hold(zhixin, tmp_path):
    """Named explicitly, a one-lane staging that cannot be staged is refused at batch start, before anything
    is written (exit 2, one line with the reason); with --approach all it is skipped, saying why."""
    out = tmp_path / "run"
    common = ["-m", "pedsafe_sumo.batch", "--scenario", "jaywalking", "--set", "queue_vehicles=8",
              "--episodes", "1", "--workers", "1", "--site", str(zhixin), "--out", str(out)]  # fmt: skip
    proc = subprocess.run(
        [sys.executable, *common, "--approach", "N"],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=300,
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "may need 115.2 m before the stop line" in proc.stderr
    assert not out.exists()
    proc = subprocess.run(
        [sys.executable, *common, "--approach", "all", "--condition", "sv"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    for arm in ("N", "S"):
        assert (
            f"skipping scenario 'jaywalking' on approach {arm} of site zhixin: cannot be staged"
            in proc.stdout
        )
    assert set(pd.read_parquet(out / "episodes.parquet")["approach"]) == {"E", "W"}
