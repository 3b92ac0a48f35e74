"""Real signalised junctions from OpenStreetMap, in four countries (tests/data/osm, ODbL; each folder's
README names its source and place): each builds into a site whose traffic light controls the junction's
links; every (scenario, approach) combination the build says it hosts runs with the signals staged and no
error rows, and the roadside camera detects the pedestrian under V2I. A left-hand junction is found from
its place (or the data, or --lefthand), built for left-hand traffic and staged mirrored.

| clip | what it exercises |
|---|---|
| seattle_westlake | diagonal legs (Lenora Street, 8th Avenue at ~45 degrees to Westlake Avenue) |
| aguascalientes_convencion | one light over a divided road's signal nodes; approaches ending in stub edges |
| copenhagen_allegade | a T-junction (one vehicle lane per approach) |
| seattle_9th_50th | one-lane approaches (9th Avenue NE); one light joined over two junctions |
| perth_albany | left-hand traffic (Australia): built left-hand, the scenarios staged mirrored |

Building a site takes ~5 s, so the builds and their checks run in the default suite; the batches are slow.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.network.traffic_side import TRAFFIC_SIDE_NOTE
from pedsafe_sumo.scenarios.geometry import load_approach, site_approaches
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode
from pedsafe_sumo.sumo_net import read_net

DATA = REPO_ROOT / "tests" / "data" / "osm"
TOOL = REPO_ROOT / "tools" / "build_network.py"
SCENARIOS = ("crossing", "jaywalking", "background_blending", "right_turn", "left_turn")
TRAITS = {"age_years": 35.0, "gender": "f", "risk": "unaware", "walking_speed_mps": 1.4}


@dataclass(frozen=True)
class Junction:
    centre: str  #: LAT,LON of the junction (the clip's centre, its README)
    country: str


#: The junctions whose sites host scenarios (right-hand traffic).
HOSTING = {
    "seattle_westlake": Junction("47.616507,-122.338017", "United States"),
    "aguascalientes_convencion": Junction("21.873629,-102.270820", "Mexico"),
    "copenhagen_allegade": Junction("55.674679,12.532216", "Denmark"),
    "seattle_9th_50th": Junction("47.664943,-122.318420", "United States"),
}
LEFT_HAND = ("perth_albany", Junction("-31.975191,115.897673", "Australia"))


def _run(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, cwd=REPO_ROOT, timeout=timeout
    )


def _build(name: str, junction: Junction, out: Path, *extra: str, osm: Path | None = None):
    return _run(
        str(TOOL), "--osm", str(osm or DATA / name / f"{name}.osm"), "--no-clip",
        f"--center={junction.centre}", "--radius", "130", "--name", name, "--out", str(out), *extra,
    )  # fmt: skip


@dataclass(frozen=True)
class Built:
    folder: Path
    build_stdout: str
    summary: str  # python -m pedsafe_sumo.site --site FOLDER --no-build
    info: dict  # the site file
    net: ET.Element


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, Built]:
    root = tmp_path_factory.mktemp("real")
    out = {}
    for name, junction in HOSTING.items():
        folder = root / name
        proc = _build(name, junction, folder)
        assert proc.returncode == 0, (name, proc.stderr)
        summary = _run("-m", "pedsafe_sumo.site", "--site", str(folder), "--no-build")
        assert summary.returncode == 0, (name, summary.stderr)
        out[name] = Built(
            folder,
            proc.stdout,
            summary.stdout,
            json.loads((folder / f"{name}.site.json").read_text()),
            ET.parse(folder / f"{name}.net.xml").getroot(),
        )
    return out


def _hosted(built: Built) -> set[tuple[str, str]]:
    """(scenario, approach) of every combination the build summary says the site hosts."""
    own = built.info["rsu_watch_arm"]
    found = set()
    for line in built.build_stdout.splitlines():
        if not line.startswith("  ") or ": " not in line:
            continue
        head, verdict = line.strip().split(": ", 1)
        if head.endswith(" under approach staging"):
            continue  # the batches here run the default (fixed) staging
        name, _, arm = head.partition(" on approach ")
        if name in SCENARIOS and verdict.startswith("hosted"):
            found.add((name, arm or own))
    return found


def _osm_signals(name: str) -> list[tuple[float, float]]:
    root = ET.parse(DATA / name / f"{name}.osm").getroot()
    return [
        (float(n.get("lat")), float(n.get("lon")))
        for n in root.iter("node")
        if any(t.get("k") == "highway" and t.get("v") == "traffic_signals" for t in n.iter("tag"))
    ]


def _distance_m(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Equirectangular distance between two (lat, lon) points: exact enough within a few hundred metres."""
    north = math.radians(b[0] - a[0]) * 6371000.0
    east = math.radians(b[1] - a[1]) * 6371000.0 * math.cos(math.radians((a[0] + b[0]) / 2))
    return math.hypot(north, east)


