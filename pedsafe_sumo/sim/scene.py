"""What the episode loop (sim/episode.py) derives from the scene at each step: the vehicles' bodies for the
snapshot, the pedestrians the stack's sensors report, whether the pedestrian is in the scene, and why the
episode ends."""

from __future__ import annotations

import math
from collections.abc import Mapping
from itertools import chain
from operator import itemgetter

import numpy as np

from pedsafe_sumo.behaviour.pedestrian import PedestrianPose, PedestrianWalker
from pedsafe_sumo.control.agent import EgoState, PerceivedPedestrian
from pedsafe_sumo.safety.collision import STATIONARY_SPEED_MPS
from pedsafe_sumo.scenarios.episode_setup import PedestrianSetup
from pedsafe_sumo.sim.staging import EGO_ID, VehicleDims


def vehicle_bodies(
    ids: tuple[str, ...], dims: Mapping[str, VehicleDims]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """(lengths, widths, heights, half_diagonals, colours, ego_index) of the vehicles `ids`, in order:
    the snapshot's body arrays, rebuilt only when a vehicle enters or leaves."""
    # One column at a time from the bodies' tuples: the same doubles as an (N, 3) array's columns, a
    # third of the time of building that array from N tuples (the loop rebuilds every few steps).
    bodies = list(map(dims.__getitem__, ids))
    n = len(bodies)
    lengths = np.fromiter(map(itemgetter(0), bodies), float, n)
    widths = np.fromiter(map(itemgetter(1), bodies), float, n)
    heights = np.fromiter(map(itemgetter(2), bodies), float, n)
    half_diagonals = 0.5 * np.hypot(lengths, widths)
    colours = np.fromiter(chain.from_iterable(map(itemgetter(3), bodies)), float, 3 * n).reshape(n, 3)
    return lengths, widths, heights, half_diagonals, colours, ids.index(EGO_ID)


def perceived_pedestrians(detections, wanted: set[str]) -> list[PerceivedPedestrian]:
    """The pedestrians the sensors the stack gets (`wanted`) report, each once, by its first reporter
    in the order onboard camera, onboard LiDAR, V2I."""
    reported: list[PerceivedPedestrian] = []
    seen: set[str] = set()
    sources = (
        ("onboard_camera", detections.camera),
        ("onboard_lidar", detections.lidar),
        ("v2i", detections.v2i_received),
    )
    for source, found in sources:
        if not found.ids or source not in wanted:
            continue
        # tolist(): the positions as Python floats (the same doubles), without a numpy row per pedestrian.
        for pid, (x_m, y_m) in zip(found.ids, found.xy_m.tolist()):
            if pid not in seen:
                seen.add(pid)
                reported.append(PerceivedPedestrian(pid, x_m, y_m, source))
    return reported


def in_scene_from_start(ped: PedestrianSetup) -> bool:
    """Whether the pedestrian is in the scene (and in SUMO) from the episode's start."""
    return ped.appear_time_s <= 0.0


def appearing_pose(walker: PedestrianWalker) -> PedestrianPose:
    """The pedestrian's pose as they enter the scene: at the start of their path, walking in to the
    step-off point or waiting there."""
    x, y, heading = walker.position(0.0)
    if walker.kerb_reached_s is None:
        return PedestrianPose(x, y, heading, walker.params.walking_speed_mps, "walking_in")
    return PedestrianPose(x, y, heading, 0.0, "waiting")


def episode_end(
    time_s: float,
    clearance_m: float,
    ego: EgoState,
    pose: PedestrianPose,
    walker: PedestrianWalker,
    ped: PedestrianSetup,
    time_limit_s: float,
) -> str | None:
    """Why the episode ends at the state of `time_s`, or None when it goes on. A contact with a standing
    ego is no collision (safety.collision): the step is logged and the episode goes on. `pose` is the
    pedestrian's last pose in the scene (before they appear: where they will); a pedestrian who has left
    the scene has cleared it; `clearance_m` is +inf while nobody is in the scene."""
    if clearance_m <= 0.0 and ego.speed_mps >= STATIONARY_SPEED_MPS:
        return "collision"
    # Not before they step off: the geometry is looked at only from then on (walker.cleared has no effect
    # on the walker beyond its memo of the conflict point).
    if time_s > walker.crossing_from_s:
        cleared = walker.cleared((ego.x_m, ego.y_m), ego.yaw_rad, ego.length_m, ego.width_m)
        if cleared is None:  # the ego's heading does not cross the path: its rear past the pedestrian
            lon = (pose.x_m - ego.x_m) * math.cos(ego.yaw_rad) + (pose.y_m - ego.y_m) * math.sin(ego.yaw_rad)
            cleared = (lon < -(ego.length_m / 2 + ped.radius_m), walker.finished)
        if all(cleared):
            return "both_cleared"
    if time_s >= time_limit_s:
        return "time_limit"
    return None
