"""The meeting rules on a network netconvert builds here: a corner C with arms to W and S (a sidewalk on
each, a crossing over the S arm, walking areas at the corners) and an arm to E without sidewalk whose
two lanes are a shared lane (index 0, pedestrians allowed) and a lane for vehicles only (index 1).

By SUMO's rules, worked out from the network's permissions and edge functions:
- a person on the crossing and a vehicle on the turn into S: they may meet (crossing);
- a person on a walking area: no vehicle lane is its foe (walkingarea, not a meeting);
- a person on edge WC, which has a sidewalk, a vehicle on its road lane WC_1 (sidewalk, not a meeting);
- a vehicle on the shared lane EC_0 with a person on EC (shared, a meeting);
- a vehicle on EC_1 (no pedestrians) with a person walking on EC, which has no sidewalk (road, a meeting);
- ids the network does not have: not judged.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from pedsafe_sumo.conflicts.meeting import MeetingRules
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.sumo_net import read_net

NODES = """<nodes>
    <node id="C" x="0" y="0" type="priority"/>
    <node id="W" x="-100" y="0" type="priority"/>
    <node id="S" x="0" y="-100" type="priority"/>
    <node id="E" x="100" y="0" type="priority"/>
</nodes>"""
EDGES = """<edges>
    <edge id="WC" from="W" to="C" numLanes="1" speed="13.89"/>
    <edge id="CW" from="C" to="W" numLanes="1" speed="13.89"/>
    <edge id="CS" from="C" to="S" numLanes="1" speed="13.89"/>
    <edge id="SC" from="S" to="C" numLanes="1" speed="13.89"/>
    <edge id="EC" from="E" to="C" numLanes="2" speed="13.89">
        <lane index="1" disallow="pedestrian"/>
    </edge>
</edges>"""


@pytest.fixture(scope="module")
def rules(tmp_path_factory):
    folder = tmp_path_factory.mktemp("meeting")
    (folder / "m.nod.xml").write_text(NODES)
    (folder / "m.edg.xml").write_text(EDGES)
    env = {**os.environ, "SUMO_HOME": str(Path(sumo_binary("netconvert")).parent.parent)}
    subprocess.run(
        [sumo_binary("netconvert"), "-n", "m.nod.xml", "-e", "m.edg.xml", "--sidewalks.guess",
         "--sidewalks.guess.exclude", "EC", "--crossings.guess", "--walkingareas", "-o", "m.net.xml"],
        cwd=folder, check=True, capture_output=True, env=env,
    )  # fmt: skip
    net = read_net(folder / "m.net.xml", withInternal=True, withPedestrianConnections=True)
    return net, MeetingRules(net)


def edge_of(net, function: str) -> list[str]:
    return sorted(e.getID() for e in net.getEdges(withInternal=True) if e.getFunction() == function)


def test_the_rules(rules):
    net, meet = rules
    crossings, walkingareas = edge_of(net, "crossing"), edge_of(net, "walkingarea")
    assert crossings and walkingareas
    turn = net.getEdge("WC").getLanes()[-1].getOutgoing()[0].getViaLaneID()  # from WC's road lane
    assert turn.startswith(":C_")
    assert [lane.allows("pedestrian") for lane in net.getEdge("WC").getLanes()] == [True, False]
    assert meet(turn, crossings[0]) == ("crossing", True)
    assert meet(turn, walkingareas[0]) == ("walkingarea", False)
    assert meet("WC_1", "WC") == ("sidewalk", False)
    assert meet("EC_0", "EC") == ("shared", True)
    assert meet("EC_1", "EC") == ("road", True)
    assert meet("nowhere_0", "WC") == ("", None) and meet("WC_1", "nowhere") == ("", None)
