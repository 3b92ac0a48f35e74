"""Actuation of the ego: its physical limits on the commanded speed (`speed_change_limits_mps`: the
parameter file's [vehicle] section), and lateral actuation beyond speed, lane changes and target paths,
the TraCI way.

* ``Command.lane_change`` (+1 left, -1 right): ``vehicle.changeLane`` to the neighbouring lane of the
  current edge, held for the rest of the episode (the ego's lane-change mode is 0: SUMO's own lane
  changing is off, and a TraCI request is executed without waiting for gaps).
* ``Command.path_xy_m`` (world points) or ``Command.lateral_offset_m`` (metres left of the current
  lane's centreline): the ego's front is placed, at the end of the step, where it gets by driving the
  commanded speed along the path (``vehicle.moveToXY``: it stays on its route, mapped
  to the nearest lane for its route, at the exact position given, keepRoute=2: SUMO keeps the lateral
  offset, which keepRoute=1 would snap back to the lane centre).

A command that would leave the road (no lane there, a sidewalk, a point off every drivable lane of the
edge or its junction) is refused: nothing is actuated laterally, and the reason is returned for the
step's log (column ``command_refused``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from pedsafe_sumo.control.agent import Command
from pedsafe_sumo.sim.road_map import NetMap
from pedsafe_sumo.units import yaw_rad_to_sumo_angle

#: How long a TraCI lane change request holds the ego in its new lane [s] (longer than any episode).
LANE_HOLD_S = 1.0e5


def wants_lateral(command: Command) -> bool:
    """Whether the command asks for more than a speed (a duck-typed command without the fields does not)."""
    return (
        bool(getattr(command, "lane_change", 0))
        or getattr(command, "path_xy_m", None) is not None
        or getattr(command, "lateral_offset_m", None) is not None
    )


def _along(path: np.ndarray, x: float, y: float, advance_m: float) -> tuple[float, float, float]:
    """Point and heading `advance_m` beyond the projection of (x, y) on the polyline."""
    a, b = path[:-1], path[1:]
    ab = b - a
    seg = np.hypot(ab[:, 0], ab[:, 1])
    denom = np.maximum(seg * seg, 1e-12)
    t = np.clip(((x - a[:, 0]) * ab[:, 0] + (y - a[:, 1]) * ab[:, 1]) / denom, 0.0, 1.0)
    d = np.hypot(a[:, 0] + t * ab[:, 0] - x, a[:, 1] + t * ab[:, 1] - y)
    k = int(np.argmin(d))
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = min(cum[k] + t[k] * seg[k] + advance_m, cum[-1])
    j = int(min(np.searchsorted(cum, s, side="right") - 1, len(seg) - 1))
    f = (s - cum[j]) / seg[j] if seg[j] > 0 else 0.0
    px, py = a[j] + f * ab[j]
    return float(px), float(py), math.atan2(ab[j, 1], ab[j, 0])


def _offset_path(shape, offset_m: float) -> np.ndarray:
    """The lane centreline shifted `offset_m` to its left (each segment shifted, joints averaged)."""
    pts = np.asarray(shape, dtype=float)
    d = np.diff(pts, axis=0)
    n = np.column_stack([-d[:, 1], d[:, 0]]) / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    normals = np.vstack([n[:1], (n[:-1] + n[1:]) / 2, n[-1:]])
    normals /= np.maximum(np.hypot(normals[:, 0], normals[:, 1]), 1e-12)[:, None]
    return pts + offset_m * normals


def plan_lateral(
    api,
    ego_id: str,
    command: Command,
    net: NetMap,
    ego_xy: tuple[float, float],
    ego_length_m: float,
    target_speed_mps: float,
    step_length_s: float,
) -> tuple[str, Callable[[], None] | None]:
    """Check the command's lane change or path: ('', action) when it is on the road, (refusal, None)
    otherwise. The loop calls ``action()`` with the step's other actuation, right before SUMO steps:
    a moveToXY left pending when an episode ends would outlive the vehicle into the next episode."""
    edge = api.vehicle.getRoadID(ego_id)
    lane_index = api.vehicle.getLaneIndex(ego_id)
    if command.lane_change:
        if edge.startswith(":"):
            return f"lane change {command.lane_change:+d} refused: inside junction {edge}", None
        target = lane_index + int(command.lane_change)
        lane_ids = net.edge_lanes.get(edge, ())
        if not 0 <= target < len(lane_ids) or not net.lanes[lane_ids[target]].drivable:
            return (
                f"lane change {command.lane_change:+d} refused: lane {target} of edge {edge} is not road",
                None,
            )
        return "", lambda: api.vehicle.changeLane(ego_id, target, LANE_HOLD_S)
    if command.path_xy_m is not None:
        path = np.asarray(command.path_xy_m, dtype=float).reshape(-1, 2)
        if path.shape[0] < 2 or not np.all(np.isfinite(path)):
            return "path refused: needs at least two finite points", None
    else:
        lane_id = api.vehicle.getLaneID(ego_id)
        offset = float(command.lateral_offset_m) if command.lateral_offset_m is not None else math.nan
        if not math.isfinite(offset):
            return "lateral offset refused: not a finite number", None
        path = _offset_path(net.lanes[lane_id].shape_xy_m, offset)
    # The ego's box centre advances by the commanded speed; SUMO places vehicles by their front.
    cx, cy, heading = _along(path, ego_xy[0], ego_xy[1], target_speed_mps * step_length_s)
    fx, fy = cx + math.cos(heading) * ego_length_m / 2, cy + math.sin(heading) * ego_length_m / 2
    route = api.vehicle.getRoute(ego_id)
    index = max(api.vehicle.getRouteIndex(ego_id), 0)
    nearby = [lane for e in route[index : index + 2] for lane in net.edge_lanes.get(e, ())]
    if len(route) > index + 1:
        nearby += list(net.vias.get((route[index], route[index + 1]), ()))
    if edge.startswith(":"):
        nearby += list(net.edge_lanes.get(edge, ()))
    if not (net.on_road(cx, cy, nearby) and net.on_road(fx, fy, nearby)):
        what = (
            "path" if command.path_xy_m is not None else f"lateral offset {command.lateral_offset_m:+.2f} m"
        )
        return f"{what} refused: ({cx:.1f}, {cy:.1f}) leaves the road", None
    angle = float(yaw_rad_to_sumo_angle(heading))
    return "", lambda: api.vehicle.moveToXY(ego_id, "", -1, fx, fy, angle=angle, keepRoute=2)


def speed_change_limits_mps(
    vehicle: dict[str, Any] | None, step_length_s: float
) -> tuple[float, float] | None:
    """(most speed lost, most speed gained) in one step from the parameter file's [vehicle] limits, or
    None when none apply (`physical_limits` false, or a run recorded before the section existed)."""
    if not vehicle or not vehicle.get("physical_limits", False):
        return None
    return float(vehicle["max_decel_mps2"]) * step_length_s, float(vehicle["max_accel_mps2"]) * step_length_s
