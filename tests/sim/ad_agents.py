"""AD stacks of the AD-interface tests, loaded like a user's plugin."""

from pedsafe_sumo.control.agent import Agent, Command, Perception


class AsksForRadar(Agent):
    """Names a sensor the simulator does not have."""

    def sensors(self):
        return ["onboard_lidar_points", "onboard_radar"]

    def run_step(self, observation, time_s):
        return Command(0.0)


class RadarPerception(Perception):
    def sensors(self):
        return ["front_radar"]

    def detect(self, observation, time_s):
        return []


class Recorder(Agent):
    """Keeps its initial speed and records every observation; `wants` is set by the test."""

    wants: list[str] = []
    command: dict = {}
    observations: list = []

    def sensors(self):
        return list(type(self).wants)

    def setup(self, config):
        self.speed_mps = config["initial_speed_mps"]
        self.config = config
        type(self).observations = []

    def run_step(self, observation, time_s):
        type(self).observations.append(observation)
        return Command(self.speed_mps, **type(self).command)
