"""What the replay draws in sumo-gui, through the TraCI handle the engine passes to its per-step hook.

- The view follows the ego (gui.trackVehicle) at a zoom that shows a chosen width of road.
- Road users in role colours, so they are told apart at a glance: the ego magenta, the pedestrian
  orange inside a white ring, the vehicles the scenario placed in the kerb lane (occluder, queue,
  waiting vehicle) cyan; background traffic keeps its colours and the roadside camera pole its blue
  POI. `scene_colours=True` keeps the colours the sensors saw instead (the background-blending
  pedestrian is dressed like the vehicle behind them), the ring still marks the pedestrian.
- The sensors' horizontal fields of view: the onboard camera's wedge and the LiDAR's range circle,
  which move with the ego (polygon dynamics tracking the ego, updated by SUMO inside its step), and
  the roadside camera's wedge from its pole.
- The first detections of the log: where the pedestrian was when the onboard sensors first saw them
  and when the roadside camera first did, as POIs with a sight line from the sensor.

Timing: sumo-gui draws after each simulation step, and gui.screenshot is taken at the end of the
step that follows the call. So everything meant for the frame of step k is done in the hook of step
k-1: markers of step k are added then, the screenshot of step k is requested then, and the
onboard field-of-view polygons are moved by SUMO itself within the step (polygon dynamics tracking
the ego). Step 0 is never rendered with the
replay's decorations; the first frame that can be is step 1.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd

from pedsafe_sumo.perception.sensors import CameraSpec
from pedsafe_sumo.replay.annotate import (
    LegendEntry,
    draw_legend,
    draw_pedestrian_marker,
    draw_stamp,
    world_to_pixel,
)
from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup
from pedsafe_sumo.sim.staging import EGO_ID, PED_ID

VIEW_ID = "View #0"

#: Role colours (RGBA). Magenta and orange are in no palette of the scenes (car bodies, clothing).
EGO_RGBA = (255, 0, 255, 255)
PEDESTRIAN_RGBA = (255, 128, 0, 255)
PEDESTRIAN_RING_RGBA = (255, 255, 255, 255)
KERB_LANE_VEHICLE_RGBA = (0, 220, 220, 255)
ONBOARD_CAMERA_FOV_RGBA = (255, 0, 255, 255)
ONBOARD_LIDAR_RANGE_RGBA = (200, 0, 200, 255)
ROADSIDE_FOV_RGBA = (0, 90, 255, 255)
ONBOARD_DETECTION_RGBA = (255, 230, 0, 255)
ROADSIDE_DETECTION_RGBA = (60, 170, 255, 255)
#: Drawing layers: above the road network, below vehicles and persons. Fields of view are outlines:
#: sumo-gui draws shapes before the lanes, so a translucent fill blends with the background colour
#: and then hides the road under it.
FOV_LAYER = 50
MARKER_LAYER = 110
FOV_LINE_WIDTH_M = 0.25
PEDESTRIAN_RING_ID = "pedestrian ring"
RING_RADIUS_M = 1.2
RING_SEGMENTS = 32
#: Distance of a detection's label from its dot, as a share of the view's width.
LABEL_OFFSET_SHARE = 0.03

#: Longest wait for sumo-gui to write a requested screenshot [s].
SCREENSHOT_TIMEOUT_S = 30.0


class ScreenshotTaken(Exception):  # noqa: N818 - ends the replay on success, not an error
    """Raised from the hook once the requested frame is on disk: ends the replay."""


@dataclass(frozen=True)
class ScreenshotRequest:
    path: Path
    #: Index of the logged step to render (>= 1, see the module's note on timing).
    step_index: int
    width_px: int
    height_px: int
    #: Stamped in the picture's top-left corner: the time and the moment, what it measures, the episode.
    stamp_lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class DetectionMarker:
    """A first detection from the log: at step `step_index` the sensor at `sensor_xy` saw the pedestrian
    at `ped_xy`."""

    kind: str  # "onboard" or "roadside"
    step_index: int
    time_s: float
    sensor_xy: tuple[float, float]
    ped_xy: tuple[float, float]
    distance_m: float
    label: str


def wedge_xy(
    apex_xy: tuple[float, float], heading_rad: float, fov_rad: float, range_m: float, segments: int = 24
) -> list[tuple[float, float]]:
    """A sensor's horizontal field of view as a closed polygon: the apex, then the arc of `range_m` from
    heading - fov/2 to heading + fov/2 (world frame, angles counter-clockwise from +x, metres)."""
    x0, y0 = apex_xy
    angles = heading_rad + np.linspace(-fov_rad / 2, fov_rad / 2, segments + 1)
    arc = [(x0 + range_m * math.cos(a), y0 + range_m * math.sin(a)) for a in angles]
    return [(x0, y0), *arc, (x0, y0)]


def circle_xy(
    centre_xy: tuple[float, float], radius_m: float, segments: int = 48
) -> list[tuple[float, float]]:
    x0, y0 = centre_xy
    angles = np.linspace(0.0, 2 * math.pi, segments + 1)
    return [(x0 + radius_m * math.cos(a), y0 + radius_m * math.sin(a)) for a in angles]


def camera_range_m(camera: CameraSpec, target_height_m: float) -> float:
    """Distance at which a target of `target_height_m` shrinks to the camera's minimum detectable height
    in pixels (pinhole: h_px = f h / d), the reach of its detections on an unoccluded pedestrian."""
    focal_px = camera.width_px / (2 * math.tan(math.radians(camera.hfov_deg) / 2))
    return focal_px * target_height_m / camera.min_height_px


def mounted_xy(
    x_m: float, y_m: float, yaw_rad: float, forward_m: float, left_m: float
) -> tuple[float, float]:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return (x_m + c * forward_m - s * left_m, y_m + s * forward_m + c * left_m)


def first_detection_markers(log: pd.DataFrame, sensors, condition: str) -> list[DetectionMarker]:
    """The log's first onboard detection (camera or LiDAR) and the roadside camera's first sighting."""
    markers = []
    onboard = log["detected_onboard_camera"].to_numpy(bool) | log["detected_onboard_lidar"].to_numpy(bool)
    if onboard.any():
        k = int(np.flatnonzero(onboard)[0])
        row = log.iloc[k]
        by_camera = bool(row["detected_onboard_camera"])
        mount = sensors.camera_mount if by_camera else sensors.lidar_mount
        sensor_xy = mounted_xy(row.ego_x_m, row.ego_y_m, row.ego_yaw_rad, mount.forward_m, mount.left_m)
        names = [n for n, flag in (("camera", by_camera), ("LiDAR", row["detected_onboard_lidar"])) if flag]
        distance_m = math.hypot(row.ped_x_m - row.ego_x_m, row.ped_y_m - row.ego_y_m)
        markers.append(
            DetectionMarker(
                "onboard",
                k,
                float(row.time_s),
                sensor_xy,
                (float(row.ped_x_m), float(row.ped_y_m)),
                distance_m,
                f"first onboard detection ({' + '.join(names)}) t={row.time_s:.2f} s, "
                f"{distance_m:.1f} m from the ego",
            )
        )
    if "roadside_raw" in log.columns and log["roadside_raw"].any() and sensors.roadside_units:
        k = int(np.flatnonzero(log["roadside_raw"].to_numpy(bool))[0])
        row = log.iloc[k]
        # The log says that a roadside camera saw them, not which: with several poles (background
        # blending) the sight line is drawn from the nearest.
        unit = min(sensors.roadside_units, key=lambda u: math.hypot(u.x_m - row.ped_x_m, u.y_m - row.ped_y_m))
        distance_m = math.hypot(row.ped_x_m - row.ego_x_m, row.ped_y_m - row.ego_y_m)
        if condition == "v2i" and log["detected_roadside"].any():
            delivered_s = float(
                log["time_s"].to_numpy()[np.flatnonzero(log["detected_roadside"].to_numpy(bool))[0]]
            )
            use = f"reached the ego over V2I at t={delivered_s:.2f} s"
        else:
            use = "not used under SV" if condition == "sv" else "never reached the ego"
        markers.append(
            DetectionMarker(
                "roadside",
                k,
                float(row.time_s),
                (unit.x_m, unit.y_m),
                (float(row.ped_x_m), float(row.ped_y_m)),
                distance_m,
                f"roadside camera first saw them t={row.time_s:.2f} s, "
                f"{distance_m:.1f} m from the ego ({use})",
            )
        )
    return markers


def ring_shape(row: dict[str, Any]) -> list[tuple[float, float]]:
    """The white ring around the pedestrian; shrunk to a point on the ego (invisible) while the pedestrian
    is not in the scene (NaN position, before they appear and after they leave)."""
    x, y = row["ped_x_m"], row["ped_y_m"]
    if math.isfinite(x) and math.isfinite(y):
        return circle_xy((x, y), RING_RADIUS_M, RING_SEGMENTS)
    return circle_xy((row["ego_x_m"], row["ego_y_m"]), 0.0, RING_SEGMENTS)


def screenshot_frame(
    log: pd.DataFrame, step_index: int, minimum_width_m: float, aspect: float
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Centre and size (width, height in metres) of the picture of step `step_index`: the ego (SUMO's
    position of it, the front bumper) and the pedestrian with 10 m to spare around them, centred on
    their midpoint, at least `minimum_width_m` wide; `aspect` is width / height. A step without the
    pedestrian in the scene (NaN position) is framed on the ego alone."""
    row = log.iloc[step_index]
    half_length_m = row.ego_length_m / 2
    front_x = row.ego_x_m + half_length_m * math.cos(row.ego_yaw_rad)
    front_y = row.ego_y_m + half_length_m * math.sin(row.ego_yaw_rad)
    ped_x, ped_y = row.ped_x_m, row.ped_y_m
    if not (math.isfinite(ped_x) and math.isfinite(ped_y)):
        ped_x, ped_y = front_x, front_y
    dx, dy = abs(ped_x - front_x), abs(ped_y - front_y)
    width_m = max(minimum_width_m, dx + 20.0, (dy + 20.0) * aspect)
    centre = ((front_x + ped_x) / 2, (front_y + ped_y) / 2)
    return (float(centre[0]), float(centre[1])), (float(width_m), float(width_m / aspect))


