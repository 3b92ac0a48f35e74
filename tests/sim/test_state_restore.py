"""SumoSession's state restore instead of `load` (sim/connection.py), in real SUMO.

The reference is the same episodes run with `restore_state=False` (a `load` each): every step of every
log and every outcome must be equal, and the restore must actually have been used. Also what a restore
leaves: SUMO's time, vehicles, persons, subscriptions; and that an episode with an additional file loads
(a state carries no parking areas, and a restore after it would keep them).

The restore is off by default: its rows can depend on the episodes run before it in the
process (tests/sim/test_episode_history.py). These tests keep the mechanism right for a session that asks
for it (`restore_state=True`).
"""

from __future__ import annotations

import pandas as pd
import pytest

from pedsafe_sumo.batch import runner as batch_runner
from pedsafe_sumo.batch.__main__ import parse_args
from pedsafe_sumo.batch.chunks import plan_chunks
from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim import connection
from pedsafe_sumo.sim.episode import EpisodeRunner

SITE = get_site("xueqing")
#: Scenario, condition, seed: background traffic, both conditions of one seed, a turning ego, seeds apart.
EPISODES = (
    ("crossing", "sv", 11),
    ("crossing", "v2i", 11),
    ("background_blending", "sv", 12),
    ("right_turn", "v2i", 13),
    ("jaywalking", "sv", 14),
)


def _run_all(restore: bool, calls: list[str]):
    runner = EpisodeRunner(SITE, load_params(), ReferenceStack)
    runner.session.restore_state = restore
    real_restore, real_load = runner.session._restore, runner.session._load

    def counted_restore() -> bool:
        restored = real_restore()
        calls.append("restore" if restored else "refused")
        return restored

    runner.session._restore = counted_restore
    runner.session._load = lambda args: (calls.append("load"), real_load(args))[1]
    try:
        return [runner.run(get_scenario(name), condition, seed) for name, condition, seed in EPISODES]
    finally:
        runner.close()


def test_restored_episodes_equal_loaded_ones_step_by_step():
    loaded_calls: list[str] = []
    restored_calls: list[str] = []
    loaded = _run_all(False, loaded_calls)
    restored = _run_all(True, restored_calls)
    assert loaded_calls == ["load"] * len(EPISODES)
    # The first episode starts SUMO; every later one differs from it only in --seed: restored.
    assert restored_calls == ["load"] + ["restore"] * (len(EPISODES) - 1)
    for a, b in zip(loaded, restored, strict=True):
        pd.testing.assert_frame_equal(a.log, b.log, check_exact=True)
        assert a.outcome.keys() == b.outcome.keys()
        for key in a.outcome:
            x, y = a.outcome[key], b.outcome[key]
            assert x == y or (x != x and y != y), (key, x, y)  # NaN equals NaN
        assert a.end_reason == b.end_reason
        assert a.signal_states == b.signal_states
        assert a.sumo_collision == b.sumo_collision


def _net_args(seed: int, extra: tuple[str, ...] = ()) -> list[str]:
    return ["-n", str(SITE.file("net.xml")), "--seed", str(seed), "--no-step-log", "true", *extra]


def _session_counting_restores() -> tuple[connection.SumoSession, list[str]]:
    """A session whose every state restore appends "restore" to the returned list."""
    session = connection.SumoSession(restore_state=True)
    calls: list[str] = []
    real_restore = session._restore
    session._restore = lambda: (calls.append("restore"), real_restore())[1]
    return session, calls


def _longest_passenger_lane(api) -> str:
    lanes = [lane for lane in api.lane.getIDList() if "passenger" in api.lane.getAllowed(lane)]
    return max(lanes, key=api.lane.getLength)


def test_a_restore_leaves_an_empty_simulation_at_time_zero():
    session, calls = _session_counting_restores()
    api = session.api
    try:
        session.run(_net_args(1))
        lane = _longest_passenger_lane(api)
        edge = api.lane.getEdgeID(lane)
        api.route.add("r", [edge])
        for i in range(3):
            api.vehicle.add(f"v{i}", "r", depart="0", departPos=str(10 * i), departLane=str(lane[-1]))
        api.vehicle.add("late", "r", depart="100")  # still waiting to depart at the restore
        api.simulation.step()
        for vehicle_id in api.vehicle.getIDList():
            api.vehicle.subscribe(vehicle_id, [api.constants.VAR_SPEED])
        for _ in range(2):
            api.simulation.step()
        assert api.simulation.getTime() == pytest.approx(3.0)
        assert len(api.vehicle.getIDList()) == 3

        session.run(_net_args(2))
        assert calls == ["restore"]
        assert api.simulation.getTime() == 0.0
        assert api.vehicle.getIDList() == ()
        assert api.person.getIDList() == ()
        # The route and the vehicle ids are free again, the waiting vehicle gone, and the last episode's
        # subscription of "v0" does not follow the new "v0" (a load drops subscriptions too).
        api.route.add("r", [edge])
        api.vehicle.add("v0", "r", depart="0")
        api.simulation.step()
        assert api.vehicle.getIDList() == ("v0",)
        assert api.vehicle.getAllSubscriptionResults() == {}
        for _ in range(120):
            api.simulation.step()
        assert "late" not in api.vehicle.getIDList()
    finally:
        session.close()


