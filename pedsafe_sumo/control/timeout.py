"""A time limit on each call of the AD stack's run_step, and on its setup (`--agent-timeout SECONDS`).

A stack whose run_step (or setup) never returns (a deadlock, a sleep, an endless loop in Python) must
end its own episode, not hold its batch forever. Python cannot interrupt a thread from outside, so the
limit works in one of two ways, chosen once per episode by `guard_step`:

* In a process's main thread (the process-pool workers, the episode and replay CLIs): a real-time
  timer (signal.setitimer, SIGALRM). When a call has run past the limit, the timer's handler raises
  AgentTimeoutError inside run_step, even in the middle of time.sleep. Cost: one clock read per step
  (the timer is armed once per episode and re-armed by its own handler; _AlarmGuard).
* In any other thread (a Dask worker runs its tasks in a thread, where signals cannot be handled): the
  call runs in a helper thread of the episode and the step waits for its answer at most the limit. On a
  timeout the helper thread is abandoned (daemon; it holds only the stack, never SUMO) and the episode
  ends. Cost: one hand-over between threads per step.

`call_within` puts one call (the stack's setup) under the same limit, the same two ways.

Either way the episode ends with status "timeout" and the message of AgentTimeoutError; the batch goes on.
A stack stuck in native code that never returns to the interpreter (and holds the GIL), or one that
catches BaseException around its hang, cannot be interrupted by either: such a worker has to be killed,
which the batch survives as a worker death.
"""

from __future__ import annotations

import queue
import signal
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Any

#: Default per-step limit [s]: the reference stack takes about 20 us per step, a heavy learned stack a
#: few hundred milliseconds; 10 s is far beyond any real-time stack and still ends a hung one quickly.
DEFAULT_AGENT_TIMEOUT_S = 10.0
#: Largest accepted limit [s]: above an hour per 0.05 s step a batch would never finish anyway.
MAX_AGENT_TIMEOUT_S = 3600.0
TIMEOUT_STATUS = "timeout"
#: After the limit, the alarm fires again this often until run_step gives up [s].
RETRY_S = 0.1
#: A timer may fire this much before the clock read at the step's start says the limit is reached [s].
CLOCK_SLACK_S = 1e-3

StepFunction = Callable[[Any, float], Any]


class AgentTimeoutError(RuntimeError):
    """run_step exceeded the per-step time limit; the message says when and how long."""


class _StillRunning(BaseException):  # noqa: N818 - never seen outside this module
    """Raised again every RETRY_S after the limit: a BaseException, so that a stack's `except Exception`
    (which swallowed the first AgentTimeoutError) does not swallow it too."""


def check_timeout_s(timeout_s: float) -> float:
    """The limit as a float; ValueError (one line) unless 0 < timeout_s <= MAX_AGENT_TIMEOUT_S."""
    value = float(timeout_s)
    if not 0 < value <= MAX_AGENT_TIMEOUT_S:
        raise ValueError(
            f"--agent-timeout must be > 0 and at most {MAX_AGENT_TIMEOUT_S:g} s (an hour per step), "
            f"got {timeout_s}"
        )
    return value


def _message(timeout_s: float, time_s: float, call: str = "run_step") -> str:
    when = f" at t={time_s:.2f} s" if call == "run_step" else ""
    return f"the AD stack's {call} did not return within {timeout_s:g} s (--agent-timeout){when}"


