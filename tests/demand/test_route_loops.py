"""The generator offers no route that loops: on a junction without u-turns (netconvert's
--no-turnarounds.tls), the shortest path to the exit on one's own arm runs through the junction, round a
dead end's turnaround and back through the junction; it was offered as a left or right turn."""

from __future__ import annotations

import subprocess
from pathlib import Path

from pedsafe_sumo.demand.site import load_site
from pedsafe_sumo.sumo_binaries import sumo_binary

DATA = Path(__file__).parent / "data"


def _cross_without_uturns_at_the_signal(tmp_path: Path) -> Path:
    out = tmp_path / "cross_no_tls_uturn.net.xml"
    subprocess.run(
        [sumo_binary("netconvert"), "-c", str(DATA / "cross.netccfg"), "--no-turnarounds", "false",
         "--no-turnarounds.tls", "true", "-o", str(out)],
        check=True, capture_output=True, cwd=DATA,
    )  # fmt: skip
    return out


def test_no_route_visits_a_junction_twice(tmp_path):
    net_file = _cross_without_uturns_at_the_signal(tmp_path)
    site = load_site("cross", net_file=net_file)
    net = site.net
    # The loop exists in the network: from N's entry, the exit back north is reachable only round the
    # east arm's dead-end turnaround (N2C, C2E, E2C, C2N), SUMO's own shortest path.
    path, _ = net.getShortestPath(net.getEdge("N2C"), net.getEdge("C2N"), vClass="passenger")
    assert [e.getID() for e in path if not e.getID().startswith(":")] == ["N2C", "C2E", "E2C", "C2N"]
    routes = {r.edges for lane in site.entering_lanes for rs in lane.routes_by_movement.values() for r in rs}
    assert routes
    for edges in routes:
        nodes = [net.getEdge(e).getToNode().getID() for e in edges]
        assert len(nodes) == len(set(nodes)), edges
    # Each entry still reaches the three other arms (left, straight, right), never its own.
    for entry in ("N2C", "E2C", "S2C", "W2C"):
        exits = {edges[-1] for edges in routes if edges[0] == entry}
        assert len(exits) == 3 and f"C2{entry[0]}" not in exits, (entry, exits)
