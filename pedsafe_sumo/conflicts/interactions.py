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
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pedsafe_sumo.conflicts.fcd import FcdStep
from pedsafe_sumo.conflicts.sizes import SizeBook
from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import first_polyline_crossing
from pedsafe_sumo.safety.interaction import InteractionMeasures, measures_of_steps, step_measures_of_rows
from pedsafe_sumo.safety.proximity import kinematic_arrays
from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre

#: Up to this many vehicle-person distances in a timestep, all are computed at once (a few MB of numpy);
#: above it a k-d tree finds the near pairs (scipy.spatial, 0.2 s to import: most files never need it).
BRUTE_FORCE_PAIRS = 4_000_000


def pairs_within(
    vx_m: np.ndarray, vy_m: np.ndarray, px_m: np.ndarray, py_m: np.ndarray, radius_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """(vehicle indices, person indices) of the pairs whose distance is at most `radius_m`, ordered by
    vehicle and then by person."""
    if len(vx_m) * len(px_m) > BRUTE_FORCE_PAIRS:
        from scipy.spatial import cKDTree  # here, not at the top: see BRUTE_FORCE_PAIRS

        tree = cKDTree(np.column_stack((px_m, py_m)))
        hits = tree.query_ball_point(np.column_stack((vx_m, vy_m)), radius_m, return_sorted=True)
        vi = np.repeat(np.arange(len(vx_m)), [len(h) for h in hits])
        return vi, np.fromiter((j for h in hits for j in h), dtype=np.intp, count=len(vi))
    dx = vx_m[:, None] - px_m[None, :]
    dy = vy_m[:, None] - py_m[None, :]
    vi, pj = np.nonzero(dx * dx + dy * dy <= radius_m * radius_m)
    return vi, pj


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

#: Numbers held per step of an open interaction: the log columns and the two FCD speeds.
_ROW_WIDTH = len(_STEP_COLUMNS) + 2

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
    "meeting",
    "collision",
    "geometry_artefact",
    "contact_time_s",
    "ttc_s",
    "ttc_time_s",
    "ttc_x_m",
    "ttc_y_m",
    "ttc_speed_mps",
    "pet_s",
    "pet_time_s",
    "pet_x_m",
    "pet_y_m",
    "pet_speed_mps",
    "drac_mps2",
    "drac_time_s",
    "drac_x_m",
    "drac_y_m",
    "drac_speed_mps",
    "encounter_type",
    "md_m",
    "tmd_s",
    "cs_mps",
    "conflict_probability",
    "conflict",
    "conflict_time_s",
    "fcd_period_s",
    "vehicle_turn_deg",
    "uncertain",
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
    "meeting",
)
BOOL_COLUMNS = ("collision", "geometry_artefact", "conflict", "uncertain")

#: Above this FCD period the measures that extrapolate at constant velocity (TTC, DRAC, the Amini
#: conflict) are not trusted for a turning vehicle. Stated assumption: a car at 14 m/s on a 10 m turning
#: radius drifts d^2 / (2 R) from its path when extrapolated straight over d: 0.39 m after 0.2 s, under
#: half a car width (0.9 m), but 9.8 m after 1 s.
COARSE_PERIOD_S = 0.2
#: A vehicle whose heading changes by more than this over the interaction is turning (stated
#: assumption: lane changes and curve-following of a straight road stay below it).
TURN_DEG = 10.0


@dataclass
class _Open:
    """An open interaction: its per-step values so far."""

    vehicle_type: str
    person_type: str
    #: per step, flat: the log columns (_STEP_COLUMNS), then the vehicle's and the person's FCD speed
    values: array = field(default_factory=lambda: array("d"))
    #: per step: the vehicle's lane and the person's edge from the FCD
    places: list[tuple[str, str]] = field(default_factory=list)


