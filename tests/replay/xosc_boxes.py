"""Every entity's box in an exported .xosc, rebuilt by OpenSCENARIO's rules from the file alone (plain
XML, nothing of pedsafe_sumo): the reference point's world position and heading from the entity's
trajectory vertex, the BoundingBox Center (in the entity's frame: x forward, y left) and Dimensions.
A vehicle's reference point is the middle of its rear axle: a file whose RearAxle sits at positionX
= a puts the rear axle, and so the point the positions give, a metres ahead of the frame's origin,
and the box's centre Center.x - a ahead of that point (esmini reads it so too).
An entity is in the world from t = 0 when Init places it, from its AddEntityAction's time when one adds
it, and until its DeleteEntityAction's time."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

from shapely.geometry import Polygon


@dataclass
class Entity:
    name: str
    centre_xy: tuple[float, float]
    length_m: float
    width_m: float
    #: vertex time -> (x, y, h) of the reference point
    vertices: dict[float, tuple[float, float, float]] = field(default_factory=dict)
    added_s: float | None = None
    deleted_s: float = math.inf

    def present(self, time_s: float) -> bool:
        return self.added_s is not None and self.added_s <= time_s < self.deleted_s

    def box(self, time_s: float) -> Polygon:
        x, y, h = self.vertices[time_s]
        cos_h, sin_h = math.cos(h), math.sin(h)
        cx = x + self.centre_xy[0] * cos_h - self.centre_xy[1] * sin_h
        cy = y + self.centre_xy[0] * sin_h + self.centre_xy[1] * cos_h
        corners = []
        for along, across in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
            dx, dy = along * self.length_m / 2, across * self.width_m / 2
            corners.append((cx + dx * cos_h - dy * sin_h, cy + dx * sin_h + dy * cos_h))
        return Polygon(corners)


def _trigger_time(event: ET.Element) -> float:
    return float(event.find("StartTrigger//SimulationTimeCondition").get("value"))


def read_entities(xosc_path: Path) -> dict[str, Entity]:
    root = ET.parse(xosc_path).getroot()
    entities = {}
    for obj in root.iter("ScenarioObject"):
        body = obj.find("Vehicle")
        if body is None:
            body = obj.find("Pedestrian")
        centre = body.find("BoundingBox/Center")
        dims = body.find("BoundingBox/Dimensions")
        rear_axle = body.find("Axles/RearAxle")
        rear_axle_x_m = 0.0 if rear_axle is None else float(rear_axle.get("positionX"))
        entities[obj.get("name")] = Entity(
            obj.get("name"),
            (float(centre.get("x")) - rear_axle_x_m, float(centre.get("y"))),
            float(dims.get("length")),
            float(dims.get("width")),
        )
    for private in root.findall("Storyboard/Init/Actions/Private"):
        if private.find(".//TeleportAction") is not None:
            entities[private.get("entityRef")].added_s = 0.0
    for group in root.iter("ManeuverGroup"):
        for event in group.iter("Event"):
            for entity_action in event.iter("EntityAction"):
                entity = entities[entity_action.get("entityRef")]
                if entity_action.find("AddEntityAction") is not None:
                    entity.added_s = _trigger_time(event)
                if entity_action.find("DeleteEntityAction") is not None:
                    entity.deleted_s = _trigger_time(event)
        actors = [ref.get("entityRef") for ref in group.iter("EntityRef")]
        for vertex in group.iter("Vertex"):
            (name,) = actors
            position = vertex.find("Position/WorldPosition")
            entities[name].vertices[float(vertex.get("time"))] = tuple(float(position.get(k)) for k in "xyh")
    return entities
