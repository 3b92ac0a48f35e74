"""The interface of the AD stack under test, and how a user's stack is loaded.

The shape is the one users of driving simulators know (CARLA leaderboard agents, scenario_runner):

    class MyStack(Agent):
        def setup(self, config): ...                 # once per episode, before the first step
        def sensors(self): return ["onboard_camera", "onboard_lidar", "v2i"]   # what it wants
        def run_step(self, observation, time_s): return Command(target_speed_mps=...)
        def close(self): ...

`python -m pedsafe_sumo.batch --algorithm mypkg.mymodule:MyStack` loads it. The simulator is never
handed to the agent: it sees only the observation, and acts only through the Command.

Beyond the detections, an agent may ask (in sensors()) for raw sensor data (RAW_SENSORS, delivered in
``observation.sensor_data[name]``) and for the world an AD stack needs (WORLD_FEEDS: perceived
vehicles, the route ahead, crosswalks and stop lines, the governing traffic light); nothing is computed
that no agent asked for. A Command may change lanes or follow a path. Frames, units and timing of
everything: docs/ad_interface.md. ``--perception pkg.module:Class`` (a :class:`Perception`) replaces
the detector while the planner and controller stay (:func:`with_perception`).
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

from pedsafe_sumo.control.stack_names import resolve_stack_name

#: Sensor names an agent may ask for in sensors(); "v2i" adds the roadside detections delivered over
#: the V2I link (the V2I condition grants it, the SV condition does not).
KNOWN_SENSORS = ("onboard_camera", "onboard_lidar", "v2i")
#: Raw data, delivered in ``observation.sensor_data[name]`` (docs/ad_interface.md):
#: onboard_lidar_points (N, 3) float, sensor frame x forward, y left, z up, m; onboard_lidar_labels
#: the ground truth of each point (explicit: for training and debugging only); onboard_camera_image
#: (H, W, 3) uint8; onboard_camera_depth (H, W) float32 m; roadside_camera_image {pole id: (H, W, 3)
#: uint8}, over the V2I link (granted under V2I only).
RAW_SENSORS = (
    "onboard_lidar_points",
    "onboard_lidar_labels",
    "onboard_camera_image",
    "onboard_camera_depth",
    "roadside_camera_image",
)
#: The world beyond pedestrians, filled in the Observation's own fields: ``vehicles`` (perceived by the
#: onboard camera and LiDAR), ``route`` (lane centrelines ahead), ``road_map`` (crosswalks, stop lines),
#: ``traffic_light`` (the signal that governs the ego; over V2I under the V2I condition).
WORLD_FEEDS = ("vehicles", "route", "road_map", "traffic_light")
#: Everything sensors() may name; any other name is refused.
ALL_SENSORS = KNOWN_SENSORS + RAW_SENSORS + WORLD_FEEDS


@dataclass(frozen=True)
class PerceivedPedestrian:
    """A pedestrian position as the sensors report it this step (world frame: SUMO x east, y north, m).

    Sensors report positions, not velocities: estimating motion (tracking) is the AD stack's job.
    """

    ped_id: str
    x_m: float
    y_m: float
    source: str  # "onboard_camera", "onboard_lidar" or "v2i"


@dataclass(frozen=True)
class PerceivedVehicle:
    """A vehicle as the onboard sensors report it this step (world frame; its box centre and heading)."""

    vehicle_id: str
    x_m: float
    y_m: float
    yaw_rad: float  # counter-clockwise from +x (east)
    length_m: float
    width_m: float
    source: str  # "onboard_camera" or "onboard_lidar"


@dataclass(frozen=True)
class LaneCentreline:
    """One lane of the ego's route ahead: its centreline (world frame, (K, 2) m, in driving direction)."""

    lane_id: str
    edge_id: str
    index: int  # SUMO lane index on its edge (0 = rightmost, the sidewalk where there is one)
    width_m: float
    speed_limit_mps: float
    shape_xy_m: tuple[tuple[float, float], ...]
    drivable: bool  # open to the ego's vehicle class (a sidewalk is not)


@dataclass(frozen=True)
class RouteAhead:
    """The ego's route from its current edge on: edges in order and the lanes of each (internal
    junction lanes between consecutive route edges included, edge ids starting with ':')."""

    edges: tuple[str, ...]
    lanes: tuple[LaneCentreline, ...]
    current_lane_id: str
    lane_position_m: float  # distance of the ego's front from the start of its current lane [m]


@dataclass(frozen=True)
class Crosswalk:
    """A pedestrian crossing: its polygon (world frame, (4, 2) m) and the traffic light that controls
    it ('' when unsignalised)."""

    crossing_id: str
    polygon_xy_m: tuple[tuple[float, float], ...]
    tls_id: str


