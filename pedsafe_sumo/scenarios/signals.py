"""The junction's traffic-light program, read from the network, and where in its cycle an episode starts.

Nothing here knows phase indices or times: the program (phases, durations, link states) and the link
index of every movement come from the site's .net.xml through sumolib, so a site whose signal plan is
replaced (another program in its net) stages the same way.

A scenario says which signal each road user has at the conflict (ScenarioSpec.ego_signal and
ped_signal: green, yellow, red or none). `cycle_start_windows` finds every point of the cycle at which
an episode can start so that these states hold from the start until `hold_after_s` after the staged
conflict; `draw_cycle_start_s` draws one from the episode's seeded Generator. The episode then puts
SUMO's signal at that point (libsumo trafficlight.setPhase / setPhaseDuration) before the first step.

Colours of SUMO's link states (https://sumo.dlr.de/docs/Simulation/Traffic_Lights.html#signal_state_definitions):
G and g green (g: a permissive green that must yield), s green after a stop (right turn on red), y yellow,
r red, u red-yellow (vehicles must still stop: red), o and O off (no signal: none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from pedsafe_sumo.network.traffic_lights import junction_lights, several_lights_problem
from pedsafe_sumo.sumo_net import read_net

SIGNAL_STATES = ("green", "yellow", "red", "none")
_COLOUR_OF_CHAR = {"G": "green", "g": "green", "s": "green", "y": "yellow", "Y": "yellow", "r": "red",
                   "u": "red", "o": "none", "O": "none"}  # fmt: skip
#: The signal state of a road user that no signal controls (a mid-block crossing).
NO_LINK = -1


class SignalStagingError(ValueError):
    """The junction's program cannot give a scenario the signal states its definition requires."""


def colour_of(state_char: str) -> str:
    """green, yellow, red or none for one character of a SUMO link-state string."""
    try:
        return _COLOUR_OF_CHAR[state_char]
    except KeyError:
        raise ValueError(f"unknown SUMO link state '{state_char}'") from None


def colour_of_link(state: str, link_index: int) -> str:
    """The colour a link shows in a state string; `none` for a road user no signal controls."""
    return "none" if link_index == NO_LINK else colour_of(state[link_index])


@dataclass(frozen=True)
class SignalProgram:
    """A fixed-time program as SUMO runs it: phase i lasts durations_s[i] and shows states[i]."""

    tls_id: str
    program_id: str
    durations_s: tuple[float, ...]
    states: tuple[str, ...]

    @property
    def cycle_s(self) -> float:
        return float(sum(self.durations_s))

    def phase_at(self, cycle_time_s: float) -> tuple[int, float]:
        """(phase index, seconds left in it) at a time of the cycle (taken modulo the cycle)."""
        t = cycle_time_s % self.cycle_s
        end = 0.0
        for index, duration in enumerate(self.durations_s):
            end += duration
            if t < end:
                return index, end - t
        return len(self.durations_s) - 1, 0.0  # t == cycle within rounding

    def colour(self, link_index: int, cycle_time_s: float) -> str:
        if link_index == NO_LINK:
            return "none"
        return colour_of(self.states[self.phase_at(cycle_time_s)[0]][link_index])

    def runs(self, link_index: int, colour: str) -> list[tuple[float, float]]:
        """Maximal intervals of cycle time, over three cycles [-cycle, 2 cycle), in which the link shows
        `colour` (a run that crosses the end of the cycle is one interval)."""
        runs: list[tuple[float, float]] = []
        t = -self.cycle_s
        for _ in range(3):
            for duration, state in zip(self.durations_s, self.states):
                shows = colour_of_link(state, link_index) == colour
                if shows and runs and math.isclose(runs[-1][1], t, abs_tol=1e-9):
                    runs[-1] = (runs[-1][0], t + duration)
                elif shows:
                    runs.append((t, t + duration))
                t += duration
        return runs


def cycle_start_windows(
    program: SignalProgram, required: dict[int, str | tuple[str, float, float]], until_s: float = 0.0
) -> list[tuple[float, float]]:
    """The cycle times c in [0, cycle) at which an episode can start so that every link of `required`
    shows its colour during the whole of [c + from_s, c + to_s]. A value of `required` is
    (colour, from_s, to_s), or a colour alone for (colour, 0, until_s). Sorted, disjoint."""
    windows = [(0.0, program.cycle_s)]
    for link_index, wanted in required.items():
        colour, from_s, to_s = (wanted, 0.0, until_s) if isinstance(wanted, str) else wanted
        if not 0 <= from_s <= to_s:
            raise ValueError(f"the signal of link {link_index} is required over [{from_s}, {to_s}] s")
        if colour not in SIGNAL_STATES:
            raise ValueError(f"unknown signal state '{colour}' (known: {', '.join(SIGNAL_STATES)})")
        if link_index == NO_LINK:
            if colour != "none":
                raise SignalStagingError(f"a road user no signal controls cannot have a {colour} signal")
            continue
        starts = [
            (s - from_s, e - to_s) for s, e in program.runs(link_index, colour) if e - s >= to_s - from_s
        ]
        # Start times of one cycle: shift each interval by whole cycles into [0, cycle).
        allowed = []
        for s, e in starts:
            for k in (-1, 0, 1):
                lo, hi = max(s + k * program.cycle_s, 0.0), min(e + k * program.cycle_s, program.cycle_s)
                if lo <= hi and lo < program.cycle_s:  # the cycle's end is its start
                    allowed.append((lo, hi))
        windows = _intersect(windows, _merge(allowed))
    return windows


def _merge(intervals: list[tuple[float, float]]) -> list[tuple[float, float]]:
    merged: list[tuple[float, float]] = []
    for lo, hi in sorted(intervals):
        if merged and lo <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], hi))
        else:
            merged.append((lo, hi))
    return merged


