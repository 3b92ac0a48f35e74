"""A replayed episode as ASAM OpenSCENARIO XML (1.2), with the site's road as OpenDRIVE, for esmini,
CARLA's scenario runner and other OpenSCENARIO players.

- Road: `netconvert --opendrive-output` from the site's SUMO network, written beside the scenario as
  `<name>.xodr` and referenced by a relative LogicFile path. netconvert keeps the network's x/y frame, so
  the scenario's world positions are the SUMO network's.
- Entities: the ego and every vehicle present at every step of the episode (the parked or queued
  kerb-lane vehicles) as Vehicles with their SUMO size and colour (property `color`, "r,g,b" 0-255),
  the pedestrian as a Pedestrian whose bounding box is its circle (2 radii square) and its height.
  Vehicles that appear or leave during the episode (background traffic) are left out: an OpenSCENARIO
  entity exists for the whole scenario.
- Motion: per entity, a FollowTrajectoryAction along a Polyline of the logged positions with their
  times (absolute timing, position following), started at t = 0 and preceded by a TeleportAction to the
  first position. Positions are the footprint centres (bounding box centred on the reference point),
  headings the yaw counter-clockwise from +x, as OpenSCENARIO's world frame has them.
"""

from __future__ import annotations

import math
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pedsafe_sumo.sim.episode import EGO_ID, PED_ID
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre

#: OpenSCENARIO minor version written (1.2: ASAM's current 1.x schema that scenariogeneration writes).
OSC_MINOR_VERSION = 2
#: Vehicle performance limits written into the entities (required by the schema, unused by a replay).
MAX_SPEED_MPS, MAX_ACCEL_MPS2, MAX_DECEL_MPS2 = 50.0, 10.0, 10.0
#: Pedestrian mass required by the schema (kg); an adult's, unused by a replay.
PEDESTRIAN_MASS_KG = 70.0


@dataclass
class Track:
    """One entity's logged motion: times, centre positions and headings, and its body."""

    length_m: float
    width_m: float
    height_m: float
    colour_rgb: tuple[int, int, int]
    times_s: list[float] = field(default_factory=list)
    x_m: list[float] = field(default_factory=list)
    y_m: list[float] = field(default_factory=list)
    yaw_rad: list[float] = field(default_factory=list)


class TrackRecorder:
    """A per-step hook (EpisodeRunner.run(on_step=...)): every vehicle's centre and the pedestrian."""

    def __init__(self, ped_radius_m: float, ped_height_m: float, ped_rgb, initial_heading_rad: float) -> None:
        self.steps = 0
        self.vehicles: dict[str, Track] = {}
        self.pedestrian = Track(2 * ped_radius_m, 2 * ped_radius_m, ped_height_m, tuple(ped_rgb))
        self._ped_heading_rad = initial_heading_rad

    def __call__(self, api, row: dict[str, Any]) -> None:
        self.steps += 1
        time_s = float(row["time_s"])
        vehicle = api.vehicle
        for vid in vehicle.getIDList():
            track = self.vehicles.get(vid)
            if track is None:
                r, g, b, _ = vehicle.getColor(vid)
                track = self.vehicles[vid] = Track(
                    vehicle.getLength(vid), vehicle.getWidth(vid), vehicle.getHeight(vid), (r, g, b)
                )
            x, y = vehicle.getPosition(vid)
            yaw = float(sumo_angle_to_yaw_rad(vehicle.getAngle(vid)))
            cx, cy = sumo_front_to_centre(x, y, yaw, track.length_m)
            track.times_s.append(time_s)
            track.x_m.append(float(cx))
            track.y_m.append(float(cy))
            track.yaw_rad.append(yaw)
        vx, vy = row["ped_vx_mps"], row["ped_vy_mps"]
        if math.hypot(vx, vy) > 0:
            self._ped_heading_rad = math.atan2(vy, vx)
        ped = self.pedestrian
        ped.times_s.append(time_s)
        ped.x_m.append(float(row["ped_x_m"]))
        ped.y_m.append(float(row["ped_y_m"]))
        ped.yaw_rad.append(self._ped_heading_rad)

    def whole_episode_vehicles(self) -> dict[str, Track]:
        """The ego first, then the vehicles present at every step, by id."""
        kept = {vid: t for vid, t in self.vehicles.items() if len(t.times_s) == self.steps}
        return dict(sorted(kept.items(), key=lambda item: (item[0] != EGO_ID, item[0])))


def write_opendrive(net_path: Path, xodr_path: Path) -> Path:
    """The SUMO network as OpenDRIVE, by netconvert (RuntimeError with its message on failure)."""
    proc = subprocess.run(
        [sumo_binary("netconvert"), "-s", str(net_path), "--opendrive-output", str(xodr_path)]
        + ["--no-warnings", "--output.street-names"],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"netconvert could not write OpenDRIVE: {proc.stderr.strip().splitlines()[-1:]}")
    return xodr_path