@dataclass(frozen=True)
class StopLine:
    """Where a lane ends at a junction: the segment across the lane end (world frame, m)."""

    lane_id: str
    junction_id: str
    start_xy_m: tuple[float, float]
    end_xy_m: tuple[float, float]
    tls_id: str


@dataclass(frozen=True)
class RoadMap:
    """Static map of the site, the same every step (read once per site from the network)."""

    crosswalks: tuple[Crosswalk, ...]
    stop_lines: tuple[StopLine, ...]


@dataclass(frozen=True)
class TrafficLightState:
    """The signal that governs the ego's next junction, as delivered this step."""

    tls_id: str
    link_index: int
    state: str  # SUMO's signal character: 'G'/'g' green, 'y' yellow, 'r' red, 'u' red-yellow, 'o' off
    distance_m: float  # from the ego's front to the stop line, at the time the state refers to [m]
    time_to_switch_s: float  # until the state changes; NaN when the source cannot know (onboard)
    #: "onboard_camera" (seen ahead), "v2i" (SPaT over the link, latency applied) or "onboard_camera+v2i"
    #: (seen ahead, the time to the switch from SPaT: [perception.v2i] signal_source "fresher").
    source: str
    measured_at_s: float  # simulation time the state refers to [s]


@dataclass(frozen=True)
class EgoState:
    x_m: float
    y_m: float
    yaw_rad: float  # counter-clockwise from +x (east)
    speed_mps: float
    length_m: float
    width_m: float


@dataclass(frozen=True)
class Observation:
    """What the AD stack gets each step: its own state and the pedestrians its sensors report, and
    what else it asked for (WORLD_FEEDS, RAW_SENSORS); fields it did not ask for stay empty."""

    ego: EgoState
    pedestrians: tuple[PerceivedPedestrian, ...] = ()
    step_length_s: float = 0.05
    #: Raw data keyed by the RAW_SENSORS names the agent asked for and the condition grants.
    sensor_data: dict[str, Any] = field(default_factory=dict)
    vehicles: tuple[PerceivedVehicle, ...] = ()
    route: RouteAhead | None = None
    road_map: RoadMap | None = None
    traffic_light: TrafficLightState | None = None


@dataclass(frozen=True)
class Command:
    """The AD stack's output for one step: the speed it wants to have at the end of the step."""

    #: A finite real number >= 0; anything else ends the episode with an error (control/stack_calls.py).
    target_speed_mps: float
    #: Free-form diagnostics logged with the step (e.g. {"braking": True}).
    info: dict[str, Any] = field(default_factory=dict)
    #: Lane change relative to the current lane: +1 one lane left, -1 one lane right, 0 none. Refused
    #: (and logged) when the target lane does not exist or is not open to the ego (a sidewalk).
    lane_change: int = 0
    #: Target lateral offset from the current lane's centreline, positive left [m]; None keeps the lane.
    lateral_offset_m: float | None = None
    #: Target path: world points (x, y) [m] the ego follows from where it is; None: follow the lane.
    path_xy_m: tuple[tuple[float, float], ...] | None = None


class Agent(ABC):
    """Base class of an AD stack under test."""

    def setup(self, config: dict[str, Any]) -> None:  # noqa: B027 - optional hook
        """Called once per episode with its settings: initial_speed_mps, condition, seed, step_length_s,
        sensors (granted), and every key of the parameter file's [algorithm] section."""

    def sensors(self) -> list[str]:
        """Sensors this stack uses, from ALL_SENSORS (default: the three detection sources of
        KNOWN_SENSORS); the condition decides which are granted."""
        return list(KNOWN_SENSORS)

    @abstractmethod
    def run_step(self, observation: Observation, time_s: float) -> Command:
        """One control step."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Called once at the end of the episode."""


class AlgorithmLoadError(ValueError):
    """`--algorithm` does not name a loadable AD stack; the message says why in one line."""


#: Joins `--algorithm` and `--perception` into the one stack spec that run.json records, workers and
#: replay load: "pkg.stack:Stack+pkg.detector:Detector" (a module name never holds a '+').
PERCEPTION_JOIN = "+"


def stack_spec(algorithm: str, perception: str | None) -> str:
    """The stack spec of `--algorithm` with `--perception` (the algorithm alone when there is none)."""
    return f"{algorithm}{PERCEPTION_JOIN}{perception}" if perception else algorithm


def load_agent_class(spec: str) -> type[Agent]:
    """Resolve 'package.module:ClassName' to an Agent subclass (or a class with the same methods); a spec
    'algorithm+perception' (stack_spec) loads the algorithm with its detector replaced. A shipped
    stack's short name (control/stack_names.py: reference, paper-v7) stands for its spec."""
    spec = resolve_stack_name(spec)
    if PERCEPTION_JOIN in spec:
        algorithm, _, perception = spec.partition(PERCEPTION_JOIN)
        return with_perception(load_agent_class(algorithm), load_perception_class(perception))
    cls: type[Agent] = _load_class(spec, "--algorithm", "agent", ("setup", "sensors", "run_step", "close"))
    return cls


