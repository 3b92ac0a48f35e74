"""Can a site host a scenario? Checked before anything runs, with the perception layer's own geometry.

A scenario under V2I needs a roadside camera that sees where it is staged. `staging_points` lists where
the pedestrian stands and walks until they reach the ego's lane: along the crosswalk (crossing); across
the road at the nearest and farthest mid-block distances (jaywalking); behind a car waiting at the stop
line (background blending). A point is seen by a pole when a pedestrian standing there, as short as the
shortest one the scenarios draw, passes the roadside camera's own culling (pedsafe_sumo.perception.
sensors.plan_camera: in front of the camera, inside the image, at least min_height_px tall) with at least
min_visible_fraction of its sample points inside the image and in clear view past the site's static
occluders (buildings, trees: the camera's own ray casting, finish_camera). Vehicles are not part of the
check (hiding the pedestrian is what the scenarios are about), nor is the colour contrast (the clothing is
drawn per episode). The scenario's poles must see where the pedestrian starts and at least half of the
points of its path.

The batch calls `check_hosting` before it writes anything; the build prints `hosting_lines` in its
summary. A site that cannot host a scenario says why in one line.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import lru_cache
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
    #: Where the pedestrian stands before stepping into the road (the kerb, the gap between parked cars,
    #: behind the waiting car): the roadside camera has to see it there.
    start: bool = False


def staging_points(spec, approach, turn=None) -> list[StagingPoint]:
    """Where the scenario's pedestrian stands and walks until the middle of the approach's farthest lane
    (network frame, m); for a turning scenario, along the crosswalk over the road turned into (`turn`,
    scenarios.geometry.load_turn), from the end the pedestrian starts at."""
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
                start=f == 0.0,
            )
            for f in np.linspace(0.0, 1.0, 5)
        ]
    if spec.placement == "turn":
        near, far = turn.crosswalk_path
        (ax, ay), (bx, by) = (near, far) if spec.ped_start_corner == "near" else (far, near)
        return [
            StagingPoint(
                f"crosswalk {turn.crosswalk_id}, {f:.0%} across",
                (ax + f * (bx - ax), ay + f * (by - ay)),
                start=f == 0,
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
                where = f"{distance_m:g} m before the stop line, {offset_m:+.1f} m"
                points.append(StagingPoint(where, xy, start=offset_m == offsets[0]))
        return points
    # behind_waiting_vehicle: a car's length, the gap and the body behind a car at the stop line.
    behind_m = 0.5 + VEHICLE_CLASSES["car"].length_m + spec.blend_gap_max_m + PEDESTRIAN_RADIUS_M
    if lanes == 1:
        # The car stands parked at the kerb beside the one lane (registry.kerb_parking_offset_m): the
        # pedestrian starts behind it, then crosses the lane.
        from pedsafe_sumo.scenarios.registry import kerb_parking_offset_m

        offsets = [0.0, -kerb_parking_offset_m(approach, VEHICLE_CLASSES["car"]), 0.0]
    return [
        StagingPoint(
            f"{behind_m:.1f} m before the stop line, {offset_m:+.1f} m",
            approach.across(0, stop_line_m - behind_m, offset_m, offset_m)[0],
            start=offset_m == offsets[1],
        )
        for offset_m in offsets[1:]
    ]


def _seen(spec, pose, points: list[StagingPoint], static) -> np.ndarray:
    """Per point: a pedestrian there passes the camera's culling and enough of its sample points are in
    the image with a clear line of sight past the site's static occluders (buildings, trees)."""
    from pedsafe_sumo.perception.pipeline import _NO_HITS, _cast_all
    from pedsafe_sumo.perception.sensors import finish_camera, plan_camera
    from pedsafe_sumo.perception.world import Pedestrians, VehicleBoxes, WorldSnapshot

    n = len(points)
    peds = Pedestrians.build(
        [str(i) for i in range(n)],
        [p.xy[0] for p in points],
        [p.xy[1] for p in points],
        [PEDESTRIAN_RADIUS_M] * n,
        [SHORTEST_PEDESTRIAN_M] * n,
        np.zeros((n, 3)),
    )
    world = WorldSnapshot(0.0, VehicleBoxes.empty(), peds, static)
    plan = plan_camera(spec, pose, peds)
    hits = _cast_all(world, [plan], -1, onboard=[False])[0] or _NO_HITS
    # Colour contrast is left out: the clothing is drawn per episode.
    result = finish_camera(spec, plan, hits, world, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    return (result.visible_fraction >= spec.min_visible_fraction) & (result.height_px >= spec.min_height_px)


def hosting_problem(
    spec, approach, roadside_units: dict, params: dict[str, Any], static=None, turn=None
) -> str | None:
    """Why the site cannot host `spec` under V2I (one line), or None when it can."""
    from pedsafe_sumo.perception.pipeline import SensorSuite

    units = [roadside_units[u] for u in spec.roadside_unit_ids if u in roadside_units]
    missing = [u for u in spec.roadside_unit_ids if u not in roadside_units]
    if missing:
        return f"the site has no roadside pole {', '.join(missing)}"
    from pedsafe_sumo.perception.world import StaticOccluders

    static = static if static is not None else StaticOccluders.empty()
    suite = SensorSuite.from_params(params["perception"], units)
    points = staging_points(spec, approach, turn)
    seen = np.zeros(len(points), dtype=bool)
    for pose in suite.roadside_poses:
        seen |= _seen(suite.roadside, pose, points, static)
    unseen = [p for p, s in zip(points, seen, strict=True) if not s]
    hidden_starts = [p for p in unseen if p.start]
    if not hidden_starts and 2 * len(unseen) <= len(points):
        return None
    first = (hidden_starts or unseen)[0]
    return f"not seen under V2I: roadside pole(s) {', '.join(spec.roadside_unit_ids)} do not see " + (
        f"where the pedestrian starts ({first.where}, at {first.xy[0]:.1f}, {first.xy[1]:.1f})"
        if hidden_starts
        else f"{len(unseen)} of the {len(points)} points of its staging area "
        f"(first: {first.where}, at {first.xy[0]:.1f}, {first.xy[1]:.1f})"
    )


def site_hosting(site, specs: dict, params: dict[str, Any], arm: str | None = None) -> dict[str, str | None]:
    """Scenario name -> why the site cannot host it under V2I, or None. On approach `arm` (None: each
    spec's own `approach`, "" meaning the site's), with that approach's poles."""
    from pedsafe_sumo.perception.world import load_roadside_units, load_static_occluders
    from pedsafe_sumo.scenarios.geometry import (
        approach_unit_ids,
        default_arm,
        load_approach,
        load_turn,
        straight_staging_problem,
    )

    rsu = params["perception"]["roadside_camera"]
    units = load_roadside_units(
        site.file("rsu.add.xml"), rsu["default_height_m"], rsu["default_pitch_down_deg"]
    )
    by_id = {u.id: u for u in units}
    static = load_static_occluders(site.file("poly.xml"), params["perception"]["occluders"])
    site_arm = default_arm(site)
    problems: dict[str, str | None] = {}
    for name, spec in specs.items():
        spec_arm = (arm if arm is not None else getattr(spec, "approach", "")) or site_arm
        try:
            approach = load_approach(site, spec_arm)
            turn = load_turn(site, spec.turn, spec_arm) if spec.placement == "turn" else None
        except ValueError as exc:
            problems[name] = f"cannot be staged: {exc}"
            continue
        straight = straight_staging_problem(approach) if spec.placement != "turn" else None
        if not straight and spec.placement != "turn" and len(approach.lane_ids) == 1:
            from pedsafe_sumo.scenarios.registry import kerb_staging_problem

            straight = kerb_staging_problem(spec, approach)
        if not straight and getattr(spec, "oncoming_vehicle", 0) and turn is not None:
            from pedsafe_sumo.scenarios.oncoming import oncoming_signal_problem

            straight = oncoming_signal_problem(
                site, spec_arm, approach.lane_ids[turn.lane_index], turn.route[1]
            )
        if straight:
            problems[name] = f"cannot be staged: site {site.name}: {straight}"
            continue
        ids = approach_unit_ids(spec.roadside_unit_ids, spec_arm, site_arm, spec.turn)
        spec = dataclasses.replace(spec, roadside_units=",".join(ids))
        problems[name] = hosting_problem(spec, approach, by_id, params, static, turn)
    return problems


def hosting_matrix(
    site, specs: dict, params: dict[str, Any], arms, conditions
) -> tuple[list[tuple[str, str]], dict[tuple[str, str], str]]:
    """([(scenario, arm)] the site hosts, {(scenario, arm): why not} for the others), scenarios in the
    order of `specs`, arms in the order given. Without V2I every combination that can be staged is
    hosted (the poles do not matter)."""
    hosted: list[tuple[str, str]] = []
    skipped: dict[tuple[str, str], str] = {}
    by_arm = {arm: site_hosting(site, specs, params, arm) for arm in arms}
    for name in specs:
        for arm in arms:
            problem = by_arm[arm][name]
            if problem is not None and ("v2i" in conditions or problem.startswith("cannot be staged")):
                skipped[(name, arm)] = problem
            else:
                hosted.append((name, arm))
    return hosted, skipped


def split_hosted(site, specs: dict, params: dict[str, Any], conditions) -> tuple[list[str], dict[str, str]]:
    """(names the site hosts, {name: why not} for the others) under these conditions; without V2I every
    scenario the site can stage is hosted."""
    if "v2i" not in conditions:
        return list(specs), {}
    problems = site_hosting(site, specs, params)
    return [n for n in specs if problems[n] is None], {n: p for n, p in problems.items() if p is not None}


def check_hosting(site, specs: dict, params: dict[str, Any], conditions) -> None:
    """SiteError (one line) when a scenario to run under V2I cannot be hosted by the site."""
    from pedsafe_sumo.network.sites import SiteError

    if "v2i" not in conditions:
        return
    for name, problem in site_hosting(site, specs, params).items():
        if problem:
            raise SiteError(f"site {site.name} cannot host scenario '{name}': {problem}")


def hosting_lines(site, params: dict[str, Any] | None = None) -> list[str]:
    """One line per registered scenario and approach: whether the site hosts it (the build's summary); the
    site's own approach (what runs without --approach) first, its lines without the arm."""
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.geometry import default_arm, site_approaches
    from pedsafe_sumo.scenarios.registry import SCENARIOS

    params = params or load_params(None)
    lines = []
    own = default_arm(site)
    arms = [own] + [a for a in site_approaches(site) if a != own]
    rows = [(arm, item) for arm in arms for item in site_hosting(site, dict(SCENARIOS), params, arm).items()]
    for arm, (name, problem) in rows:
        lines.append(
            f"  {name}{'' if arm == own else f' on approach {arm}'}: "
            + (
                "hosted (its roadside poles see its staging area)"
                if problem is None
                else f"NOT hosted: {problem}"
            )
        )
    return lines


def hosted_count(site, poles: list[dict], poly_file: str) -> int:
    """How many registered scenarios (default settings) the site would host under V2I with these poles
    (dicts as tools/build_network.py writes them); used by the build to place its poles."""
    from pedsafe_sumo.perception.world import RoadsideUnit
    from pedsafe_sumo.scenarios.registry import SCENARIOS
    from pedsafe_sumo.units import sumo_angle_to_yaw_rad

    params, approach, static = _site_world(site, poly_file)
    if approach is None:
        return 0
    units = {
        p["id"]: RoadsideUnit(
            id=p["id"],
            x_m=p["x"],
            y_m=p["y"],
            height_m=p["height_m"],
            yaw_rad=float(sumo_angle_to_yaw_rad(p["yaw_deg"])),
            pitch_down_rad=math.radians(p["pitch_deg"]),
        )
        for p in poles
    }
    # The scenarios staged on the watched approach; the turning ones (issue 13) are hosted where these
    # poles happen to see the crosswalk turned into, and do not move the poles the build places.
    return sum(
        hosting_problem(spec, approach, units, params, static) is None
        for spec in SCENARIOS.values()
        if spec.placement != "turn"
    )


@lru_cache(maxsize=4)
def _site_world(site, poly_file: str):
    """(default parameters, the scenarios' approach or None, static occluders) of a site being built."""
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.perception.world import load_static_occluders
    from pedsafe_sumo.scenarios.geometry import load_approach

    params = load_params(None)
    try:
        approach = load_approach(site)
    except ValueError:
        return params, None, None
    return (
        params,
        approach,
        load_static_occluders(site.directory / poly_file, params["perception"]["occluders"]),
    )