class ReplayScene:
    """The replay's per-step hook in sumo-gui: colours, view, fields of view, markers, screenshot."""

    def __init__(
        self,
        setup: EpisodeSetup,
        sensors,
        reference: pd.DataFrame,
        condition: str,
        *,
        view_width_m: float,
        scene_colours: bool = False,
        screenshot: ScreenshotRequest | None = None,
        say=print,
    ) -> None:
        self.setup = setup
        self.sensors = sensors
        self.condition = condition
        self.view_width_m = view_width_m
        self.scene_colours = scene_colours
        self.screenshot = screenshot
        self.say = say
        self.reference = reference
        self.markers = first_detection_markers(reference, sensors, condition)
        self.label_offset_m = LABEL_OFFSET_SHARE * view_width_m
        if screenshot is not None:
            self.shot_centre_xy, self.shot_size_m = screenshot_frame(
                reference, screenshot.step_index, view_width_m, screenshot.width_px / screenshot.height_px
            )
            self.label_offset_m = LABEL_OFFSET_SHARE * self.shot_size_m[0]
        self.step_index = 0
        self.pedestrian_coloured = False

    def __call__(self, api, row: dict[str, Any]) -> None:
        k = self.step_index
        self.step_index += 1
        if k == 0:
            self._start(api, row)
        else:
            # Moved by hand: SUMO 1.28 crashes (segmentation fault) in the step after a collision when a
            # polygon tracks the person with addDynamics. Drawn in the next frame, the ring trails the
            # pedestrian by one step (under 0.15 m), well inside its 1.2 m radius.
            api.polygon.setShape(PEDESTRIAN_RING_ID, ring_shape(row))
        if not self.scene_colours and not self.pedestrian_coloured and PED_ID in api.person.getIDList():
            # A staging that lets the pedestrian appear later adds them to SUMO then.
            api.person.setColor(PED_ID, PEDESTRIAN_RGBA)
            self.pedestrian_coloured = True
        for marker in self.markers:
            # Drawn in the hook before their step so that they are in that step's frame.
            if marker.step_index == k + 1 or (marker.step_index == 0 and k == 0):
                self._draw_marker(api, marker)
        shot = self.screenshot
        if shot is None:
            return
        if k + 1 == shot.step_index:
            self._request_screenshot(api, shot)
        elif k == shot.step_index:
            wait_for_file(self._canvas_path(shot), SCREENSHOT_TIMEOUT_S)
            shown = self.reference.iloc[shot.step_index]
            ped_xy = (float(shown["ped_x_m"]), float(shown["ped_y_m"]))
            finish_screenshot(
                self._canvas_path(shot),
                shot,
                api.gui.getBoundary(VIEW_ID),
                ped_xy if all(map(math.isfinite, ped_xy)) else None,
                self.legend(shot.step_index),
            )
            raise ScreenshotTaken(str(shot.path))

    def legend(self, step_index: int) -> list[LegendEntry]:
        """The legend of the frame of `step_index`: the road users and the drawings it holds."""
        if self.scene_colours:
            entries = [LegendEntry("ego (its own colour)", self.setup.ego.colour_rgb, "box")]
        else:
            entries = [LegendEntry("ego", EGO_RGBA[:3], "box")]
        entries.append(LegendEntry("pedestrian", PEDESTRIAN_RGBA[:3], "ring"))
        if self.setup.parked:
            entries.append(
                LegendEntry(
                    "kerb-lane vehicles (occluder, queue)"
                    + (" in their own colours" if self.scene_colours else ""),
                    tuple(self.setup.parked[0].colour_rgb)
                    if self.scene_colours
                    else KERB_LANE_VEHICLE_RGBA[:3],
                    "box",
                )
            )
        if self.setup.background:
            entries.append(LegendEntry("other vehicles (their own colours)", (150, 150, 150), "box"))
        entries.append(LegendEntry("onboard camera view, LiDAR range", ONBOARD_CAMERA_FOV_RGBA[:3], "line"))
        if self.sensors.roadside_units:
            entries.append(LegendEntry("roadside camera pole", ROADSIDE_FOV_RGBA[:3], "box"))
            entries.append(LegendEntry("roadside camera view", ROADSIDE_FOV_RGBA[:3], "line"))
        for marker in self.markers:
            if marker.step_index <= step_index:
                rgba = ONBOARD_DETECTION_RGBA if marker.kind == "onboard" else ROADSIDE_DETECTION_RGBA
                entries.append(LegendEntry(f"first {marker.kind} detection", rgba[:3], "dot"))
        return entries

    # ------------------------------------------------------------------ view
    def _start(self, api, row: dict[str, Any]) -> None:
        x, y = row["ego_x_m"], row["ego_y_m"]
        self._frame(api, (x, y), self.view_width_m, self.view_width_m)
        api.gui.trackVehicle(VIEW_ID, EGO_ID)
        if not self.scene_colours:
            api.vehicle.setColor(EGO_ID, EGO_RGBA)
            for vehicle in self.setup.parked:
                api.vehicle.setColor(vehicle.vehicle_id, KERB_LANE_VEHICLE_RGBA)
        self._draw_sensors(api, row)
        api.polygon.add(
            PEDESTRIAN_RING_ID,
            ring_shape(row),
            PEDESTRIAN_RING_RGBA,
            fill=False,
            layer=MARKER_LAYER,
            lineWidth=0.15,
        )

    @staticmethod
    def _frame(api, centre_xy: tuple[float, float], width_m: float, height_m: float) -> None:
        """Centre the view on `centre_xy` with at least `width_m` x `height_m` visible (sumo-gui's zoom is
        relative to the network's size; framing a box sets it in metres)."""
        x, y = centre_xy
        api.gui.setBoundary(VIEW_ID, x - width_m / 2, y - height_m / 2, x + width_m / 2, y + height_m / 2)

    def _request_screenshot(self, api, shot: ScreenshotRequest) -> None:
        """Frame the ego and the pedestrian of the requested step and ask for the frame of that step.

        sumo-gui's vehicle tracking recentres the view when it redraws, which may lag the simulation by
        a few steps; for the picture tracking stops and the view is set from the log instead. sumo-gui
        renders its whole canvas, cropped to the requested size afterwards.
        """
        api.gui.trackVehicle(VIEW_ID, "")
        self._frame(api, self.shot_centre_xy, *self.shot_size_m)
        path = self._canvas_path(shot)
        path.unlink(missing_ok=True)
        api.gui.screenshot(VIEW_ID, str(path), -1, -1)

    @staticmethod
    def _canvas_path(shot: ScreenshotRequest) -> Path:
        return shot.path.with_name(f".{shot.path.stem}.canvas{shot.path.suffix}")

    # ------------------------------------------------------------------ drawing
    def _draw_sensors(self, api, row: dict[str, Any]) -> None:
        sensors = self.sensors
        x, y, yaw = row["ego_x_m"], row["ego_y_m"], row["ego_yaw_rad"]
        ped_height_m = self.setup.pedestrian.height_m
        camera, mount = sensors.camera, sensors.camera_mount
        camera_xy = mounted_xy(x, y, yaw, mount.forward_m, mount.left_m)
        api.polygon.add(
            "onboard camera field of view",
            wedge_xy(
                camera_xy,
                yaw + mount.yaw_offset_rad,
                math.radians(camera.hfov_deg),
                camera_range_m(camera, ped_height_m),
            ),
            ONBOARD_CAMERA_FOV_RGBA,
            fill=False,
            layer=FOV_LAYER,
            lineWidth=FOV_LINE_WIDTH_M,
        )
        lidar_mount = sensors.lidar_mount
        lidar_xy = mounted_xy(x, y, yaw, lidar_mount.forward_m, lidar_mount.left_m)
        api.polygon.add(
            "onboard LiDAR range",
            circle_xy(lidar_xy, sensors.lidar.range_m, 96),
            ONBOARD_LIDAR_RANGE_RGBA,
            fill=False,
            layer=FOV_LAYER,
            lineWidth=FOV_LINE_WIDTH_M,
        )
        # Both move and turn with the ego, SUMO updating them inside each step.
        for polygon_id in ("onboard camera field of view", "onboard LiDAR range"):
            api.polygon.addDynamics(polygon_id, EGO_ID, rotate=True)
        roadside = sensors.roadside
        for unit in sensors.roadside_units:
            api.polygon.add(
                f"{unit.id} field of view",
                wedge_xy(
                    (unit.x_m, unit.y_m),
                    unit.yaw_rad,
                    math.radians(roadside.hfov_deg),
                    camera_range_m(roadside, ped_height_m),
                ),
                ROADSIDE_FOV_RGBA,
                fill=False,
                layer=FOV_LAYER,
                lineWidth=FOV_LINE_WIDTH_M,
            )

    def _draw_marker(self, api, marker: DetectionMarker) -> None:
        """A dot where the pedestrian was, the sight line from the sensor, and a label beside the dot:
        north of it for the onboard detection, south for the roadside one, so that the two labels stay
        apart when both detections happen close by."""
        rgba = ONBOARD_DETECTION_RGBA if marker.kind == "onboard" else ROADSIDE_DETECTION_RGBA
        name = f"first {marker.kind} detection"
        api.poi.add(name, *marker.ped_xy, rgba, layer=MARKER_LAYER, width=1.2, height=1.2)
        api.polygon.add(
            f"{name} sight line",
            [marker.sensor_xy, marker.ped_xy],
            rgba,
            fill=False,
            layer=MARKER_LAYER,
            lineWidth=0.2,
        )
        offset_m = self.label_offset_m if marker.kind == "onboard" else -self.label_offset_m
        api.poi.add(
            f"{name} label",
            marker.ped_xy[0],
            marker.ped_xy[1] + offset_m,
            (0, 0, 0, 0),
            poiType=f"{name}: t={marker.time_s:.2f} s, {marker.distance_m:.1f} m",
            layer=MARKER_LAYER,
            width=0.01,
            height=0.01,
        )
        self.say(f"  t={marker.time_s:.2f} s: {marker.label}")


