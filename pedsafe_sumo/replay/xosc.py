"""A replayed episode as ASAM OpenSCENARIO XML 1.2, its road as OpenDRIVE, for esmini, CARLA's scenario
runner and other OpenSCENARIO players (docs/openscenario.md).

- Road: `netconvert --opendrive-output` from the site's SUMO network, written beside the scenario as
  `<name>.xodr` and referenced by a relative LogicFile path. netconvert keeps the network's x/y frame
  (its OpenDRIVE header carries `<offset>` = -netOffset, the way back to UTM), so the scenario's world
  positions are the SUMO network's x/y, the same numbers as the case log.
- Entities: the ego, the pedestrian, every other vehicle SUMO had during the episode (the kerb-lane
  vehicles the scenario placed and the background traffic) and every background person, with their
  SUMO length, width, height and colour (property `color`, "#RRGGBB").
- Reference points as OpenSCENARIO defines them: a vehicle's is the middle of its rear axle on the
  ground, so a vehicle's BoundingBox Center lies ahead of it (length/2 - rear overhang), its RearAxle
  at positionX 0, and its trajectory is its rear axle's path. A pedestrian's reference point is the
  centre of its footprint (Center x = y = 0).
- Motion: per entity, a FollowTrajectoryAction along a Polyline of its logged reference-point
  positions with their times (absolute timing, position following). A road user on the road at the
  first logged step is placed there in Init (TeleportAction); one that appears later has no Init action
  and is added at its first logged step (AddEntityAction, then the trajectory); one that leaves before
  the end is removed one step after its last position (DeleteEntityAction).
- Traffic lights: every change of a SUMO traffic light's state as TrafficSignalStateActions on the
  OpenDRIVE signals netconvert writes for its links (write_opendrive numbers them).
"""

from __future__ import annotations

import math
import re
import subprocess
from pathlib import Path

from pedsafe_sumo import OSM_ATTRIBUTION
from pedsafe_sumo.replay.xosc_tracks import SignalChange, Track, TrackRecorder
from pedsafe_sumo.sim.staging import PED_ID
from pedsafe_sumo.sumo_binaries import sumo_binary

__all__ = ["Track", "TrackRecorder", "write_xosc", "write_opendrive", "conform_opendrive"]

#: OpenSCENARIO 1.x minor version written: 1.2, the newest whose rules ASAM's checker
#: (asam-qc-openscenarioxml 1.0.0) defines, so that every one of its checks applies.
OSC_MINOR_VERSION = 2
#: OpenDRIVE 1.x minor version the road is declared as (see conform_opendrive).
XODR_MINOR_VERSION = 6
#: Performance limits the schema requires of a Vehicle; a replay follows the log and never uses them.
#: Chosen above anything a car on this site reaches (50 m/s = 180 km/h, 10 m/s2 ~ 1 g).
MAX_SPEED_MPS, MAX_ACCEL_MPS2, MAX_DECEL_MPS2 = 50.0, 10.0, 10.0
#: Where the axles sit (SUMO has no axles; a passenger car's proportions, stated, not measured): the
#: rear axle 20 % of the length ahead of the rear bumper, the wheelbase 60 % of the length (4.6 m car:
#: 0.92 m rear overhang, 2.76 m wheelbase). The rear axle is the reference point, so these place
#: the bounding box around it; the trajectory keeps the logged footprint exactly wherever they put it.
REAR_OVERHANG_SHARE_OF_LENGTH, WHEELBASE_SHARE_OF_LENGTH = 0.2, 0.6
#: Wheels and steering the schema requires of an Axle (unused by a replay): wheels 0.6 m, track 85 %
#: of the width, 0.5 rad steering.
WHEEL_DIAMETER_M, TRACK_SHARE_OF_WIDTH, MAX_STEER_RAD = 0.6, 0.85, 0.5
#: Pedestrian mass the schema requires (kg, an adult's; unused by a replay).
PEDESTRIAN_MASS_KG = 70.0
#: SUMO's signal state characters as lamp modes of the red;yellow;green light netconvert's signals
#: are (OpenDRIVE types 1000001 and 1000011; the mode list is esmini's, top lamp first, as
#: OpenSCENARIO leaves a state's text to the road network's signal). SUMO: r red, y/Y yellow,
#: g/G green (minor/major), s green after stopping, u red-yellow, o blinking yellow, O off.
LAMPS_OF_SUMO_STATE = {
    "r": "on;off;off",
    "y": "off;on;off",
    "Y": "off;on;off",
    "g": "off;off;on",
    "G": "off;off;on",
    "s": "off;off;on",
    "u": "on;on;off",
    "o": "off;flashing;off",
    "O": "off;off;off",
}


