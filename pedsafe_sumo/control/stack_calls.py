"""What the episode checks around every call of the AD stack under test: a misbehaving stack ends its
own episode with a one-line reason, and is never scored as a safe run.

* The command (`checked_speed_mps`): run_step must return a `Command` whose `target_speed_mps` is a
  finite real number >= 0. Anything else (None, another object, a string, NaN, inf, a negative speed)
  raises `StackError` naming the stack, the value and the time; nothing is clamped or guessed.
* The stack's exits (`stack_failure`): an exception out of the stack's constructor, sensors(), setup(),
  run_step() or close() ends the episode with the stack's own message; `sys.exit` in the stack
  (SystemExit, a BaseException) is turned into a `StackError` for that episode instead of ending the
  worker or the batch. KeyboardInterrupt is left alone: it stops the batch.
* setup() runs under the same time limit as run_step (`setup_within`, pedsafe_sumo.control.timeout).
* close() (`close_quietly`): its exception ends an episode that ran; while the episode is already
  failing, the first failure is the one reported.

`os._exit` in a stack ends its process: the batch sees a worker death (docs/batch.md, "Faults").
"""

from __future__ import annotations

import math
import numbers
import sys
from typing import Any

from pedsafe_sumo.control.agent import Command
from pedsafe_sumo.control.timeout import call_within


class StackError(RuntimeError):
    """The AD stack under test misbehaved (an invalid command, sys.exit); the message says how."""


def stack_label(agent_class: type) -> str:
    """How messages name a stack: 'package.module:ClassName', as `--algorithm` names it."""
    return f"{agent_class.__module__}:{agent_class.__qualname__}"


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def checked_speed_mps(command: Any, stack: str, time_s: float) -> float:
    """The command's target speed as a float [m/s]; StackError unless `command` is a Command whose
    target_speed_mps is a finite real number >= 0 (-0.0 counts as 0.0)."""
    if not isinstance(command, Command):
        raise StackError(
            f"AD stack {stack} returned {_shown(command)} ({type(command).__name__}) instead of a Command "
            f"at t={time_s:.2f} s"
        )
    speed = command.target_speed_mps
    if type(speed) is not float:  # the usual case skips these checks
        if isinstance(speed, bool) or not isinstance(speed, numbers.Real):
            raise StackError(
                f"AD stack {stack} returned target_speed_mps={_shown(speed)} ({type(speed).__name__}, "
                f"not a number) at t={time_s:.2f} s"
            )
        speed = float(speed)
    if not 0.0 <= speed < math.inf:  # NaN fails the comparison too
        raise StackError(f"AD stack {stack} returned target_speed_mps={speed!r} at t={time_s:.2f} s")
    return speed + 0.0  # -0.0 becomes 0.0; every other speed keeps its bits


def stack_failure(exc: BaseException, stack: str) -> BaseException | None:
    """The exception that ends the episode for `exc` raised out of the stack's code: `exc` itself for an
    Exception, a StackError for sys.exit, None for what must stop the batch (KeyboardInterrupt)."""
    if isinstance(exc, Exception):
        return exc
    if isinstance(exc, SystemExit):
        return StackError(f"AD stack {stack} called sys.exit({exc.code!r})")
    if isinstance(exc, KeyboardInterrupt):
        return None
    return StackError(f"AD stack {stack} raised {type(exc).__name__}: {exc}")


def episode_error_message(exc: BaseException) -> str:
    """The one-line `error` of an episode's row for `exc` (its type and message)."""
    return f"{type(exc).__name__}: {exc}"


def setup_within(agent: Any, config: dict[str, Any], timeout_s: float) -> None:
    """agent.setup(config) under the per-call time limit (AgentTimeoutError past it)."""
    call_within(lambda: agent.setup(config), timeout_s, "setup")


def close_quietly(agent: Any) -> None:
    """agent.close(): its exception propagates, unless the episode is already failing (called from a
    `finally` while an exception propagates): then the first failure stands and close's is dropped."""
    failing = sys.exc_info()[1] is not None
    try:
        agent.close()
    except (Exception, SystemExit):
        if not failing:
            raise