def wait_for_file(path: Path, timeout_s: float) -> None:
    """Until sumo-gui has written `path` completely (its size stops changing)."""
    deadline = time.monotonic() + timeout_s
    last_size = -1
    while time.monotonic() < deadline:
        if path.exists():
            size = path.stat().st_size
            if size > 0 and size == last_size:
                return
            last_size = size
        time.sleep(0.1)
    raise TimeoutError(f"sumo-gui did not write {path} within {timeout_s:.0f} s")


def finish_screenshot(
    canvas_path: Path,
    shot: ScreenshotRequest,
    view_boundary,
    ped_xy: tuple[float, float] | None,
    legend: list[LegendEntry],
) -> None:
    """The centre `shot.width_px` x `shot.height_px` of the rendered canvas (all of it where it is
    smaller), with the pedestrian's ring (at `ped_xy`, when in the scene), the stamp and the legend,
    written to `shot.path`; the canvas file is removed. `view_boundary` is the world box the canvas
    shows (gui.getBoundary)."""
    image = cv2.imread(str(canvas_path), cv2.IMREAD_COLOR)
    if image is None:
        raise RuntimeError(f"sumo-gui wrote an unreadable screenshot {canvas_path}")
    height, width = image.shape[:2]
    top, left = max(0, (height - shot.height_px) // 2), max(0, (width - shot.width_px) // 2)
    cropped = np.ascontiguousarray(image[top : top + shot.height_px, left : left + shot.width_px])
    if ped_xy is not None:
        column, row = world_to_pixel(ped_xy, view_boundary, (width, height))
        draw_pedestrian_marker(cropped, (column - left, row - top), PEDESTRIAN_RGBA[:3])
    if shot.stamp_lines:
        draw_stamp(cropped, list(shot.stamp_lines))
    if legend:
        draw_legend(cropped, legend)
    path = shot.path
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    if not cv2.imwrite(str(tmp), cropped):
        raise RuntimeError(f"cannot write {path}")
    tmp.replace(path)
    canvas_path.unlink(missing_ok=True)
