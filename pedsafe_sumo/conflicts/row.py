"""The output row of one measured interaction (ROW_COLUMNS, docs/conflicts.md): from its stacked log,
its measures (`pedsafe_sumo.safety.interaction.measures_of_steps`), its place and its meeting rules."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.geometry import first_polyline_crossing
from pedsafe_sumo.safety.interaction import InteractionMeasures

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

#: Whether the network lets them meet: (vehicle lane, person edge) -> (kind of place, True / False / None
#: for not known), `pedsafe_sumo.conflicts.meeting.MeetingRules`.
MeetingLookup = Callable[[str, str], tuple[str, "bool | None"]]


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


def step_turns_rad(yaw_rad: np.ndarray) -> np.ndarray:
    """The heading's change from each step to the next, taken the short way round (crossing +-180 deg is
    no turn), rad. Element by element: over the steps of many interactions stacked, each interaction's
    turns are its own slice (one fewer than its steps)."""
    return (np.diff(yaw_rad) + math.pi) % (2.0 * math.pi) - math.pi


def turn_degrees(turns_rad: np.ndarray, starts: list[int], stops: list[int]) -> list[float]:
    """How far the heading ranges over the steps of each of the stacked interactions (interaction k from
    starts[k] to stops[k]; `turns_rad` over all their steps, `step_turns_rad`), deg: the spread of its
    summed step-to-step turns, the heading at its first step counting as 0. Each interaction's turns are
    laid in one row of a table padded with zeros after them, and summed along the row (a running sum adds
    in order: the same floats as the interaction's own `np.cumsum`; the zeros repeat its last sum)."""
    counts = np.asarray(stops) - np.asarray(starts) - 1  # turns: one fewer than steps
    table = np.zeros((len(starts), max(int(counts.max(initial=0)), 1)))
    row = np.repeat(np.arange(len(starts)), counts)
    # interaction k's turns are turns_rad[starts[k] : stops[k] - 1]; `within`: the place in its row
    first_turn = np.repeat(np.asarray(starts), counts)
    within = np.arange(len(row)) - np.repeat(np.cumsum(counts) - counts, counts)
    table[row, within] = turns_rad[first_turn + within]
    heading = np.cumsum(table, axis=1)
    highest, lowest = heading.max(axis=1).tolist(), heading.min(axis=1).tolist()
    return [math.degrees(max(0.0, hi) - min(0.0, lo)) for hi, lo in zip(highest, lowest)]


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
    vehicle_type: str,
    person_type: str,
    log: dict[str, np.ndarray],
    speeds: np.ndarray,
    m: InteractionMeasures,
    turn_deg: float,
    lane_crossing: tuple[str, str],
    places_at_min: tuple[str, str],
    places_judged: tuple[str, str],
    meeting: MeetingLookup | None = None,
) -> dict[str, Any]:
    """The output row of one finished interaction (ROW_COLUMNS): its log (_STEP_COLUMNS), its vehicle's
    and person's FCD speeds (two rows), its measures (`measures_of_steps`), how far its vehicle turned
    (`turn_degrees`), the lane and crossing at the person's place at the minimum clearance, and the FCD's
    (vehicle lane, person edge) at the minimum clearance and at the step judged (the first contact, else
    the minimum clearance)."""
    t = log[steplog.TIME]
    k = m.min_clearance_step
    x_m, y_m = float(log[steplog.PED_X][k]), float(log[steplog.PED_Y][k])
    lane_id, crossing_id = lane_crossing
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
    meeting_kind, may_meet = meeting(*places_judged) if meeting is not None else ("", None)
    # On coarse FCD a turning vehicle extrapolated straight makes conflicts that are not there: flagged.
    period_s = float(t[-1] - t[0]) / (len(t) - 1) if len(t) > 1 else math.nan
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
        "vehicle_type": vehicle_type,
        "person_type": person_type,
        "begin_s": float(t[0]),
        "end_s": float(t[-1]),
        "time_s": float(t[k]),
        "x_m": x_m,
        "y_m": y_m,
        "vehicle_lane": places_at_min[0],
        "person_edge": places_at_min[1],
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
