"""AD stacks used by the engine tests, loaded through --algorithm like a user's plugin."""

from pedsafe_sumo.control.agent import Agent, Command


class NeverBrakes(Agent):
    """Holds the initial speed whatever it sees: forces collisions."""

    def setup(self, config):
        self.speed_mps = config["initial_speed_mps"]

    def run_step(self, observation, time_s):
        return Command(self.speed_mps)


class StopsAtOnce(Agent):
    """Plain duck-typed plugin (no base class): stops as soon as anything is perceived."""

    def __init__(self):
        self.stopped = False

    def setup(self, config):
        self.speed_mps = config["initial_speed_mps"]

    def sensors(self):
        return ["onboard_camera", "onboard_lidar", "v2i"]

    def run_step(self, observation, time_s):
        self.stopped = self.stopped or bool(observation.pedestrians)
        return Command(0.0 if self.stopped else self.speed_mps, {"braking": self.stopped})

    def close(self):
        pass


class FailsOnOddSeeds(Agent):
    """Raises inside run_step on odd seeds: the batch must record an error and go on."""

    def setup(self, config):
        self.seed = config["seed"]
        self.speed_mps = config["initial_speed_mps"]

    def run_step(self, observation, time_s):
        if self.seed % 2 and time_s > 0.5:
            raise RuntimeError(f"planner crashed on seed {self.seed}")
        return Command(self.speed_mps)
