"""The interface of the AD stack under test, and how a user's stack is loaded.

The shape is the one users of driving simulators know (CARLA leaderboard agents, scenario_runner):

    class MyStack(Agent):
        def setup(self, config): ...                 # once per episode, before the first step
        def sensors(self): return ["onboard_camera", "onboard_lidar", "v2i"]   # what it wants
        def run_step(self, observation, time_s): return Command(target_speed_mps=...)
        def close(self): ...

`python -m pedsafe_sumo.batch --algorithm mypkg.mymodule:MyStack` loads it. The simulator is never
handed to the agent: it sees only the observation, and acts only through the Command.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

#: Sensor names an agent may ask for in sensors(); "v2i" adds the roadside detections delivered over
#: the V2I link (the V2I condition grants it, the SV condition does not).
KNOWN_SENSORS = ("onboard_camera", "onboard_lidar", "v2i")


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
class EgoState:
    x_m: float
    y_m: float
    yaw_rad: float  # counter-clockwise from +x (east)
    speed_mps: float
    length_m: float
    width_m: float


@dataclass(frozen=True)
class Observation:
    """What the AD stack gets each step: its own state and the pedestrians its sensors report."""

    ego: EgoState
    pedestrians: tuple[PerceivedPedestrian, ...] = ()
    step_length_s: float = 0.05


@dataclass(frozen=True)
class Command:
    """The AD stack's output for one step: the speed it wants to have at the end of the step."""

    target_speed_mps: float
    #: Free-form diagnostics logged with the step (e.g. {"braking": True}).
    info: dict[str, Any] = field(default_factory=dict)


class Agent(ABC):
    """Base class of an AD stack under test."""

    def setup(self, config: dict[str, Any]) -> None:  # noqa: B027 - optional hook
        """Called once per episode with its settings: initial_speed_mps, condition, seed, step_length_s,
        sensors (granted), and every key of the parameter file's [algorithm] section."""

    def sensors(self) -> list[str]:
        """Sensors this stack uses, from KNOWN_SENSORS; the condition decides which are granted."""
        return list(KNOWN_SENSORS)

    @abstractmethod
    def run_step(self, observation: Observation, time_s: float) -> Command:
        """One control step."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Called once at the end of the episode."""


class AlgorithmLoadError(ValueError):
    """`--algorithm` does not name a loadable AD stack; the message says why in one line."""


def load_agent_class(spec: str) -> type[Agent]:
    """Resolve 'package.module:ClassName' to an Agent subclass (or a class with the same methods)."""
    if ":" not in spec:
        raise AlgorithmLoadError(f"--algorithm must look like package.module:ClassName, got '{spec}'")
    module_name, _, class_name = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise AlgorithmLoadError(f"cannot import module '{module_name}' for --algorithm: {exc}") from None
    except Exception as exc:  # an error inside the user's module while importing it
        raise AlgorithmLoadError(
            f"importing '{module_name}' for --algorithm failed: {type(exc).__name__}: {exc}"
        ) from None
    cls: Any = getattr(module, class_name, None)
    if cls is None or not isinstance(cls, type):
        raise AlgorithmLoadError(f"module '{module_name}' has no class '{class_name}'")
    missing = [
        name for name in ("setup", "sensors", "run_step", "close") if not callable(getattr(cls, name, None))
    ]
    if missing:
        raise AlgorithmLoadError(
            f"'{spec}' does not implement the agent interface: missing {', '.join(missing)}"
        )
    abstract = getattr(cls, "__abstractmethods__", None)
    if abstract:
        raise AlgorithmLoadError(
            f"'{spec}' leaves abstract methods unimplemented: {', '.join(sorted(abstract))}"
        )
    unknown = [s for s in _sensors_of(cls) if s not in KNOWN_SENSORS]
    if unknown:
        raise AlgorithmLoadError(
            f"'{spec}' asks for unknown sensors {unknown}; known: {', '.join(KNOWN_SENSORS)}"
        )
    return cls


def _sensors_of(cls: Any) -> list[str]:
    try:
        return list(cls.sensors(cls.__new__(cls)))
    except Exception:  # sensors() that needs setup() first: checked when the episode starts
        return []
