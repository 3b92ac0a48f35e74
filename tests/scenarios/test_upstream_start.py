"""Approach staging starts the ego on the road before its approach when the approach lane is shorter than
the drawn start distance (docs/engine.md, "Approach staging", fallback 1).

A network built here by netconvert from a plain description: a signalised four-arm junction C; its south
arm, 40 m node to node, comes from a priority junction P (a side road to the east, one lane each way, of
lower priority), and before P the road runs 200 m from the network's edge U. Two lanes each way, sidewalks
and crosswalks guessed. The distances are read from the written .net.xml with ElementTree (lane lengths,
the `via` lane of the straight connection through P), not from sumolib. A second network makes P a
traffic light (70 m before C): the ego is then not started through it. On Xueqing the southern approach
(its lanes 47 m) hosts crossing under approach staging, in SUMO.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo.network.sites import Site, get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.safety.compliance import stop_line_of
from pedsafe_sumo.sampling.draws import Draws
from pedsafe_sumo.scenarios.geometry import load_approach
from pedsafe_sumo.scenarios.hosting import hosting_lines, site_hosting, staging_problem
from pedsafe_sumo.scenarios.placements.straight import ego_start
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode
from pedsafe_sumo.sim.staging import stop_line_lane_shape
from pedsafe_sumo.sumo_binaries import sumo_binary

TRAITS = {"age_years": 35.0, "gender": "f", "risk": "unaware", "walking_speed_mps": 1.4}
PEDESTRIANS = [
    "--sidewalks.guess", "--sidewalks.guess.max-speed", "30", "--crossings.guess", "--walkingareas",
    "--tls.default-type", "static",
]  # fmt: skip
#: The spec's default start-distance range, written out by hand [m].
START_RANGE_M = (100.0, 160.0)


def _nodes(upstream_type: str, approach_m: float) -> str:
    points = {
        "C": ((0, 0), "traffic_light"),
        "N": ((0, 200), "priority"),
        "E": ((200, 0), "priority"),
        "W": ((-200, 0), "priority"),
        "P": ((0, -approach_m), upstream_type),
        "U": ((0, -approach_m - 200), "priority"),
        "PE": ((100, -approach_m), "priority"),
    }
    rows = "".join(f'<node id="{n}" x="{x}" y="{y}" type="{t}"/>' for n, ((x, y), t) in points.items())
    return f"<nodes>{rows}</nodes>"


def _edges() -> str:
    roads = [("U", "P", 2, 3), ("P", "C", 2, 3), ("N", "C", 2, 3), ("E", "C", 2, 2), ("W", "C", 2, 2)]
    roads += [("PE", "P", 1, 1)]
    rows = []
    for a, b, lanes, priority in roads:
        for f, t in ((a, b), (b, a)):
            attributes = f'numLanes="{lanes}" speed="13.89" priority="{priority}"'
            rows.append(f'<edge id="{f}{t}" from="{f}" to="{t}" {attributes}/>')
    return "<edges>" + "".join(rows) + "</edges>"


def _site(folder: Path, name: str, upstream_type: str, approach_m: float) -> Site:
    (folder / f"{name}.nod.xml").write_text(_nodes(upstream_type, approach_m))
    (folder / f"{name}.edg.xml").write_text(_edges())
    env = {**os.environ, "SUMO_HOME": str(Path(sumo_binary("netconvert")).parent.parent)}
    subprocess.run(
        [sumo_binary("netconvert"), "-n", f"{name}.nod.xml", "-e", f"{name}.edg.xml", *PEDESTRIANS,
         "-o", f"{name}.net.xml"],
        cwd=folder, check=True, capture_output=True, env=env,
    )  # fmt: skip
    approaches = {arm: {"junction": "C", "poles": []} for arm in ("N", "E", "S", "W")}
    (folder / f"{name}.site.json").write_text(
        json.dumps({"approaches": approaches, "roadside_unit": {"watched_arm": "S"}})
    )
    return Site(name, folder, "", 0.0, 0.0, 250.0, None, folder / f"{name}.osm")


@pytest.fixture(scope="module")
def sites(tmp_path_factory) -> dict[str, Site]:
    folder = tmp_path_factory.mktemp("upstream_nets")
    return {
        "priority": _site(folder, "upstream_priority", "priority", 40.0),
        # 70 m: signal nodes within 60 m of C would be taken as part of its intersection
        # (network.approaches.SIGNAL_GROUP_DIST_M).
        "signalised": _site(folder, "upstream_signal", "traffic_light", 70.0),
    }


def _lanes(site: Site) -> dict[str, ET.Element]:
    root = ET.parse(site.file("net.xml")).getroot()
    return {lane.get("id"): lane for lane in root.iter("lane")}


def _via(site: Site, from_edge: str, to_edge: str, from_lane: int) -> str:
    root = ET.parse(site.file("net.xml")).getroot()
    return next(
        c.get("via")
        for c in root.iter("connection")
        if (c.get("from"), c.get("to"), c.get("fromLane")) == (from_edge, to_edge, str(from_lane))
    )


def _shape(lane: ET.Element) -> list[tuple[float, float]]:
    return [tuple(float(v) for v in p.split(",")) for p in lane.get("shape").split()]


def _draw(site: Site, seed: int, speed_mps: float = 8.0):
    spec = get_scenario("crossing").with_overrides({"staging": "approach", "approach": "S"})
    draws = Draws(np.random.default_rng(seed))
    setup = draw_episode(spec, load_approach(site, "S"), seed, TRAITS, speed_mps, draws)
    return spec, setup, draws.inputs


def test_the_ego_starts_the_drawn_distance_before_the_conflict_on_the_road_before(sites):
    site = sites["priority"]
    lanes = _lanes(site)
    # The ego drives the median lane (index 2; lane 0 is the sidewalk), next to the kerb lane.
    approach_lane, upstream_lane = lanes["PC_2"], lanes["UP_2"]
    internal = lanes[_via(site, "UP", "PC", 2)]
    approach_m = float(approach_lane.get("length"))
    assert approach_m < START_RANGE_M[0] - 50.0  # a short approach: no draw fits on it
    for seed in range(4):
        spec, setup, drawn = _draw(site, seed)
        assert setup.ego.lane_id == "UP_2"
        assert setup.ego_route[0] == "UP"
        assert setup.ego_route[:2] == ("UP", "PC")
        assert setup.ego.stop_line_lane_id == "PC_2"
        # Every lane here is straight along +y, drawn as long as SUMO's length: the conflict point lies
        # conflict_y - (end of the approach lane) beyond the stop line.
        beyond_m = setup.conflict_xy[1] - _shape(approach_lane)[-1][1]
        assert 0.0 < beyond_m < 10.0
        along_m = (
            float(upstream_lane.get("length")) - setup.ego.front_pos_m
            + float(internal.get("length")) + approach_m + beyond_m
        )  # fmt: skip
        assert along_m == pytest.approx(drawn["ego_start_distance_m"], abs=1e-6)
        assert setup.ego_start_distance_m == pytest.approx(drawn["ego_start_distance_m"], abs=1e-9)
        # The front's drawn point, straight along the lane: the same distance in the plane.
        front_y = _shape(upstream_lane)[0][1] + setup.ego.front_pos_m
        assert setup.conflict_xy[1] - front_y == pytest.approx(drawn["ego_start_distance_m"], abs=1e-3)
        assert setup.conflict_time_s == pytest.approx(drawn["ego_start_distance_m"] / 8.0)


def test_the_stop_line_is_the_junctions(sites):
    site = sites["priority"]
    _spec, setup, _drawn = _draw(site, 0)
    shape = stop_line_lane_shape(str(site.file("net.xml")), setup)
    end = _shape(_lanes(site)["PC_2"])[-1]
    point, direction = stop_line_of(shape)
    # The approach lane's end at C, facing north (+y); not the end of UP_2, where the ego starts, at P.
    assert point == pytest.approx(end)
    assert direction == pytest.approx((0.0, 1.0))
    assert math.dist(point, _shape(_lanes(site)["UP_2"])[-1]) > 30.0


def test_a_front_on_the_junction_before_is_inserted_on_the_lane_before_it(sites):
    approach = load_approach(sites["priority"], "S")
    lanes = _lanes(sites["priority"])
    via = _via(sites["priority"], "UP", "PC", 2)
    ego, route = ego_start(approach, 1, -5.0, 8.0)
    assert (ego.lane_id, ego.front_pos_m) == ("UP_2", pytest.approx(float(lanes["UP_2"].get("length"))))
    assert ego.internal_lane_id == via
    assert ego.internal_pos_m == pytest.approx(float(lanes[via].get("length")) - 5.0)
    assert route == ("UP", "PC", "CN")


def test_no_start_through_a_signalised_junction(sites):
    """A traffic light at P: the ego would have to be given its green there too; it is not started through
    it, and the short approach then hosts no approach staging."""
    site = sites["signalised"]
    approach = load_approach(site, "S")
    assert approach.upstream_roads[1].edges == ()
    spec = get_scenario("crossing").with_overrides({"staging": "approach", "approach": "S"})
    problem = staging_problem(site, spec, approach, None, "S")
    assert problem is not None and "less than ego_start_min_m" in problem
    hosted = staging_problem(sites["priority"], spec, load_approach(sites["priority"], "S"), None, "S")
    assert hosted is None


def test_xueqing_south_hosts_crossing_under_approach_staging():
    site = get_site("xueqing")
    spec = get_scenario("crossing").with_overrides({"staging": "approach"})
    assert site_hosting(site, {"crossing": spec}, load_params(None), "S")["crossing"] is None
    line = "  crossing on approach S under approach staging: hosted (its roadside poles see its staging area)"
    assert line in hosting_lines(site)


@pytest.mark.slow
def test_xueqing_south_crossing_runs_in_sumo(tmp_path):
    """Two pairs of crossing on Xueqing's southern approach under approach staging: no error rows, and the
    distance the ego starts before the conflict point is the one drawn (its lanes hold 47 m; the road
    before them, through a priority junction, the rest)."""
    out = tmp_path / "run"
    site = get_site("xueqing")
    subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--scenario", "crossing", "--approach", "S",
         "--set", "staging=approach", "--episodes", "2", "--workers", "1", "--keep-logs", "all",
         "--out", str(out)],
        check=True, capture_output=True,
    )  # fmt: skip
    rows = pd.read_parquet(out / "episodes.parquet")
    assert len(rows) == 4
    assert (rows["error"].fillna("") == "").all()
    drawn = rows["sampler_inputs"].map(lambda text: json.loads(text)["inputs"]["ego_start_distance_m"])
    assert np.allclose(rows["ego_start_distance_m"], drawn, rtol=0, atol=1e-9)
    assert ((rows["ego_start_distance_m"] >= START_RANGE_M[0]) & (rows["ego_start_distance_m"] <= 160)).all()
    # The ego starts before its approach lane, on the road before it: its first logged centre lies farther
    # from the approach lane's end (the stop line, read from net.xml) than that lane is long.
    lane = next(
        ln for ln in ET.parse(site.file("net.xml")).getroot().iter("lane") if ln.get("id") == "1104710653#1_2"
    )
    stop_xy = _shape(lane)[-1]
    for log_file in (out / "steplogs").glob("*.parquet"):
        first = pd.read_parquet(log_file).iloc[0]
        assert math.dist((first["ego_x_m"], first["ego_y_m"]), stop_xy) > float(lane.get("length")) + 10.0
