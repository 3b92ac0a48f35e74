"""AD stacks that misbehave, for the batch's fault tests (loaded through --algorithm like a user's
plugin). Each drives like the reference stack except for its one fault."""

import math
import os
import sys
import time
from pathlib import Path

from pedsafe_sumo.control.agent import Command
from pedsafe_sumo.control.reference import ReferenceStack


class _CommandsOnce(ReferenceStack):
    """Returns `bad` (instead of the reference's command) at its first step."""

    bad: object = None

    def run_step(self, observation, time_s):
        return type(self).bad


class ReturnsNaN(_CommandsOnce):
    bad = Command(math.nan)


class ReturnsInf(_CommandsOnce):
    bad = Command(math.inf)


class ReturnsNegative(_CommandsOnce):
    bad = Command(-1.5)


class ReturnsText(_CommandsOnce):
    bad = Command("fast")  # type: ignore[arg-type]


class ReturnsNone(_CommandsOnce):
    bad = None


class ReturnsNumber(_CommandsOnce):
    bad = 8.0


class RaisesAtFirstStep(ReferenceStack):
    def run_step(self, observation, time_s):
        raise RuntimeError("planner crashed at its first step")


class RaisesInSetup(ReferenceStack):
    def setup(self, config):
        raise ValueError("no map for this site")


class RaisesInClose(ReferenceStack):
    def close(self):
        raise OSError("cannot flush the stack's log")


class ExitsInRunStep(ReferenceStack):
    def run_step(self, observation, time_s):
        if time_s >= 0.5:
            sys.exit(3)
        return super().run_step(observation, time_s)


class HangsInSetup(ReferenceStack):
    def setup(self, config):
        while True:
            time.sleep(3600)


class KillsItsProcess(ReferenceStack):
    """os._exit in run_step: the worker process ends (the batch sees a worker death)."""

    def run_step(self, observation, time_s):
        os._exit(7)


#: SleepsWhileMarked sleeps at its first step while this file exists, after creating "<file>.asleep".
SLEEP_MARKER_ENV = "PEDSAFE_TEST_SLEEP_MARKER"


class SleepsWhileMarked(ReferenceStack):
    """A slow planner (60 s at its first step) while the marker file exists; the reference otherwise."""

    def run_step(self, observation, time_s):
        marker = Path(os.environ[SLEEP_MARKER_ENV])
        if marker.exists():
            marker.with_suffix(".asleep").touch()
            time.sleep(60)
        return super().run_step(observation, time_s)
