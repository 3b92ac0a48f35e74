"""Can a site host a scenario? Checked before anything runs, with the perception layer's own geometry.

A scenario under V2I needs a roadside camera that sees where it is staged. `staging_points` lists where
the pedestrian stands and walks until they reach the ego's lane, as the scenario's placement
(scenarios/placements/) gives them: along the crosswalk (crossing); across the road at the nearest and
farthest mid-block distances (jaywalking); behind a car waiting at the stop line (background blending);
along the crosswalk turned into (the turning scenarios). A point is seen by a pole when a pedestrian
standing there, as short as the shortest one the scenarios draw, passes the roadside camera's own
culling (pedsafe_sumo.perception.sensors.plan_camera: in front of the camera, inside the image, at least
min_height_px tall) with at least min_visible_fraction of its sample points inside the image and in
clear view past the site's static occluders (buildings, trees: the camera's own ray casting,
finish_camera). Vehicles are not part of the check (hiding the pedestrian is what the scenarios are
about), nor is the colour contrast (the clothing is drawn per episode). The scenario's poles must see
where the pedestrian starts and at least half of the points of its path.

The batch calls `check_hosting` before it writes anything, then stages every episode it will run
(batch/staging_check.py); the build prints `hosting_lines` in its summary, with that staging over a
sample of seeds (site/staged_hosting.py). A site that cannot host a scenario says why in one line.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from functools import lru_cache
from typing import Any

import numpy as np

from pedsafe_sumo.network.sites import Site, SiteError
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.geometry import (
    approach_unit_ids,
    default_arm,
    load_approach,
    site_approaches,
)
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.placements.base import StagingPoint
from pedsafe_sumo.scenarios.road_users import PEDESTRIAN_RADIUS_M
from pedsafe_sumo.scenarios.specs import SCENARIOS

#: The shortest pedestrian the scenarios draw (road_users.pedestrian_height_m: 1.60 m, 5 cm less under
#: 19) [m].
SHORTEST_PEDESTRIAN_M = 1.55


def staging_points(spec, approach, turn=None) -> list[StagingPoint]:
    """Where the scenario's pedestrian stands and walks until the middle of the approach's farthest lane
    (network frame, m); for a turning scenario, along the crosswalk over the road turned into (`turn`,
    scenarios.geometry.load_turn), from the end the pedestrian starts at."""
    return placement_of(spec).staging_points(spec, approach, turn)


def staging_problem(site, spec, approach, turn, arm: str) -> str | None:
    """Why `spec` cannot be staged on approach `arm` of `site` (one line), or None: the placement's own
    reasons first (placements/base.py, staging_problem), then, under approach staging, the approach's
    (the road before the conflict, the sidewalk to the step-off point: approach_staging_problem)."""
    placement = placement_of(spec)
    problem = placement.staging_problem(site, spec, approach, turn, arm)
    if problem is None and spec.staging == "approach":
        problem = placement.approach_staging_problem(spec, approach, turn)
    return problem


def _seen(spec, pose, points: list[StagingPoint], static) -> np.ndarray:
    """Per point: a pedestrian there passes the camera's culling and enough of its sample points are in
    the image with a clear line of sight past the site's static occluders (buildings, trees)."""
    # The perception package is imported where it is used: its kernels take about a second to import,
    # and the batch, the build and the CLIs import this module whether or not they check V2I.
    from pedsafe_sumo.perception.pipeline import _NO_HITS, _cast_all
    from pedsafe_sumo.perception.sensors import finish_camera, plan_camera  # as above
    from pedsafe_sumo.perception.world import Pedestrians, VehicleBoxes, WorldSnapshot  # as above

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
    from pedsafe_sumo.perception.pipeline import SensorSuite  # about a second to import (see _seen)
    from pedsafe_sumo.perception.world import StaticOccluders  # as above

    units = [roadside_units[u] for u in spec.roadside_unit_ids if u in roadside_units]
    missing = [u for u in spec.roadside_unit_ids if u not in roadside_units]
    if missing:
        return f"the site has no roadside pole {', '.join(missing)}"
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
    # About a second to import (see _seen).
    from pedsafe_sumo.perception.world import load_roadside_units, load_static_occluders

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
        placement = placement_of(spec)
        try:
            approach = load_approach(site, spec_arm)
            turn = placement.load_turn(site, spec, spec_arm)
        except ValueError as exc:
            problems[name] = f"cannot be staged: {exc}"
            continue
        problem = staging_problem(site, spec, approach, turn, spec_arm)
        if problem:
            problems[name] = f"cannot be staged: site {site.name}: {problem}"
            continue
        ids = approach_unit_ids(spec.roadside_unit_ids, spec_arm, site_arm, spec.turn, approach.keep_side)
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
    if "v2i" not in conditions:
        return
    for name, problem in site_hosting(site, specs, params).items():
        if problem:
            raise SiteError(f"site {site.name} cannot host scenario '{name}': {problem}")