#: Finds the lane and the crossing at a point: (x_m, y_m) -> (lane_id, crossing_id); "" where none.
PlaceLookup = Callable[[float, float], tuple[str, str]]
#: Whether the network lets them meet: (vehicle lane, person edge) -> (kind of place, True / False / None
#: for not known), `pedsafe_sumo.conflicts.meeting.MeetingRules`.
MeetingLookup = Callable[[str, str], tuple[str, "bool | None"]]


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
        meeting: MeetingLookup | None = None,
    ) -> None:
        self.radius_m = radius_m
        self.sizes = sizes
        self.emit = emit
        self.place = place
        self.meeting = meeting
        self.open: dict[tuple[str, str], _Open] = {}
        #: the interactions that ended at this timestep, measured together (`_flush`)
        self.closed: list[tuple[tuple[str, str], _Open]] = []
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
            vi, pj = pairs_within(cx, cy, persons.x_m, persons.y_m, self.radius_m)
            rows = np.column_stack(
                (
                    np.full(len(vi), step.time_s),
                    cx[vi],
                    cy[vi],
                    yaw[vi],
                    np.maximum(vehicles.speed_mps[vi], 0.0),
                    length[vi],
                    width[vi],
                    persons.x_m[pj],
                    persons.y_m[pj],
                    pvx[pj],
                    pvy[pj],
                    radius[pj],
                    vehicles.speed_mps[vi],
                    persons.speed_mps[pj],
                )
            )
            # Each pair's row appended as its 8-byte doubles (no Python float per number); the pairs'
            # keys and places gathered by whole lists first (fewer Python steps per pair).
            raw, width = memoryview(rows.tobytes()), 8 * _ROW_WIDTH
            v_list, p_list = vi.tolist(), pj.tolist()
            keys = list(zip(map(vehicles.ids.__getitem__, v_list), map(persons.ids.__getitem__, p_list)))
            places = zip(map(vehicles.places.__getitem__, v_list), map(persons.places.__getitem__, p_list))
            near = set(keys)
            open_records, start = self.open, 0
            for key, place, i, j in zip(keys, places, v_list, p_list):
                record = open_records.get(key)
                if record is None:
                    record = open_records[key] = _Open(vehicles.types[i], persons.types[j])
                record.values.frombytes(raw[start : start + width])
                record.places.append(place)
                start += width
        for key in [k for k in self.open if k not in near]:
            self.closed.append((key, self.open.pop(key)))
        self._flush()

    def finish(self) -> None:
        self.closed.extend(self.open.items())
        self.open.clear()
        self._flush()

    def _flush(self) -> None:
        """Measure and emit the interactions that ended at this timestep, in the order they ended: the
        per-step measures (clearance, TTC, DRAC, the Amini conflict measures) of all of them in one call
        (`step_measures_of_rows`: each row stands alone), whose fixed cost (some hundred numpy
        operations) they share; the reductions and the row interaction by interaction. Nothing is held
        from one timestep to the next but the open interactions."""
        if not self.closed:
            return
        tables = [
            np.frombuffer(record.values, dtype=float).reshape(-1, _ROW_WIDTH) for _, record in self.closed
        ]
        stops = np.cumsum([len(table) for table in tables]).tolist()
        starts = [0, *stops[:-1]]
        # one contiguous array per column: the element-wise measures run faster on it than on strides
        stacked = np.ascontiguousarray(np.concatenate(tables).T)
        columns = {name: stacked[k] for k, name in enumerate(_STEP_COLUMNS)}
        if not steplog.logs_pass(columns, starts):
            for table in tables:  # raises the contract's message for the first log that breaks it
                kinematic_arrays({name: table[:, k] for k, name in enumerate(_STEP_COLUMNS)})
        steps = step_measures_of_rows(columns)
        turns = _step_turns_rad(columns[steplog.EGO_YAW])
        for (key, record), start, stop in zip(self.closed, starts, stops):
            self.interactions += 1
            log = {name: values[start:stop] for name, values in columns.items()}
            speeds = stacked[len(_STEP_COLUMNS) :, start:stop]
            m = measures_of_steps(log, steps.part(start, stop))
            row = interaction_row(
                key[0], key[1], record, log, speeds, m, turns[start : stop - 1], self.place, self.meeting
            )
            self.emit(row)
        self.closed = []


#: SUMO's SSM encounter type codes (SSM device documentation, "Encounter types") used for a vehicle and
#: a person: the vehicle comes up behind a person on its own path (no crossing of the two paths).
FOLLOWING_FOLLOWER = 2
#: The two centre paths cross and the vehicle reaches the crossing point first.
CROSSING_LEADER = 10
#: The two centre paths cross and the person reaches the crossing point first.
CROSSING_FOLLOWER = 11
#: The type SUMO gives a PET: both have passed the conflict area.
BOTH_LEFT_CONFLICT_AREA = 17


def _nearest_step(x_m: np.ndarray, y_m: np.ndarray, point: tuple[float, float]) -> int:
    """The first step at which the track (x_m, y_m) is nearest to `point`."""
    return int(np.argmin(np.hypot(x_m - point[0], y_m - point[1])))


def _step_turns_rad(yaw_rad: np.ndarray) -> np.ndarray:
    """The heading's change from each step to the next, taken the short way round (crossing +-180 deg is
    no turn), rad. Element by element: over the steps of many interactions stacked, each interaction's
    turns are its own slice (one fewer than its steps)."""
    return (np.diff(yaw_rad) + math.pi) % (2.0 * math.pi) - math.pi


def _turn_deg(step_turns_rad: np.ndarray) -> float:
    """How far the heading ranges over the steps, deg: the spread of the summed step-to-step turns
    (`_step_turns_rad`), the heading at the first step counting as 0."""
    if len(step_turns_rad) == 0:
        return 0.0
    heading = np.cumsum(step_turns_rad)
    return math.degrees(float(max(0.0, float(heading.max())) - min(0.0, float(heading.min()))))


def _encounter_type(ex, ey, px, py, path_crossing: tuple[float, float] | None) -> int:
    """SUMO's encounter type of the interaction's TTC and DRAC: who reaches the crossing of the two
    centre paths first, or FOLLOWING_FOLLOWER when the paths do not cross (the person on the car's path)."""
    if path_crossing is None:
        return FOLLOWING_FOLLOWER
    vehicle_first = _nearest_step(ex, ey, path_crossing) <= _nearest_step(px, py, path_crossing)
    return CROSSING_LEADER if vehicle_first else CROSSING_FOLLOWER


