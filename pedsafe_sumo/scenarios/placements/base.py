"""What every placement provides, and what it is given and gives back.

A placement is where and how a scenario is staged on the junction ("crosswalk", "midblock",
"behind_waiting_vehicle", "turn"; a ScenarioSpec names its own). One module per placement subclasses
Placement, and placements/__init__.py registers it under its name: the spec's validation, the drawing
of an episode (staging.draw_episode), the hosting check (scenarios/hosting.py) and the engine ask the
registered object, never the name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.sampling.draws import Draws
from pedsafe_sumo.scenarios.episode_setup import VehicleSetup
from pedsafe_sumo.scenarios.geometry import Approach, Turn
from pedsafe_sumo.scenarios.oncoming import OncomingPath

if TYPE_CHECKING:
    # Annotations only: specs.py imports the placement registry to validate a spec's placement.
    from pedsafe_sumo.scenarios.specs import ScenarioSpec


@dataclass(frozen=True)
class StagingInputs:
    """What a placement stages an episode from: the spec, the site's geometry, and what was drawn
    before the placement's own draws (staging.draw_episode draws the conflict offset, then the
    clothing; the placement's draws follow through `draws`)."""

    spec: ScenarioSpec
    approach: Approach
    #: age_years, gender, risk, walking_speed_mps (the demand model's samplers).
    traits: dict
    #: The ego's initial speed, clipped to the spec's range [m/s].
    ego_speed_mps: float
    conflict_offset_s: float
    clothing_rgb: tuple[int, int, int]
    draws: Draws
    #: The turn the ego makes (turning placements; None otherwise).
    turn: Turn | None = None
    #: The path of the vehicle coming the other way (a turning scenario with an oncoming vehicle).
    oncoming: OncomingPath | None = None


@dataclass(frozen=True)
class StagedScene:
    """What a placement decides: the ego, the pedestrian's path and timing, the other vehicles."""

    ego: VehicleSetup
    ego_route: tuple[str, ...]
    #: The pedestrian's path, from where they stand at the start (network frame, m).
    path: tuple
    clothing_rgb: tuple[int, int, int]
    #: The pedestrian waits this long before stepping off [s].
    start_delay_s: float
    parked: tuple[VehicleSetup, ...]
    conflict_xy: tuple[float, float]
    #: Seconds from the start until the ego's front reaches `conflict_xy` at its initial speed.
    conflict_time_s: float
    #: The signalised crossing whose signal faces the pedestrian ("" when none does).
    ped_crossing_id: str
    #: Distance along the ego's path from its front at the start to `conflict_xy` [m].
    ego_start_distance_m: float = math.nan
    #: Approach staging (placements/approach.py): when the pedestrian enters the scene [s], the index in
    #: `path` of their step-off point (the points before it are their walk along the sidewalk to it), and
    #: whether they leave the scene at the end of `path`. The fixed staging: 0, 0, False.
    appear_time_s: float = 0.0
    kerb_index: int = 0
    leaves_scene: bool = False
    #: Approach staging: the fallbacks its timing took (placements/approach.py, FALLBACKS), in order.
    approach_fallbacks: tuple[str, ...] = ()


@dataclass(frozen=True)
class StagingPoint:
    """A point the scenario's pedestrian stands on or walks through, for the hosting check."""

    where: str
    xy: tuple[float, float]
    #: Where the pedestrian stands before stepping into the road (the kerb, the gap between parked cars,
    #: behind the waiting car): the roadside camera has to see it there.
    start: bool = False


class Placement:
    """One placement; subclasses set `name` and implement the methods that raise NotImplementedError."""

    name: ClassVar[str]
    #: The ego turns at the junction (the spec's `turn` says which way) instead of driving straight on.
    turning: ClassVar[bool] = False

    def load_turn(self, site: Site, spec: ScenarioSpec, arm: str | None) -> Turn | None:
        """The turn the ego makes on approach `arm` of `site` (None: the site's own approach), or None
        when it drives straight on. ValueError when the site has no such turn."""
        return None

    def stage(self, inputs: StagingInputs) -> StagedScene:
        """Stage one episode; every random draw goes through `inputs.draws`, in a fixed order."""
        raise NotImplementedError

    def staging_points(self, spec: ScenarioSpec, approach: Approach, turn: Turn | None) -> list[StagingPoint]:
        """Where the pedestrian stands and walks until the middle of the approach's farthest lane
        (network frame, m), for the hosting check; for a turning scenario along the crosswalk over the
        road turned into, from the end the pedestrian starts at."""
        raise NotImplementedError

    def staging_problem(
        self, site: Site, spec: ScenarioSpec, approach: Approach, turn: Turn | None, arm: str
    ) -> str | None:
        """Why `spec` cannot be staged on approach `arm` of `site` (one line), or None."""
        raise NotImplementedError

    def approach_staging_problem(
        self, spec: ScenarioSpec, approach: Approach, turn: Turn | None
    ) -> str | None:
        """Why `spec`, which `staging_problem` lets stage, cannot be staged under approach staging (one
        line), or None (hosting.staging_problem asks it after `staging_problem`)."""
        return None


def first_crossing(polyline, path) -> tuple[float, float] | None:
    """First intersection of the pedestrian's straight path (two points) with a polyline, or None."""
    (ax, ay), (bx, by) = path
    for (px, py), (qx, qy) in zip(polyline[:-1], polyline[1:]):
        d1x, d1y, d2x, d2y = bx - ax, by - ay, qx - px, qy - py
        denom = d1x * d2y - d1y * d2x
        if abs(denom) < 1e-12:
            continue
        t = ((px - ax) * d2y - (py - ay) * d2x) / denom
        u = ((px - ax) * d1y - (py - ay) * d1x) / denom
        if 0 <= t <= 1 and 0 <= u <= 1:
            return ax + t * d1x, ay + t * d1y
    return None