def check_sensor_names(names: Iterable[str], who: str) -> None:
    """Refuse, in one line, sensor names outside ALL_SENSORS."""
    unknown = [s for s in names if s not in ALL_SENSORS]
    if unknown:
        known = ", ".join(ALL_SENSORS)
        raise AlgorithmLoadError(f"'{who}' asks for unknown sensors {unknown}; known: {known}")


def _sensors_of(cls: Any) -> list[str]:
    try:
        return list(cls.sensors(cls.__new__(cls)))
    except Exception:  # sensors() that needs setup() first: checked when the episode starts
        return []


class Perception(ABC):
    """A detector under test (``--perception pkg.module:Class``): it reads the raw data it asks for and
    reports the road users it finds; the stack's own planner and controller then run on its output
    (its pedestrians replace ``observation.pedestrians``, its vehicles ``observation.vehicles``)."""

    def setup(self, config: dict[str, Any]) -> None:  # noqa: B027 - optional hook
        """Called once per episode with the same config as the agent's setup()."""

    def sensors(self) -> list[str]:
        """Sensors the detector reads, from ALL_SENSORS (typically RAW_SENSORS)."""
        return ["onboard_lidar_points"]

    @abstractmethod
    def detect(self, observation: Observation, time_s: float) -> list[PerceivedPedestrian | PerceivedVehicle]:
        """The road users found this step (PerceivedPedestrian and PerceivedVehicle items, world frame)."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Called once at the end of the episode."""


def with_perception(agent_class: type[Agent], perception_class: type) -> type[Agent]:
    """The agent with its detector replaced: it asks for the perception's sensors plus its own world
    feeds (not our detections), and its run_step sees the perception's road users."""

    class PluggedStack(agent_class):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self._perception = perception_class()

        def setup(self, config: dict[str, Any]) -> None:
            self._perception.setup(dict(config))
            super().setup(config)

        def sensors(self) -> list[str]:
            own = [s for s in super().sensors() if s not in KNOWN_SENSORS]
            return list(dict.fromkeys([*self._perception.sensors(), *own]))

        def run_step(self, observation: Observation, time_s: float) -> Command:
            found = list(self._perception.detect(observation, time_s))
            peds = tuple(f for f in found if isinstance(f, PerceivedPedestrian))
            vehicles = tuple(f for f in found if isinstance(f, PerceivedVehicle))
            return super().run_step(replace(observation, pedestrians=peds, vehicles=vehicles), time_s)

        def close(self) -> None:
            try:
                self._perception.close()
            finally:
                super().close()

    PluggedStack.__name__ = PluggedStack.__qualname__ = f"{agent_class.__name__}+{perception_class.__name__}"
    PluggedStack.__module__ = agent_class.__module__  # messages name the user's module (stack_label)
    return PluggedStack


def load_perception_class(spec: str) -> type:
    """Resolve '--perception package.module:ClassName' to a class with setup, sensors, detect, close."""
    return _load_class(spec, "--perception", "perception", ("setup", "sensors", "detect", "close"))


def _load_class(spec: str, flag: str, interface: str, methods: tuple[str, ...]) -> Any:
    """Import 'package.module:ClassName' for `flag` and check that it implements `methods` (none left
    abstract) and asks only for known sensors; every problem is one AlgorithmLoadError line."""
    if ":" not in spec:
        raise AlgorithmLoadError(f"{flag} must look like package.module:ClassName, got '{spec}'")
    module_name, _, class_name = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise AlgorithmLoadError(f"cannot import module '{module_name}' for {flag}: {exc}") from None
    except Exception as exc:  # an error inside the user's module while importing it
        raise AlgorithmLoadError(
            f"importing '{module_name}' for {flag} failed: {type(exc).__name__}: {exc}"
        ) from None
    cls: Any = getattr(module, class_name, None)
    if cls is None or not isinstance(cls, type):
        raise AlgorithmLoadError(f"module '{module_name}' has no class '{class_name}'")
    missing = [name for name in methods if not callable(getattr(cls, name, None))]
    if missing:
        raise AlgorithmLoadError(
            f"'{spec}' does not implement the {interface} interface: missing {', '.join(missing)}"
        )
    abstract_methods = getattr(cls, "__abstractmethods__", None)
    if abstract_methods:
        raise AlgorithmLoadError(
            f"'{spec}' leaves abstract methods unimplemented: {', '.join(sorted(abstract_methods))}"
        )
    check_sensor_names(_sensors_of(cls), spec)
    return cls
