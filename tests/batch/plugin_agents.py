"""AD stacks for the batch's fault tests, loaded through --algorithm like a user's plugin.

All drive exactly like the reference stack (same commands, so the same rows); they only add a fault
or a pause. Which episode a fault hits is chosen through environment variables, which the batch's
worker processes inherit.
"""

import os
import signal
import time
from pathlib import Path

from pedsafe_sumo.control.reference import ReferenceStack

#: Seed of the episode whose worker process kills itself.
KILL_SEED_ENV = "PEDSAFE_TEST_KILL_SEED"
#: KillsWorkerOnce: kill only while this file does not exist (it is created just before the kill).
KILL_MARKER_ENV = "PEDSAFE_TEST_KILL_MARKER"
#: Seed of the episode whose run_step sleeps for ever (SleepsForever).
SLEEP_SEED_ENV = "PEDSAFE_TEST_SLEEP_SEED"
#: When SleepsForever falls asleep in that episode [s of simulated time].
SLEEP_AT_S = 1.0


def _kill_this_process() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


class PausingReference(ReferenceStack):
    """The reference stack, 0.15 s slower per episode: gives a test time to kill the batch mid-run."""

    def setup(self, config):
        time.sleep(0.15)
        super().setup(config)


class KillsWorkerOnce(ReferenceStack):
    """SIGKILLs its own worker process on the chosen seed, the first time only (marker file)."""

    def setup(self, config):
        marker = Path(os.environ[KILL_MARKER_ENV])
        if config["seed"] == int(os.environ[KILL_SEED_ENV]) and not marker.exists():
            marker.write_text(f"killed pid {os.getpid()} on seed {config['seed']}\n")
            _kill_this_process()
        super().setup(config)


class KillsWorkerAlways(ReferenceStack):
    """SIGKILLs its own worker process every time it is set up on the chosen seed."""

    def setup(self, config):
        if config["seed"] == int(os.environ[KILL_SEED_ENV]):
            _kill_this_process()
        super().setup(config)


class SleepsForever(ReferenceStack):
    """The reference stack, except that on the chosen seed its run_step never returns from t = SLEEP_AT_S
    on (a hung planner); every other episode drives exactly like the reference."""

    def setup(self, config):
        self._hangs = config["seed"] == int(os.environ[SLEEP_SEED_ENV])
        super().setup(config)

    def run_step(self, observation, time_s):
        if self._hangs and time_s >= SLEEP_AT_S:
            while True:
                time.sleep(3600)
        return super().run_step(observation, time_s)


class NoRunStep:
    """Has setup and close but no run_step: not an AD stack."""

    def setup(self, config):
        pass

    def sensors(self):
        return ["onboard_camera"]

    def close(self):
        pass