class _AlarmGuard:
    """run_step under SIGALRM; main thread only. Use as a context manager around the episode's loop.

    The timer is armed once, at the first step, not around every call (a setitimer system call costs
    about 2 us on the development machine, against 0.2 us for reading the clock): when it fires, the
    handler looks at the step in progress. Past the limit it raises; otherwise it re-arms the timer for
    the rest of the current step's limit (or a whole limit between steps), so a step is cut off between
    `timeout_s` and `timeout_s` plus a few milliseconds after it began. Between start() and stop() the
    alarm fires about once per `timeout_s`, handled in Python between bytecodes; it is off while SUMO
    loads and stages an episode."""

    def __init__(self, step: StepFunction, timeout_s: float) -> None:
        self._step = step
        self.timeout_s = timeout_s
        self.timed_out = False
        #: The stack's method under the limit, for the message ("run_step", "setup").
        self.call = "run_step"
        self._active = False
        self._armed = False
        self._fired = False
        self._started = 0.0
        self._time_s = 0.0
        self._previous: Any = None

    def _on_alarm(self, signum: int, frame: FrameType | None) -> None:
        if not self._active:
            signal.setitimer(signal.ITIMER_REAL, self.timeout_s)  # between steps: the next one is later
            return
        elapsed_s = time.perf_counter() - self._started
        if not self._fired and elapsed_s < self.timeout_s - CLOCK_SLACK_S:
            signal.setitimer(signal.ITIMER_REAL, self.timeout_s - elapsed_s)
            return
        # Fire again every RETRY_S until run_step gives up: a stack that swallows the exception
        # (a broad `except`) is interrupted again, and the step counts as timed out anyway.
        again = self._fired
        self._fired = True
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)
        if again:
            raise _StillRunning
        raise AgentTimeoutError(_message(self.timeout_s, self._time_s, self.call))

    def start(self) -> _AlarmGuard:
        self._previous = signal.signal(signal.SIGALRM, self._on_alarm)
        return self

    def stop(self) -> None:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, self._previous)
        self._armed = False

    def __enter__(self) -> _AlarmGuard:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def __call__(self, observation: Any, time_s: float) -> Any:
        self._time_s = time_s
        self._started = time.perf_counter()
        self._active = True
        if not self._armed:
            self._armed = True
            signal.setitimer(signal.ITIMER_REAL, self.timeout_s)
        try:
            command = self._step(observation, time_s)
        except _StillRunning:
            command = None
        finally:
            self._active = False
            if self._fired:
                self.timed_out = True
        if self.timed_out:  # the stack caught the AgentTimeoutError and returned late, or was stopped again
            raise AgentTimeoutError(_message(self.timeout_s, time_s, self.call))
        return command


class _ThreadGuard:
    """run_step in a helper thread, waited for at most the limit; for threads that cannot take signals."""

    def __init__(self, step: StepFunction, timeout_s: float) -> None:
        self._step = step
        self.timeout_s = timeout_s
        self.timed_out = False
        self.call = "run_step"
        self._requests: queue.SimpleQueue[tuple[Any, float] | None] = queue.SimpleQueue()
        self._answers: queue.SimpleQueue[tuple[bool, Any]] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None

    def _serve(self) -> None:
        while True:
            request = self._requests.get()
            if request is None:
                return
            try:
                self._answers.put((True, self._step(*request)))
            except BaseException as exc:  # noqa: BLE001 - handed to the episode's thread, raised there
                self._answers.put((False, exc))

    def start(self) -> _ThreadGuard:
        self._thread = threading.Thread(target=self._serve, name="pedsafe-agent-step", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        # A timed-out helper is abandoned, still inside run_step; any other one ends here.
        if not self.timed_out:
            self._requests.put(None)

    def __enter__(self) -> _ThreadGuard:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def __call__(self, observation: Any, time_s: float) -> Any:
        self._requests.put((observation, time_s))
        try:
            ok, value = self._answers.get(timeout=self.timeout_s)
        except queue.Empty:
            self.timed_out = True
            raise AgentTimeoutError(_message(self.timeout_s, time_s, self.call)) from None
        if not ok:
            raise value
        return value


def guard_step(step: StepFunction, timeout_s: float) -> _AlarmGuard | _ThreadGuard:
    """`step` (an agent's run_step) under the per-step limit, as a context manager that is also the
    guarded callable: `with guard_step(agent.run_step, 10.0) as run_step: run_step(obs, t)` (or
    `run_step = guard_step(...).start()` ... `run_step.stop()`).

    After the `with`, `.timed_out` says whether the stack was cut off (then do not call it again: with
    the thread guard it may still be running)."""
    in_main = threading.current_thread() is threading.main_thread()
    if in_main and hasattr(signal, "setitimer"):
        return _AlarmGuard(step, timeout_s)
    return _ThreadGuard(step, timeout_s)


def call_within(function: Callable[[], Any], timeout_s: float, call: str) -> Any:
    """`function()` (the stack's `call`, e.g. "setup") under the limit: its value, or AgentTimeoutError
    when it has not returned within `timeout_s` (the same two ways as `guard_step`). After a timeout
    the stack may still be running in an abandoned thread: do not call it again."""
    guard = guard_step(lambda _observation, _time_s: function(), timeout_s)
    guard.call = call
    with guard:
        return guard(None, 0.0)
