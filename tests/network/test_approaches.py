"""Every approach: a pole pair per approach, --approach, the approach column.

Checked on the shipped Xueqing site against the network itself (sumolib), not against the code's output.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo.network.sites import compass_sector, resolve_site
from pedsafe_sumo.scenarios.geometry import approach_unit_ids, load_approach, site_approaches
from pedsafe_sumo.sumo_net import read_net

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "batch"))
from batch_cli import batch  # noqa: E402

SITE = resolve_site("xueqing")
INFO = json.loads(SITE.file("site.json").read_text(encoding="utf-8"))
NET = read_net(SITE.file("net.xml"), withInternal=True)
#: Unit vectors of the arms (network frame: x east, y north).
ARM_AXES = {"N": (0.0, 1.0), "E": (1.0, 0.0), "S": (0.0, -1.0), "W": (-1.0, 0.0)}


def test_pole_ids_follow_the_approach():
    assert approach_unit_ids(("rsu_camera_0", "rsu_camera_1"), "E", "N") == (
        "rsu_camera_0_E",
        "rsu_camera_1_E",
    )
    # The site's own approach keeps the ids the scenarios name; an id the build did not make is kept.
    assert approach_unit_ids(("rsu_camera_0",), "N", "N") == ("rsu_camera_0",)
    assert approach_unit_ids(("rsu_camera_0",), "", "N") == ("rsu_camera_0",)
    assert approach_unit_ids(("my_pole", "rsu_camera_1"), "S", "N") == ("my_pole", "rsu_camera_1_S")


def test_a_turns_exit_pole_is_the_pole_of_the_arm_it_leaves_by():
    # Right-hand traffic: from the north a left turn leaves by the east arm, a right turn by the west;
    # the site's own arm (here N) keeps the bare id.
    exit_pole = ("rsu_camera_0", "rsu_camera_0@exit")
    assert approach_unit_ids(exit_pole, "N", "N", "left") == ("rsu_camera_0", "rsu_camera_0_E")
    assert approach_unit_ids(exit_pole, "N", "N", "right") == ("rsu_camera_0", "rsu_camera_0_W")
    assert approach_unit_ids(exit_pole, "S", "N", "left") == ("rsu_camera_0_S", "rsu_camera_0_W")
    assert approach_unit_ids(exit_pole, "E", "N", "left") == ("rsu_camera_0_E", "rsu_camera_0_S")
    assert approach_unit_ids(exit_pole, "W", "N", "left") == ("rsu_camera_0_W", "rsu_camera_0")
    assert approach_unit_ids(exit_pole, "", "W", "right") == ("rsu_camera_0", "rsu_camera_0_S")


def test_every_arm_with_an_entering_road_is_an_approach_with_its_own_poles():
    junction = NET.getNode(INFO["main_junction"])
    centre = junction.getCoord()
    # Independently: the arms from which a road with vehicle lanes enters the junction.
    entering = {
        compass_sector(centre, e.getShape()[0])
        for e in junction.getIncoming()
        if e.getFunction() == "" and any(lane.allows("passenger") for lane in e.getLanes())
    }
    assert set(site_approaches(SITE)) == entering == {"N", "E", "S", "W"}
    poles = {p["id"]: p for p in INFO["roadside_units"]}
    for arm, entry in INFO["approaches"].items():
        assert len(entry["poles"]) == 2 and all(p in poles for p in entry["poles"])
        for pole_id in entry["poles"]:
            pole = poles[pole_id]
            assert pole["watched_arm"] == arm
            # The camera looks out along its arm: its aim (yaw clockwise from north) points at the arm's
            # half-plane as seen from the junction centre, or across the road at it (the far-side pole).
            yaw = math.radians(pole["yaw_deg"])
            aim_x, aim_y = pole["x"] + 30 * math.sin(yaw), pole["y"] + 30 * math.cos(yaw)
            ax, ay = ARM_AXES[arm]
            assert (aim_x - centre[0]) * ax + (aim_y - centre[1]) * ay > 0, (pole_id, aim_x, aim_y)
    # The site's own approach keeps its poles where they were before poles per approach existed.
    assert INFO["approaches"]["N"]["poles"] == ["rsu_camera_0", "rsu_camera_1"]
    assert (poles["rsu_camera_0"]["x"], poles["rsu_camera_0"]["y"]) == (187.36, 212.34)
    assert (poles["rsu_camera_1"]["x"], poles["rsu_camera_1"]["y"]) == (220.51, 229.38)


def test_the_approach_from_each_arm_starts_on_that_arm():
    centre = NET.getNode(INFO["main_junction"]).getCoord()
    for arm in ("N", "S", "E"):
        approach = load_approach(SITE, arm)
        edge = NET.getEdge(approach.edge_id)
        start = edge.getShape()[0]
        ax, ay = ARM_AXES[arm]
        # The road comes from the arm's side (more along its axis than across it) and ends at the junction.
        along = (start[0] - centre[0]) * ax + (start[1] - centre[1]) * ay
        across = abs((start[0] - centre[0]) * ay - (start[1] - centre[1]) * ax)
        assert along > across, (arm, start)
        assert edge.getToNode().getID() == INFO["main_junction"]
    assert load_approach(SITE) == load_approach(SITE, "N")


def test_a_lane_that_only_turns_is_no_lane_for_the_straight_ego():
    """On the east approach the lane next to the kerb turns left or back: crossing, jaywalking and
    background blending (the ego straight through in that lane) cannot be staged there."""
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.hosting import site_hosting
    from pedsafe_sumo.scenarios.specs import SCENARIOS

    approach = load_approach(SITE, "E")
    lane = NET.getLane(approach.lane_ids[1])
    assert "s" not in {c.getDirection() for c in lane.getOutgoing()}
    problems = site_hosting(SITE, dict(SCENARIOS), load_params(None), "E")
    for name in ("crossing", "jaywalking", "background_blending"):
        assert problems[name] == (
            f"cannot be staged: site xueqing: lane {lane.getID()}, where the ego drives, has no straight "
            f"movement onto {approach.through_route[1]}"
        )


def test_a_one_lane_approach_stages_the_straight_scenarios_with_cars_parked_at_the_kerb():
    """Linye Daxue North Road (the west arm) enters with one vehicle lane: the straight scenarios are staged
    there with the vehicles that hide the pedestrian parked at the kerb (tests/network/
    test_one_lane_straight.py); what is left is whether the W poles see them, said in one line."""
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.hosting import site_hosting
    from pedsafe_sumo.scenarios.specs import SCENARIOS

    approach = load_approach(SITE, "W")
    edge = NET.getEdge(approach.edge_id)
    assert sum(lane.allows("passenger") for lane in edge.getLanes()) == 1
    problems = site_hosting(SITE, dict(SCENARIOS), load_params(None), "W")
    # The crosswalk at the stop line (the edge has another one at its upstream end, another junction's).
    assert approach.crosswalk_id.startswith(":" + approach.junction_id + "_c")
    assert problems["crossing"] is None and problems["background_blending"] is None
    assert problems["jaywalking"].startswith("not seen under V2I: roadside pole(s) rsu_camera_0_W do not see")
    # The turns are staged there (the SUMO crash once seen on a one-lane approach had another cause, a
    # median refuge: tests/network/test_one_lane_turns.py); whether the poles see them is another matter.
    assert problems["right_turn"] is None or problems["right_turn"].startswith("not seen under V2I")
    # left_turn's oncoming vehicle would come from the E approach's median lane, which only turns.
    assert problems["left_turn"] == (
        "cannot be staged: site xueqing: lane 121399195#0_2 of the E approach (the oncoming lane) has no "
        "straight movement"
    )


def test_an_episode_on_another_approach_is_staged_there():
    """The ego, the occluders and the pedestrian's path of a crossing episode on the south approach lie on
    that approach; the signal staged is that approach's."""
    from pedsafe_sumo.control.reference import ReferenceStack
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sim.episode import EpisodeRunner

    runner = EpisodeRunner(SITE, load_params(None), ReferenceStack)
    try:
        spec = get_scenario("crossing").with_overrides({"approach": "S"})
        setup = runner.draw_setup(spec, 11)
    finally:
        runner.close()
    south = load_approach(SITE, "S")
    assert setup.approach == "S"
    assert setup.ego.lane_id == south.lane_ids[1]
    assert {v.lane_id for v in setup.parked} == {south.lane_ids[0]}
    assert setup.ego_route[0] == south.edge_id
    # The pedestrian starts beside the south crosswalk's kerb end (1 m back on the sidewalk).
    assert math.dist(setup.pedestrian.path_xy[0], south.crosswalk_path[0]) == pytest.approx(1.0, abs=1e-6)
    centre = NET.getNode(INFO["main_junction"]).getCoord()
    assert setup.conflict_xy[1] < centre[1]  # south of the junction centre
    # The ego's signal is that of its own lane's straight movement (SUMO's link index of the connection).
    conn = next(
        c for c in NET.getLane(south.lane_ids[1]).getOutgoing() if c.getTo().getID() == setup.ego_route[1]
    )
    assert setup.signals.ego_link_index == conn.getTLLinkIndex()