def interaction_row(
    vehicle_id: str,
    person_id: str,
    record: _Open,
    log: dict[str, np.ndarray],
    speeds: np.ndarray,
    m: InteractionMeasures,
    step_turns_rad: np.ndarray,
    place: PlaceLookup | None,
    meeting: MeetingLookup | None = None,
) -> dict[str, Any]:
    """The output row of one finished interaction (ROW_COLUMNS): its log (_STEP_COLUMNS), its vehicle's
    and person's FCD speeds (two rows), its measures (`measures_of_steps`) and its vehicle's turns from
    step to step (`_step_turns_rad`)."""
    t = log[steplog.TIME]
    k = m.min_clearance_step
    x_m, y_m = float(log[steplog.PED_X][k]), float(log[steplog.PED_Y][k])
    lane_id, crossing_id = place(x_m, y_m) if place is not None else ("", "")
    vehicle_speed, person_speed = speeds[0], speeds[1]
    ex, ey, px, py = log[steplog.EGO_X], log[steplog.EGO_Y], log[steplog.PED_X], log[steplog.PED_Y]
    drac_step = m.drac_step
    # Where the centre paths cross: the PET's point without a contact and the encounter type of a TTC or
    # DRAC. The measures found it without a contact; with one it is sought only for a TTC or DRAC.
    path_crossing = m.path_crossing
    if m.collision and (m.ttc_step is not None or drac_step is not None):
        path_crossing = first_polyline_crossing(ex, ey, px, py)
    # The encroachment point: where the two met for a contact, else where the centre paths cross.
    point: tuple[float, float] | None
    if m.collision:
        point = (float(px[m.contact_step]), float(py[m.contact_step]))
    else:
        point = path_crossing if math.isfinite(m.pet_s) else None
    pet_step = None
    if m.collision:
        pet_step = m.contact_step
    elif point is not None:
        pet_step = max(_nearest_step(ex, ey, point), _nearest_step(px, py, point))
    # Judged where they touched first, else at the minimum clearance: a contact is a collision only where
    # the network lets the two meet (docs/conflicts.md, "Where vehicles and persons meet").
    judged = m.contact_step if m.contact_step is not None else k
    meeting_kind, may_meet = meeting(*record.places[judged]) if meeting is not None else ("", None)
    # On coarse FCD a turning vehicle extrapolated straight makes conflicts that are not there: flagged.
    period_s = float(t[-1] - t[0]) / (len(t) - 1) if len(t) > 1 else math.nan
    turn_deg = _turn_deg(step_turns_rad)
    extrapolated = m.conflict or math.isfinite(m.ttc_s)
    uncertain = bool(not m.collision and extrapolated and period_s > COARSE_PERIOD_S and turn_deg > TURN_DEG)
    encounter_type = math.nan
    if m.ttc_step is not None or drac_step is not None:
        encounter_type = float(_encounter_type(ex, ey, px, py, path_crossing))

    def at(step: int | None) -> float:
        return float(t[step]) if step is not None else math.nan

    def speed_at(step: int | None) -> float:
        return float(vehicle_speed[step]) if step is not None else math.nan

    def person_at(step: int | None) -> tuple[float, float]:
        return (float(px[step]), float(py[step])) if step is not None else (math.nan, math.nan)

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
        "vehicle_lane": record.places[k][0],
        "person_edge": record.places[k][1],
        "lane_id": lane_id,
        "crossing_id": crossing_id,
        "vehicle_speed_mps": float(vehicle_speed[k]),
        "person_speed_mps": float(person_speed[k]),
        "min_clearance_m": m.min_clearance_m,
        "meeting": meeting_kind,
        "collision": m.collision and may_meet is not False,
        "geometry_artefact": m.collision and may_meet is False,
        "contact_time_s": at(m.contact_step),
        "ttc_s": m.ttc_s,
        "ttc_time_s": at(m.ttc_step),
        "ttc_x_m": person_at(m.ttc_step)[0],
        "ttc_y_m": person_at(m.ttc_step)[1],
        "ttc_speed_mps": speed_at(m.ttc_step),
        "pet_s": m.pet_s,
        "pet_time_s": at(pet_step),
        "pet_x_m": point[0] if point is not None else math.nan,
        "pet_y_m": point[1] if point is not None else math.nan,
        "pet_speed_mps": speed_at(pet_step),
        "drac_mps2": m.drac_mps2,
        "drac_time_s": at(drac_step),
        "drac_x_m": person_at(drac_step)[0],
        "drac_y_m": person_at(drac_step)[1],
        "drac_speed_mps": speed_at(drac_step),
        "encounter_type": encounter_type,
        "md_m": m.md_m,
        "tmd_s": m.tmd_s,
        "cs_mps": m.cs_mps,
        "conflict_probability": m.conflict_probability,
        "conflict": m.conflict,
        "conflict_time_s": at(m.conflict_step),
        "fcd_period_s": period_s,
        "vehicle_turn_deg": turn_deg,
        "uncertain": uncertain,
    }
