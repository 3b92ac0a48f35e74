"""What an OpenSCENARIO export records during the replay: every road user's logged motion and body, and
the traffic lights' states (pedsafe_sumo/replay/xosc.py writes them; docs/openscenario.md).

Positions are footprint centres in the SUMO network's x/y frame, headings the yaw counter-clockwise from
+x; the writer moves a vehicle's centre to its rear axle, OpenSCENARIO's reference point. The ego and
the scenario's pedestrian come from the case log's row; every other vehicle and person from SUMO, whose
position is the middle of the front (pedsafe_sumo/units.py), moved back half a length to the centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pedsafe_sumo.sim.staging import EGO_ID, PED_ID
from pedsafe_sumo.units import sumo_angle_to_yaw_rad, sumo_front_to_centre


@dataclass
class Track:
    """One road user's logged motion (times, centre positions, headings) and its body."""

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


@dataclass(frozen=True)
class SignalChange:
    """A traffic light's state (SUMO's red/yellow/green string, one character per link index) from
    `time_s` on: the first logged step, and every step at which it differs from the step before."""

    time_s: float
    tls_id: str
    state: str


class TrackRecorder:
    """A per-step hook (EpisodeRunner.run(on_step=...)): the ego and the scenario's pedestrian from the
    log row; every other vehicle, every background person and every traffic light from SUMO.
    `vehicle_rgb`: the colours the episode's setup gave its vehicles (the engine sets the staged ones on
    their vehicle type, so SUMO's per-vehicle colour is its default there)."""

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
        #: Background persons (SUMO's pedestrian demand), by id.
        self.persons: dict[str, Track] = {}
        self.signal_changes: list[SignalChange] = []
        self._signal_state: dict[str, str] = {}
        #: The pedestrian's heading while standing: their path's direction until they first move.
        self._ped_heading_rad = initial_heading_rad

    def __call__(self, api, row: dict[str, Any]) -> None:
        time_s = float(row["time_s"])
        self.times_s.append(time_s)
        vehicle = api.vehicle
        for vid in vehicle.getIDList():
            track = self.vehicles.get(vid)
            if track is None:
                colour = self._vehicle_rgb.get(vid) or vehicle.getColor(vid)[:3]
                track = self.vehicles[vid] = _body(vehicle, vid, colour)
            if vid == EGO_ID:
                track.add(time_s, float(row["ego_x_m"]), float(row["ego_y_m"]), float(row["ego_yaw_rad"]))
                continue
            _add_from_front(track, time_s, vehicle, vid)
        person = api.person
        for pid in person.getIDList():
            if pid == PED_ID:
                continue  # the scenario's pedestrian: the log row below, not SUMO's lagging copy
            track = self.persons.get(pid)
            if track is None:
                track = self.persons[pid] = _body(person, pid, person.getColor(pid)[:3])
            _add_from_front(track, time_s, person, pid)
        vx, vy = float(row["ped_vx_mps"]), float(row["ped_vy_mps"])
        if math.hypot(vx, vy) > 0:
            self._ped_heading_rad = math.atan2(vy, vx)
        self.pedestrian.add(time_s, float(row["ped_x_m"]), float(row["ped_y_m"]), self._ped_heading_rad)
        lights = api.trafficlight
        for tls_id in lights.getIDList():
            state = lights.getRedYellowGreenState(tls_id)
            if self._signal_state.get(tls_id) != state:
                self._signal_state[tls_id] = state
                self.signal_changes.append(SignalChange(time_s, tls_id, state))

    def exported_vehicles(self) -> dict[str, Track]:
        """The ego first, then by id every other vehicle SUMO had during the episode."""
        kept = {vid: t for vid, t in self.vehicles.items() if t.times_s}
        return dict(sorted(kept.items(), key=lambda item: (item[0] != EGO_ID, item[0])))

    def entered_later(self) -> list[str]:
        """Vehicles and background persons whose first position is after the first logged step."""
        first = self.times_s[0] if self.times_s else None
        tracks = {**self.vehicles, **self.persons}
        return sorted(name for name, t in tracks.items() if t.times_s and t.times_s[0] != first)


def _rgb(values) -> tuple[int, int, int]:
    r, g, b = (int(v) for v in values)
    return r, g, b


def _body(domain, object_id: str, colour) -> Track:
    """A Track with SUMO's length, width and height of the vehicle or person (TraCI domain `domain`)."""
    return Track(
        domain.getLength(object_id), domain.getWidth(object_id), domain.getHeight(object_id), _rgb(colour)
    )


def _add_from_front(track: Track, time_s: float, domain, object_id: str) -> None:
    """SUMO's position moved back half a length to the footprint centre: SUMO places vehicles and
    persons alike by the middle of their front (a person's 0.215 m default length makes that 0.11 m)."""
    x, y = domain.getPosition(object_id)
    yaw = float(sumo_angle_to_yaw_rad(domain.getAngle(object_id)))
    cx, cy = sumo_front_to_centre(x, y, yaw, track.length_m)
    track.add(time_s, float(cx), float(cy), yaw)
