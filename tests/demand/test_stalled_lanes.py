"""demand.validate names an entering lane that stopped inserting while vehicles waited (the route files
insert at departSpeed="desired"; a very fast draw can block its lane for the rest of the run, and every
vehicle behind it then counted as backlog, as if the road were full)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import pytest

from pedsafe_sumo.demand import validate
from pedsafe_sumo.demand.site import load_site
from pedsafe_sumo.params import load_params, with_overrides
from pedsafe_sumo.sumo_net import read_net

STRAIGHT_NET = Path(__file__).parent / "data" / "straight.net.xml"


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_a_lane_that_stopped_inserting_is_named_and_a_busy_one_is_not(tmp_path):
    routes = _write(
        tmp_path / "r.rou.xml",
        """<routes>
  <route id="ra" edges="A X"/><route id="rb" edges="B X"/>
  <vehicle id="a0" route="ra" depart="10" departLane="0" speedFactor="1.0"/>
  <vehicle id="a1" route="ra" depart="20" departLane="0" speedFactor="2.0"/>
  <vehicle id="a2" route="ra" depart="30" departLane="0" speedFactor="0.5"/>
  <vehicle id="c0" route="ra" depart="10" departLane="1" speedFactor="1.0"/>
  <vehicle id="c1" route="ra" depart="990" departLane="1" speedFactor="1.0"/>
  <vehicle id="b0" route="rb" depart="100" departLane="0" speedFactor="1.5"/>
  <vehicle id="late" route="rb" depart="1200" departLane="0" speedFactor="1.0"/>
</routes>""",
    )
    tripinfo = _write(
        tmp_path / "t.xml",
        '<tripinfos><tripinfo id="a0" depart="10.50"/><tripinfo id="c0" depart="12.00"/></tripinfos>',
    )
    stalled = validate.stalled_lanes(routes, tripinfo, 1000.0, {"A_0": 10.0, "A_1": 10.0, "B_0": 8.0})
    # A_0: a0 in at 10.5, then nothing for 989.5 s while a1 (due at 20, 2.0 x 10 m/s) and a2 wait.
    # A_1: c1 is due 10 s before the end: waiting, not stalled. B_0: b0 never inserted; "late" not due.
    found = [
        (s.lane_id, s.last_insertion_s, s.waiting, s.head_id, s.head_due_s, s.head_desired_mps)
        for s in stalled
    ]
    assert found == [("A_0", 10.5, 2, "a1", 20.0, 20.0), ("B_0", -1.0, 1, "b0", 100.0, 12.0)]
    assert "after 10 s while 2 vehicles waited" in stalled[0].line()
    assert "nothing inserted at all" in stalled[1].line()


@pytest.mark.slow
def test_validate_names_the_lane_a_fast_driver_blocks_on_the_straight_road(tmp_path):
    # Seed 6 of the calibrated law (more fast draws than the fit) on the straight test road, 20 minutes at
    # the paper's rate: one lane is blocked (found by running seeds 1-8; the others stall nowhere).
    args = SimpleNamespace(
        site="straight", net=STRAIGHT_NET, duration=1200.0, seed=6, params=None, warmup=300.0
    )
    params = with_overrides(load_params(), {"traffic.desired_speed_law": "calibrated"})
    site = load_site("straight", net_file=STRAIGHT_NET)
    run = validate.run_once(args, site, params, 0.1742, "configured", tmp_path)
    assert len(run.stalled) == 1
    stall = run.stalled[0]
    # From SUMO's own tripinfo output and the route file, read here: the lane's last insertion, and the
    # first vehicle still waiting, with its desired speed = speed factor x the lane's limit in the net.
    departs = [
        float(t.get("depart"))
        for t in ET.parse(tmp_path / "tripinfo.xml").getroot().iter("tripinfo")
        if t.get("departLane") == stall.lane_id
    ]
    assert max(departs) == pytest.approx(stall.last_insertion_s)
    assert max(departs) < 1200.0 - validate.STALL_S
    inserted = {t.get("id") for t in ET.parse(tmp_path / "tripinfo.xml").getroot().iter("tripinfo")}
    routes = ET.parse(tmp_path / "straight.vehicles.rou.xml").getroot()
    edge_of = {r.get("id"): r.get("edges").split()[0] for r in routes.iter("route")}
    waiting = sorted(
        (float(v.get("depart")), v.get("id"), float(v.get("speedFactor")))
        for v in routes.iter("vehicle")
        if f"{edge_of[v.get('route')]}_{v.get('departLane')}" == stall.lane_id
        and v.get("id") not in inserted
        and float(v.get("depart")) < 1200.0
    )
    due_s, head, factor = waiting[0]
    limit = read_net(str(STRAIGHT_NET)).getLane(stall.lane_id).getSpeed()
    assert (stall.head_id, stall.head_due_s, stall.waiting) == (head, due_s, len(waiting))
    assert stall.head_desired_mps == pytest.approx(factor * limit)
    # The blocking driver is far faster than the road's limit: the one the lane waits for.
    assert stall.head_desired_mps > 1.5 * limit
