"""Edits a traffic engineer makes to the Xueqing network: each is refused in one line until the derived
files are re-derived from the edited network (build_network --refresh), and then either adapts or is
refused in one line (docs/sites.md has the table). The shifted network is in
test_sites.py."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT
from pedsafe_sumo.network.sites import SiteError, resolve_site
from pedsafe_sumo.scenarios.specs import SCENARIOS
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.sumo_net import read_net

TOOL = REPO_ROOT / "tools" / "build_network.py"
JUNCTION = "cluster_12817118532_12817118533_12817118534_12817118535_#15more"
APPROACH = "177353854#0"  # the southbound Xueqing Road approach the scenarios use


def edited_site(tmp_path: Path, **patches: str) -> Path:
    """A copy of the Xueqing folder (with its own OSM clip) whose network netconvert has edited with the
    given patch files (option name -> XML text)."""
    folder = tmp_path / "xueqing_edit"
    shutil.copytree(NETWORKS_DIR / "xueqing", folder)
    shutil.copyfile(REPO_ROOT / "osm" / "xueqing.osm", folder / "xueqing.osm")
    info = json.loads((folder / "xueqing.site.json").read_text())
    (folder / "xueqing.site.json").write_text(json.dumps({**info, "clip_osm": "xueqing.osm"}))
    net = folder / "xueqing.net.xml"
    args = [sumo_binary("netconvert"), "-s", str(net), "-o", str(tmp_path / "edited.net.xml")]
    for option, text in patches.items():
        patch = tmp_path / f"patch.{option}.xml"
        patch.write_text(text)
        args += [f"--{option}", str(patch)]
    subprocess.run(args, check=True, capture_output=True)
    shutil.copyfile(tmp_path / "edited.net.xml", net)
    return folder


def refused_until_refresh(folder: Path) -> subprocess.CompletedProcess:
    with pytest.raises(SiteError) as info:
        resolve_site(str(folder))
    assert "changed after its site file" in str(info.value) and "--refresh" in str(info.value)
    return subprocess.run(
        [sys.executable, str(TOOL), "--refresh", str(folder)], capture_output=True, text=True, cwd=REPO_ROOT
    )


def _vehicle_lanes(net_file: Path, edge: str) -> list:
    return [lane for lane in read_net(str(net_file)).getEdge(edge).getLanes() if lane.allows("passenger")]


@pytest.mark.slow
def test_a_lane_added_to_the_approach(tmp_path):
    from pedsafe_sumo.scenarios.geometry import load_approach

    folder = edited_site(tmp_path, **{"edge-files": f'<edges><edge id="{APPROACH}" numLanes="4"/></edges>'})
    proc = refused_until_refresh(folder)
    assert proc.returncode == 0, proc.stderr
    site = resolve_site(str(folder))
    # numLanes 4 = the sidewalk and three vehicle lanes; the scenarios see all three.
    assert len(_vehicle_lanes(site.file("net.xml"), APPROACH)) == 3
    assert len(load_approach(site).lane_ids) == 3
    assert "crossing:" in proc.stdout  # the hosting lines for the edited site


#: Where the northbound background enters the site (Xueqing Road south of the junction).
SOUTH_ENTRY = "1104710653#0"


@pytest.mark.slow
def test_a_lower_speed_limit(tmp_path):
    """The scenarios' approach and the southern entry lowered from 60 to 30 km/h: the ego's initial speed
    and the desired speeds of the background entering there are the same draws scaled by 8.33 / 16.67
    (traffic.fit_speed_limit_mps, the limit the fits were measured at); every other entry is unchanged, and
    each background driver keeps its speed factor (desired speed / limit), so SUMO drives them at the scaled
    speed on the slowed road and at the fit's speed once on a 60 km/h road. With
    traffic.background_speed_limit_scaled = false the background's desired speeds are the draws as they are
    (paper-v5's model)."""
    from pedsafe_sumo.control.reference import ReferenceStack
    from pedsafe_sumo.params import load_params, with_overrides
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sim.episode import EpisodeRunner

    edges = f'<edges><edge id="{APPROACH}" speed="8.33"/><edge id="{SOUTH_ENTRY}" speed="8.33"/></edges>'
    folder = edited_site(tmp_path, **{"edge-files": edges})
    proc = refused_until_refresh(folder)
    assert proc.returncode == 0, proc.stderr
    site = resolve_site(str(folder))
    assert {round(lane.getSpeed(), 2) for lane in _vehicle_lanes(site.file("net.xml"), APPROACH)} == {8.33}
    params = load_params(None)
    assert params["traffic"]["fit_speed_limit_mps"] == 16.67
    assert params["traffic"]["background_speed_limit_scaled"] is True
    unscaled = with_overrides(params, {"traffic.background_speed_limit_scaled": False})
    # No clipping of the ego's speed in this test: the scale is what is checked.
    spec = get_scenario("jaywalking").with_overrides({"ego_speed_min_mps": 0.1, "ego_speed_max_mps": 50})
    runners = [
        EpisodeRunner(s, p, ReferenceStack)
        for s, p in ((resolve_site("xueqing"), params), (site, params), (site, unscaled))
    ]
    try:
        for seed in (1, 2, 3):
            before, after, off = (runner.draw_setup(spec, seed) for runner in runners)
            assert after.ego.speed_mps == pytest.approx(before.ego.speed_mps * 8.33 / 16.67, rel=1e-9)
            old = {v.vehicle_id: v for v in before.background}
            new = {v.vehicle_id: v for v in after.background}
            kept = {v.vehicle_id: v for v in off.background}
            slowed = [i for i in old if i in new and new[i].route[0] == SOUTH_ENTRY]
            others = [i for i in old if i in new and new[i].route[0] != SOUTH_ENTRY]
            assert slowed and others
            for i in slowed:
                assert new[i].desired_speed_mps == pytest.approx(old[i].desired_speed_mps * 8.33 / 16.67)
                assert new[i].speed_factor == pytest.approx(old[i].speed_factor)
                # Unscaled: the same draw, so on the slowed road its speed factor doubles.
                assert kept[i].desired_speed_mps == pytest.approx(old[i].desired_speed_mps)
                assert kept[i].speed_factor == pytest.approx(old[i].speed_factor * 16.67 / 8.33)
            for i in others:
                assert new[i].desired_speed_mps == old[i].desired_speed_mps
    finally:
        for runner in runners:
            runner.close()


@pytest.mark.slow
def test_a_new_signal_programme(tmp_path):
    from pedsafe_sumo.network.summary import summarise

    before = summarise(resolve_site("xueqing"))
    plan = (
        f'<tlLogics><tlLogic id="{JUNCTION}" type="static" programID="0" offset="0">'
        '<phase duration="40" state="' + "G" * 37 + '"/><phase duration="5" state="' + "y" * 37 + '"/>'
        "</tlLogic></tlLogics>"
    )
    folder = edited_site(tmp_path, **{"tllogic-files": plan})
    proc = refused_until_refresh(folder)
    assert proc.returncode == 0, proc.stderr
    after = summarise(resolve_site(str(folder)))
    assert (before.cycle_s, after.cycle_s) == (90.0, 45.0) and after.phases == 2


@pytest.mark.slow
def test_the_signal_removed_is_refused_in_one_line(tmp_path):
    xy = json.loads((NETWORKS_DIR / "xueqing" / "xueqing.site.json").read_text())["main_junction_xy"]
    node = f'<nodes><node id="{JUNCTION}" x="{xy[0]:.2f}" y="{xy[1]:.2f}" type="priority"/></nodes>'
    folder = edited_site(tmp_path, **{"node-files": node})
    proc = refused_until_refresh(folder)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "the network has no signalised junction" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.slow
def test_the_approach_split_in_two(tmp_path):
    from pedsafe_sumo.scenarios.geometry import load_approach

    folder = edited_site(
        tmp_path, **{"edge-files": f'<edges><edge id="{APPROACH}"><split pos="60"/></edge></edges>'}
    )
    proc = refused_until_refresh(folder)
    assert proc.returncode == 0, proc.stderr
    # The part that reaches the stop line is the approach now; netconvert dropped the crosswalk over the
    # edge it split (its crossing named the old edge): every scenario is refused, saying so.
    net = read_net(str(folder / "xueqing.net.xml"), withInternal=True)
    downstream = next(e for e in net.getNode(JUNCTION).getIncoming() if e.getID().startswith(APPROACH))
    assert downstream.getID() == f"{APPROACH}.60"
    crossings = [e for e in net.getEdges(withInternal=True) if e.getFunction() == "crossing"]
    assert not [c for c in crossings if downstream in c._crossingEdges]
    message = f"NOT hosted: cannot be staged: site xueqing: no crosswalk over {APPROACH}.60"
    # Every scenario on the site's own approach, under either staging; and nothing anywhere is hosted, as
    # no episode runs without the site's own approach.
    assert proc.stdout.count(message) >= 2 * len(SCENARIOS)
    assert ": hosted (" not in proc.stdout
    with pytest.raises(ValueError, match="no crosswalk over"):
        load_approach(resolve_site(str(folder)))


@pytest.mark.slow
def test_the_junction_moved(tmp_path):
    original = json.loads((NETWORKS_DIR / "xueqing" / "xueqing.site.json").read_text())["main_junction_xy"]
    node = f'<nodes><node id="{JUNCTION}" x="{original[0] + 5.0:.2f}" y="{original[1]:.2f}"/></nodes>'
    folder = edited_site(tmp_path, **{"node-files": node})
    proc = refused_until_refresh(folder)
    assert proc.returncode == 0, proc.stderr
    moved = json.loads((folder / "xueqing.site.json").read_text())["main_junction_xy"]
    assert moved == pytest.approx([original[0] + 5.0, original[1]], abs=0.01)
    resolve_site(str(folder))


def _states_over(phases: list[tuple[float, str]], start_s: float, times_s, link: int) -> set[str]:
    """The characters link `link` shows at cycle time start_s + t for each t (walked by hand over the
    phases of a tlLogic)."""
    cycle_s = sum(d for d, _ in phases)
    shown = set()
    for t in times_s:
        at = (start_s + t) % cycle_s
        for duration, state in phases:
            if at < duration:
                shown.add(state[link])
                break
            at -= duration
    return shown


@pytest.mark.slow
def test_a_new_signal_programme_changes_when_road_users_meet(tmp_path):
    """Every phase of Xueqing's program made twice as long (a 180 s cycle): the crossing episode of the same
    seed starts at another point of the cycle, and in the new program the ego still has green from the
    start until after the staged conflict, the pedestrian red from stepping off (checked by walking the
    new phases from the net file, not with the staging code)."""
    import xml.etree.ElementTree as ET

    from pedsafe_sumo.control.reference import ReferenceStack
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sim.episode import EpisodeRunner

    original = ET.parse(NETWORKS_DIR / "xueqing" / "xueqing.net.xml").getroot().find("tlLogic")
    slow = ET.Element("tlLogics")
    logic = ET.SubElement(slow, "tlLogic", dict(original.attrib))
    for phase in original.iter("phase"):
        ET.SubElement(
            logic, "phase", duration=str(2 * float(phase.get("duration"))), state=phase.get("state")
        )
    folder = edited_site(tmp_path, **{"tllogic-files": ET.tostring(slow, encoding="unicode")})
    proc = refused_until_refresh(folder)
    assert proc.returncode == 0, proc.stderr
    site = resolve_site(str(folder))
    edited = ET.parse(site.file("net.xml")).getroot().find("tlLogic")
    phases = [(float(p.get("duration")), p.get("state")) for p in edited.iter("phase")]
    assert sum(d for d, _ in phases) == 180.0
    spec = get_scenario("crossing")
    runners = [EpisodeRunner(s, load_params(None), ReferenceStack) for s in (resolve_site("xueqing"), site)]
    try:
        for seed in (1, 2):
            before, after = (runner.draw_setup(spec, seed) for runner in runners)
            assert after.signals.cycle_start_s != before.signals.cycle_start_s
            until_s = after.conflict_time_s + spec.signal_hold_after_s
            times = np.arange(0.0, until_s, 0.05)
            start_s, staged = after.signals.cycle_start_s, after.signals
            assert _states_over(phases, start_s, times, staged.ego_link_index) <= {"G", "g"}
            ped_times = times[times >= after.pedestrian.start_delay_s]
            assert _states_over(phases, start_s, ped_times, staged.ped_link_index) == {"r"}
    finally:
        for runner in runners:
            runner.close()