def _intersect(a: list[tuple[float, float]], b: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out = []
    for alo, ahi in a:
        for blo, bhi in b:
            lo, hi = max(alo, blo), min(ahi, bhi)
            if lo <= hi:
                out.append((lo, hi))
    return _merge(out)


def draw_cycle_start_s(
    program: SignalProgram,
    required: dict[int, str | tuple[str, float, float]],
    until_s: float,
    rng: np.random.Generator,
) -> float:
    """A cycle time drawn uniformly over cycle_start_windows (one draw from `rng`); raises
    SignalStagingError when there is none."""
    windows = cycle_start_windows(program, required, until_s)
    total = sum(hi - lo for lo, hi in windows)
    u = float(rng.uniform(0.0, 1.0))
    if not windows:
        wanted = ", ".join(
            f"link {k} {v}" if isinstance(v, str) else f"link {k} {v[0]} from {v[1]:.1f} to {v[2]:.1f} s"
            for k, v in required.items()
        )
        raise SignalStagingError(
            f"signal program {program.tls_id}/{program.program_id} cannot show {wanted}"
            + (f" (until {until_s:.1f} s)" if any(isinstance(v, str) for v in required.values()) else "")
        )
    if total <= 0:  # only single instants qualify
        return windows[0][0]
    target = u * total
    for lo, hi in windows:
        if target <= hi - lo:
            return lo + target
        target -= hi - lo
    return windows[-1][1]


@dataclass(frozen=True)
class JunctionSignals:
    """The main junction's program and the link indices of the movements the scenarios use."""

    program: SignalProgram
    #: (from lane id, to edge id) -> link index of that vehicle connection.
    vehicle_links: dict[tuple[str, str], int]
    #: crossing edge id -> link index of the signal that controls walking onto it.
    crossing_links: dict[str, int]
    #: (from lane id, to edge id) -> SUMO's direction of that connection (s, r, l, R, L, t).
    vehicle_directions: dict[tuple[str, str], str]

    def turn_link(self, from_lane_id: str, direction: str) -> int:
        """Link index of the first connection from a lane in a direction (r: right turn), or NO_LINK."""
        for key, found in self.vehicle_directions.items():
            if key[0] == from_lane_id and found == direction:
                return self.vehicle_links[key]
        return NO_LINK

    def vehicle_link(self, from_lane_id: str, to_edge_id: str) -> int:
        try:
            return self.vehicle_links[(from_lane_id, to_edge_id)]
        except KeyError:
            raise SignalStagingError(
                f"no signalised connection from lane {from_lane_id} to edge {to_edge_id}"
            ) from None

    def crossing_link(self, crossing_id: str) -> int:
        return self.crossing_links.get(crossing_id, NO_LINK)


@lru_cache(maxsize=4)
def load_junction_signals(net_file: Path, junction_id: str) -> JunctionSignals:
    """Read the traffic light that controls the junction's links from the network.

    The light is the one on the junction's connections (network.traffic_lights: their `tl`), whatever
    its id (netconvert's joinedS_..., joinedG_..., GS_<junction>); a light that controls neighbouring
    junctions too is read whole (every link of it). SignalStagingError, in one line, for a
    traffic-light junction none of whose connections a light controls and for a junction several
    lights control (the scenarios stage one program); "has no traffic light" only for a junction that
    is not a traffic-light junction and that no light controls."""
    lights = junction_lights(net_file, junction_id)
    net = read_net(str(net_file), withInternal=True, withPedestrianConnections=True, withPrograms=True)
    try:
        node = net.getNode(junction_id)
    except KeyError:
        raise SignalStagingError(f"{net_file.name} has no junction {junction_id}") from None
    if not lights:
        if node.getType().startswith("traffic_light"):
            raise SignalStagingError(
                f"junction {junction_id} of {net_file.name} is a traffic-light junction, but no traffic "
                "light controls any of its connections (no tl attribute on them)"
            )
        raise SignalStagingError(f"junction {junction_id} of {net_file.name} has no traffic light")
    several = several_lights_problem(net_file, junction_id, lights)
    if several:
        raise SignalStagingError(several)
    tls = net.getTLS(next(iter(lights)))
    tls_id = tls.getID()
    programs = tls.getPrograms()
    if not programs:
        raise SignalStagingError(f"traffic light {tls_id} of {net_file.name} has no program")
    # SUMO starts the last program the network defines for a traffic light.
    program_id, program = list(programs.items())[-1]
    if program.getType() != "static":
        raise SignalStagingError(
            f"traffic light {tls_id} runs a {program.getType()} program; scenarios stage only "
            "fixed-time (static) programs"
        )
    phases = program.getPhases()
    signals = SignalProgram(
        tls_id=tls_id,
        program_id=str(program_id),
        durations_s=tuple(float(p.duration) for p in phases),
        states=tuple(p.state for p in phases),
    )
    vehicle_links: dict[tuple[str, str], int] = {}
    crossing_links: dict[str, int] = {}
    directions: dict[tuple[str, str], str] = {}
    # Every link of the light, the neighbouring junctions' too: a light over a split intersection (a
    # divided road's two junctions) stages a movement through the other junction in the same program.
    for connection in tls.getConnections():
        from_lane, to_lane, link_index = connection
        to_edge = to_lane.getEdge()
        if to_edge.getFunction() == "crossing":
            crossing_links[to_edge.getID()] = int(link_index)
        else:
            key = (from_lane.getID(), to_edge.getID())
            vehicle_links[key] = int(link_index)
            directions[key] = next(
                (c.getDirection() for c in from_lane.getOutgoing() if c.getToLane() is to_lane), ""
            )
    return JunctionSignals(signals, vehicle_links, crossing_links, directions)
