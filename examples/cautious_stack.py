"""A user AD stack: the reference pedestrian braking, plus stopping at red lights and keeping a gap to
the vehicle ahead, from the world feeds of the AD interface (docs/ad_interface.md).

    python -m pedsafe_sumo.batch --scenario crossing --algorithm examples.cautious_stack:CautiousStack
    python -m pedsafe_sumo.batch --scenario crossing --algorithm examples.cautious_stack:CautiousStack \
        --perception examples.lidar_clustering:LidarClustering      # its detector replaced
"""

from __future__ import annotations

import math

from pedsafe_sumo.control.agent import Command
from pedsafe_sumo.control.reference import ReferenceStack

COMFORT_DECEL_MPS2 = 3.0  # braking for a red light or a slower vehicle [m/s2]
STOP_SHORT_M = 1.0  # stop this far before the stop line [m]
GAP_M = 3.0  # standstill gap kept to the vehicle ahead [m]
HEADWAY_S = 1.5  # time gap kept to the vehicle ahead [s]
STOPPING_STATES = "ryu"  # red, yellow, red-yellow: do not enter (stop if it can be done comfortably)


class CautiousStack(ReferenceStack):
    def sensors(self):
        return ["onboard_camera", "onboard_lidar", "v2i", "vehicles", "traffic_light"]

    def run_step(self, observation, time_s):
        command = super().run_step(observation, time_s)
        ego = observation.ego
        target = command.target_speed_mps
        info = dict(command.info)
        light = observation.traffic_light
        if light is not None and light.state in STOPPING_STATES and math.isfinite(light.distance_m):
            room_m = light.distance_m - STOP_SHORT_M
            # Stop when it can be done with at most the hardest braking; a yellow too close is run.
            needed = ego.speed_mps**2 / (2 * max(room_m, 0.01))
            if room_m > 0 and (light.state != "y" or needed <= COMFORT_DECEL_MPS2):
                target = min(target, math.sqrt(max(0.0, 2 * COMFORT_DECEL_MPS2 * max(room_m - 0.5, 0.0))))
                info["red_light"] = True
        c, s = math.cos(ego.yaw_rad), math.sin(ego.yaw_rad)
        for v in observation.vehicles:
            lon = (v.x_m - ego.x_m) * c + (v.y_m - ego.y_m) * s
            lat = -(v.x_m - ego.x_m) * s + (v.y_m - ego.y_m) * c
            if lon <= 0 or abs(lat) > (ego.width_m + v.width_m) / 2:
                continue
            gap = lon - (ego.length_m + v.length_m) / 2 - GAP_M
            target = min(
                target, max(0.0, min(gap / HEADWAY_S, math.sqrt(max(0.0, 2 * COMFORT_DECEL_MPS2 * gap))))
            )
            info["following"] = v.vehicle_id
        dt = observation.step_length_s
        target = max(target, ego.speed_mps - self.max_decel_mps2 * dt)
        info["braking"] = info.get("braking", False) or target < ego.speed_mps - 1e-6
        return Command(target, info)