def reference_offset_m(length_m: float) -> float:
    """How far a vehicle's footprint centre lies ahead of its reference point (the rear axle), m."""
    return length_m / 2 - REAR_OVERHANG_SHARE_OF_LENGTH * length_m


def hex_colour(rgb: tuple[int, int, int]) -> str:
    """ "#RRGGBB", the form esmini reads from the `color` property (OpenSCENARIO 1.2 has no colour
    element for an entity: its Color type is a light's)."""
    return "#" + "".join(f"{int(c):02X}" for c in rgb)


def write_opendrive(net_path: Path, xodr_path: Path) -> dict[str, int]:
    """The SUMO network as OpenDRIVE, by netconvert (RuntimeError with its last message on failure).
    Returns the OpenDRIVE signal id of each SUMO traffic light link, "<tls id>_<link index>"."""
    proc = subprocess.run(
        [sumo_binary("netconvert"), "-s", str(net_path), "--opendrive-output", str(xodr_path)]
        + ["--no-warnings", "--output.street-names"],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0 or not xodr_path.is_file():
        last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"netconvert could not write OpenDRIVE from {net_path}: {last}")
    text, signal_ids = number_signals(conform_opendrive(xodr_path.read_text(encoding="utf-8")))
    xodr_path.write_text(text, encoding="utf-8")
    return signal_ids


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


def number_signals(text: str) -> tuple[str, dict[str, int]]:
    """netconvert's signals renumbered 1, 2, ... in the order they appear, SUMO's link kept as the
    signal's `name`; the controllers' `<control signalId>` follow.

    netconvert names a signal after the SUMO traffic light link it shows, "<tls id>_<link index>".
    OpenDRIVE allows such a string id, but players read signal ids as integers (esmini: atoi, so every
    netconvert signal would be signal 0 and no TrafficSignalStateAction could name one), so the ids
    become integers and the SUMO name moves to the `name` attribute."""
    ids: dict[str, int] = {}

    def renumber(match: re.Match) -> str:
        sumo_name = match.group(1)
        number = ids.setdefault(sumo_name, len(ids) + 1)
        return f'<signal id="{number}" name="{sumo_name}"'

    text = re.sub(r'<signal id="([^"]*)"(?![^>]*\bname=)', renumber, text)
    text = re.sub(
        r'<control signalId="([^"]*)"',
        lambda m: f'<control signalId="{ids[m.group(1)]}"' if m.group(1) in ids else m.group(0),
        text,
    )
    return text, ids


def _time_trigger(xosc, name: str, time_s: float, rule=None):
    return xosc.ValueTrigger(
        name,
        0,
        xosc.ConditionEdge.none,
        xosc.SimulationTimeCondition(time_s, rule or xosc.Rule.greaterOrEqual),
    )


def reference_path(track: Track, is_vehicle: bool) -> list[tuple[float, float, float]]:
    """(x, y, heading) of the entity's reference point at each logged time: a vehicle's rear axle,
    reference_offset_m behind its footprint centre along its heading; a pedestrian's centre."""
    back_m = reference_offset_m(track.length_m) if is_vehicle else 0.0
    return [
        (x - back_m * math.cos(h), y - back_m * math.sin(h), h)
        for x, y, h in zip(track.x_m, track.y_m, track.yaw_rad)
    ]


def _follow_log(xosc, name: str, track: Track, path: list[tuple[float, float, float]]):
    positions = [xosc.WorldPosition(x, y, 0.0, h) for x, y, h in path]
    trajectory = xosc.Trajectory(f"{name}_trajectory", False)
    trajectory.add_shape(xosc.Polyline(list(track.times_s), positions))
    # Absolute timing: a vertex's time is simulation time, the log's time_s (scale 1, offset 0).
    return xosc.FollowTrajectoryAction(
        trajectory, xosc.FollowingMode.position, xosc.ReferenceContext.absolute, 1, 0
    )


def _vehicle(xosc, name: str, track: Track):
    # Center in the vehicle's frame, whose origin is the rear axle on the ground.
    centre_x_m = reference_offset_m(track.length_m)
    box = xosc.BoundingBox(track.width_m, track.length_m, track.height_m, centre_x_m, 0.0, track.height_m / 2)
    track_m = TRACK_SHARE_OF_WIDTH * track.width_m
    wheel_z_m = WHEEL_DIAMETER_M / 2
    wheelbase_m = WHEELBASE_SHARE_OF_LENGTH * track.length_m
    front = xosc.Axle(MAX_STEER_RAD, WHEEL_DIAMETER_M, track_m, wheelbase_m, wheel_z_m)
    rear = xosc.Axle(0.0, WHEEL_DIAMETER_M, track_m, 0.0, wheel_z_m)
    body = xosc.Vehicle(
        name, xosc.VehicleCategory.car, box, front, rear, MAX_SPEED_MPS, MAX_ACCEL_MPS2, MAX_DECEL_MPS2
    )
    body.add_property("color", hex_colour(track.colour_rgb))
    return body


