"""The lane and the pedestrian crossing at a point of a SUMO network (sumolib, internal lanes included)."""

from __future__ import annotations

import math
from pathlib import Path

from pedsafe_sumo.sumo_net import read_net

#: Search radius around the point for lanes, m: wider than any lane, so a point on a lane finds it.
SEARCH_RADIUS_M = 5.0


class NetError(ValueError):
    """The --net file cannot be read."""


class PlaceFinder:
    """`finder(x_m, y_m)` -> (lane_id, crossing_id): the nearest lane (crossings and walking areas
    included) within SEARCH_RADIUS_M, and the crossing edge when that lane lies on one ("" if none)."""

    def __init__(self, net_path: str | Path) -> None:
        path = Path(net_path)
        if not path.is_file():
            raise NetError(f"network file not found: {path}")
        try:
            self.net = read_net(str(path), withInternal=True, withPedestrianConnections=True)
        except Exception as exc:  # sumolib raises whatever its SAX parser raises on a broken file
            raise NetError(f"cannot read network {path}: {exc}") from None
        if not self.net.getEdges():
            raise NetError(f"network {path} has no edges")

    def __call__(self, x_m: float, y_m: float) -> tuple[str, str]:
        if not (math.isfinite(x_m) and math.isfinite(y_m)):
            return "", ""
        lanes = self.net.getNeighboringLanes(x_m, y_m, SEARCH_RADIUS_M, includeJunctions=True)
        if not lanes:
            return "", ""
        lane, _ = min(lanes, key=lambda pair: (pair[1], pair[0].getID()))
        edge = lane.getEdge()
        return lane.getID(), edge.getID() if edge.getFunction() == "crossing" else ""
