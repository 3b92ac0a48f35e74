"""Perception layer: geometric sensors over world snapshots (no SUMO import here).

Onboard camera and LiDAR, roadside camera and the V2I link of the paper's eqs. 5-6. Frames and
units: see :mod:`pedsafe_sumo.perception.geometry` and docs/perception.md.
"""

from .geometry import (
    focal_length_px,
    intrinsic_matrix,
    project_points,
    roadside_to_vehicle_camera,
    sumo_angle_to_yaw_rad,
    sumo_front_to_centre,
    world_to_camera_transform,
    yaw_rad_to_sumo_angle,
)
from .pipeline import Detections, Mount, PerceptionSystem, SensorDetections, SensorSuite, perceive
from .v2i import V2ILink, V2IMessage, V2ISpec
from .world import (
    EgoPose,
    Pedestrians,
    RoadsideUnit,
    StaticOccluders,
    VehicleBoxes,
    WorldSnapshot,
    load_roadside_units,
    load_static_occluders,
)

__all__ = [
    "Detections",
    "EgoPose",
    "Mount",
    "Pedestrians",
    "PerceptionSystem",
    "RoadsideUnit",
    "SensorDetections",
    "SensorSuite",
    "StaticOccluders",
    "V2ILink",
    "V2IMessage",
    "V2ISpec",
    "VehicleBoxes",
    "WorldSnapshot",
    "focal_length_px",
    "sumo_front_to_centre",
    "intrinsic_matrix",
    "load_roadside_units",
    "load_static_occluders",
    "perceive",
    "project_points",
    "roadside_to_vehicle_camera",
    "sumo_angle_to_yaw_rad",
    "world_to_camera_transform",
    "yaw_rad_to_sumo_angle",
]