def hosting_lines(
    site,
    params: dict[str, Any] | None = None,
    staged: Callable[[dict[str, Any]], dict[str, str]] | None = None,
) -> list[str]:
    """One line per registered scenario and approach: whether the site hosts it (the build's summary); the
    site's own approach (what runs without --approach) first, its lines without the arm; each scenario
    under its own staging, then under approach staging (docs/engine.md, "Approach staging") where that
    differs. `staged` (the batch's staging check over a sample of seeds, given by the caller: unit
    `name@arm` -> spec in, unit -> why not out) turns a combination the check above hosts but whose
    episodes cannot be staged into NOT hosted."""
    params = params or load_params(None)
    lines = []
    own = default_arm(site)
    arms = [own] + [a for a in site_approaches(site) if a != own]
    approach_specs = {
        name: spec.with_overrides({"staging": "approach"})
        for name, spec in SCENARIOS.items()
        if spec.staging != "approach"
    }
    for label, specs in (("", dict(SCENARIOS)), (" under approach staging", approach_specs)):
        rows = [
            (arm, name, problem)
            for arm in arms
            for name, problem in site_hosting(site, specs, params, arm).items()
        ]
        if staged is not None:
            units = {
                f"{name}@{arm}": dataclasses.replace(specs[name], approach=arm)
                for arm, name, problem in rows
                if problem is None
            }
            failed = staged(units) if units else {}
            rows = [
                (arm, name, f"cannot be staged: {failed[unit]}" if (unit := f"{name}@{arm}") in failed else p)
                for arm, name, p in rows
            ]
        for arm, name, problem in rows:
            lines.append(
                f"  {name}{'' if arm == own else f' on approach {arm}'}{label}: "
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
    from pedsafe_sumo.perception.world import RoadsideUnit  # about a second to import (see _seen)

    params, approach, static = _site_world(site, poly_file)
    if approach is None:
        return 0
    units = {p["id"]: RoadsideUnit.from_pole(p) for p in poles}
    # The scenarios staged on the watched approach; the turning ones are hosted where these poles
    # happen to see the crosswalk turned into, and do not move the poles the build places.
    return sum(
        hosting_problem(spec, approach, units, params, static) is None
        for spec in SCENARIOS.values()
        if not placement_of(spec).turning
    )


def hosting_scorer(site: Site) -> Callable[[list[dict], str], int]:
    """How many of the scenarios staged on the staged `site`'s approach a pole pair lets it host
    (hosted_count): the scorer the site build places the poles with (network.poles.HostingScorer)."""
    # Both cache by site: the staging folder describes another approach on each call, and its name may
    # come back in a later build of this process.
    _site_world.cache_clear()
    load_approach.cache_clear()
    return functools.partial(hosted_count, site)


@lru_cache(maxsize=4)
def _site_world(site, poly_file: str):
    """(default parameters, the scenarios' approach or None, static occluders) of a site being built."""
    from pedsafe_sumo.perception.world import load_static_occluders  # about a second to import (see _seen)

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
