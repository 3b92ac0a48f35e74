"""The parts of the Observation beyond today's pedestrian detections, built only when asked for.

An agent's sensors() names what it wants (pedsafe_sumo.control.agent: RAW_SENSORS, WORLD_FEEDS); the
episode loop builds one :class:`ObservationFeeds` per episode when any of those is wanted (none: the
loop pays one ``is None`` test per step) and adds ``feeds.step(...)`` to each Observation.

Timing: everything refers to the step's snapshot at ``time_s`` (before the command of this step is
actuated), except what travels over the V2I link: the roadside camera image and the V2I traffic-light
state arrive with the link's latency (``perception.v2i.latency_s``): the one delivered at t is the
latest measured at or before t - latency.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import Any

from pedsafe_sumo.control.agent import (
    RAW_SENSORS,
    WORLD_FEEDS,
    LaneCentreline,
    PerceivedVehicle,
    RouteAhead,
    TrafficLightState,
)
from pedsafe_sumo.perception.raw import lidar_point_cloud, render_image
from pedsafe_sumo.perception.vehicles import camera_sees_vehicles, lidar_sees_vehicles
from pedsafe_sumo.sim.road_map import NetMap, load_net_map

#: What each condition grants beyond the onboard sensors: these travel over the V2I link.
V2I_ONLY = frozenset({"roadside_camera_image"})


def sensor_mounts(perception_params: dict[str, Any]) -> dict[str, dict[str, float]]:
    """Where the onboard sensors sit on the ego (handed to setup() as ``sensor_mounts``): per sensor,
    forward_offset_m and left_offset_m from the box centre, height_m above ground, and the camera's
    yaw_offset_deg, pitch_down_deg and hfov_deg."""
    cam, lid = perception_params["camera"], perception_params["lidar"]
    keys = ("forward_offset_m", "left_offset_m", "height_m")
    return {
        "onboard_lidar": {k: float(lid[k]) for k in keys},
        "onboard_camera": {
            **{k: float(cam[k]) for k in (*keys, "yaw_offset_deg", "pitch_down_deg", "hfov_deg")},
        },
    }


def granted_names(condition: str) -> set[str]:
    """Every RAW_SENSORS / WORLD_FEEDS name the condition grants."""
    names = set(RAW_SENSORS) | set(WORLD_FEEDS)
    return names if condition == "v2i" else names - V2I_ONLY


class ObservationFeeds:
    """Per-episode builder of the asked-for observation parts (see module docstring)."""

    def __init__(
        self,
        api,
        ego_id: str,
        wanted: set[str],
        condition: str,
        net_file,
        sensors,
        perception_params: dict[str, Any],
    ) -> None:
        self.api = api
        self.ego_id = ego_id
        self.wanted = set(wanted)
        self.condition = condition
        self.sensors = sensors
        raw = perception_params["raw"]
        self.raw = raw
        self.latency_s = float(perception_params["v2i"]["latency_s"])
        # A parameter set without the key (a run recorded before it existed) delivered SPaT.
        self.fresher_signal = perception_params["v2i"].get("signal_source", "spat") == "fresher"
        self.net = load_net_map(str(net_file)) if self.wanted & {"route", "road_map"} else None
        self._roadside_buffer: deque = deque()
        self._signal_buffer: deque = deque()
        self._route_key: tuple | None = None
        self._route_lanes: tuple[LaneCentreline, ...] = ()
        self._route_edges: tuple[str, ...] = ()

    @classmethod
    def for_agent(cls, api, ego_id, wanted, condition, net_file, sensors, perception_params):
        """The builder when the agent asked for anything beyond the detections, else None."""
        extra = set(wanted) & (set(RAW_SENSORS) | set(WORLD_FEEDS))
        if not extra:
            return None
        return cls(api, ego_id, extra, condition, net_file, sensors, perception_params)

    def subscribe_ego(self) -> None:
        """With the route feed: add what it reads of the ego at each step (lane, route index, position on
        the lane) to the ego's subscription (position, angle, speed), so that the loop's one read of the
        subscription replaces three calls a step (step's `ego_values`)."""
        if "route" in self.wanted:
            tc = self.api.constants
            variables = [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, *self._route_variables]
            self.api.vehicle.subscribe(self.ego_id, variables)

    @property
    def _route_variables(self) -> tuple[int, int, int]:
        tc = self.api.constants
        return tc.VAR_LANE_ID, tc.VAR_ROUTE_INDEX, tc.VAR_LANEPOSITION

    @property
    def sees_scene(self) -> bool:
        """Whether any wanted part is made from the world snapshot (raw sensor data, perceived vehicles);
        route, road map and signal come from SUMO and the network alone."""
        return bool(self.wanted & (set(RAW_SENSORS) | {"vehicles"}))

    # ----------------------------------------------------------------------------- per step
    def step(
        self, snapshot, ego_pose, ego_index: int, time_s: float, ego_values: Mapping[int, Any] | None = None
    ) -> dict[str, Any]:
        """Keyword arguments for this step's Observation. `ego_values`: the ego's subscription results
        of this step (subscribe_ego), or None (the route feed asks SUMO)."""
        out: dict[str, Any] = {}
        wanted = self.wanted
        data: dict[str, Any] = {}
        suite = self.sensors
        if wanted & {"onboard_lidar_points", "onboard_lidar_labels"}:
            points, labels = lidar_point_cloud(
                snapshot,
                suite.lidar_mount.pose(ego_pose),
                suite.lidar,
                ego_index,
                labels="onboard_lidar_labels" in wanted,
            )
            if "onboard_lidar_points" in wanted:
                data["onboard_lidar_points"] = points
            if labels is not None:
                data["onboard_lidar_labels"] = labels
        if wanted & {"onboard_camera_image", "onboard_camera_depth"}:
            image = render_image(
                snapshot,
                suite.camera_mount.pose(ego_pose),
                int(self.raw["camera_image_width_px"]),
                int(self.raw["camera_image_height_px"]),
                suite.camera.hfov_deg,
                suite.ground_rgb,
                suite.sky_rgb,
                float(self.raw["render_max_distance_m"]),
                ego_index,
                depth="onboard_camera_depth" in wanted,
            )
            if "onboard_camera_image" in wanted:
                data["onboard_camera_image"] = image.rgb
            if image.depth_m is not None:
                data["onboard_camera_depth"] = image.depth_m
        if "roadside_camera_image" in wanted:
            images = {
                unit.id: render_image(
                    snapshot,
                    pose,
                    int(self.raw["roadside_image_width_px"]),
                    int(self.raw["roadside_image_height_px"]),
                    suite.roadside.hfov_deg,
                    suite.ground_rgb,
                    suite.sky_rgb,
                    float(self.raw["render_max_distance_m"]),
                ).rgb
                for unit, pose in zip(suite.roadside_units, suite.roadside_poses, strict=True)
            }
            delivered = self._delayed(self._roadside_buffer, time_s, images)
            if delivered is not None:
                data["roadside_camera_image"] = delivered[1]
        out["sensor_data"] = data
        if "vehicles" in wanted:
            out["vehicles"] = self._vehicles(snapshot, ego_pose, ego_index)
        if "route" in wanted:
            out["route"] = self._route(ego_values)
        if "road_map" in wanted:
            out["road_map"] = self._net().road_map
        if "traffic_light" in wanted:
            out["traffic_light"] = self._traffic_light(time_s)
        return out

    def _delayed(self, buffer: deque, time_s: float, value):
        """Push (time_s, value); return the latest entry measured at or before time_s - latency."""
        buffer.append((time_s, value))
        delivered = None
        while buffer and buffer[0][0] <= time_s - self.latency_s + 1e-9:
            delivered = buffer.popleft()
        if delivered is not None:
            buffer.appendleft(delivered)  # it stays the latest deliverable until a newer one is due
        return delivered

    def _vehicles(self, snapshot, ego_pose, ego_index: int) -> tuple[PerceivedVehicle, ...]:
        suite = self.sensors
        veh = snapshot.vehicles
        cam = camera_sees_vehicles(snapshot, suite.camera_mount.pose(ego_pose), suite.camera, ego_index)
        lid = lidar_sees_vehicles(snapshot, suite.lidar_mount.pose(ego_pose), suite.lidar, ego_index)
        out = []
        for i in range(len(veh)):
            if not (cam[i] or lid[i]):
                continue
            out.append(
                PerceivedVehicle(
                    veh.ids[i],
                    float(veh.x_m[i]),
                    float(veh.y_m[i]),
                    float(veh.yaw_rad[i]),
                    float(veh.length_m[i]),
                    float(veh.width_m[i]),
                    "onboard_camera" if cam[i] else "onboard_lidar",
                )
            )
        return tuple(out)

    def _net(self) -> NetMap:
        """The parsed net map; loaded at construction whenever route or road_map is wanted."""
        if self.net is None:
            raise RuntimeError("the net map was not loaded: neither route nor road_map was asked for")
        return self.net

    def _route(self, ego_values: Mapping[int, Any] | None = None) -> RouteAhead:
        api, ego = self.api, self.ego_id
        lane_var, index_var, position_var = self._route_variables
        if ego_values is not None and position_var in ego_values:
            lane_id, route_index = ego_values[lane_var], ego_values[index_var]
            lane_position_m = float(ego_values[position_var])
        else:
            lane_id = api.vehicle.getLaneID(ego)
            route_index = api.vehicle.getRouteIndex(ego)
            lane_position_m = float(api.vehicle.getLanePosition(ego))
        key = (lane_id, route_index)
        if key != self._route_key:
            route = tuple(api.vehicle.getRoute(ego))[max(route_index, 0) :]
            net = self._net()
            lanes: list[LaneCentreline] = []
            if lane_id.startswith(":") and lane_id in net.lanes:
                lanes.append(net.lanes[lane_id])
            for k, edge in enumerate(route):
                lanes.extend(net.lanes[i] for i in net.edge_lanes.get(edge, ()))
                if k + 1 < len(route):
                    lanes.extend(
                        net.lanes[v] for v in net.vias.get((edge, route[k + 1]), ()) if v in net.lanes
                    )
            self._route_key, self._route_edges, self._route_lanes = key, route, tuple(lanes)
        return RouteAhead(self._route_edges, self._route_lanes, lane_id, lane_position_m)

    def _traffic_light(self, time_s: float) -> TrafficLightState | None:
        api = self.api
        upcoming = api.vehicle.getNextTLS(self.ego_id)
        measured = None
        if upcoming:
            tls_id, link_index, distance_m, state = upcoming[0]
            switch_in_s = float(api.trafficlight.getNextSwitch(tls_id)) - time_s
            measured = (tls_id, int(link_index), float(distance_m), str(state), switch_in_s)
        reach_m = float(self.raw["signal_visibility_m"])
        if self.condition == "v2i":
            delivered = self._delayed(self._signal_buffer, time_s, measured)
            if delivered is not None and delivered[1] is not None:
                at_s, (tls_id, link_index, _, state, switch_in_s) = delivered
                switch_now_s = switch_in_s - (time_s - at_s)
                if (
                    self.fresher_signal
                    and measured is not None
                    and measured[2] <= reach_m
                    and measured[0] == tls_id
                ):
                    # The camera reads the head now, SPaT `latency_s` ago: its state, with SPaT's timing
                    # while SPaT tells the same state.
                    _, link_now, distance_m, seen, _ = measured
                    timing = switch_now_s if seen == state else math.nan
                    return TrafficLightState(
                        tls_id, link_now, seen, distance_m, timing, "onboard_camera+v2i", time_s
                    )
                # Distance now (the ego knows where it is); the state and its timing as sent at at_s.
                now_m = measured[2] if measured is not None and measured[0] == tls_id else math.nan
                return TrafficLightState(tls_id, link_index, state, now_m, switch_now_s, "v2i", at_s)
        if measured is not None and measured[2] <= reach_m:
            tls_id, link_index, distance_m, state, _ = measured
            return TrafficLightState(
                tls_id, link_index, state, distance_m, math.nan, "onboard_camera", time_s
            )
        return None
