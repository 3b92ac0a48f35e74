"""Pedestrian-vehicle interactions in a stream of FCD timesteps, and their row of measures.

An interaction of vehicle V and person P is a run of consecutive timesteps at which both are in the file
and V's footprint centre lies within the interaction radius of P. It ends at the first timestep that
breaks the run (one of them gone, or apart); if they meet again later, that is a new interaction. Only
the open interactions and at most a batch of ended ones waiting to be measured (FLUSH_INTERACTIONS,
FLUSH_ROWS) are held in memory, so memory depends on how many pairs are near each other at once, never
on the length of the simulation.

The measures of a finished interaction come from `pedsafe_sumo.safety.interaction` (the same functions
as a batch episode's indexes), on a log built in the contract of `pedsafe_sumo.safety.log`: the vehicle's
centre half a length behind SUMO's front-bumper position, its velocity its speed along its heading, the
person's velocity its speed along its angle.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pedsafe_sumo.conflicts.fcd import FcdError, FcdStep
from pedsafe_sumo.conflicts.row import MeetingLookup, interaction_row, step_turns_rad, turn_degrees
from pedsafe_sumo.conflicts.sizes import SizeBook
from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.interaction import measures_of_stacked_steps, step_measures_of_rows
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

#: Numbers held per step of an interaction: the log columns, the vehicle's and the person's FCD speed,
#: and the codes of the vehicle's lane and the person's edge (InteractionTracker's place names).
_ROW_WIDTH = len(_STEP_COLUMNS) + 4
#: Where a pair's row takes its vehicle's numbers (centre x, y, yaw, speed (not below 0), length, width,
#: FCD speed, lane code) and its person's (x, y, vx, vy, radius, FCD speed, edge code); column 0 is the time.
_VEHICLE_ROW_COLUMNS = [1, 2, 3, 4, 5, 6, 12, 14]
_PERSON_ROW_COLUMNS = [7, 8, 9, 10, 11, 13, 15]

#: The interactions that have ended are measured together once this many have ended (or at the end of the
#: file): they share the fixed cost of some hundred numpy operations, of one place lookup over the net and
#: of taking their rows out of the table of held rows. Measured (BENCHMARKS.md, "Pedestrian conflicts: CPU
#: per interaction"): on Xueqing's FCD 256 costs 4 % less CPU than 64; a batch of a few hundred
#: interactions of a few dozen steps holds a few MB while it is measured.
FLUSH_INTERACTIONS = 256
#: ... or once the ended interactions waiting hold this many rows, so that what waits stays bounded however
#: long they are (16 numbers a row: 2 MB).
FLUSH_ROWS = 16384
#: Rows the table of held rows has room for at first. It doubles when a timestep's rows do not fit (each
#: timestep's rows are written into it in place, not joined to it): its size follows the most rows held
#: at once, never the length of the file.
HELD_ROWS_AT_FIRST = 4096

#: Finds the lane and the crossing at a point: (x_m, y_m) -> (lane_id, crossing_id); "" where none.
#: An object with a `many(x_m, y_m)` method (arrays -> a list of such pairs) is asked for all the
#: interactions measured together at once (`pedsafe_sumo.conflicts.places.PlaceFinder`).
PlaceLookup = Callable[[float, float], tuple[str, str]]


class InteractionTracker:
    """Feed it FCD timesteps in order; it calls `emit(row)` for every interaction, in the order the
    interactions end (those ending at one timestep in the order they began), some timesteps after it ends:
    the ended interactions are measured together (FLUSH_INTERACTIONS, FLUSH_ROWS).

    `finish()` ends the interactions still open at the end of the file and measures all that are left.

    The rows of all interactions are held in one table, each row tagged with its interaction's number
    (its slot: numbered in the order the interactions began). A vehicle and a person get an integer code
    while they are in the file; a pair's key is the two codes, and the open pairs are found among a
    timestep's near pairs by a sorted search, not pair by pair.
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
        self.steps = 0
        self.vehicle_rows = 0
        self.person_rows = 0
        self.interactions = 0
        #: codes of the vehicles and persons of the last timestep with near pairs (codes start at 1)
        self._vehicle_codes: dict[str, int] = {}
        self._person_codes: dict[str, int] = {}
        self._next_code = 1
        #: lane and edge names -> their codes in the rows (the names of the network or of the file)
        self._place_codes: dict[str, int] = {}
        #: keys (vehicle code << 32 | person code) of the open interactions, sorted, and their slots
        self._open_keys = np.empty(0, dtype=np.int64)
        self._open_slots = np.empty(0, dtype=np.int64)
        #: how many steps each open interaction has so far (aligned with _open_keys)
        self._open_steps = np.empty(0, dtype=np.int64)
        self._next_slot = 0
        #: slot -> (vehicle id, person id, vehicle type, person type) of the interactions not yet measured
        self._meta: dict[int, tuple[str, str, str, str]] = {}
        #: the held rows (all steps of the open interactions and of the ended ones not yet measured): the
        #: first _held rows of the table, and their slots
        self._rows = np.empty((HELD_ROWS_AT_FIRST, _ROW_WIDTH))
        self._slots = np.empty(HELD_ROWS_AT_FIRST, dtype=np.int64)
        self._held = 0
        #: slots of the interactions that ended and wait to be measured, in the order they ended
        self._ended: list[np.ndarray] = []
        self._ended_count = 0
        self._ended_rows = 0

    @property
    def open_interactions(self) -> int:
        """How many interactions are open (their pair near at the last timestep)."""
        return len(self._open_keys)

    def _codes(
        self, ids: list[str], known: dict[str, int], kind: str, time_s: float
    ) -> tuple[dict[str, int], np.ndarray]:
        """(the codes of this timestep's ids as a dict and as an array): ids of the last timestep with near
        pairs keep their code, the others get a new one (never given before)."""
        found = list(map(known.get, ids))
        codes: list[int] = found  # type: ignore[assignment]  # the None among them replaced next
        if None in found:
            for k, code in enumerate(found):
                if code is None:
                    codes[k] = self._next_code
                    self._next_code += 1
        present = dict(zip(ids, codes))
        if len(present) != len(ids):
            seen: set[str] = set()
            twice = next(i for i in ids if i in seen or seen.add(i))  # type: ignore[func-returns-value]
            raise FcdError(f"{kind} '{twice}' appears more than once at t={time_s:g} s")
        return present, np.array(codes, dtype=np.int64)

    def _place_code_array(self, places: list[str]) -> np.ndarray:
        known = self._place_codes
        codes = list(map(known.get, places))  # most names are known: looked up at C speed
        if None in codes:
            for k, name in enumerate(places):
                if codes[k] is None:
                    codes[k] = known.setdefault(name, len(known))
        return np.array(codes, dtype=float)

    def step(self, step: FcdStep) -> None:
        self.steps += 1
        vehicles, persons = step.vehicles, step.persons
        self.vehicle_rows += len(vehicles)
        self.person_rows += len(persons)
        keys = slots = counts = np.empty(0, dtype=np.int64)
        if len(vehicles) and len(persons):
            length, width = self.sizes.vehicle_sizes(vehicles.types, vehicles.length_m, vehicles.width_m)
            yaw = sumo_angle_to_yaw_rad(vehicles.angle_deg)
            cx, cy = sumo_front_to_centre(vehicles.x_m, vehicles.y_m, yaw, length)
            radius = self.sizes.person_radii(persons.types, persons.length_m, persons.width_m)
            p_yaw = sumo_angle_to_yaw_rad(persons.angle_deg)
            pvx, pvy = persons.speed_mps * np.cos(p_yaw), persons.speed_mps * np.sin(p_yaw)
            vi, pj = pairs_within(cx, cy, persons.x_m, persons.y_m, self.radius_m)
            if len(vi):
                time_s = step.time_s
                self._vehicle_codes, v_codes = self._codes(
                    vehicles.ids, self._vehicle_codes, "vehicle", time_s
                )
                self._person_codes, p_codes = self._codes(persons.ids, self._person_codes, "person", time_s)
                keys = (v_codes[vi] << 32) | p_codes[pj]
                vehicle_columns = np.column_stack(
                    (
                        cx,
                        cy,
                        yaw,
                        np.maximum(vehicles.speed_mps, 0.0),
                        length,
                        width,
                        vehicles.speed_mps,
                        self._place_code_array(vehicles.places),
                    )
                )
                person_columns = np.column_stack(
                    (
                        persons.x_m,
                        persons.y_m,
                        pvx,
                        pvy,
                        radius,
                        persons.speed_mps,
                        self._place_code_array(persons.places),
                    )
                )
                slots, counts = self._slots_of(keys, vi, pj, vehicles, persons)
                first, stop = self._held, self._held + len(vi)
                self._make_room(stop)
                rows = self._rows[first:stop]
                rows[:, 0] = time_s
                rows[:, _VEHICLE_ROW_COLUMNS] = vehicle_columns[vi]
                rows[:, _PERSON_ROW_COLUMNS] = person_columns[pj]
                self._slots[first:stop] = slots
                self._held = stop
        order = np.argsort(keys)
        sorted_keys = keys[order]
        if len(self._open_keys):
            # the open interactions whose pair is not near at this timestep end here, in slot order
            still = np.zeros(len(self._open_keys), dtype=bool)
            if len(keys):
                at = np.minimum(np.searchsorted(sorted_keys, self._open_keys), len(keys) - 1)
                still = sorted_keys[at] == self._open_keys
            self._end(self._open_slots[~still], self._open_steps[~still])
        self._open_keys, self._open_slots, self._open_steps = sorted_keys, slots[order], counts[order]
        if self._ended_count >= FLUSH_INTERACTIONS or self._ended_rows >= FLUSH_ROWS:
            self._flush()

    def _slots_of(
        self, keys: np.ndarray, vi: np.ndarray, pj: np.ndarray, vehicles, persons
    ) -> tuple[np.ndarray, np.ndarray]:
        """(the slot of each near pair: its open interaction's, or a new one numbered in pair order; how
        many steps its interaction has with this one)."""
        slots = np.empty(len(keys), dtype=np.int64)
        counts = np.ones(len(keys), dtype=np.int64)
        found = np.zeros(len(keys), dtype=bool)
        if len(self._open_keys):
            at = np.minimum(np.searchsorted(self._open_keys, keys), len(self._open_keys) - 1)
            found = self._open_keys[at] == keys
            slots[found] = self._open_slots[at[found]]
            counts[found] += self._open_steps[at[found]]
        new = np.flatnonzero(~found)
        if len(new):
            first = self._next_slot
            self._next_slot += len(new)
            slots[new] = np.arange(first, self._next_slot)
            for slot, i, j in zip(range(first, self._next_slot), vi[new].tolist(), pj[new].tolist()):
                self._meta[slot] = (vehicles.ids[i], persons.ids[j], vehicles.types[i], persons.types[j])
        return slots, counts

    def _end(self, slots: np.ndarray, steps: np.ndarray) -> None:
        """The interactions of `slots` (with so many steps each) end: queued in slot order."""
        if len(slots):
            self._ended.append(np.sort(slots))
            self._ended_count += len(slots)
            self._ended_rows += int(steps.sum())

    def _make_room(self, rows: int) -> None:
        """The table of held rows with room for `rows` rows: doubled (or more) when it has not."""
        if rows > len(self._rows):
            size = max(2 * len(self._rows), rows)
            grown, grown_slots = np.empty((size, _ROW_WIDTH)), np.empty(size, dtype=np.int64)
            grown[: self._held], grown_slots[: self._held] = (
                self._rows[: self._held],
                self._slots[: self._held],
            )
            self._rows, self._slots = grown, grown_slots

    def finish(self) -> None:
        self._end(self._open_slots, self._open_steps)
        self._open_keys = self._open_slots = self._open_steps = np.empty(0, dtype=np.int64)
        self._flush()

    def _flush(self) -> None:
        """Measure and emit the interactions that have ended, in the order they ended: their rows taken
        out of the held table and stacked interaction after interaction (`_measure`)."""
        if not self._ended:
            return
        ended = np.concatenate(self._ended)
        self._ended, self._ended_count, self._ended_rows = [], 0, 0
        held_rows, held_slots = self._rows[: self._held], self._slots[: self._held]
        # each held row's rank among the ended interactions (in the order they ended), if it is of one
        by_slot = np.argsort(ended)
        sorted_ended = ended[by_slot]
        at = np.minimum(np.searchsorted(sorted_ended, held_slots), len(ended) - 1)
        of_ended = sorted_ended[at] == held_slots
        rank = by_slot[at]
        taken = np.flatnonzero(of_ended)
        taken = taken[np.argsort(rank[taken], kind="stable")]  # stable: each one's steps stay in order
        table = held_rows[taken]
        # the rows kept move to the top of the table, in their order (the indexing copies them first)
        kept = np.flatnonzero(~of_ended)
        self._rows[: len(kept)], self._slots[: len(kept)] = held_rows[kept], held_slots[kept]
        self._held = len(kept)
        stops = np.cumsum(np.bincount(rank[of_ended], minlength=len(ended))).tolist()
        starts = [0, *stops[:-1]]
        metas = [self._meta.pop(slot) for slot in ended.tolist()]
        self._measure(table, starts, stops, metas)

    def _measure(
        self, table: np.ndarray, starts: list[int], stops: list[int], metas: list[tuple[str, str, str, str]]
    ) -> None:
        """The rows of interactions stacked one after another (table; interaction k from starts[k] to
        stops[k]): the per-step measures (clearance, TTC, DRAC, the Amini conflict measures) of all of them
        in one call (`step_measures_of_rows`: each row stands alone), whose fixed cost (some hundred numpy
        operations) they share; their first contacts, minima and maxima over the stack too, the crossing
        of the paths and PET interaction by interaction (`measures_of_stacked_steps`); the places in one
        lookup."""
        # one contiguous array per column: the element-wise measures run faster on it than on strides
        stacked = np.ascontiguousarray(table.T)
        columns = {name: stacked[k] for k, name in enumerate(_STEP_COLUMNS)}
        if not steplog.logs_pass(columns, starts):
            for start, stop in zip(starts, stops):  # raises the contract's message for the first that fails
                kinematic_arrays({name: values[start:stop] for name, values in columns.items()})
        steps = step_measures_of_rows(columns)
        logs = [
            {name: values[start:stop] for name, values in columns.items()}
            for start, stop in zip(starts, stops)
        ]
        measures = measures_of_stacked_steps(columns, steps, starts)
        turns_deg = turn_degrees(step_turns_rad(columns[steplog.EGO_YAW]), starts, stops)
        # the place of each interaction: where the person was at the minimum clearance
        at_min = np.array([start + m.min_clearance_step for start, m in zip(starts, measures)], dtype=np.intp)
        px, py = columns[steplog.PED_X][at_min], columns[steplog.PED_Y][at_min]
        if self.place is None:
            found = [("", "")] * len(measures)
        elif hasattr(self.place, "many"):
            found = self.place.many(px, py)
        else:
            found = [self.place(x, y) for x, y in zip(px.tolist(), py.tolist())]
        names = list(self._place_codes)
        extra = stacked[len(_STEP_COLUMNS) :]
        for meta, log, start, stop, m, turn_deg, lane_crossing in zip(
            metas, logs, starts, stops, measures, turns_deg, found
        ):
            self.interactions += 1
            own = extra[:, start:stop]
            k = m.contact_step if m.contact_step is not None else m.min_clearance_step
            # the FCD's vehicle lane and person edge at the minimum clearance and at the judged step
            at_min_places = (
                names[int(own[2, m.min_clearance_step])],
                names[int(own[3, m.min_clearance_step])],
            )
            judged_places = (names[int(own[2, k])], names[int(own[3, k])])
            vehicle_id, person_id, vehicle_type, person_type = meta
            self.emit(
                interaction_row(
                    vehicle_id,
                    person_id,
                    vehicle_type,
                    person_type,
                    log,
                    own[:2],
                    m,
                    turn_deg,
                    lane_crossing,
                    at_min_places,
                    judged_places,
                    self.meeting,
                )
            )