def test_a_combination_the_site_cannot_host_is_refused_before_anything_is_written(tmp_path):
    out = tmp_path / "run"
    proc = batch("--scenario", "jaywalking", "--approach", "S", "--episodes", "1", "--out", str(out))
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: site xueqing cannot host scenario 'jaywalking' on approach S: not seen under V2I: roadside "
        "pole(s) rsu_camera_0_S do not see where the pedestrian starts (30 m before the stop line, -3.1 m, "
        "at 220.6, 144.0)"
    ]
    assert not out.exists()
    proc = batch("--scenario", "crossing", "--approach", "X", "--episodes", "1", "--out", str(out))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "unknown approach 'X'" in proc.stderr
    assert not out.exists()


@pytest.mark.slow
def test_approach_all_runs_what_the_site_hosts_and_the_own_approach_gives_todays_rows(tmp_path):
    common = ("--scenario", "crossing", "--episodes", "2", "--seed", "9", "--workers", "1")
    plain, every = tmp_path / "plain", tmp_path / "every"
    proc = batch(*common, "--out", str(plain))
    assert proc.returncode == 0, proc.stderr
    proc = batch(*common, "--approach", "all", "--out", str(every))
    assert proc.returncode == 0, proc.stderr
    # E: the lane next to the kerb turns: skipped, with why. W (one vehicle lane): staged with the occluders
    # parked at the kerb.
    assert "skipping scenario 'crossing' on approach E of site xueqing: cannot be staged" in proc.stdout
    assert "Table I on approach S:" in proc.stdout
    a = pd.read_parquet(plain / "episodes.parquet")
    b = pd.read_parquet(every / "episodes.parquet")
    assert set(a["approach"]) == {"N"} and set(b["approach"]) == {"N", "S", "W"}
    assert (b["status"] == "ok").all()
    # Without --approach the rows are the site's own approach's, identical to those of --approach all.
    pd.testing.assert_frame_equal(a, b[b["approach"] == "N"].reset_index(drop=True))
    # The same seeds on S: the same pedestrians, another place.
    south = b[b["approach"] == "S"].reset_index(drop=True)
    assert np.array_equal(south["ped_age"], a["ped_age"]) and list(south["seed"]) == list(a["seed"])
    # The report reports every approach (and the pooled table), or the one asked for; each approach's
    # Table I counts that approach's rows.
    report = [sys.executable, "-m", "pedsafe_sumo.report", str(every)]
    proc = subprocess.run(report, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "== approach S ==" in proc.stdout and "== approach N ==" in proc.stdout
    proc = subprocess.run([*report, "--approach", "S"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(every / "approach_S" / "tables" / "table1.csv")
    for condition, rows in south.groupby("condition"):
        row = table[table["condition"].str.lower() == condition].iloc[0]
        assert row["n"] == len(rows) == 2
        assert row["collision_rate"] == pytest.approx(rows["collision"].mean())
