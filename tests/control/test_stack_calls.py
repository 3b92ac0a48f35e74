"""The checks around the AD stack's calls (pedsafe_sumo.control.stack_calls), on their own: every
invalid command raises StackError with a one-line message naming the stack, the value and the time;
a valid one gives its speed unchanged; sys.exit becomes the episode's StackError; setup has the
time limit of run_step; close's failure does not hide the episode's first one."""

from __future__ import annotations

import math
import sys
import threading
import time

import numpy as np
import pytest

from pedsafe_sumo.control.agent import Command, with_perception
from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.control.stack_calls import (
    StackError,
    checked_speed_mps,
    close_quietly,
    setup_within,
    stack_failure,
    stack_label,
)
from pedsafe_sumo.control.timeout import AgentTimeoutError

STACK = "mypkg.stack:MyStack"
#: Every message of an invalid command at t = 0.05 s reads RETURNED + what + AT.
RETURNED, AT = "AD stack mypkg.stack:MyStack returned ", " at t=0.05 s"

INVALID = [
    (Command(math.nan), "target_speed_mps=nan"),
    (Command(math.inf), "target_speed_mps=inf"),
    (Command(-math.inf), "target_speed_mps=-inf"),
    (Command(-0.1), "target_speed_mps=-0.1"),
    (Command(np.float32("nan")), "target_speed_mps=nan"),
    (Command("fast"), "target_speed_mps='fast' (str, not a number)"),
    (Command(None), "target_speed_mps=None (NoneType, not a number)"),
    (Command(True), "target_speed_mps=True (bool, not a number)"),
    (None, "None (NoneType) instead of a Command"),
    (8.0, "8.0 (float) instead of a Command"),
    ({"target_speed_mps": 8.0}, "{'target_speed_mps': 8.0} (dict) instead of a Command"),
]  # fmt: skip

VALID = [
    (8.0, 8.0),
    (0.0, 0.0),
    (-0.0, 0.0),
    (3, 3.0),
    (np.float64(2.5), 2.5),
    (np.float32(1.5), 1.5),
    (np.int64(4), 4.0),
]


@pytest.mark.parametrize(("command", "message"), INVALID)
def test_an_invalid_command_is_an_error_naming_the_stack_and_the_value(command, message):
    with pytest.raises(StackError) as raised:
        checked_speed_mps(command, STACK, 0.05)
    assert str(raised.value) == RETURNED + message + AT


@pytest.mark.parametrize(("speed", "expected"), VALID)
def test_a_valid_speed_is_applied_as_commanded(speed, expected):
    got = checked_speed_mps(Command(speed), STACK, 1.0)
    assert type(got) is float and got == expected and math.copysign(1.0, got) == 1.0


def test_a_long_value_is_cut_to_one_short_line():
    with pytest.raises(StackError) as raised:
        checked_speed_mps(Command("x" * 500), STACK, 0.0)
    assert len(str(raised.value)) < 200 and "\n" not in str(raised.value)


@pytest.mark.parametrize(
    ("exc", "expected"),
    [
        (SystemExit(3), "StackError: AD stack mypkg.stack:MyStack called sys.exit(3)"),
        (SystemExit("bye"), "StackError: AD stack mypkg.stack:MyStack called sys.exit('bye')"),
        (SystemExit(), "StackError: AD stack mypkg.stack:MyStack called sys.exit(None)"),
        (GeneratorExit("odd"), "StackError: AD stack mypkg.stack:MyStack raised GeneratorExit: odd"),
        (RuntimeError("planner crashed"), "RuntimeError: planner crashed"),
    ],
)
def test_what_a_stack_raises_becomes_the_episodes_error(exc, expected):
    failure = stack_failure(exc, STACK)
    assert failure is not None and f"{type(failure).__name__}: {failure}" == expected


def test_keyboard_interrupt_is_left_to_stop_the_batch():
    assert stack_failure(KeyboardInterrupt(), STACK) is None


def test_the_label_names_the_stack_as_algorithm_does():
    assert stack_label(ReferenceStack) == "pedsafe_sumo.control.reference:ReferenceStack"

    class Detector:
        pass

    plugged = with_perception(ReferenceStack, Detector)
    assert stack_label(plugged) == "pedsafe_sumo.control.reference:ReferenceStack+Detector"


class _HangsInSetup:
    def setup(self, config):
        while True:
            time.sleep(3600)


class _Records:
    def setup(self, config):
        self.config = config


@pytest.mark.parametrize("where", ["main", "thread"])
def test_setup_has_the_time_limit_of_run_step(where):
    box: dict = {}

    def call():
        started = time.perf_counter()
        try:
            setup_within(_HangsInSetup(), {}, 0.2)
        except AgentTimeoutError as exc:
            box["message"] = str(exc)
        box["took_s"] = time.perf_counter() - started

    if where == "main":
        call()
    else:
        thread = threading.Thread(target=call)
        thread.start()
        thread.join(10)
    assert box["message"] == "the AD stack's setup did not return within 0.2 s (--agent-timeout)"
    assert box["took_s"] < 2.0
    agent = _Records()
    setup_within(agent, {"seed": 1}, 0.2)  # a prompt setup is called once, with its config
    assert agent.config == {"seed": 1}


class _FailsToClose:
    def close(self):
        raise OSError("cannot flush")


def test_close_fails_the_episode_unless_it_already_failed():
    with pytest.raises(OSError, match="cannot flush"):
        close_quietly(_FailsToClose())
    with pytest.raises(RuntimeError, match="planner crashed"):
        try:
            raise RuntimeError("planner crashed")
        finally:
            close_quietly(_FailsToClose())
    assert sys.exc_info()[1] is None
