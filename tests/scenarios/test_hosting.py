"""The hosting check (scenarios/hosting.py): which scenarios a site's roadside poles can host under V2I."""

from __future__ import annotations

import dataclasses
import math

from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.perception.world import load_roadside_units
from pedsafe_sumo.scenarios.geometry import load_approach
from pedsafe_sumo.scenarios.hosting import hosting_problem, site_hosting, staging_points
from pedsafe_sumo.scenarios.specs import SCENARIOS


def test_a_pole_turned_away_cannot_host_the_crossing():
    """The corner pole turned 180 degrees: every staging point is behind it; with the pole as built, all
    are in view."""
    site = resolve_site("xueqing")
    params = load_params(None)
    hosting = site_hosting(site, dict(SCENARIOS), params)
    # Every scenario but left_turn: Xueqing's split-phase program never lets the oncoming vehicle that
    # hides its pedestrian move while the ego turns left (networks/xueqing_two_phase can).
    assert {name for name, problem in hosting.items() if problem is not None} == {"left_turn"}
    assert "never shows green to the oncoming through movement" in hosting["left_turn"]
    units = {u.id: u for u in load_roadside_units(site.file("rsu.add.xml"), 6.0, 20.0)}
    turned = {k: dataclasses.replace(u, yaw_rad=u.yaw_rad + math.pi) for k, u in units.items()}
    approach = load_approach(site)
    spec = SCENARIOS["crossing"]
    problem = hosting_problem(spec, approach, turned, params)
    start = staging_points(spec, approach)[0]
    assert start.start
    assert problem == (
        "not seen under V2I: roadside pole(s) rsu_camera_0 do not see where the pedestrian starts "
        f"({start.where}, at {start.xy[0]:.1f}, {start.xy[1]:.1f})"
    )
    assert hosting_problem(spec, approach, units, params) is None
