"""Pedestrian-vehicle interactions in a stream of FCD timesteps, and their row of measures.

An interaction of vehicle V and person P is a run of consecutive timesteps at which both are in the file
and V's footprint centre lies within the interaction radius of P. It ends at the first timestep that
breaks the run (one of them gone, or apart); if they meet again later, that is a new interaction. Only
open interactions are held in memory, so memory depends on how many pairs are near each other at once,
never on the length of the simulation.

The measures of a finished interaction come from `pedsafe_sumo.safety.interaction` (the same functions
as a batch episode's indexes), on a log built in the contract of `pedsafe_sumo.safety.log`: the vehicle's
centre half a length behind SUMO's front-bumper position, its velocity its speed along its heading, the
person's velocity its speed along its angle.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from pedsafe_sumo.conflicts.fcd import FcdStep
from pedsafe_sumo.conflicts.sizes import SizeBook
from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import first_polyline_crossing
from pedsafe_sumo.safety.interaction import interaction_measures
from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre

#: Columns of the per-step buffer of an open interaction, in the log contract's names.
_STEP_COLUMNS = (
    steplog.TIME,
    steplog.EGO_X,
    steplog.EGO_Y,
    steplog.EGO_YAW,
    steplog.EGO_SPEED,
    steplog.EGO_LENGTH,
    steplog.EGO_WIDTH,
    steplog.PED_X,
    steplog.PED_Y,
    steplog.PED_VX,
    steplog.PED_VY,
    steplog.PED_RADIUS,
)

#: The output columns, in order (docs/conflicts.md defines each).
ROW_COLUMNS = (
    "vehicle_id",
    "person_id",
    "vehicle_type",
    "person_type",
    "begin_s",
    "end_s",
    "time_s",
    "x_m",
    "y_m",
    "vehicle_lane",
    "person_edge",
    "lane_id",
    "crossing_id",
    "vehicle_speed_mps",
    "person_speed_mps",
    "min_clearance_m",
    "collision",
    "contact_time_s",
    "ttc_s",
    "ttc_time_s",
    "ttc_x_m",
    "ttc_y_m",
    "pet_s",
    "pet_x_m",
    "pet_y_m",
    "drac_mps2",
    "md_m",
    "tmd_s",
    "cs_mps",
    "conflict_probability",
    "conflict",
    "conflict_time_s",
)
STRING_COLUMNS = (
    "vehicle_id",
    "person_id",
    "vehicle_type",
    "person_type",
    "vehicle_lane",
    "person_edge",
    "lane_id",
    "crossing_id",
)
BOOL_COLUMNS = ("collision", "conflict")


@dataclass
class _Open:
    """An open interaction: its per-step values so far."""

    vehicle_type: str
    person_type: str
    values: list[tuple[float, ...]] = field(default_factory=list)
    vehicle_lanes: list[str] = field(default_factory=list)
    person_edges: list[str] = field(default_factory=list)
    vehicle_speeds: list[float] = field(default_factory=list)
    person_speeds: list[float] = field(default_factory=list)


#: Finds the lane and the crossing at a point: (x_m, y_m) -> (lane_id, crossing_id); "" where none.
PlaceLookup = Callable[[float, float], tuple[str, str]]


class InteractionTracker:
    """Feed it FCD timesteps in order; it calls `emit(row)` for every interaction as it ends.

    `finish()` ends the interactions still open at the end of the file.
    """

    def __init__(
        self,
        radius_m: float,
        sizes: SizeBook,
        emit: Callable[[dict[str, Any]], None],
        place: PlaceLookup | None = None,
    ) -> None:
        self.radius_m = radius_m
        self.sizes = sizes
        self.emit = emit
        self.place = place
        self.open: dict[tuple[str, str], _Open] = {}
        self.steps = 0
        self.vehicle_rows = 0
        self.person_rows = 0
        self.interactions = 0

    def step(self, step: FcdStep) -> None:
        self.steps += 1
        vehicles, persons = step.vehicles, step.persons
        self.vehicle_rows += len(vehicles)
        self.person_rows += len(persons)
        near: set[tuple[str, str]] = set()
        if len(vehicles) and len(persons):
            length, width = self.sizes.vehicle_sizes(vehicles.types, vehicles.length_m, vehicles.width_m)
            yaw = sumo_angle_to_yaw_rad(vehicles.angle_deg)
            cx, cy = sumo_front_to_centre(vehicles.x_m, vehicles.y_m, yaw, length)
            radius = self.sizes.person_radii(persons.types, persons.length_m, persons.width_m)
            p_yaw = sumo_angle_to_yaw_rad(persons.angle_deg)
            pvx, pvy = persons.speed_mps * np.cos(p_yaw), persons.speed_mps * np.sin(p_yaw)
            tree = cKDTree(np.column_stack((persons.x_m, persons.y_m)))
            for i, hits in enumerate(tree.query_ball_point(np.column_stack((cx, cy)), self.radius_m)):
                for j in hits:
                    key = (vehicles.ids[i], persons.ids[j])
                    near.add(key)
                    record = self.open.get(key)
                    if record is None:
                        record = self.open[key] = _Open(vehicles.types[i], persons.types[j])
                    record.values.append(
                        (
                            step.time_s,
                            cx[i],
                            cy[i],
                            yaw[i],
                            max(vehicles.speed_mps[i], 0.0),
                            length[i],
                            width[i],
                            persons.x_m[j],
                            persons.y_m[j],
                            pvx[j],
                            pvy[j],
                            radius[j],
                        )
                    )
                    record.vehicle_lanes.append(vehicles.places[i])
                    record.person_edges.append(persons.places[j])
                    record.vehicle_speeds.append(float(vehicles.speed_mps[i]))
                    record.person_speeds.append(float(persons.speed_mps[j]))
        for key in [k for k in self.open if k not in near]:
            self._close(key)

    def finish(self) -> None:
        for key in list(self.open):
            self._close(key)

    def _close(self, key: tuple[str, str]) -> None:
        record = self.open.pop(key)
        self.interactions += 1
        self.emit(interaction_row(key[0], key[1], record, self.place))


def interaction_row(
    vehicle_id: str, person_id: str, record: _Open, place: PlaceLookup | None
) -> dict[str, Any]:
    """The output row of one finished interaction (ROW_COLUMNS)."""
    table = np.asarray(record.values, dtype=float)
    log = {name: table[:, k] for k, name in enumerate(_STEP_COLUMNS)}
    m = interaction_measures(log)
    t = log[steplog.TIME]
    k = m.min_clearance_step
    x_m, y_m = float(log[steplog.PED_X][k]), float(log[steplog.PED_Y][k])
    lane_id, crossing_id = place(x_m, y_m) if place is not None else ("", "")
    crossing = (
        None
        if m.collision
        else first_polyline_crossing(
            log[steplog.EGO_X], log[steplog.EGO_Y], log[steplog.PED_X], log[steplog.PED_Y]
        )
    )
    if m.collision:
        crossing = (float(log[steplog.PED_X][m.contact_step]), float(log[steplog.PED_Y][m.contact_step]))
    has_pet = math.isfinite(m.pet_s)

    def at(step: int | None) -> float:
        return float(t[step]) if step is not None else math.nan

    return {
        "vehicle_id": vehicle_id,
        "person_id": person_id,
        "vehicle_type": record.vehicle_type,
        "person_type": record.person_type,
        "begin_s": float(t[0]),
        "end_s": float(t[-1]),
        "time_s": float(t[k]),
        "x_m": x_m,
        "y_m": y_m,
        "vehicle_lane": record.vehicle_lanes[k],
        "person_edge": record.person_edges[k],
        "lane_id": lane_id,
        "crossing_id": crossing_id,
        "vehicle_speed_mps": record.vehicle_speeds[k],
        "person_speed_mps": record.person_speeds[k],
        "min_clearance_m": m.min_clearance_m,
        "collision": m.collision,
        "contact_time_s": at(m.contact_step),
        "ttc_s": m.ttc_s,
        "ttc_time_s": at(m.ttc_step),
        "ttc_x_m": float(log[steplog.PED_X][m.ttc_step]) if m.ttc_step is not None else math.nan,
        "ttc_y_m": float(log[steplog.PED_Y][m.ttc_step]) if m.ttc_step is not None else math.nan,
        "pet_s": m.pet_s,
        "pet_x_m": crossing[0] if has_pet and crossing else math.nan,
        "pet_y_m": crossing[1] if has_pet and crossing else math.nan,
        "drac_mps2": m.drac_mps2,
        "md_m": m.md_m,
        "tmd_s": m.tmd_s,
        "cs_mps": m.cs_mps,
        "conflict_probability": m.conflict_probability,
        "conflict": m.conflict,
        "conflict_time_s": at(m.conflict_step),
    }