def _trajectory_action(xosc, name: str, track: Track):
    positions = [xosc.WorldPosition(x, y, 0.0, h) for x, y, h in zip(track.x_m, track.y_m, track.yaw_rad)]
    trajectory = xosc.Trajectory(f"{name}_trajectory", False)
    trajectory.add_shape(xosc.Polyline(list(track.times_s), positions))
    return xosc.FollowTrajectoryAction(
        trajectory,
        xosc.FollowingMode.position,
        xosc.ReferenceContext.absolute,
        1,
        0,
    )


def build_scenario(recorder: TrackRecorder, xodr_name: str, description: str):
    """The scenariogeneration Scenario of a recorded episode."""
    from scenariogeneration import xosc

    entities = xosc.Entities()
    init = xosc.Init()
    tracks: dict[str, Track] = {}
    for vid, track in recorder.whole_episode_vehicles().items():
        box = xosc.BoundingBox(track.width_m, track.length_m, track.height_m, 0.0, 0.0, track.height_m / 2)
        axle = 0.3 * track.length_m  # axles a fixed share of the length each side of the centre
        front = xosc.Axle(0.5, 0.6, track.width_m * 0.85, axle, 0.3)
        rear = xosc.Axle(0.0, 0.6, track.width_m * 0.85, -axle, 0.3)
        category = xosc.VehicleCategory.car
        body = xosc.Vehicle(vid, category, box, front, rear, MAX_SPEED_MPS, MAX_ACCEL_MPS2, MAX_DECEL_MPS2)
        body.add_property("color", ",".join(str(int(c)) for c in track.colour_rgb))
        entities.add_scenario_object(vid, body)
        tracks[vid] = track
    ped = recorder.pedestrian
    ped_box = xosc.BoundingBox(ped.width_m, ped.length_m, ped.height_m, 0.0, 0.0, ped.height_m / 2)
    walker = xosc.Pedestrian(
        PED_ID, PEDESTRIAN_MASS_KG, xosc.PedestrianCategory.pedestrian, ped_box, model="ped"
    )
    walker.add_property("color", ",".join(str(int(c)) for c in ped.colour_rgb))
    entities.add_scenario_object(PED_ID, walker)
    tracks[PED_ID] = ped

    start = xosc.ValueTrigger(
        "start", 0, xosc.ConditionEdge.none, xosc.SimulationTimeCondition(0, xosc.Rule.greaterOrEqual)
    )
    act = xosc.Act("replay", start)
    for name, track in tracks.items():
        init.add_init_action(
            name, xosc.TeleportAction(xosc.WorldPosition(track.x_m[0], track.y_m[0], 0.0, track.yaw_rad[0]))
        )
        event = xosc.Event(f"{name}_follows_log", xosc.Priority.override)
        event.add_action(f"{name}_follow", _trajectory_action(xosc, name, track))
        event.add_trigger(
            xosc.ValueTrigger(
                f"{name}_start",
                0,
                xosc.ConditionEdge.none,
                xosc.SimulationTimeCondition(0, xosc.Rule.greaterOrEqual),
            )
        )
        maneuver = xosc.Maneuver(f"{name}_maneuver")
        maneuver.add_event(event)
        group = xosc.ManeuverGroup(f"{name}_group")
        group.add_actor(name)
        group.add_maneuver(maneuver)
        act.add_maneuver_group(group)
    story = xosc.Story("logged_episode")
    story.add_act(act)
    end_s = max(t.times_s[-1] for t in tracks.values())
    stop = xosc.ValueTrigger(
        "end",
        0,
        xosc.ConditionEdge.rising,
        xosc.SimulationTimeCondition(end_s, xosc.Rule.greaterThan),
        "stop",
    )
    storyboard = xosc.StoryBoard(init, stop)
    storyboard.add_story(story)
    return xosc.Scenario(
        description,
        "pedsafe_sumo",
        xosc.ParameterDeclarations(),
        entities,
        storyboard,
        xosc.RoadNetwork(roadfile=xodr_name),
        xosc.Catalog(),
        osc_minor_version=OSC_MINOR_VERSION,
    )


def write_xosc(recorder: TrackRecorder, net_path: Path, path: Path, description: str) -> tuple[Path, Path]:
    """Write `path` (.xosc) and its road `path.with_suffix('.xodr')`; temporary names until complete."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    xodr = path.with_suffix(".xodr")
    tmp_xodr = xodr.with_name(xodr.name + ".tmp")
    write_opendrive(net_path, tmp_xodr)
    scenario = build_scenario(recorder, xodr.name, description)
    tmp = path.with_name(path.name + ".tmp")
    scenario.write_xml(str(tmp))
    tmp_xodr.replace(xodr)
    tmp.replace(path)
    return path, xodr
