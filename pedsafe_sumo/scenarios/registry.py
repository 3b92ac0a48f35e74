"""The names pedsafe_sumo.sim imports from the scenarios package, at the modules that define them:
scenarios/specs.py (the scenario table), episode_setup.py (the initial world), road_users.py (sizes and
colours), staging.py (drawing and signal staging)."""

from pedsafe_sumo.scenarios.episode_setup import (
    BackgroundVehicle,
    EpisodeSetup,
    PedestrianSetup,
    SignalStaging,
    VehicleSetup,
)
from pedsafe_sumo.scenarios.road_users import CAR_COLOURS_RGB, VEHICLE_CLASSES
from pedsafe_sumo.scenarios.specs import ScenarioSpec
from pedsafe_sumo.scenarios.staging import draw_episode, stage_signals

__all__ = [
    "CAR_COLOURS_RGB",
    "VEHICLE_CLASSES",
    "BackgroundVehicle",
    "EpisodeSetup",
    "PedestrianSetup",
    "ScenarioSpec",
    "SignalStaging",
    "VehicleSetup",
    "draw_episode",
    "stage_signals",
]