def test_an_episode_with_an_additional_file_loads_and_so_does_the_next(tmp_path):
    session, calls = _session_counting_restores()
    api = session.api
    try:
        session.run(_net_args(1))
        edge_lane = _longest_passenger_lane(api)
        parking = tmp_path / "parking.add.xml"
        parking.write_text(
            f'<additional><parkingArea id="pa" lane="{edge_lane}" startPos="5" endPos="25"/></additional>',
            encoding="utf-8",
        )
        session.run(_net_args(2, ("-a", str(parking))))
        assert api.parkingarea.getIDList() == ("pa",)
        assert calls == []  # loaded: a state holds no parking areas
        session.run(_net_args(3))
        assert calls == []  # loaded again: a restore would have kept "pa"
        assert api.parkingarea.getIDList() == ()
        session.run(_net_args(4))
        assert calls == ["restore"]
        assert api.parkingarea.getIDList() == ()
    finally:
        session.close()


def test_options_that_differ_in_more_than_the_seed_load():
    session, calls = _session_counting_restores()
    try:
        session.run(_net_args(1))
        session.run(_net_args(1, ("--step-length", "0.05")))
        assert calls == []
        assert session.api.simulation.getDeltaT() == 0.05
        session.run(_net_args(5, ("--step-length", "0.05")))
        assert calls == ["restore"]
        assert session.api.simulation.getDeltaT() == 0.05
        off = connection.SumoSession()  # the default: every episode loads
        assert off._base_args is None and not off.restore_state
    finally:
        session.close()


def _batch_rows(restore: bool, calls: list[str]) -> pd.DataFrame:
    """The worker side of a batch (one pair per scenario, as a pool worker runs them) in this process."""
    from pedsafe_sumo.batch.plan import prepare

    plan = prepare(parse_args(["--scenario", "crossing,jaywalking,background_blending,right_turn",
                               "--episodes", "1", "--out", "/nonexistent"]))  # fmt: skip
    chunks = plan_chunks(plan.scenarios, plan.conditions, 1, plan.arguments["seed"], 1)
    batch_runner._close_runner()
    session = batch_runner._runner_for(plan.config).session
    session.restore_state = restore
    real_restore = session._restore
    session._restore = lambda: (calls.append(real_restore()), calls[-1])[1]
    rows = []
    try:
        for chunk in chunks:
            rows += batch_runner.run_chunk(plan.config, chunk.key, chunk.tasks).rows
    finally:
        batch_runner._close_runner()
    return pd.DataFrame(rows)


@pytest.mark.slow
def test_a_batchs_rows_are_the_same_with_restores():
    loaded_calls: list[str] = []
    restored_calls: list[str] = []
    loaded = _batch_rows(False, loaded_calls)
    restored = _batch_rows(True, restored_calls)
    # Every episode after the first restored (True: the restore gave the loaded simulation back).
    assert loaded_calls == [] and restored_calls == [True] * (len(loaded) - 1)
    assert (loaded["status"] == "ok").all()
    pd.testing.assert_frame_equal(loaded, restored, check_exact=True)


def test_a_signal_program_changed_through_traci_makes_the_next_episode_load():
    """A state holds which program a traffic light runs and where in it, not the program: one that TraCI
    replaced (setProgramLogic) would stay replaced after a restore; the session sees it and loads."""
    session = connection.SumoSession(restore_state=True)
    api = session.api
    results: list[bool] = []
    real_restore = session._restore
    session._restore = lambda: (results.append(real_restore()), results[-1])[1]

    def durations(tls: str) -> list[float]:
        return [p.duration for p in api.trafficlight.getAllProgramLogics(tls)[0].phases]

    try:
        session.run(_net_args(1))
        tls = api.trafficlight.getIDList()[0]
        pristine = durations(tls)
        logic = api.trafficlight.getAllProgramLogics(tls)[0]
        logic.phases[0].duration = logic.phases[0].minDur = logic.phases[0].maxDur = pristine[0] + 7.0
        api.trafficlight.setProgramLogic(tls, logic)
        api.simulation.step()
        assert durations(tls)[0] == pristine[0] + 7.0
        session.run(_net_args(2))
        assert results == [False]  # restored, found changed, loaded
        assert durations(tls) == pristine
        session.run(_net_args(3))
        assert results == [False, True]
        assert durations(tls) == pristine
    finally:
        session.close()


def test_two_sessions_in_one_process_take_turns_in_libsumo():
    """libsumo is one simulation per process: after another session loaded (here another network), a
    session's saved state is not restored into it; it loads its own network."""
    first, second = connection.SumoSession(restore_state=True), connection.SumoSession(restore_state=True)
    api = first.api
    restores: list[str] = []
    for name, session in (("first", first), ("second", second)):
        real = session._restore
        session._restore = lambda real=real, name=name: (restores.append(name), real())[1]
    other = get_site("xueqing_two_phase").file("net.xml")
    try:
        first.run(_net_args(1))
        second.run(["-n", str(other), "--seed", "1", "--no-step-log", "true"])
        assert api.simulation.getNetBoundary() != ()  # the other network runs now
        net_files = []
        first.run(_net_args(2))
        net_files.append(api.simulation.getOption("net-file"))
        first.run(_net_args(3))
        net_files.append(api.simulation.getOption("net-file"))
        assert restores == ["first"]  # the second run of `first` loaded, its third restored
        assert net_files == [str(SITE.file("net.xml"))] * 2
    finally:
        second.close()
        first.close()
