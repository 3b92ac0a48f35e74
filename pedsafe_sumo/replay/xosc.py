"""A replayed episode as ASAM OpenSCENARIO XML 1.2, its road as OpenDRIVE, for esmini, CARLA's scenario
runner and other OpenSCENARIO players (docs/openscenario.md).

- Road: `netconvert --opendrive-output` from the site's SUMO network, written beside the scenario as
  `<name>.xodr` and referenced by a relative LogicFile path. netconvert keeps the network's x/y frame
  (its OpenDRIVE header carries `<offset>` = -netOffset, the way back to UTM), so the scenario's world
  positions are the SUMO network's x/y, the same numbers as the case log.
- Entities: the ego, the pedestrian, and every other vehicle on the road at the episode's first step
  (the kerb-lane vehicles the scenario placed and the background traffic then present), as Vehicles
  with their SUMO length, width, height and colour (property `color`, "r,g,b" 0-255); the pedestrian
  as a Pedestrian whose bounding box holds their circle (2 radii square) and their height. A vehicle
  that enters during the episode is left out (an OpenSCENARIO entity is in the world from the start).
- Motion: per entity, a FollowTrajectoryAction along a Polyline of its logged positions with their
  times (absolute timing, position following), started at t = 0, after a TeleportAction to its first
  position in Init. Positions are footprint centres (the bounding box is centred on the reference
  point), headings the yaw counter-clockwise from +x, as OpenSCENARIO's world frame has them. The ego
  and the pedestrian are the case log's rows (`ego_x_m`, `ego_y_m`, `ego_yaw_rad`; `ped_x_m`,
  `ped_y_m` and the direction of `ped_vx_mps`, `ped_vy_mps`); other vehicles are SUMO's positions
  moved from the front bumper to the centre (pedsafe_sumo/units.py). A vehicle that leaves the road
  before the end is removed then (DeleteEntityAction).
"""

from __future__ import annotations

import math
import re
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pedsafe_sumo import OSM_ATTRIBUTION
from pedsafe_sumo.sim.staging import EGO_ID, PED_ID
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre

#: OpenSCENARIO 1.x minor version written: 1.2, the newest whose rules ASAM's checker
#: (asam-qc-openscenarioxml 1.0.0) defines, so that every one of its checks applies.
OSC_MINOR_VERSION = 2
#: OpenDRIVE 1.x minor version the road is declared as (see conform_opendrive).
XODR_MINOR_VERSION = 6
#: Performance limits the schema requires of a Vehicle; a replay follows the log and never uses them.
#: Chosen above anything a car on this site reaches (50 m/s = 180 km/h, 10 m/s2 ~ 1 g).
MAX_SPEED_MPS, MAX_ACCEL_MPS2, MAX_DECEL_MPS2 = 50.0, 10.0, 10.0
#: Axles the schema requires of a Vehicle (unused by a replay): a passenger car's, stated, not measured:
#: axles 30 % of the length ahead of and behind the centre, wheels 0.6 m, track 85 % of the width.
AXLE_SHARE_OF_LENGTH, WHEEL_DIAMETER_M, TRACK_SHARE_OF_WIDTH, MAX_STEER_RAD = 0.3, 0.6, 0.85, 0.5
#: Pedestrian mass the schema requires (kg, an adult's; unused by a replay).
PEDESTRIAN_MASS_KG = 70.0


@dataclass
class Track:
    """One entity's logged motion (times, centre positions, headings) and its body."""

    length_m: float
    width_m: float
    height_m: float
    colour_rgb: tuple[int, int, int]
    times_s: list[float] = field(default_factory=list)
    x_m: list[float] = field(default_factory=list)
    y_m: list[float] = field(default_factory=list)
    yaw_rad: list[float] = field(default_factory=list)

    def add(self, time_s: float, x_m: float, y_m: float, yaw_rad: float) -> None:
        self.times_s.append(time_s)
        self.x_m.append(x_m)
        self.y_m.append(y_m)
        self.yaw_rad.append(yaw_rad)