def _pedestrian(xosc, name: str, track: Track):
    box = xosc.BoundingBox(track.width_m, track.length_m, track.height_m, 0.0, 0.0, track.height_m / 2)
    walker = xosc.Pedestrian(name, PEDESTRIAN_MASS_KG, xosc.PedestrianCategory.pedestrian, box)
    walker.add_property("color", hex_colour(track.colour_rgb))
    return walker


def _signal_events(xosc, changes: list[SignalChange], signal_ids: dict[str, int]):
    """One event per time a light changed: a TrafficSignalStateAction for each of its links whose state
    differs from before and that has an OpenDRIVE signal (the first state of every such link at t = 0)."""
    group = xosc.ManeuverGroup("traffic_lights")
    maneuver = xosc.Maneuver("traffic_light_states")
    before: dict[str, str] = {}
    first_time_s = changes[0].time_s if changes else 0.0
    for change in changes:
        actions = []
        for index, char in enumerate(change.state):
            link = f"{change.tls_id}_{index}"
            if link not in signal_ids or before.get(link) == char:
                continue
            before[link] = char
            actions.append(
                (link, xosc.TrafficSignalStateAction(str(signal_ids[link]), LAMPS_OF_SUMO_STATE[char]))
            )
        if not actions:
            continue
        stem = f"{change.tls_id}_at_{change.time_s:.3f}s"
        event = xosc.Event(stem, xosc.Priority.parallel)
        for link, action in actions:
            event.add_action(f"signal_{link}_at_{change.time_s:.3f}s", action)
        # The state of the first logged step holds from the start.
        start_s = 0.0 if change.time_s == first_time_s else change.time_s
        event.add_trigger(_time_trigger(xosc, f"{stem}_start", start_s))
        maneuver.add_event(event)
    if not maneuver.events:
        return None
    group.add_maneuver(maneuver)
    return group


def build_scenario(
    recorder: TrackRecorder,
    xodr_name: str,
    description: str,
    step_length_s: float,
    signal_ids: dict[str, int] | None = None,
):
    """The scenariogeneration Scenario of a recorded episode."""
    # Imported here, not at module top: scenariogeneration takes about half a second to import, and only
    # --export-xosc needs it.
    from scenariogeneration import xosc

    entities = xosc.Entities()
    tracks: dict[str, tuple[Track, bool]] = {}
    for vid, track in recorder.exported_vehicles().items():
        entities.add_scenario_object(vid, _vehicle(xosc, vid, track))
        tracks[vid] = (track, True)
    entities.add_scenario_object(PED_ID, _pedestrian(xosc, PED_ID, recorder.pedestrian))
    tracks[PED_ID] = (recorder.pedestrian, False)
    for pid, track in sorted(recorder.persons.items()):
        entities.add_scenario_object(pid, _pedestrian(xosc, pid, track))
        tracks[pid] = (track, False)

    init = xosc.Init()
    act = xosc.Act("replay", _time_trigger(xosc, "replay_start", 0.0))
    first_s, end_s = recorder.times_s[0], recorder.times_s[-1]
    for name, (track, is_vehicle) in tracks.items():
        path = reference_path(track, is_vehicle)
        x, y, h = path[0]
        maneuver = xosc.Maneuver(f"{name}_maneuver")
        follow = xosc.Event(f"{name}_follows_log", xosc.Priority.override)
        if track.times_s[0] == first_s:
            init.add_init_action(name, xosc.TeleportAction(xosc.WorldPosition(x, y, 0.0, h)))
            follow.add_trigger(_time_trigger(xosc, f"{name}_start", 0.0))
        else:
            # Appeared during the episode: no Init action, so not in the world until added here.
            follow.add_action(f"{name}_added", xosc.AddEntityAction(name, xosc.WorldPosition(x, y, 0.0, h)))
            follow.add_trigger(_time_trigger(xosc, f"{name}_enters", track.times_s[0]))
        follow.add_action(f"{name}_follow", _follow_log(xosc, name, track, path))
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
    lights = _signal_events(xosc, recorder.signal_changes, signal_ids or {})
    if lights is not None:
        act.add_maneuver_group(lights)
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
        signal_ids = write_opendrive(net_path, tmp_xodr)
        scenario = build_scenario(
            recorder, xodr.name, f"{description}; {OSM_ATTRIBUTION}", step_length_s, signal_ids
        )
        scenario.write_xml(str(tmp))
        tmp_xodr.replace(xodr)
        tmp.replace(path)
    finally:
        tmp_xodr.unlink(missing_ok=True)
        tmp.unlink(missing_ok=True)
    return path, xodr
