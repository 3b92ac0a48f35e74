"""An approach whose incoming edge is a stub (network/approach_chain.py, scenarios/chained.py): a plain
signalised cross built by netconvert from node and edge files, once as it is and once with a node 10.7 m
south of the centre, which leaves the south approach entering the junction on an edge 0.3 m long. The
approach is the chain of edges before it: the same length as without the split, its route through the
stub, the ego staged on the chain's lane its front stands on."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.approach_chain import approach_chain
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.sumo_net import read_net

BUILD_TOOL = REPO_ROOT / "tools" / "build_network.py"
#: netconvert gives the node's straight internal lanes its minimum length, 0.1 m (read from the split
#: network below): the chain is that much longer than the unsplit edge. The tolerance covers it [m].
TOLERANCE_M = 0.25


def _netconvert(folder: Path, name: str, split_y: float | None) -> Path:
    nodes = '<node id="C" x="0" y="0" type="traffic_light"/>' + "".join(
        f'<node id="{a}" x="{x}" y="{y}"/>'
        for a, x, y in (("N", 0, 200), ("E", 200, 0), ("S", 0, -200), ("W", -200, 0))
    )
    edges = "".join(
        f'<edge id="C{a}" from="C" to="{a}" numLanes="2" speed="13.89"/>' for a in "NESW"
    ) + "".join(f'<edge id="{a}C" from="{a}" to="C" numLanes="2" speed="13.89"/>' for a in "NEW")
    if split_y is None:
        edges += '<edge id="SC" from="S" to="C" numLanes="2" speed="13.89"/>'
    else:
        nodes += f'<node id="P" x="0" y="{split_y}" type="priority"/>'
        edges += (
            '<edge id="SP" from="S" to="P" numLanes="2" speed="13.89"/>'
            '<edge id="SC" from="P" to="C" numLanes="2" speed="13.89"/>'
        )
    (folder / f"{name}.nod.xml").write_text(f"<nodes>{nodes}</nodes>")
    (folder / f"{name}.edg.xml").write_text(f"<edges>{edges}</edges>")
    env = {**os.environ, "SUMO_HOME": str(Path(sumo_binary("netconvert")).parent.parent)}
    subprocess.run(
        [sumo_binary("netconvert"), "-n", f"{name}.nod.xml", "-e", f"{name}.edg.xml",
         "--sidewalks.guess", "true", "--crossings.guess", "true", "-o", f"{name}.net.xml"],
        cwd=folder, check=True, capture_output=True, env=env,
    )  # fmt: skip
    return folder / f"{name}.net.xml"


@pytest.fixture(scope="module")
def sites(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("chain")
    out = {}
    for name, split_y in (("plain", None), ("split", -10.7)):
        net = _netconvert(root, name, split_y)
        proc = subprocess.run(
            [sys.executable, str(BUILD_TOOL), "--net", str(net), "--junction", "C", "--rsu-watch", "S",
             "--out", str(root / f"{name}_site")],
            capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
        )  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        out[name] = root / f"{name}_site"
    return out


def _lane_length_m(net_file: Path, lane_id: str) -> float:
    return read_net(str(net_file)).getLane(lane_id).getLength()


def test_the_split_leaves_a_stub_before_the_stop_line(sites):
    split = resolve_site(str(sites["split"]))
    # Read from the network netconvert wrote: the south approach enters the junction on 0.3 m.
    assert _lane_length_m(split.file("net.xml"), "SC_1") == pytest.approx(0.3, abs=0.005)


def test_the_chain_looks_past_the_stub_and_stops_at_the_network_edge(sites):
    net = read_net(str(resolve_site(str(sites["split"])).file("net.xml")), withInternal=True)
    chain = approach_chain(net, net.getEdge("SC"))
    assert chain.edges == ("SP", "SC")
    assert [lane.lane_id for lane in chain.lanes[0]][0] == "SP_1"
    assert chain.lanes[0][-1].lane_id == "SC_1"
    # A non-stub edge is its own chain.
    plain = read_net(str(resolve_site(str(sites["plain"])).file("net.xml")), withInternal=True)
    assert approach_chain(plain, plain.getEdge("SC")).edges == ("SC",)


def test_the_approach_over_a_stub_is_as_long_as_without_the_split(sites):
    from pedsafe_sumo.scenarios.geometry import load_approach

    plain = load_approach(resolve_site(str(sites["plain"])), "S")
    split = load_approach(resolve_site(str(sites["split"])), "S")
    # The plain approach's length, read from its network file.
    plain_m = _lane_length_m(resolve_site(str(sites["plain"])).file("net.xml"), "SC_1")
    assert plain.lane_lengths_m[0] == pytest.approx(plain_m)
    for k in range(len(split.lane_ids)):
        assert abs(split.lane_lengths_m[k] - plain_m) <= TOLERANCE_M, (k, split.lane_lengths_m)
    assert split.edge_id == "SC" and split.through_route[:2] == ("SP", "SC")
    assert plain.through_route[0] == "SC"


def test_the_ego_stands_on_the_chains_lane_its_route_through_the_stub(sites):
    from pedsafe_sumo.control.baseline import BaselineStack
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sim.episode import EpisodeRunner

    site = resolve_site(str(sites["split"]))
    runner = EpisodeRunner(site, load_params(None), BaselineStack)
    try:
        for seed in range(3):
            setup = runner.draw_setup(get_scenario("crossing").with_overrides({"approach": "S"}), seed)
            ego = setup.ego
            # Its front is tens of metres before the stop line: on SP, the route from there through the stub.
            assert ego.lane_id.startswith("SP_") and ego.approach_lane_id.startswith("SC_")
            assert 0.0 <= ego.front_pos_m <= _lane_length_m(site.file("net.xml"), ego.lane_id)
            assert setup.ego_route[:2] == ("SP", "SC")
            for vehicle in setup.parked:
                assert vehicle.route[-1] == "SC" and vehicle.route[0] == vehicle.lane_id.rsplit("_", 1)[0]
    finally:
        runner.close()


@pytest.mark.slow
def test_a_crossing_batch_runs_on_the_split_approach(sites, tmp_path):
    import pandas as pd

    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--site", str(sites["split"]), "--scenario", "crossing",
         "--approach", "S", "--episodes", "2", "--workers", "1", "--out", str(tmp_path / "run")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=900,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    episodes = pd.read_parquet(tmp_path / "run" / "episodes.parquet")
    assert len(episodes) == 4 and (episodes["status"] == "ok").all(), episodes["error"].tolist()
    assert (episodes["ego_signal"] != "none").all()
