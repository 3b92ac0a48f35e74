"""Signals: the program read from the network, start times in the cycle, and the
signal states SUMO shows at the conflict of real episodes.

Expected values come from a hand-built program (worked by hand), from the .net.xml parsed here with
ElementTree (not sumolib), and from SUMO's own trafficlight state during real episodes.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.geometry import load_approach
from pedsafe_sumo.scenarios.signals import (
    NO_LINK,
    SignalProgram,
    SignalStagingError,
    colour_of,
    cycle_start_windows,
    draw_cycle_start_s,
    load_junction_signals,
)
from pedsafe_sumo.scenarios.specs import SCENARIOS, get_scenario

#: Hand-built program: link 0 green 0-10 s, yellow 10-13 s, red 13-33 s; link 1 red 0-13 s, green 13-33 s.
PROGRAM = SignalProgram("tls", "0", (10.0, 3.0, 20.0), ("Gr", "yr", "rG"))


def test_colours_of_sumo_link_states():
    assert [colour_of(c) for c in "GgsyYruoO"] == [
        "green", "green", "green", "yellow", "yellow", "red", "red", "none", "none"
    ]  # fmt: skip
    with pytest.raises(ValueError):
        colour_of("x")


def test_program_phase_and_colour_by_hand():
    assert PROGRAM.cycle_s == 33.0
    assert PROGRAM.phase_at(0.0) == (0, 10.0)
    assert PROGRAM.phase_at(11.5) == (1, 1.5)
    assert PROGRAM.phase_at(33.0 + 20.0) == (2, 13.0)
    assert PROGRAM.colour(0, 9.99) == "green" and PROGRAM.colour(0, 10.0) == "yellow"
    assert PROGRAM.colour(1, 32.9) == "green" and PROGRAM.colour(NO_LINK, 5.0) == "none"


def test_start_windows_by_hand():
    # Link 0 green for 4 s from the start: start anywhere in [0, 6].
    assert cycle_start_windows(PROGRAM, {0: "green"}, 4.0) == [(0.0, 6.0)]
    # Link 1 green for 5 s: its green 13-33 s, so [13, 28].
    assert cycle_start_windows(PROGRAM, {1: "green"}, 5.0) == [(13.0, 28.0)]
    # Link 0 red for 25 s: its red 13-33 s runs on into the next cycle's green only at 33 s, so the 20 s
    # red cannot hold 25 s: nothing.
    assert cycle_start_windows(PROGRAM, {0: "red"}, 25.0) == []
    # Link 1 red for 8 s: red 0-13 s (and the previous cycle's end is green): [0, 5].
    assert cycle_start_windows(PROGRAM, {1: "red"}, 8.0) == [(0.0, 5.0)]
    # Both: link 0 green and link 1 red for 2 s: [0, 8].
    assert cycle_start_windows(PROGRAM, {0: "green", 1: "red"}, 2.0) == [(0.0, 8.0)]


def test_start_window_across_the_end_of_the_cycle():
    # Link 0 red 13-33 s and, in the next cycle, not red from 33 s: a run of red that wraps needs a
    # program whose red spans the cycle end. Shift the hand-built program: link 1 green 0-20 s and
    # 30-33 s of the previous cycle: green 30-53 (mod 33: 30-33 and 0-20).
    program = SignalProgram("tls", "0", (20.0, 10.0, 3.0), ("G", "r", "G"))
    windows = cycle_start_windows(program, {0: "green"}, 10.0)
    assert windows == [(0.0, 10.0), (30.0, 33.0)]


def test_draw_is_uniform_over_the_windows_and_reproducible():
    program = SignalProgram("tls", "0", (20.0, 10.0, 3.0), ("G", "r", "G"))
    draws = [draw_cycle_start_s(program, {0: "green"}, 10.0, np.random.default_rng(s)) for s in range(2000)]
    assert all(0 <= d <= 10 or 30 <= d <= 33 for d in draws)
    # 3 s of the 13 s of windows lie in [30, 33].
    share = np.mean([d >= 30 for d in draws])
    assert share == pytest.approx(3 / 13, abs=0.03)
    again = draw_cycle_start_s(program, {0: "green"}, 10.0, np.random.default_rng(7))
    assert again == draws[7]
    with pytest.raises(SignalStagingError):
        draw_cycle_start_s(program, {0: "red"}, 11.0, np.random.default_rng(0))


@pytest.fixture(scope="module")
def site():
    return get_site("xueqing")


def test_program_and_links_match_the_net_file(site):
    approach = load_approach(site)
    signals = load_junction_signals(site.file("net.xml"), approach.junction_id)
    root = ET.parse(site.file("net.xml")).getroot()
    logic = next(t for t in root.iter("tlLogic") if t.get("id") == approach.junction_id)
    phases = logic.findall("phase")
    assert signals.program.durations_s == tuple(float(p.get("duration")) for p in phases)
    assert signals.program.states == tuple(p.get("state") for p in phases)
    for connection in root.iter("connection"):
        if connection.get("tl") != approach.junction_id:
            continue
        from_lane = f"{connection.get('from')}_{connection.get('fromLane')}"
        if connection.get("from") == approach.edge_id:
            assert signals.vehicle_link(from_lane, connection.get("to")) == int(connection.get("linkIndex"))
        if connection.get("to") == approach.crosswalk_id:
            assert signals.crossing_link(approach.crosswalk_id) == int(connection.get("linkIndex"))


def _runner(site):
    from pedsafe_sumo.sim.episode import EpisodeRunner

    return EpisodeRunner(site, load_params(), ReferenceStack)


@pytest.mark.slow
def test_sumo_shows_the_staged_program_step_by_step(site):
    """SUMO's own link states during an episode are the program's states at cycle_start + t."""
    runner = _runner(site)
    try:
        result = runner.run(get_scenario("crossing"), "sv", 11)
    finally:
        runner.close()
    staging = result.setup.signals
    program = runner.signals.program
    assert len(result.signal_states) == len(result.log)
    mismatches = 0
    for time_s, state in zip(result.log["time_s"], result.signal_states):
        # SUMO reports the state valid during the step that ended at time_s; a phase switch within the
        # last step may show at the boundary, so compare 1 ms inside the step.
        index, _ = program.phase_at(staging.cycle_start_s + time_s - 0.001)
        mismatches += state != program.states[index]
    assert mismatches == 0


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_signals_at_the_conflict_match_the_definition_over_a_seed_sweep(site, name):
    """Every staged episode of a sweep, under both conditions: SUMO's signal of the ego at the staged
    conflict is the scenario's, and the pedestrian's is too, at the conflict (ped_signal_hold
    "conflict") or when they step off the kerb ("step_off")."""
    spec = get_scenario(name)
    # left_turn's oncoming vehicle needs a program that lets it move with the ego's left (not Xueqing's).
    runner = _runner(get_site("xueqing_two_phase") if name == "left_turn" else site)
    wrong = []
    try:
        for seed in range(8):
            for condition in ("sv", "v2i"):
                result = runner.run(spec, condition, seed)
                outcome, log, setup = result.outcome, result.log, result.setup
                ped = outcome["ped_signal"]
                if spec.ped_signal_hold == "step_off":
                    step = int(np.searchsorted(log["time_s"].to_numpy(), setup.pedestrian.start_delay_s))
                    link = setup.signals.ped_link_index
                    ped = colour_of(result.signal_states[step][link])
                if (outcome["ego_signal"], ped) != (spec.ego_signal, spec.ped_signal):
                    wrong.append((seed, condition, outcome["ego_signal"], ped))
    finally:
        runner.close()
    assert not wrong, f"{name}: expected ego {spec.ego_signal}, pedestrian {spec.ped_signal}; got {wrong}"


class _FakeTrafficLight:
    """Just the trafficlight calls start_signals makes (a unit test of its arithmetic and its check)."""

    def __init__(self, durations, states):
        phases = [type("Phase", (), {"duration": d, "state": st})() for d, st in zip(durations, states)]
        self.logic = type("Logic", (), {"programID": "0", "phases": phases})()
        self.calls = []

    def getProgram(self, tls):  # noqa: N802 - libsumo's name
        return "0"

    def getAllProgramLogics(self, tls):  # noqa: N802
        return [self.logic]

    def setPhase(self, tls, index):  # noqa: N802
        self.calls.append(("phase", index))

    def setPhaseDuration(self, tls, remaining):  # noqa: N802
        self.calls.append(("remaining", remaining))


def test_start_signals_sets_the_phase_and_what_is_left_of_it():
    from types import SimpleNamespace

    from pedsafe_sumo.scenarios.episode_setup import SignalStaging
    from pedsafe_sumo.sim.staging import start_signals

    light = _FakeTrafficLight(PROGRAM.durations_s, PROGRAM.states)
    staging = SignalStaging("tls", "0", cycle_start_s=11.5, ego_link_index=0, ped_link_index=1)
    start_signals(SimpleNamespace(trafficlight=light), staging, PROGRAM)
    # 11.5 s into (10, 3, 20): phase 1, 1.5 s left.
    assert light.calls == [("phase", 1), ("remaining", pytest.approx(1.5))]
    other = _FakeTrafficLight((10.0, 3.0, 25.0), PROGRAM.states)
    with pytest.raises(RuntimeError, match="another program"):
        start_signals(SimpleNamespace(trafficlight=other), staging, PROGRAM)


def test_a_junction_without_a_traffic_light_stages_no_signal():
    """Another site's unsignalised junction: nothing to place, and the episode records none for both."""
    from pedsafe_sumo.scenarios.geometry import load_turn  # noqa: F401 - the module the staging uses
    from pedsafe_sumo.scenarios.staging import draw_episode, stage_signals

    approach = load_approach(get_site("xueqing"))
    traits = {"age_years": 35.0, "gender": "f", "risk": "unaware", "walking_speed_mps": 1.4}
    spec = get_scenario("crossing")
    setup = draw_episode(spec, approach, 3, traits, 6.0, np.random.default_rng(3))
    assert stage_signals(spec, setup, None, np.random.default_rng(3)) == setup
    assert setup.signals is None
