"""A LiDAR perception a user could write: ground removal, grid clustering, a size rule, a tracker.

Plug it in front of the reference planner and controller:

    python -m pedsafe_sumo.batch --scenario crossing --perception examples.lidar_clustering:LidarClustering

It reads only ``onboard_lidar_points`` (no ground-truth labels), in the sensor frame (x forward,
y left, z up, metres, origin at the LiDAR), and reports pedestrians and vehicles in the world frame.

What it gets wrong, as a simple detector does: the visible corner of a queued car half hidden behind the
one in front is pedestrian-sized, so it reports a few false pedestrians beside a queue (the planner
then brakes early, and drives on once they are out of its path); a pedestrian whose legs are hidden
behind a parked car is not reported until she steps out.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from pedsafe_sumo.control.agent import PerceivedPedestrian, PerceivedVehicle, Perception

CELL_M = 0.4  # grid cell of the clustering: points in touching cells form one cluster [m]
GROUND_CLEARANCE_M = 0.2  # points lower than this above the ground are ground [m]
MAX_RANGE_M = 50.0  # clusters farther than this are ignored [m]
MIN_POINTS = 5  # smaller clusters are noise
PED_MAX_EXTENT_M = 0.8  # a pedestrian's footprint fits in this square (body about 0.6 m across) [m]
PED_HEIGHT_RANGE_M = (0.8, 2.3)  # and its top lies this high above the ground [m]
# A pedestrian in view shows from her feet up: a small cluster that starts higher is the visible corner of
# a vehicle half hidden behind another (queued and parked cars otherwise make pedestrian-sized fragments).
PED_MAX_LOWEST_M = 0.6
VEHICLE_MAX_EXTENT_M = 7.0  # larger clusters are buildings, hedges, tree rows
ASSOCIATION_M = 1.5  # a cluster within this of last step's track keeps its id [m]


def cluster_grid(xy: np.ndarray, cell_m: float) -> np.ndarray:
    """Connected components of the occupied grid cells (8-neighbourhood): a label per point (0-based)."""
    if xy.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    cells = np.floor(xy / cell_m).astype(np.int64)
    cells -= cells.min(axis=0)
    grid = np.zeros(cells.max(axis=0) + 1, dtype=bool)
    grid[cells[:, 0], cells[:, 1]] = True
    labels, _ = ndimage.label(grid, structure=np.ones((3, 3), dtype=bool))
    return labels[cells[:, 0], cells[:, 1]].astype(np.int64) - 1


class LidarClustering(Perception):
    """Pedestrians and vehicles from raw LiDAR points (see module docstring)."""

    def setup(self, config):
        mount = config["sensor_mounts"]["onboard_lidar"]
        self.forward_m = float(mount["forward_offset_m"])
        self.left_m = float(mount["left_offset_m"])
        self.height_m = float(mount["height_m"])
        self.tracks: dict[str, tuple[float, float]] = {}
        self.next_id = 0

    def sensors(self):
        return ["onboard_lidar_points"]

    def detect(self, observation, time_s):
        points = observation.sensor_data["onboard_lidar_points"]
        above = points[:, 2] > -self.height_m + GROUND_CLEARANCE_M
        near = np.hypot(points[:, 0], points[:, 1]) < MAX_RANGE_M
        pts = points[above & near]
        labels = cluster_grid(pts[:, :2], CELL_M)
        ego = observation.ego
        c, s = math.cos(ego.yaw_rad), math.sin(ego.yaw_rad)
        ox = ego.x_m + c * self.forward_m - s * self.left_m
        oy = ego.y_m + s * self.forward_m + c * self.left_m
        found, tracks = [], {}
        order = np.argsort(labels, kind="stable")
        bounds = np.flatnonzero(np.diff(labels[order])) + 1
        for k, members in enumerate(np.split(order, bounds) if labels.size else []):
            cl = pts[members]
            if cl.shape[0] < MIN_POINTS:
                continue
            lo, hi = cl[:, :2].min(axis=0), cl[:, :2].max(axis=0)
            extent = float(max(hi - lo))
            top_m = float(cl[:, 2].max()) + self.height_m
            lowest_m = float(cl[:, 2].min()) + self.height_m
            cx_s, cy_s = (lo + hi) / 2
            wx, wy = ox + c * cx_s - s * cy_s, oy + s * cx_s + c * cy_s
            ped_sized = extent <= PED_MAX_EXTENT_M and PED_HEIGHT_RANGE_M[0] <= top_m <= PED_HEIGHT_RANGE_M[1]
            if ped_sized and lowest_m <= PED_MAX_LOWEST_M:
                track = self._associate(wx, wy, tracks)
                found.append(PerceivedPedestrian(track, wx, wy, "onboard_lidar"))
            elif not ped_sized and extent <= VEHICLE_MAX_EXTENT_M:
                length, width = float(hi[0] - lo[0]), float(hi[1] - lo[1])
                found.append(
                    PerceivedVehicle(f"cluster_{k}", wx, wy, ego.yaw_rad, length, width, "onboard_lidar")
                )
        self.tracks = tracks
        return found

    def _associate(self, x, y, tracks):
        best, best_d = None, ASSOCIATION_M
        for tid, (tx, ty) in self.tracks.items():
            d = math.hypot(x - tx, y - ty)
            if d < best_d and tid not in tracks:
                best, best_d = tid, d
        if best is None:
            best = f"lidar_{self.next_id}"
            self.next_id += 1
        tracks[best] = (x, y)
        return best
