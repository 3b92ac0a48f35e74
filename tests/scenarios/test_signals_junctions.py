"""The junction's traffic light is the one that controls its links, whatever netconvert named it.

Each network is built here by netconvert from a plain description (a four-arm junction C, two-lane
arms N, E, S, W; with a second junction D 30 m east of C for the lights that span two junctions), the
way netconvert builds real junctions: stop-line signals joined (`--tls.join`: joinedS_C_D), a light
guessed over a cluster (`--tls.guess.joining`: joinedG_C_D), signals guessed at the stop lines
(`--tls.guess-signals`: GS_C), one program shared by two nodes (`tl="shared"`), and a junction whose
links two lights control. The expected light and link indices are read from the written .net.xml with
ElementTree (the `tl` and `linkIndex` of each <connection>), not with sumolib.
"""

from __future__ import annotations

import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pedsafe_sumo.scenarios.signals import SignalStagingError, load_junction_signals
from pedsafe_sumo.sumo_binaries import sumo_binary

ARMS = {"N": (0, 200), "S": (0, -200), "W": (-200, 0)}
PEDESTRIANS = [
    "--sidewalks.guess", "--sidewalks.guess.max-speed", "30", "--crossings.guess", "--walkingareas",
    "--tls.default-type", "static",
]  # fmt: skip


def _nodes(types: dict[str, str], extra: dict[str, str] | None = None, two: bool = True) -> str:
    """C at the origin, the arm ends, and D 30 m east (two junctions) or E 200 m east (one)."""
    extra = extra or {}
    points = {"C": (0, 0), **ARMS}
    points.update({"D": (30, 0), "E": (230, 0), "DN": (30, 200)} if two else {"E": (200, 0)})
    rows = []
    for name, (x, y) in points.items():
        rows.append(
            f'<node id="{name}" x="{x}" y="{y}" type="{types.get(name, "priority")}" {extra.get(name, "")}/>'
        )
    return "<nodes>" + "".join(rows) + "</nodes>"


def _edges(two: bool = True) -> str:
    pairs = [("N", "C"), ("S", "C"), ("W", "C")]
    pairs += [("D", "C"), ("E", "D"), ("DN", "D")] if two else [("E", "C")]
    rows = []
    for a, b in pairs:
        lanes = 1 if "DN" in (a, b) else 2
        rows.append(f'<edge id="{a}{b}" from="{a}" to="{b}" numLanes="{lanes}" speed="16.67"/>')
        rows.append(f'<edge id="{b}{a}" from="{b}" to="{a}" numLanes="{lanes}" speed="16.67"/>')
    return "<edges>" + "".join(rows) + "</edges>"


def _netconvert(folder: Path, name: str, nodes: str, edges: str, *options: str) -> Path:
    (folder / f"{name}.nod.xml").write_text(nodes)
    (folder / f"{name}.edg.xml").write_text(edges)
    net = folder / f"{name}.net.xml"
    env = {**os.environ, "SUMO_HOME": str(Path(sumo_binary("netconvert")).parent.parent)}
    subprocess.run(
        [sumo_binary("netconvert"), "-n", f"{name}.nod.xml", "-e", f"{name}.edg.xml", *PEDESTRIANS, *options,
         "-o", net.name],
        cwd=folder, check=True, capture_output=True, env=env,
    )  # fmt: skip
    return net