class TrackRecorder:
    """A per-step hook (EpisodeRunner.run(on_step=...)): the ego and pedestrian from the log row, every
    other vehicle from SUMO. `vehicle_rgb`: the colours the episode's setup gave its vehicles (the engine
    sets the staged ones on their vehicle type, so SUMO's per-vehicle colour is its default there)."""

    def __init__(
        self,
        ped_radius_m: float,
        ped_height_m: float,
        ped_rgb,
        initial_heading_rad: float,
        vehicle_rgb: dict[str, tuple[int, int, int]] | None = None,
    ) -> None:
        self.times_s: list[float] = []
        self._vehicle_rgb = dict(vehicle_rgb or {})
        self.vehicles: dict[str, Track] = {}
        self.pedestrian = Track(2 * ped_radius_m, 2 * ped_radius_m, ped_height_m, _rgb(ped_rgb))
        #: The pedestrian's heading while standing: their path's direction until they first move.
        self._ped_heading_rad = initial_heading_rad

    def __call__(self, api, row: dict[str, Any]) -> None:
        time_s = float(row["time_s"])
        self.times_s.append(time_s)
        vehicle = api.vehicle
        for vid in vehicle.getIDList():
            track = self.vehicles.get(vid)
            if track is None:
                track = self.vehicles[vid] = Track(
                    vehicle.getLength(vid),
                    vehicle.getWidth(vid),
                    vehicle.getHeight(vid),
                    _rgb(self._vehicle_rgb.get(vid) or vehicle.getColor(vid)[:3]),
                )
            if vid == EGO_ID:
                track.add(time_s, float(row["ego_x_m"]), float(row["ego_y_m"]), float(row["ego_yaw_rad"]))
                continue
            x, y = vehicle.getPosition(vid)
            yaw = float(sumo_angle_to_yaw_rad(vehicle.getAngle(vid)))
            cx, cy = sumo_front_to_centre(x, y, yaw, track.length_m)
            track.add(time_s, float(cx), float(cy), yaw)
        vx, vy = float(row["ped_vx_mps"]), float(row["ped_vy_mps"])
        if math.hypot(vx, vy) > 0:
            self._ped_heading_rad = math.atan2(vy, vx)
        self.pedestrian.add(time_s, float(row["ped_x_m"]), float(row["ped_y_m"]), self._ped_heading_rad)

    def exported_vehicles(self) -> dict[str, Track]:
        """The ego first, then by id every vehicle on the road at the first step."""
        first = self.times_s[0] if self.times_s else None
        kept = {vid: t for vid, t in self.vehicles.items() if t.times_s and t.times_s[0] == first}
        return dict(sorted(kept.items(), key=lambda item: (item[0] != EGO_ID, item[0])))

    def left_out(self) -> list[str]:
        """Vehicles that entered during the episode (not exported)."""
        return sorted(set(self.vehicles) - set(self.exported_vehicles()))


def _rgb(values) -> tuple[int, int, int]:
    r, g, b = (int(v) for v in values)
    return r, g, b


def write_opendrive(net_path: Path, xodr_path: Path) -> Path:
    """The SUMO network as OpenDRIVE, by netconvert (RuntimeError with its last message on failure)."""
    proc = subprocess.run(
        [sumo_binary("netconvert"), "-s", str(net_path), "--opendrive-output", str(xodr_path)]
        + ["--no-warnings", "--output.street-names"],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0 or not xodr_path.is_file():
        last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"netconvert could not write OpenDRIVE from {net_path}: {last}")
    xodr_path.write_text(conform_opendrive(xodr_path.read_text(encoding="utf-8")), encoding="utf-8")
    return xodr_path


def conform_opendrive(text: str) -> str:
    """netconvert 1.28's OpenDRIVE declared as the version its content follows.

    netconvert writes a 1.4 header (revMinor="4") but elements 1.4 does not have: the header's
    `<offset>` and the crosswalk objects' `<outline id fillType outer closed laneType>` with
    `<cornerLocal id>`, introduced in 1.5; ASAM's schema check then fails on every one of them (136
    issues on the Xueqing site) and skips all further checks. Declared 1.6, the first version whose
    schema holds these, with the one attribute 1.6 requires of an object that netconvert leaves out
    (`zOffset`, 0: the crosswalk lies on the road), the file passes the schema and every check of
    1.6 (tests/replay/test_xosc_export.py). Nothing else changes: the road geometry is netconvert's.
    """
    header = 'revMajor="1" revMinor="4"'
    if header not in text:
        raise RuntimeError("netconvert's OpenDRIVE has no 1.4 header: check conform_opendrive on this SUMO")
    text = text.replace(header, f'revMajor="1" revMinor="{XODR_MINOR_VERSION}"', 1)
    return re.sub(r"<object (?![^>]*\bzOffset=)", '<object zOffset="0.00000000" ', text)


def _time_trigger(xosc, name: str, time_s: float, rule=None):
    return xosc.ValueTrigger(
        name,
        0,
        xosc.ConditionEdge.none,
        xosc.SimulationTimeCondition(time_s, rule or xosc.Rule.greaterOrEqual),
    )


def _follow_log(xosc, name: str, track: Track):
    positions = [xosc.WorldPosition(x, y, 0.0, h) for x, y, h in zip(track.x_m, track.y_m, track.yaw_rad)]
    trajectory = xosc.Trajectory(f"{name}_trajectory", False)
    trajectory.add_shape(xosc.Polyline(list(track.times_s), positions))
    # Absolute timing: a vertex's time is simulation time, the log's time_s (scale 1, offset 0).
    return xosc.FollowTrajectoryAction(
        trajectory, xosc.FollowingMode.position, xosc.ReferenceContext.absolute, 1, 0
    )