def _lights_of_junction(net: ET.Element, junction: str) -> dict[str, set[str]]:
    """Traffic light id -> the junctions whose connections it controls, for the lights on `junction`'s
    connections (read from the net.xml: a connection through a junction passes its internal lane
    `:<junction>_...`, and names its light in `tl`)."""
    by_light: dict[str, set[str]] = {}
    for conn in net.iter("connection"):
        via, tl = conn.get("via"), conn.get("tl")
        if via and tl:
            by_light.setdefault(tl, set()).add(via[1:].rsplit("_", 2)[0])
    return {tl: nodes for tl, nodes in by_light.items() if junction in nodes}


def _incoming_edges(net: ET.Element, junction: str) -> list[ET.Element]:
    return [e for e in net.iter("edge") if e.get("to") == junction and not e.get("function")]


def _vehicle_lanes(edge: ET.Element) -> list[ET.Element]:
    return [lane for lane in edge.iter("lane") if lane.get("allow") != "pedestrian"]


def _bearing_deg(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Compass bearing from a to b in the network's x (east), y (north) plane."""
    return math.degrees(math.atan2(b[0] - a[0], b[1] - a[1])) % 360.0


# --- every hosting junction: built, signalised, its light on its links (default suite) --------------------


@pytest.mark.parametrize("name", list(HOSTING))
def test_the_junction_builds_signalised_and_one_light_controls_its_links(built, name):
    site = built[name]
    main = site.info["main_junction"]
    junction = next(j for j in site.net.iter("junction") if j.get("id") == main)
    assert junction.get("type").startswith("traffic_light")
    assert f"site {name}: main junction {main} (traffic_light, " in site.summary
    lights = _lights_of_junction(site.net, main)
    assert len(lights) == 1, lights  # one light stages the junction's signals
    (light,) = lights
    assert f"traffic light(s) on its connections: {light}" in site.summary
    assert any(t.get("id") == light for t in site.net.iter("tlLogic"))
    # Every vehicle movement through the junction (a connection from a road edge via the junction's
    # internal lane) and every crosswalk (a connection from one of its walking areas onto one of its
    # crossings) is controlled by that light.
    vehicle = [
        c
        for c in site.net.iter("connection")
        if not c.get("from").startswith(":") and (c.get("via") or "").startswith(f":{main}_")
    ]
    crosswalks = [
        c
        for c in site.net.iter("connection")
        if c.get("from").startswith(f":{main}_w") and c.get("to").startswith(f":{main}_c")
    ]
    assert vehicle and crosswalks
    assert {c.get("tl") for c in vehicle + crosswalks} == {light}
    assert _hosted(site)


def test_a_junction_with_diagonal_legs_names_them_by_their_bearing(built):
    site = built["seattle_westlake"]
    # Lenora Street leaves the junction towards the north-east (OSM way 490176742 at ~41 degrees) and the
    # south-west, 8th Avenue towards the south-east (~132 degrees); such legs, sharing a compass sector with
    # another, are named by the eight-point rose.
    legs = {
        line.split(":")[0].strip(): line.split(": ", 1)[1]
        for line in site.summary.splitlines()
        if line.startswith("    ") and " lane(s) in" in line
    }
    assert legs["NE"].startswith("Lenora Street")
    diagonal = [name for name in legs if name in ("NE", "SE", "SW", "NW")]
    assert len(diagonal) >= 2, legs
    # Independently from the network: an edge entering the junction group from the NE leg has its far end at
    # a bearing within 22.5 degrees of 45.
    node_xy = {j.get("id"): (float(j.get("x")), float(j.get("y"))) for j in site.net.iter("junction")}
    edges = {e.get("id"): e for e in site.net.iter("edge")}
    ne_edges = site.info["approaches"]["NE"]
    junction = ne_edges["junction"]
    bearings = [
        _bearing_deg(node_xy[junction], tuple(map(float, lane.get("shape").split()[0].split(","))))
        for e in _incoming_edges(site.net, junction)
        if e.get("id") in edges
        for lane in _vehicle_lanes(e)[:1]
    ]
    assert any(abs(b - 45.0) < 22.5 for b in bearings), bearings
    assert {arm for _, arm in _hosted(site)} >= {"NE"}


@pytest.mark.parametrize("name", ["seattle_9th_50th", "aguascalientes_convencion"])
def test_signals_netconvert_joins_are_one_light_over_several_nodes(built, name):
    site = built[name]
    # The clip maps two or more signal nodes near the junction (within 100 m of the one nearest the centre).
    signals = _osm_signals(name)
    centre = tuple(map(float, HOSTING[name].centre.split(",")))
    nearest = min(signals, key=lambda s: _distance_m(s, centre))
    assert sum(_distance_m(s, nearest) <= 100.0 for s in signals) >= 2
    # netconvert joined them: the junction's one light (joinedS_...) controls connections through two or
    # more traffic-light junctions of the network.
    ((light, nodes),) = _lights_of_junction(site.net, site.info["main_junction"]).items()
    assert light.startswith("joinedS_") and len(nodes) >= 2, (light, nodes)
    types = {j.get("id"): j.get("type") for j in site.net.iter("junction")}
    assert all(types[node].startswith("traffic_light") for node in nodes)


def test_a_t_junction_is_staged_on_a_through_road_not_on_its_stem(built):
    site = built["copenhagen_allegade"]
    main = site.info["main_junction"]
    assert "  3 arms:" in site.summary
    # The stem (Frederiksberg Alle, from the east) has no straight movement: every connection of its lanes
    # turns (SUMO's dir "l" or "r"), read from the net.xml.
    incoming = _incoming_edges(site.net, main)
    straight_from = {
        c.get("from") for c in site.net.iter("connection") if c.get("dir") == "s" and c.get("via")
    }
    stems = [e for e in incoming if e.get("id") not in straight_from]
    assert len(incoming) == 3 and len(stems) == 1
    assert stems[0].get("name") == "Frederiksberg Alle"
    # The site's own approach is a through road (crossing, jaywalking, background blending can be staged
    # there), so the batch without --approach runs on it.
    assert site.info["rsu_watch_arm"] in ("N", "S")
    hosted = _hosted(site)
    assert ("crossing", site.info["rsu_watch_arm"]) in hosted
    assert not any(arm == "E" for _, arm in hosted)
    # Every approach of this T has one vehicle lane.
    assert {len(_vehicle_lanes(e)) for e in incoming} == {1}


def test_one_lane_approaches_host_the_straight_scenarios(built):
    site = built["seattle_9th_50th"]
    lanes_in = {}
    for line in site.summary.splitlines():
        if line.startswith("    ") and " lane(s) in" in line:
            arm, rest = line.strip().split(": ", 1)
            lanes_in[arm] = int(rest.split(" - ")[1].split(" lane(s) in")[0])
    assert lanes_in["N"] == lanes_in["S"] == 1 and lanes_in["E"] == lanes_in["W"] == 2
    # From the net.xml: 9th Avenue Northeast enters the junction with one vehicle lane.
    ninth = [
        e
        for e in _incoming_edges(site.net, site.info["main_junction"])
        if e.get("name") == "9th Avenue Northeast"
    ]
    assert len(ninth) == 2 and all(len(_vehicle_lanes(e)) == 1 for e in ninth)
    hosted = _hosted(site)
    assert {("crossing", "N"), ("jaywalking", "N"), ("background_blending", "N")} <= hosted


def test_a_junction_whose_approaches_end_in_stub_edges_is_staged_along_their_chains(built):
    """netconvert keeps a node just before each stop line of aguascalientes_convencion: every road enters the
    junction on an edge 0.2 m long. The approaches are the chains of edges before those stubs
    (network/approach_chain.py): the south one (Avenida Convencion de 1914 Oriente) hosts crossing, and
    what it cannot host it refuses for a reason of its own, not the stub's length."""
    site = built["aguascalientes_convencion"]
    main = site.info["main_junction"]
    lengths = [float(_vehicle_lanes(e)[0].get("length")) for e in _incoming_edges(site.net, main)]
    assert lengths and max(lengths) < 1.0, lengths
    hosted = _hosted(site)
    assert ("crossing", "S") in hosted, site.build_stdout
    # The south stub 837164836#4 comes straight from 837164836#2 (42.5 m, read from the net.xml): the ego's
    # lane and the queue's are measured along both, so no vehicle is refused for the stub's 0.2 m.
    edges = {e.get("id"): e for e in site.net.iter("edge")}
    assert float(_vehicle_lanes(edges["837164836#2"])[0].get("length")) > 40.0
    south = [
        line
        for line in site.build_stdout.split("under approach staging")[0].splitlines()
        if line.startswith("  ") and line.strip().split(":")[0] in SCENARIOS
    ]
    assert south and not any("(0.2 m long)" in line for line in south), south
    # The east stub widens its road: 103039302#2's two vehicle lanes feed its four (read from the net.xml),
    # so no lane of it comes from a lane of its own and its approach is the stub alone, still refused.
    assert len(_vehicle_lanes(edges["103039302#2"])) == 2 and len(_vehicle_lanes(edges["837164834"])) == 4
    assert "crossing on approach E: NOT hosted" in site.build_stdout


# The combinations of aguascalientes_convencion that stand or fall with its chains (approach, scenario):
# crossing on S stages its occluder on the internal lane of the node before the stub.
AGUASCALIENTES_SEEDS = 2


@pytest.mark.slow
def test_every_hosted_combination_on_the_stub_junction_runs_with_its_signals(built, tmp_path):
    site = built["aguascalientes_convencion"]
    hosted = _hosted(site)
    out = tmp_path / "run"
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", "all", "--approach", "all",
        "--episodes", str(AGUASCALIENTES_SEEDS), "--workers", "1", "--site", str(site.folder),
        "--out", str(out), timeout=900,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert hosted <= set(zip(episodes["scenario"], episodes["approach"], strict=True))
    for _, seeds in episodes.groupby(["scenario", "approach"])["seed"]:
        assert seeds.nunique() == AGUASCALIENTES_SEEDS
    assert (episodes["status"] == "ok").all() and (episodes["error"] == "").all(), episodes["error"].tolist()
    assert (episodes["ego_signal"] != "none").all(), episodes[["scenario", "approach", "ego_signal"]]
    at_signals = episodes[episodes["scenario"] != "jaywalking"]
    assert (at_signals["ped_signal"] != "none").all(), at_signals[["scenario", "approach", "ped_signal"]]


@pytest.mark.slow
def test_sumo_puts_the_staged_vehicles_on_the_chains_lanes(built):
    """In SUMO, at the episode's first step, every staged vehicle of crossing on the south approach stands
    on the lane and at the position the staging gives (a vehicle on a node's internal lane moved there
    from where it was inserted), and the ego's route passes the stub."""
    from pedsafe_sumo.control.baseline import BaselineStack
    from pedsafe_sumo.network.sites import resolve_site
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sim.episode import EpisodeRunner

    site = resolve_site(str(built["aguascalientes_convencion"].folder))
    runner = EpisodeRunner(site, load_params(None), BaselineStack)
    spec = get_scenario("crossing").with_overrides({"approach": "S"})
    try:
        for seed in (0, 1):
            setup = runner.draw_setup(spec, seed)
            seen: dict[str, tuple[str, float]] = {}
            route: list[str] = []

            def first_step(api, row, seen=seen, route=route) -> None:
                if not seen:
                    for vid in api.vehicle.getIDList():
                        seen[vid] = (api.vehicle.getLaneID(vid), api.vehicle.getLanePosition(vid))
                    route.extend(api.vehicle.getRoute("ego"))

            runner.run(spec, "sv", seed, setup=setup, on_step=first_step)
            assert "837164836#4" in route and route.index("837164836#4") > 0, route
            assert any(v.internal_lane_id for v in setup.parked) or seed != 0
            for vehicle in (setup.ego, *setup.parked):
                lane, pos = seen[vehicle.vehicle_id]
                want_lane = vehicle.internal_lane_id or vehicle.lane_id
                want_pos = vehicle.internal_pos_m if vehicle.internal_lane_id else vehicle.front_pos_m
                # The ego has driven one step at its speed when the first step is logged.
                slack_m = vehicle.speed_mps * 0.05 + 1e-3
                assert lane == want_lane, (vehicle.vehicle_id, lane, want_lane)
                assert abs(pos - want_pos) <= slack_m, (vehicle.vehicle_id, pos, want_pos)
    finally:
        runner.close()


# --- left-hand traffic (default suite) ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def perth(tmp_path_factory) -> Built:
    """The left-hand junction built as the build finds it: no --lefthand, no driving_side in the data."""
    name, junction = LEFT_HAND
    folder = tmp_path_factory.mktemp("left") / name
    proc = _build(name, junction, folder)
    assert proc.returncode == 0, proc.stderr
    info = json.loads((folder / f"{name}.site.json").read_text())
    return Built(folder, proc.stdout, "", info, ET.parse(folder / f"{name}.net.xml").getroot())


def _left_of(pose: tuple[float, float, float], xy) -> float:
    """How far `xy` lies to the left of the line through pose (x, y, heading) along its heading [m]."""
    x, y, heading = pose
    return -(xy[0] - x) * math.sin(heading) + (xy[1] - y) * math.cos(heading)


def test_a_left_hand_junction_is_found_from_its_place_and_built_left_hand(perth, tmp_path):
    name, junction = LEFT_HAND
    osm_text = (DATA / name / f"{name}.osm").read_text(encoding="utf-8")
    assert "driving_side" not in osm_text  # the data does not say it: the place does (Australia)
    assert perth.net.get("lefthand") == "true"
    assert "traffic side: left-hand (the junction lies in Australia, where all traffic keeps left)" in (
        perth.build_stdout
    )
    assert TRAFFIC_SIDE_NOTE not in perth.build_stdout

    def network(folder: Path) -> str:  # the network from its <net> root on: the header has the build's time
        text = (folder / f"{name}.net.xml").read_text(encoding="utf-8")
        return text[text.index("<net ") :]

    net_text = network(perth.folder)
    # The user says so (--lefthand), or the data (driving_side=left, as Australia's boundary relation
    # carries it): the same network.
    told = _build(name, junction, tmp_path / "told", "--lefthand")
    assert told.returncode == 0 and "traffic side: left-hand (--lefthand)" in told.stdout, told.stderr
    assert network(tmp_path / "told") == net_text
    tagged = tmp_path / f"{name}.osm"
    tagged.write_text(
        osm_text.replace(
            '<tag k="name" v="Albany Highway"/>',
            '<tag k="name" v="Albany Highway"/><tag k="driving_side" v="left"/>',
            1,
        ),
        encoding="utf-8",
    )
    from_data = _build(name, junction, tmp_path / "data", osm=tagged)
    assert from_data.returncode == 0, from_data.stderr
    assert "traffic side: left-hand (the OSM data says driving_side=left)" in from_data.stdout


def test_on_the_left_hand_junction_the_kerb_lies_left_of_travel_on_every_approach(perth):
    """From the network's drawing: on every approach the sidewalk and the kerb-side lane (lane 0) lie left
    of the direction of travel, the median lane right of the kerb lane, the oncoming carriageway right."""
    site = resolve_site(str(perth.folder))
    net = read_net(str(site.file("net.xml")))
    arms = list(site_approaches(site))
    assert len(arms) >= 3
    for arm in arms:
        approach = load_approach(site, arm)
        assert approach.keep_side == -1.0
        pos_m = approach.lane_lengths_m[-1] / 2
        pose = approach.pose(len(approach.lane_ids) - 1, pos_m)  # the median lane
        kerb = approach.pose(0, approach.lane_lengths_m[0] / 2)
        sidewalk = approach.sidewalk_shape[len(approach.sidewalk_shape) // 2]
        assert _left_of(pose, sidewalk) > 0, arm
        if len(approach.lane_ids) > 1:
            assert _left_of(pose, kerb[:2]) > 0.5 * approach.lane_width_m, arm
        edge = net.getEdge(approach.edge_id)
        oncoming = [
            e
            for e in edge.getToNode().getOutgoing()
            if e.getToNode() == edge.getFromNode() and e.getFunction() == ""
        ]
        for other in oncoming:
            for lane in other.getLanes():
                if lane.allows("passenger"):
                    shape = lane.getShape()
                    assert _left_of(pose, shape[len(shape) // 2]) < 0, (arm, lane.getID())


def _footprint(approach, vehicle):
    """Corners of a staged vehicle, its front at its lane position, moved to the kerb by kerb_offset_m."""
    fx, fy, heading = approach.pose(approach.lane_ids.index(vehicle.lane_id), vehicle.front_pos_m)
    ux, uy = math.cos(heading), math.sin(heading)
    lx, ly = -uy, ux
    kerb_m = -approach.keep_side * vehicle.kerb_offset_m  # to the left of travel in left-hand traffic
    fx, fy = fx + kerb_m * lx, fy + kerb_m * ly
    rx, ry = fx - vehicle.size.length_m * ux, fy - vehicle.size.length_m * uy
    half = vehicle.size.width_m / 2
    return [(fx + half * lx, fy + half * ly), (fx - half * lx, fy - half * ly),
            (rx - half * lx, ry - half * ly), (rx + half * lx, ry + half * ly)]  # fmt: skip


def _crosses(p, q, corners) -> bool:
    def orient(u, v, w):
        return (v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0])

    return any(
        orient(p, q, a) * orient(p, q, b) < 0 and orient(a, b, p) * orient(a, b, q) < 0
        for a, b in zip(corners, corners[1:] + corners[:1])
    )


@pytest.mark.parametrize("name", ["crossing", "background_blending"])
def test_on_the_left_hand_junction_the_pedestrian_starts_at_the_kerb_hidden_as_the_scenario_says(perth, name):
    """Staged on every approach that hosts it: the pedestrian starts left of the ego (its kerb side), their
    path crosses the ego's lane, and a staged vehicle stands between them and the ego's front (crossing:
    the waiting queue hides them) or right behind them on the ego's line of sight (background_blending)."""
    site = resolve_site(str(perth.folder))
    arms = [arm or perth.info["rsu_watch_arm"] for scenario, arm in _hosted(perth) if scenario == name]
    assert arms, perth.build_stdout
    spec = get_scenario(name)
    checked = 0
    for arm in arms:
        approach = load_approach(site, arm)
        for seed in range(8):
            setup = draw_episode(spec, approach, seed, TRAITS, 8.0, np.random.default_rng(seed))
            index = approach.lane_ids.index(setup.ego.lane_id)
            front_m = setup.ego.front_pos_m + setup.ego.speed_mps * setup.pedestrian.start_delay_s
            eye = approach.pose(index, min(front_m, approach.lane_lengths_m[index]))
            start, end = setup.pedestrian.path_xy[0], setup.pedestrian.path_xy[-1]
            assert _left_of(eye, start) > 0 and _left_of(eye, end) < -approach.lane_width_m / 2, (arm, seed)
            corners = [_footprint(approach, v) for v in setup.parked]
            if name == "crossing":
                # While the ego is still behind the queue's head (its front behind the head's rear; on the
                # short one-lane approaches it can be beside it at the step-off) and within 50 m (as
                # tests/scenarios/test_staging.py), the queue stands between the ego and the pedestrian.
                head = setup.parked[0]
                if front_m < head.front_pos_m - head.size.length_m and math.dist(eye[:2], start) <= 50.0:
                    checked += 1
                    assert any(_crosses(eye[:2], start, c) for c in corners), (arm, seed)
            else:
                ux, uy = start[0] - eye[0], start[1] - eye[1]
                norm = math.hypot(ux, uy)
                beyond = (start[0] + 3.0 * ux / norm, start[1] + 3.0 * uy / norm)
                checked += 1
                assert any(_crosses(start, beyond, c) for c in corners), (arm, seed)
    assert checked >= 8 * len(arms) // 2


# --- a plain SUMO network without geo-reference ------------------------------------------------------------
# The sixth junction: a SUMO network without geo-reference, built with tools/build_network.py --net NET.
# Its tests go here, as for the OSM junctions above: it builds, its light controls the junction's links,
# and every hosted combination runs (test_every_hosted_combination_runs_with_signals_and_roadside_detection).


# --- every hosted combination runs (slow) ------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("name", [name for name in HOSTING if name != "aguascalientes_convencion"])
def test_every_hosted_combination_runs_with_signals_and_roadside_detection(built, tmp_path, name):
    site = built[name]
    hosted = _hosted(site)
    out = tmp_path / "run"
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", "all", "--approach", "all", "--episodes", "1",
        "--workers", "1", "--site", str(site.folder), "--out", str(out), timeout=900,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    episodes = pd.read_parquet(out / "episodes.parquet")
    # Every combination the build hosts runs. The build stages 20 seeds of each combination, the batch the
    # seeds it runs, so a combination one of whose 20 seeds cannot be staged may still run here.
    assert hosted <= set(zip(episodes["scenario"], episodes["approach"], strict=True))
    for _, conditions in episodes.groupby(["scenario", "approach"])["condition"]:
        assert sorted(conditions) == ["sv", "v2i"]  # one pair per combination
    assert (episodes["status"] == "ok").all() and (episodes["error"] == "").all(), episodes["error"].tolist()
    # The signals are staged: the ego has its light's state at the conflict, and so has the pedestrian
    # everywhere but mid-block (jaywalking crosses where no signal stands: docs/engine.md).
    assert (episodes["ego_signal"] != "none").all(), episodes[["scenario", "approach", "ego_signal"]]
    at_signals = episodes[episodes["scenario"] != "jaywalking"]
    assert (at_signals["ped_signal"] != "none").all(), at_signals[["scenario", "approach", "ped_signal"]]
    # Under V2I the roadside camera is the first to detect the pedestrian in some episode.
    v2i = episodes[episodes["condition"] == "v2i"]
    assert (v2i["detected_by"] == "roadside").any(), v2i["detected_by"].tolist()


@pytest.mark.slow
def test_every_hosted_combination_on_the_left_hand_junction_runs_on_the_kerb_side(perth, tmp_path):
    """The batch over every combination the left-hand site hosts: it says once how the scenarios' names read
    there, no error rows, the signals staged, and in SUMO's own positions at the first step the ego's lane
    lies left of the road's centre line (the oncoming carriageway to its right) with the pedestrian on the
    kerb side (left of the ego), and later the pedestrian on the ego's lane."""
    site = resolve_site(str(perth.folder))
    hosted = _hosted(perth)
    out = tmp_path / "run"
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", "all", "--approach", "all", "--episodes", "2",
        "--workers", "1", "--keep-logs", "all", "--site", str(perth.folder), "--out", str(out), timeout=900,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("keeps left (left-hand traffic): every scenario is staged mirrored") == 1
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert hosted and hosted <= set(zip(episodes["scenario"], episodes["approach"], strict=True))
    assert (episodes["error"] == "").all(), episodes["error"].tolist()
    assert (episodes["ego_signal"] != "none").all(), episodes[["scenario", "approach", "ego_signal"]]
    # Under V2I the roadside camera is the first to detect the pedestrian in some episode.
    v2i = episodes[episodes["condition"] == "v2i"]
    assert (v2i["detected_by"] == "roadside").any(), v2i["detected_by"].tolist()
    net = read_net(str(site.file("net.xml")))
    # A step log per unit and chunk: SCENARIO@ARM-....parquet.
    steps = pd.concat(
        pd.read_parquet(f).assign(approach=f.name.split("@")[1].split("-")[0])
        for f in sorted((out / "steplogs").glob("*@*.parquet"))
    )
    checked = 0
    for (scenario, arm, _, seed), log in steps.groupby(["scenario", "approach", "condition", "seed"]):
        log = log.sort_values("time_s")
        approach = load_approach(site, arm)
        first = log.iloc[0]
        ego = (first["ego_x_m"], first["ego_y_m"], first["ego_yaw_rad"])
        edge = net.getEdge(approach.edge_id)
        oncoming = [
            lane.getShape()
            for e in edge.getToNode().getOutgoing()
            if e.getToNode() == edge.getFromNode() and e.getFunction() == ""
            for lane in e.getLanes()
            if lane.allows("passenger")
        ]
        assert oncoming and all(_left_of(ego, s[len(s) // 2]) < 0 for s in oncoming), (scenario, seed)
        walked = log[log["ped_x_m"].notna()]
        assert _left_of(ego, (walked.iloc[0]["ped_x_m"], walked.iloc[0]["ped_y_m"])) > 0, (scenario, seed)
        # The ego's lane: the approach lane its first position lies on. The pedestrian starts beside it on the
        # kerb side and reaches its centre line, continued straight over the crosswalk at the stop line.
        lane = min(
            range(len(approach.lane_ids)),
            key=lambda k: abs(_left_of(approach.pose(k, approach.lane_lengths_m[k] - 1.0), ego[:2])),
        )
        stop_line = approach.pose(lane, approach.lane_lengths_m[lane] - 1.0)
        offsets = [_left_of(stop_line, p) for p in zip(walked["ped_x_m"], walked["ped_y_m"], strict=True)]
        half_m = approach.lane_width_m / 2
        assert offsets[0] > half_m and min(abs(o) for o in offsets) < half_m, (scenario, seed, offsets[0])
        checked += 1
    assert checked == len(episodes)
