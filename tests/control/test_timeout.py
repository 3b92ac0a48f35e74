"""The per-step time limit of the AD stack (pedsafe_sumo.control.timeout), on its own: a run_step that
sleeps for ever is cut off after the limit, in the main thread (SIGALRM) and in any other thread (a
helper thread, as in a Dask worker); a fast one returns its value and pays no timeout."""

from __future__ import annotations

import signal
import threading
import time

import pytest

from pedsafe_sumo.control.timeout import (
    AgentTimeoutError,
    _AlarmGuard,
    _ThreadGuard,
    check_timeout_s,
    guard_step,
)

LIMIT_S = 0.2


def sleeps_forever(observation, time_s):
    while True:
        time.sleep(3600)


def swallows_the_timeout(observation, time_s):
    """A stack with a broad `except` around a hang: it swallows the first interruption and hangs on."""
    while True:
        try:
            time.sleep(3600)
        except Exception:  # noqa: BLE001 - the fault under test
            pass


def doubles(observation, time_s):
    return 2 * observation


def fails(observation, time_s):
    raise ValueError("planner crashed")


def in_thread(func):
    """func() in a fresh (non-main) thread; its return value or exception."""
    box = {}

    def target():
        try:
            box["value"] = func()
        except BaseException as exc:  # noqa: BLE001 - handed back to the test
            box["error"] = exc

    thread = threading.Thread(target=target)
    thread.start()
    thread.join(30)
    assert not thread.is_alive(), "the guarded call did not come back"
    return box


def test_the_guard_is_chosen_by_thread():
    assert isinstance(guard_step(doubles, LIMIT_S), _AlarmGuard)
    assert isinstance(in_thread(lambda: guard_step(doubles, LIMIT_S))["value"], _ThreadGuard)


def test_main_thread_cuts_off_a_sleep_after_the_limit_and_restores_the_handler():
    before = signal.getsignal(signal.SIGALRM)
    started = time.perf_counter()
    with guard_step(sleeps_forever, LIMIT_S) as step, pytest.raises(AgentTimeoutError, match="within 0.2 s"):
        step(None, 1.25)
    elapsed = time.perf_counter() - started
    assert LIMIT_S <= elapsed < LIMIT_S + 2.0
    assert step.timed_out
    assert signal.getsignal(signal.SIGALRM) is before
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_main_thread_cuts_off_a_stack_that_swallows_the_interruption():
    with guard_step(swallows_the_timeout, LIMIT_S) as step, pytest.raises(AgentTimeoutError):
        step(None, 0.0)
    assert step.timed_out


def test_other_thread_cuts_off_a_sleep_after_the_limit():
    def run():
        started = time.perf_counter()
        with guard_step(sleeps_forever, LIMIT_S) as step:
            try:
                step(None, 2.5)
            except AgentTimeoutError as exc:
                return time.perf_counter() - started, str(exc), step.timed_out
        return None

    box = in_thread(run)
    elapsed, message, timed_out = box["value"]
    assert LIMIT_S <= elapsed < LIMIT_S + 2.0
    assert "at t=2.50 s" in message and timed_out


@pytest.mark.parametrize("where", ["main", "thread"])
def test_a_fast_stack_returns_its_value_and_its_exceptions(where):
    def run():
        with guard_step(doubles, LIMIT_S) as step:
            values = [step(k, 0.05 * k) for k in range(50)]
        with guard_step(fails, LIMIT_S) as failing, pytest.raises(ValueError, match="planner crashed"):
            failing(None, 0.0)
        return values, step.timed_out, failing.timed_out

    values, timed_out, failing_timed_out = run() if where == "main" else in_thread(run)["value"]
    assert values == [2 * k for k in range(50)]
    assert not timed_out and not failing_timed_out


def test_a_step_slower_than_the_limit_in_total_but_not_per_step_is_not_cut_off():
    def slow(observation, time_s):
        time.sleep(LIMIT_S / 4)
        return observation

    with guard_step(slow, LIMIT_S) as step:
        assert [step(k, 0.0) for k in range(8)] == list(range(8))  # 2x the limit in total
    assert not step.timed_out


def test_time_between_steps_does_not_count():
    """The timer is armed once; firing between two steps (here: 1.5 limits apart) only re-arms it."""

    def fast(observation, time_s):
        return observation

    with guard_step(fast, LIMIT_S) as step:
        assert step(1, 0.0) == 1
        time.sleep(1.5 * LIMIT_S)  # the episode's own work between two run_step calls
        assert step(2, 0.05) == 2
        time.sleep(0.8 * LIMIT_S)
        assert step(3, 0.10) == 3
    assert not step.timed_out


def test_a_step_that_starts_late_gets_its_whole_limit():
    """A slow step that begins just before the timer fires is cut off only a whole limit after it began."""

    def slow_third(observation, time_s):
        if observation == 3:
            time.sleep(0.7 * LIMIT_S)
        return observation

    with guard_step(slow_third, LIMIT_S) as step:
        step(1, 0.0)
        time.sleep(0.6 * LIMIT_S)
        assert step(3, 0.05) == 3  # runs from 0.6 to 1.3 limits after arming: 0.7 limits of its own
    assert not step.timed_out


@pytest.mark.parametrize("value", [0, -1, 3601, float("nan"), float("inf")])
def test_limits_out_of_range_are_refused(value):
    with pytest.raises(ValueError, match="--agent-timeout must be > 0 and at most 3600"):
        check_timeout_s(value)