def _vehicle(xosc, name: str, track: Track):
    box = xosc.BoundingBox(track.width_m, track.length_m, track.height_m, 0.0, 0.0, track.height_m / 2)
    axle_x_m = AXLE_SHARE_OF_LENGTH * track.length_m
    track_m = TRACK_SHARE_OF_WIDTH * track.width_m
    wheel_z_m = WHEEL_DIAMETER_M / 2
    front = xosc.Axle(MAX_STEER_RAD, WHEEL_DIAMETER_M, track_m, axle_x_m, wheel_z_m)
    rear = xosc.Axle(0.0, WHEEL_DIAMETER_M, track_m, -axle_x_m, wheel_z_m)
    body = xosc.Vehicle(
        name, xosc.VehicleCategory.car, box, front, rear, MAX_SPEED_MPS, MAX_ACCEL_MPS2, MAX_DECEL_MPS2
    )
    body.add_property("color", ",".join(str(c) for c in track.colour_rgb))
    return body


def build_scenario(recorder: TrackRecorder, xodr_name: str, description: str, step_length_s: float):
    """The scenariogeneration Scenario of a recorded episode."""
    # Imported here, not at module top: scenariogeneration takes about half a second to import, and only
    # --export-xosc needs it.
    from scenariogeneration import xosc

    entities = xosc.Entities()
    tracks: dict[str, Track] = {}
    for vid, track in recorder.exported_vehicles().items():
        entities.add_scenario_object(vid, _vehicle(xosc, vid, track))
        tracks[vid] = track
    ped = recorder.pedestrian
    ped_box = xosc.BoundingBox(ped.width_m, ped.length_m, ped.height_m, 0.0, 0.0, ped.height_m / 2)
    walker = xosc.Pedestrian(PED_ID, PEDESTRIAN_MASS_KG, xosc.PedestrianCategory.pedestrian, ped_box)
    walker.add_property("color", ",".join(str(c) for c in ped.colour_rgb))
    entities.add_scenario_object(PED_ID, walker)
    tracks[PED_ID] = ped

    init = xosc.Init()
    act = xosc.Act("replay", _time_trigger(xosc, "replay_start", 0.0))
    end_s = recorder.times_s[-1]
    for name, track in tracks.items():
        first = xosc.WorldPosition(track.x_m[0], track.y_m[0], 0.0, track.yaw_rad[0])
        init.add_init_action(name, xosc.TeleportAction(first))
        maneuver = xosc.Maneuver(f"{name}_maneuver")
        follow = xosc.Event(f"{name}_follows_log", xosc.Priority.override)
        follow.add_action(f"{name}_follow", _follow_log(xosc, name, track))
        follow.add_trigger(_time_trigger(xosc, f"{name}_start", 0.0))
        maneuver.add_event(follow)
        if track.times_s[-1] < end_s:
            # Left the road (SUMO removed it) before the end: gone one step after its last position.
            leave = xosc.Event(f"{name}_leaves", xosc.Priority.parallel)
            leave.add_action(f"{name}_removed", xosc.DeleteEntityAction(name))
            leave.add_trigger(_time_trigger(xosc, f"{name}_gone", track.times_s[-1] + step_length_s))
            maneuver.add_event(leave)
        group = xosc.ManeuverGroup(f"{name}_group")
        group.add_actor(name)
        group.add_maneuver(maneuver)
        act.add_maneuver_group(group)
    story = xosc.Story("logged_episode")
    story.add_act(act)
    stop = xosc.ValueTrigger(
        "episode_end",
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


def write_xosc(
    recorder: TrackRecorder, net_path: Path, path: Path, description: str, step_length_s: float
) -> tuple[Path, Path]:
    """Write `path` (.xosc) and its road `path.with_suffix('.xodr')`, each through a temporary name
    renamed when complete (a failure leaves any earlier export as it was)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    xodr = path.with_suffix(".xodr")
    tmp_xodr = xodr.with_name(xodr.name + ".tmp")
    tmp = path.with_name(path.name + ".tmp")
    try:
        write_opendrive(net_path, tmp_xodr)
        scenario = build_scenario(recorder, xodr.name, f"{description}; {OSM_ATTRIBUTION}", step_length_s)
        scenario.write_xml(str(tmp))
        tmp_xodr.replace(xodr)
        tmp.replace(path)
    finally:
        tmp_xodr.unlink(missing_ok=True)
        tmp.unlink(missing_ok=True)
    return path, xodr