@pytest.fixture(scope="module")
def nets(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("signal_nets")
    lights = {"C": "traffic_light", "D": "traffic_light"}
    built = {
        "joinedS": _netconvert(
            folder, "joined", _nodes(lights), _edges(), "--tls.join", "--tls.join-dist", "40"
        ),
        "joinedG": _netconvert(
            folder,
            "guessed",
            _nodes({}),
            _edges(),
            "--tls.guess",
            "--tls.guess.threshold",
            "10",
            "--tls.guess.joining",
        ),
        "shared": _netconvert(
            folder, "shared", _nodes(lights, {"C": 'tl="shared"', "D": 'tl="shared"'}), _edges()
        ),
        "own": _netconvert(folder, "own", _nodes(lights, {"C": 'tl="A"', "D": 'tl="B"'}), _edges()),
        "unsignalised": _netconvert(folder, "plain", _nodes({}, two=False), _edges(two=False)),
    }
    # Signals mapped at the stop lines, 15 m before C on each arm (as OSM maps them).
    stops = {"sN": (0, 15), "sS": (0, -15), "sW": (-15, 0), "sE": (15, 0)}
    nodes = "".join(f'<node id="{n}" x="{x}" y="{y}" type="traffic_light"/>' for n, (x, y) in stops.items())
    nodes += '<node id="C" x="0" y="0" type="priority"/>'
    nodes += "".join(f'<node id="{a}" x="{x}" y="{y}"/>' for a, (x, y) in {**ARMS, "E": (200, 0)}.items())
    edges = ""
    for arm, stop in (("N", "sN"), ("S", "sS"), ("W", "sW"), ("E", "sE")):
        edges += f'<edge id="{arm}{stop}" from="{arm}" to="{stop}" numLanes="2" speed="16.67"/>'
        edges += f'<edge id="{arm}C" from="{stop}" to="C" numLanes="2" speed="16.67"/>'
        edges += f'<edge id="C{arm}" from="C" to="{arm}" numLanes="2" speed="16.67"/>'
    built["GS"] = _netconvert(
        folder, "stoplines", f"<nodes>{nodes}</nodes>", f"<edges>{edges}</edges>",
        "--tls.guess-signals", "--tls.guess-signals.dist", "25",
    )  # fmt: skip
    # Junction C's north approach moved to light B (D's), with link indices 14-17 added to B's program;
    # C's crosswalks stay A's: the ego's link and the pedestrian's crossing have different lights.
    root = ET.parse(built["own"]).getroot()
    logic = next(t for t in root.iter("tlLogic") if t.get("id") == "B")
    width = len(logic.find("phase").get("state"))
    north = [c for c in root.iter("connection") if c.get("from") == "NC" and c.get("tl") == "A"]
    north = [c for c in north if c.get("to") != "CN"]  # the U-turn stays A's
    phases = "".join(
        f'<phase duration="{p.get("duration")}" state="{p.get("state")}{"G" * len(north)}"/>'
        for p in logic.iter("phase")
    )
    moved = "".join(
        f'<connection from="NC" to="{c.get("to")}" fromLane="{c.get("fromLane")}" toLane="{c.get("toLane")}" '
        f'tl="B" linkIndex="{width + i}"/>'
        for i, c in enumerate(north)
    )
    program = f'<tlLogic id="B" type="static" programID="0" offset="0">{phases}</tlLogic>'
    (folder / "two.tll.xml").write_text(f"<tlLogics>{program}{moved}</tlLogics>")
    subprocess.run(
        [sumo_binary("netconvert"), "-s", "own.net.xml", "-i", "two.tll.xml", "-o", "two.net.xml"],
        cwd=folder, check=True, capture_output=True,
    )  # fmt: skip
    built["two"] = folder / "two.net.xml"
    return built


def _net_links(net: Path, junction: str) -> dict[tuple[str, str], tuple[str, int]]:
    """(from lane, to edge) -> (tl, linkIndex) of every controlled connection through `junction`, from
    the XML: a vehicle connection's from edge ends at the junction (its <edge to=...>); a crossing's
    connection comes from a walking area of the junction (:<junction>_w<k>)."""
    root = ET.parse(net).getroot()
    ends_at = {e.get("id"): e.get("to") for e in root.iter("edge") if e.get("to")}
    links = {}
    for c in root.iter("connection"):
        through = ends_at.get(c.get("from")) == junction or c.get("from", "").startswith(f":{junction}_w")
        if through and c.get("tl"):
            links[(f"{c.get('from')}_{c.get('fromLane')}", c.get("to"))] = (
                c.get("tl"),
                int(c.get("linkIndex")),
            )
    return links


@pytest.mark.parametrize(
    ("case", "junction", "light"),
    [
        ("joinedS", "C", "joinedS_C_D"),
        ("joinedS", "D", "joinedS_C_D"),
        ("joinedG", "C", "joinedG_C_D"),
        ("GS", "C", "GS_C"),
        ("shared", "C", "shared"),
        ("shared", "D", "shared"),
        ("own", "C", "A"),
    ],
)
def test_the_light_is_the_one_on_the_junctions_connections(nets, case, junction, light):
    net = nets[case]
    links = _net_links(net, junction)
    assert links and {tl for tl, _ in links.values()} == {light}  # the network is what the case says
    signals = load_junction_signals(net, junction)
    assert signals.program.tls_id == light
    logic = next(t for t in ET.parse(net).getroot().iter("tlLogic") if t.get("id") == light)
    assert signals.program.states == tuple(p.get("state") for p in logic.iter("phase"))
    assert signals.program.durations_s == tuple(float(p.get("duration")) for p in logic.iter("phase"))
    for (from_lane, to), (_, index) in links.items():
        if to.startswith(":"):
            assert signals.crossing_link(to) == index
        else:
            assert signals.vehicle_link(from_lane, to) == index


def test_a_light_over_two_junctions_numbers_their_links_apart(nets):
    """joinedS_C_D: C's and D's links are indices of one program, so no index is both's."""
    c_links = {index for _, index in _net_links(nets["joinedS"], "C").values()}
    d_links = {index for _, index in _net_links(nets["joinedS"], "D").values()}
    assert c_links and d_links and not c_links & d_links
    signals = load_junction_signals(nets["joinedS"], "C")
    # Every link of the light is read, D's too (a movement through the neighbour stages in the program).
    assert set(signals.vehicle_links.values()) | set(signals.crossing_links.values()) == c_links | d_links


def test_a_junction_two_lights_control_is_refused_in_one_line(nets):
    links = _net_links(nets["two"], "C")
    assert {tl for tl, _ in links.values()} == {"A", "B"}
    with pytest.raises(SignalStagingError) as refused:
        load_junction_signals(nets["two"], "C")
    message = str(refused.value)
    assert "\n" not in message and "controlled by 2 traffic lights" in message
    assert "A " in message and "B 4 links" in message and "has no traffic light" not in message


def test_an_unsignalised_junction_has_no_traffic_light(nets):
    assert _net_links(nets["unsignalised"], "C") == {}
    with pytest.raises(SignalStagingError, match="has no traffic light"):
        load_junction_signals(nets["unsignalised"], "C")


def test_a_traffic_light_junction_without_controlled_links_is_not_taken_for_unsignalised(nets, tmp_path):
    """A network edited by hand: C keeps its type traffic_light, its connections lose their tl. That is
    a broken signal, refused, never staged as a junction without one (the message does not say "has no
    traffic light", which the engine reads as unsignalised)."""
    tree = ET.parse(nets["own"])
    for c in tree.getroot().iter("connection"):
        if c.get("tl") == "A":
            del c.attrib["tl"]
            del c.attrib["linkIndex"]
    edited = tmp_path / "edited.net.xml"
    tree.write(edited)
    with pytest.raises(SignalStagingError) as refused:
        load_junction_signals(edited, "C")
    assert "traffic-light junction" in str(refused.value)
    assert "has no traffic light" not in str(refused.value)
