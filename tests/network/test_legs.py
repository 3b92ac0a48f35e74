"""A junction's approaches are its legs, found from the road geometry whatever their bearings.

Each network is built here by netconvert from a plain description: a signalised node C at the origin and,
per leg, an end node 200 m out at a chosen bearing with a two-lane road each way. The expected bearing of
each leg is computed from the node coordinates written here (atan2(dx, dy), clockwise from north), its
name from the naming rule by hand (N/E/S/W alone in a compass sector; else NE/SE/SW/NW; else B and the
bearing). Xueqing's legs are checked against the bearings read from its net.xml with ElementTree.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pedsafe_sumo.batch.plan import UsageError, approach_units
from pedsafe_sumo.network.approaches import (
    LEG_MERGE_TOLERANCE_DEG,
    Leg,
    approach_nodes,
    arm_axis,
    choose_approach,
    cluster_bearings,
    is_leg_name,
    junction_arms,
    junction_legs,
    leg_names,
    signal_group,
)
from pedsafe_sumo.network.sites import Site, resolve_site
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.geometry import load_approach, site_approaches
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.sumo_net import read_net

ROAD_M = 200.0
#: A leg's bearing (to the far end of its incoming edge's shape) against the end node's: the edge's shape
#: runs a few metres beside the axis between the nodes (netconvert lays the lanes of each direction to
#: its right), under 2 degrees at ROAD_M [deg].
BEARING_TOLERANCE_DEG = 2.0
PEDESTRIANS = [
    "--sidewalks.guess", "--sidewalks.guess.max-speed", "30", "--crossings.guess", "--walkingareas",
    "--tls.default-type", "static",
]  # fmt: skip


def _point(bearing_deg: float, distance_m: float = ROAD_M) -> tuple[float, float]:
    return (
        round(distance_m * math.sin(math.radians(bearing_deg)), 2),
        round(distance_m * math.cos(math.radians(bearing_deg)), 2),
    )


def _build(folder: Path, name: str, ends: dict[str, tuple[float, float]]) -> Path:
    """netconvert a signalised node C at the origin with a two-lane road each way to every end node."""
    nodes = ['<node id="C" x="0" y="0" type="traffic_light"/>']
    nodes += [f'<node id="{end}" x="{x}" y="{y}" type="priority"/>' for end, (x, y) in ends.items()]
    edges = []
    for end in ends:
        edges.append(
            f'<edge id="{end}_in" from="{end}" to="C" numLanes="2" speed="13.89" name="road {end}"/>'
        )
        edges.append(
            f'<edge id="{end}_out" from="C" to="{end}" numLanes="2" speed="13.89" name="road {end}"/>'
        )
    (folder / f"{name}.nod.xml").write_text("<nodes>" + "".join(nodes) + "</nodes>")
    (folder / f"{name}.edg.xml").write_text("<edges>" + "".join(edges) + "</edges>")
    net = folder / f"{name}.net.xml"
    env = {**os.environ, "SUMO_HOME": str(Path(sumo_binary("netconvert")).parent.parent)}
    subprocess.run(
        [sumo_binary("netconvert"), "-n", f"{name}.nod.xml", "-e", f"{name}.edg.xml", *PEDESTRIANS,
         "-o", net.name],
        cwd=folder, check=True, capture_output=True, env=env,
    )  # fmt: skip
    return net


def _bearing_deg(x: float, y: float) -> float:
    return math.degrees(math.atan2(x, y)) % 360.0


def _off_deg(a: float, b: float) -> float:
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


#: name -> (bearing of the leg's end node [deg], the name the rule gives it, worked out by hand).
JUNCTIONS = {
    # Two legs in each of the E (45-135) and W (225-315) sectors: none alone, all by eight-point name.
    "diagonal": {"a": (55, "NE"), "b": (120, "SE"), "c": (235, "SW"), "d": (300, "NW")},
    # 0 N alone, 72 E alone, 144 and 216 share S (135-225): SE and SW, 288 W alone.
    "five": {"a": (0, "N"), "b": (72, "E"), "c": (144, "SE"), "d": (216, "SW"), "e": (288, "W")},
    # 60 and 120 share E, 240 and 300 share W: NE, SE, SW, NW; 0 and 180 alone: N, S.
    "six": {
        "a": (0, "N"), "b": (60, "NE"), "c": (120, "SE"), "d": (180, "S"), "e": (240, "SW"), "f": (300, "NW"),
    },
    "tee": {"a": (0, "N"), "b": (90, "E"), "c": (270, "W")},
    # 70 and 110 (40 degrees apart: two legs) share E and both are eight-point E: named by their bearings
    # ("B" here: B and the bearing of the incoming edge, within BEARING_TOLERANCE_DEG of the node's).
    "close": {"a": (0, "N"), "b": (70, "B"), "c": (110, "B"), "d": (270, "W")},
}  # fmt: skip


@pytest.fixture(scope="module")
def nets(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("leg_nets")
    built = {
        name: _build(folder, name, {end: _point(bearing) for end, (bearing, _) in legs.items()})
        for name, legs in JUNCTIONS.items()
    }
    # A leg whose road comes in as two carriageways from end nodes 10 m apart (each 2.9 degrees off the
    # leg's axis, 5.7 apart: one leg), beside an ordinary road to the south.
    built["split"] = _build(folder, "split", {"p": (-10.0, ROAD_M), "q": (10.0, ROAD_M), "s": (0.0, -ROAD_M)})
    return built


def _legs(net_file: Path):
    net = read_net(net_file, withInternal=True)
    group = signal_group(net, net.getNode("C").getCoord())
    return net, group, junction_legs(group)


@pytest.mark.parametrize("junction", list(JUNCTIONS))
def test_every_leg_is_an_approach_with_its_own_name(nets, junction):
    net, group, legs = _legs(nets[junction])
    expected = JUNCTIONS[junction]
    assert len(legs) == len(expected)
    by_edge = {leg.edge_ids: leg for leg in legs}
    assert set(by_edge) == {(f"{end}_in",) for end in expected}
    for end, (bearing, name) in expected.items():
        leg = by_edge[(f"{end}_in",)]
        x, y = _point(bearing)
        assert _off_deg(leg.bearing_deg, _bearing_deg(x, y)) < BEARING_TOLERANCE_DEG
        if name == "B":
            assert leg.name.startswith("B") and _off_deg(int(leg.name[1:]), bearing) < BEARING_TOLERANCE_DEG
        else:
            assert leg.name == name
        assert leg.road_name == f"road {end}"
        assert is_leg_name(leg.name)


@pytest.mark.parametrize("junction", list(JUNCTIONS))
def test_each_leg_can_be_selected(nets, junction):
    net, group, legs = _legs(nets[junction])
    names = {leg.edge_ids: leg.name for leg in legs}
    for end, (bearing, _) in JUNCTIONS[junction].items():
        name = names[(f"{end}_in",)]
        node, chosen = choose_approach(net, group, name)
        assert (node.getID(), chosen) == ("C", name)
        ax, ay = arm_axis(net, node, name)  # the leg's roads in and out, both towards the end node
        assert _off_deg(_bearing_deg(ax, ay), bearing) < BEARING_TOLERANCE_DEG
    found = approach_nodes(net, group, legs[0].name, group[0])
    assert sorted(found) == sorted(names.values())
    assert len(set(names.values())) == len(JUNCTIONS[junction])


@pytest.mark.parametrize("junction", ["diagonal", "five", "six", "tee"])
def test_each_leg_stages_on_its_own_road(nets, junction):
    """A site whose file lists every leg as an approach: load_approach(site, leg) stages the scenarios on
    that leg's incoming road (its two vehicle lanes, beside the guessed sidewalk); the stem of the T has no
    road straight ahead, so nothing going straight is staged there."""
    net_file = nets[junction]
    _net, _group, legs = _legs(net_file)
    name = f"{junction}_site"
    shutil.copy(net_file, net_file.parent / f"{name}.net.xml")
    (net_file.parent / f"{name}.site.json").write_text(
        json.dumps(
            {
                "approaches": {leg.name: {"junction": "C", "poles": []} for leg in legs},
                "roadside_unit": {"watched_arm": legs[0].name},
            }
        )
    )
    site = Site(name, net_file.parent, "", 0.0, 0.0, ROAD_M, None, net_file.parent / f"{name}.osm")
    for leg in legs:
        (edge_id,) = leg.edge_ids
        if junction == "tee" and leg.name == "N":
            with pytest.raises(ValueError, match="no straight movement from a_in"):
                load_approach(site, leg.name)
            continue
        approach = load_approach(site, leg.name)
        assert approach.edge_id == edge_id
        assert approach.lane_ids == (f"{edge_id}_1", f"{edge_id}_2")  # lane 0 is the sidewalk


def test_two_carriageways_of_one_road_are_one_leg(nets):
    _net, _group, legs = _legs(nets["split"])
    assert [(leg.name, leg.edge_ids) for leg in legs] == [("N", ("p_in", "q_in")), ("S", ("s_in",))]
    # The mean of about 357.1 and 2.9, across north.
    assert _off_deg(legs[0].bearing_deg, 0.0) < BEARING_TOLERANCE_DEG


def test_bearings_cluster_round_the_circle():
    # 350 and 10 are 20 degrees apart across north: one leg; 100 is 90 away from both.
    assert cluster_bearings([350.0, 10.0, 100.0]) == [[0, 1], [2]]
    assert cluster_bearings([0.0, LEG_MERGE_TOLERANCE_DEG + 1.0]) == [[0], [1]]
    assert cluster_bearings([0.0, LEG_MERGE_TOLERANCE_DEG]) == [[0, 1]]
    assert leg_names([55.0, 120.0, 235.0, 300.0]) == ["NE", "SE", "SW", "NW"]
    assert leg_names([2.0, 88.0, 181.0, 268.0]) == ["N", "E", "S", "W"]


def test_roads_only_leaving_are_arms_of_their_own_in_the_summary():
    # A T of one-way roads: one leg in from the north, roads out to the east and west (and north).
    north = Leg("N", 0.0, ("n_in",), ("C",), "")
    assert junction_arms([north], [2.0, 90.0, 270.0]) == {"N": 0.0, "E": 90.0, "W": 270.0}
    # A road out 20 degrees off a leg is on that leg; one 40 off is an arm (NE beside the leg due E).
    east = Leg("E", 90.0, ("e_in",), ("C",), "")
    assert list(junction_arms([east], [110.0, 50.0])) == ["NE", "E"]


def test_xueqing_legs_stay_n_e_s_w():
    """Hand-check from net.xml: the bearing from the main junction to the first shape point of each road
    entering it lies in a compass sector of its own (N, E, S, W), so the legs keep those names."""
    site = resolve_site("xueqing")
    root = ET.parse(site.file("net.xml")).getroot()
    main = site_approaches(site)["N"]
    junction = next(j for j in root.iter("junction") if j.get("id") == main)
    jx, jy = float(junction.get("x")), float(junction.get("y"))
    expected = {}
    for edge in root.iter("edge"):
        if edge.get("function") or edge.get("to") != main:
            continue
        lanes = list(edge.iter("lane"))
        if not any(
            "passenger" not in (ln.get("disallow") or "") and ln.get("allow") in (None, "") for ln in lanes
        ):
            continue
        x, y = (float(v) for v in lanes[0].get("shape").split()[0].split(","))
        expected[edge.get("id")] = _bearing_deg(x - jx, y - jy)
    sectors = {edge_id: "NESW"[int(((b + 45.0) % 360.0) // 90.0)] for edge_id, b in expected.items()}
    assert sorted(sectors.values()) == ["E", "N", "S", "W"]
    net = read_net(site.file("net.xml"), withInternal=True)
    legs = junction_legs(signal_group(net, net.getNode(main).getCoord()))
    assert [leg.name for leg in legs] == ["N", "E", "S", "W"]
    for leg in legs:
        (edge_id,) = leg.edge_ids
        assert sectors[edge_id] == leg.name
        assert _off_deg(leg.bearing_deg, expected[edge_id]) < 3.0  # lane 0's first point vs the edge's
    assert list(site_approaches(site)) == ["N", "E", "S", "W"]


def test_leg_names_are_accepted_and_others_refused():
    spec = get_scenario("crossing")
    for name in ("N", "W", "NE", "SW", "B055", "B359"):
        assert dataclasses.replace(spec, approach=name).approach == name
    for bad in ("NNE", "B360", "B55", "north", "n"):
        with pytest.raises(ScenarioError):
            dataclasses.replace(spec, approach=bad)
        with pytest.raises(UsageError, match="unknown approach"):
            approach_units(resolve_site("xueqing"), {}, {}, [], "crossing", bad)


def test_a_leg_the_site_lacks_is_refused_in_one_line():
    with pytest.raises(UsageError, match="no approach from the NE"):
        approach_units(resolve_site("xueqing"), {}, {}, [], "crossing", "NE")
