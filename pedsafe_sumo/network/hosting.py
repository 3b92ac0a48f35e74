"""Can a site host a scenario? Checked before anything runs, with the perception layer's own geometry.

A scenario under V2I needs a roadside camera that sees where it is staged. `staging_points` lists where
the pedestrian stands and walks until they reach the ego's lane: along the crosswalk (crossing); across
the road at the nearest and farthest mid-block distances (jaywalking); behind a car waiting at the stop
line (background blending). A point is seen by a pole when a pedestrian standing there, as short as the
shortest one the scenarios draw, passes the roadside camera's own culling (pedsafe_sumo.perception.
sensors.plan_camera: in front of the camera, inside the image, at least min_height_px tall) with at least
min_visible_fraction of its sample points inside the image. Occlusion is not part of the check: hiding
the pedestrian is what the scenarios are about. Every point must be seen by one of the scenario's poles.

The batch calls `check_hosting` before it writes anything; the build prints `hosting_lines` in its
summary. A site that cannot host a scenario says why in one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: The shortest pedestrian the scenarios draw (registry.draw_episode: 1.60 m, 5 cm less under 19) and
#: the body radius they use [m].
SHORTEST_PEDESTRIAN_M = 1.55
PEDESTRIAN_RADIUS_M = 0.3


@dataclass(frozen=True)
class StagingPoint:
    where: str
    xy: tuple[float, float]


def staging_points(spec, approach) -> list[StagingPoint]:
    """Where the scenario's pedestrian stands and walks until the middle of the approach's farthest lane
    (network frame, m)."""
    from pedsafe_sumo.scenarios.registry import VEHICLE_CLASSES

    lanes = len(approach.lane_ids)
    lane_w = approach.lane_width_m
    stop_line_m = approach.lane_lengths_m[0]
    # Offsets to the left of the kerb lane's centre: the sidewalk's middle, then each lane's centre.
    offsets = [-(lane_w / 2 + approach.sidewalk_width_m / 2)] + [k * lane_w for k in range(lanes)]
    if spec.placement == "crosswalk":
        (ax, ay), (bx, by) = approach.crosswalk_path
        width = math.dist((ax, ay), (bx, by))
        reach = min(1.0, (approach.sidewalk_width_m / 2 + lanes * lane_w) / width) if width else 1.0
        return [
            StagingPoint(
                f"crosswalk {approach.crosswalk_id}, {f * reach:.0%} across",
                (ax + f * reach * (bx - ax), ay + f * reach * (by - ay)),
            )
            for f in np.linspace(0.0, 1.0, 5)
        ]
    if spec.placement == "midblock":
        points = []
        for distance_m in (spec.midblock_distance_min_m, spec.midblock_distance_max_m):
            line = approach.across(0, stop_line_m - distance_m, offsets[0], offsets[-1])
            for offset_m in offsets:
                start, end = line
                f = (offset_m - offsets[0]) / (offsets[-1] - offsets[0]) if offsets[-1] != offsets[0] else 0.0
                xy = (start[0] + f * (end[0] - start[0]), start[1] + f * (end[1] - start[1]))
                points.append(StagingPoint(f"{distance_m:g} m before the stop line, {offset_m:+.1f} m", xy))
        return points
    # behind_waiting_vehicle: a car's length, the gap and the body behind a car at the stop line.
    behind_m = 0.5 + VEHICLE_CLASSES["car"].length_m + spec.blend_gap_max_m + PEDESTRIAN_RADIUS_M
    return [
        StagingPoint(
            f"{behind_m:.1f} m before the stop line, {offset_m:+.1f} m",
            approach.across(0, stop_line_m - behind_m, offset_m, offset_m)[0],
        )
        for offset_m in offsets[1:]
    ]


def _seen(spec, pose, points: list[StagingPoint]) -> np.ndarray:
    """Per point: a pedestrian there passes the camera's culling and enough samples are in the image."""
    from pedsafe_sumo.perception.sensors import plan_camera
    from pedsafe_sumo.perception.world import Pedestrians

    n = len(points)
    peds = Pedestrians.build(
        [str(i) for i in range(n)],
        [p.xy[0] for p in points],
        [p.xy[1] for p in points],
        [PEDESTRIAN_RADIUS_M] * n,
        [SHORTEST_PEDESTRIAN_M] * n,
        np.zeros((n, 3)),
    )
    plan = plan_camera(spec, pose, peds)
    seen = np.zeros(n, dtype=bool)
    if plan.ped.size:
        in_image = plan.extra["in_image"].reshape(plan.ped.size, -1)
        seen[plan.ped] = in_image.mean(axis=1) >= spec.min_visible_fraction
    return seen


def hosting_problem(spec, approach, roadside_units: dict, params: dict[str, Any]) -> str | None:
    """Why the site cannot host `spec` under V2I (one line), or None when it can."""
    from pedsafe_sumo.perception.pipeline import SensorSuite

    units = [roadside_units[u] for u in spec.roadside_unit_ids if u in roadside_units]
    missing = [u for u in spec.roadside_unit_ids if u not in roadside_units]
    if missing:
        return f"the site has no roadside pole {', '.join(missing)}"
    suite = SensorSuite.from_params(params["perception"], units)
    points = staging_points(spec, approach)
    seen = np.zeros(len(points), dtype=bool)
    for pose in suite.roadside_poses:
        seen |= _seen(suite.roadside, pose, points)
    if seen.all():
        return None
    unseen = [p for p, s in zip(points, seen, strict=True) if not s]
    first = unseen[0]
    return (
        f"not seen under V2I: roadside pole(s) {', '.join(spec.roadside_unit_ids)} do not see "
        f"{len(unseen)} of the {len(points)} points of its staging area "
        f"(first: {first.where}, at {first.xy[0]:.1f}, {first.xy[1]:.1f})"
    )


def site_hosting(site, specs: dict, params: dict[str, Any]) -> dict[str, str | None]:
    """Scenario name -> why the site cannot host it under V2I, or None."""
    from pedsafe_sumo.perception.world import load_roadside_units
    from pedsafe_sumo.scenarios.geometry import load_approach

    rsu = params["perception"]["roadside_camera"]
    units = load_roadside_units(
        site.file("rsu.add.xml"), rsu["default_height_m"], rsu["default_pitch_down_deg"]
    )
    by_id = {u.id: u for u in units}
    try:
        approach = load_approach(site)
    except ValueError as exc:
        return {name: f"cannot be staged: {exc}" for name in specs}
    return {name: hosting_problem(spec, approach, by_id, params) for name, spec in specs.items()}


def check_hosting(site, specs: dict, params: dict[str, Any], conditions) -> None:
    """SiteError (one line) when a scenario to run under V2I cannot be hosted by the site."""
    from pedsafe_sumo.network.sites import SiteError

    if "v2i" not in conditions:
        return
    for name, problem in site_hosting(site, specs, params).items():
        if problem:
            raise SiteError(f"site {site.name} cannot host scenario '{name}': {problem}")


def hosting_lines(site, params: dict[str, Any] | None = None) -> list[str]:
    """One line per registered scenario: whether the site hosts it (the build's summary)."""
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.registry import SCENARIOS

    params = params or load_params(None)
    lines = []
    for name, problem in site_hosting(site, dict(SCENARIOS), params).items():
        lines.append(
            f"  {name}: "
            + (
                "hosted (its roadside poles see its staging area)"
                if problem is None
                else f"NOT hosted: {problem}"
            )
        )
    return lines
