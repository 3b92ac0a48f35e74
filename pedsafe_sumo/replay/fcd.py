"""A replayed episode as SUMO floating car data (FCD XML), for SUMO's own tools.

The file has the layout `sumo --fcd-output` writes, element per line and attributes in SUMO's order
(sumolib's fast parsers and tools/plot_trajectories.py rely on both):

    <fcd-export ...>
        <timestep time="0.05">
            <vehicle id="ego" x=".." y=".." angle=".." type=".." speed=".." pos=".." lane=".." slope=".."/>
            <person id="ped" x=".." y=".." angle=".." type=".." speed=".." pos=".." edge=".." slope=".."/>
        </timestep>

One timestep per logged step. Vehicles (the ego, the kerb-lane vehicles, background traffic) are as
SUMO has them: x, y the middle of the front bumper, angle in degrees clockwise from north. The
pedestrian is where the behaviour model put them, which is the log's `ped_x_m`, `ped_y_m`: SUMO only
receives that position (person.moveToXY) at the next step, so its own person position lags one step
at the start, and its speed for a person moved that way is meaningless; angle and speed are those of
the model's motion. `edge` and `pos` are SUMO's for the person (a person moved across the road stays
logically on its sidewalk).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from pedsafe_sumo import OSM_ATTRIBUTION
from pedsafe_sumo.sim.staging import PED_ID
from pedsafe_sumo.units import yaw_rad_to_sumo_angle

#: Decimal places of positions, angles and speeds (SUMO's --precision; 6 keeps micrometres).
PRECISION = 6


@dataclass(frozen=True)
class VehicleState:
    vehicle_id: str
    x_m: float
    y_m: float
    angle_deg: float
    type_id: str
    speed_mps: float
    lane_pos_m: float
    lane_id: str
    slope_deg: float


@dataclass(frozen=True)
class PersonState:
    person_id: str
    x_m: float
    y_m: float
    angle_deg: float
    type_id: str
    speed_mps: float
    edge_pos_m: float
    edge_id: str
    slope_deg: float


@dataclass(frozen=True)
class Timestep:
    time_s: float
    vehicles: tuple[VehicleState, ...]
    persons: tuple[PersonState, ...]


class FcdRecorder:
    """A per-step hook (EpisodeRunner.run(on_step=...)) that collects every road user each step."""

    def __init__(self, initial_heading_rad: float) -> None:
        self.timesteps: list[Timestep] = []
        #: The pedestrian's heading while standing: their path's direction until they first move.
        self._ped_heading_rad = initial_heading_rad

    def __call__(self, api, row: dict[str, Any]) -> None:
        vehicle = api.vehicle
        vehicles = tuple(
            VehicleState(
                vid,
                *vehicle.getPosition(vid),
                vehicle.getAngle(vid),
                vehicle.getTypeID(vid),
                vehicle.getSpeed(vid),
                vehicle.getLanePosition(vid),
                vehicle.getLaneID(vid),
                vehicle.getSlope(vid),
            )
            for vid in vehicle.getIDList()
        )
        vx, vy = row["ped_vx_mps"], row["ped_vy_mps"]
        speed_mps = math.hypot(vx, vy)
        if speed_mps > 0:
            self._ped_heading_rad = math.atan2(vy, vx)
        person = api.person
        if not math.isfinite(float(row["ped_x_m"])):
            # Not in the scene (before they appear, after they leave): SUMO has no person to describe.
            self.timesteps.append(Timestep(float(row["time_s"]), vehicles, ()))
            return
        persons = (
            PersonState(
                PED_ID,
                float(row["ped_x_m"]),
                float(row["ped_y_m"]),
                float(yaw_rad_to_sumo_angle(self._ped_heading_rad)),
                person.getTypeID(PED_ID),
                speed_mps,
                person.getLanePosition(PED_ID),
                person.getRoadID(PED_ID),
                person.getSlope(PED_ID),
            ),
        )
        self.timesteps.append(Timestep(float(row["time_s"]), vehicles, persons))


def _number(value: float) -> str:
    return f"{value:.{PRECISION}f}"


def _time(time_s: float) -> str:
    """Simulation time as SUMO writes it: two decimals, more only when the step needs them."""
    return f"{time_s:.2f}" if abs(time_s * 100 - round(time_s * 100)) < 1e-6 else f"{time_s:.6f}"


#: One level of indentation (SUMO's own FCD output indents by four spaces).
XML_INDENT = "    "
#: The root's attributes as SUMO writes them (the schema of FCD files).
FCD_ROOT_ATTRIBUTES = {
    "xmlns:xsi": "http://www.w3.org/2001/XMLSchema-instance",
    "xsi:noNamespaceSchemaLocation": "http://sumo.dlr.de/xsd/fcd_file.xsd",
}


def fcd_element(timesteps: list[Timestep]) -> ElementTree.Element:
    """The <fcd-export> element of `timesteps`, attributes in SUMO's order."""
    root = ElementTree.Element("fcd-export", FCD_ROOT_ATTRIBUTES)
    for step in timesteps:
        timestep = ElementTree.SubElement(root, "timestep", {"time": _time(step.time_s)})
        for v in step.vehicles:
            ElementTree.SubElement(
                timestep,
                "vehicle",
                {
                    "id": v.vehicle_id,
                    "x": _number(v.x_m),
                    "y": _number(v.y_m),
                    "angle": _number(v.angle_deg),
                    "type": v.type_id,
                    "speed": _number(v.speed_mps),
                    "pos": _number(v.lane_pos_m),
                    "lane": v.lane_id,
                    "slope": _number(v.slope_deg),
                },
            )
        for person in step.persons:
            ElementTree.SubElement(
                timestep,
                "person",
                {
                    "id": person.person_id,
                    "x": _number(person.x_m),
                    "y": _number(person.y_m),
                    "angle": _number(person.angle_deg),
                    "type": person.type_id,
                    "speed": _number(person.speed_mps),
                    "pos": _number(person.edge_pos_m),
                    "edge": person.edge_id,
                    "slope": _number(person.slope_deg),
                },
            )
    return root


def write_fcd(path: Path, timesteps: list[Timestep], comment: str = "") -> Path:
    """Write `timesteps` as SUMO FCD XML to `path` (through a temporary file, renamed when complete)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    root = fcd_element(timesteps)
    ElementTree.indent(root, space=XML_INDENT)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>']
    for text in (comment, OSM_ATTRIBUTION):
        if text:  # "--" may not stand in an XML comment
            lines.append(
                ElementTree.tostring(ElementTree.Comment(f" {text.replace('--', '- -')} "), "unicode")
            )
    lines.append(ElementTree.tostring(root, encoding="unicode"))
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
        tmp.replace(path)
    except Exception:
        # A write that fails (no room, a folder at the target) leaves nothing beside the target; a process
        # that dies on the way leaves the temporary file, which the next write (or --resume) removes.
        tmp.unlink(missing_ok=True)
        raise
    return path
