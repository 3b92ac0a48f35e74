"""AD stacks of the Euro NCAP suite's tests, loadable with --algorithm tests.ncap.agents:Class."""

from pedsafe_sumo.control.agent import Agent, Command

#: The oracle's deceleration [m/s2] (9 m/s2: a full emergency stop on dry asphalt).
ORACLE_DECELERATION_MPS2 = 9.0


class NeverBrakes(Agent):
    """Holds the test speed whatever it sees."""

    def setup(self, config):
        self.speed_mps = config["initial_speed_mps"]

    def run_step(self, observation, time_s):
        return Command(self.speed_mps)


class BrakesFromFirstFrame(Agent):
    """An oracle: brakes at ORACLE_DECELERATION_MPS2 from the first step, seeing nothing."""

    def setup(self, config):
        self.speed_mps = config["initial_speed_mps"]
        self.step_s = config["step_length_s"]

    def sensors(self):
        return []

    def run_step(self, observation, time_s):
        self.speed_mps = max(0.0, self.speed_mps - ORACLE_DECELERATION_MPS2 * self.step_s)
        return Command(self.speed_mps, {"braking": True})


class RaisesAt20Kmh(Agent):
    """A stack with a bug: raises on its second step whenever it starts at 20 km/h; holds speed otherwise."""

    def setup(self, config):
        self.speed_mps = config["initial_speed_mps"]
        self.steps = 0

    def run_step(self, observation, time_s):
        self.steps += 1
        if self.steps == 2 and abs(self.speed_mps - 20 / 3.6) < 1e-9:
            raise ZeroDivisionError("the stack's bug")
        return Command(self.speed_mps)
