"""networks/xueqing_dual_ring: the Xueqing junction with entrance widening and a dual-ring
plan with protected lefts, as patches. Checked against SUMO's own view of the built network: the foe matrix
libsumo reports for the junction's internal lanes, the link table of the signal, the geometry of the paths."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT
from pedsafe_sumo.demand.site import turn_movement
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.sumo_net import read_net

NAME = "xueqing_dual_ring"
FOLDER = NETWORKS_DIR / NAME
NET = FOLDER / f"{NAME}.net.xml"
TOOL = REPO_ROOT / "tools" / "build_network.py"
#: A vehicle lane inside a junction (":J_12_0"); walking areas and crossings are ":J_w3_0", ":J_c3_0".
INTERNAL_VEHICLE_LANE = re.compile(r"^:.*_\d+_\d+$")


@pytest.fixture(scope="module")
def signal():
    """(phases [(duration s, state)], links {tl index: (from lane, to lane, [internal lanes])},
    foes {tl index: set of internal lanes in conflict}) read through libsumo from the built network."""
    import libsumo

    libsumo.start(["sumo", "-n", str(NET), "--no-step-log", "--no-warnings"])
    try:
        (tls,) = libsumo.trafficlight.getIDList()
        (logic,) = libsumo.trafficlight.getAllProgramLogics(tls)
        phases = [(p.duration, p.state) for p in logic.phases]
        links = {}
        for index, group in enumerate(libsumo.trafficlight.getControlledLinks(tls)):
            if not group:
                continue
            ((from_lane, to_lane, via),) = group
            if not via:  # a crosswalk's link: the crossing lane is the path
                links[index] = (from_lane, to_lane, [to_lane])
                continue
            chain, lane = [], via
            while INTERNAL_VEHICLE_LANE.search(lane) and lane not in chain:  # a left turn may wait midway
                chain.append(lane)
                following = [link[0] for link in libsumo.lane.getLinks(lane)]
                lane = following[0] if following else ""
            links[index] = (from_lane, to_lane, chain)
        foes = {
            i: set().union(*(libsumo.lane.getInternalFoes(x) for x in chain))
            for i, (_, _, chain) in links.items()
        }
    finally:
        libsumo.close()
    return phases, links, foes


def _conflict(foes, links, i: int, j: int) -> bool:
    return bool(foes[i] & set(links[j][2])) or bool(foes[j] & set(links[i][2]))


def _kinds(links):
    """tl index -> 'crosswalk' or the movement (left/straight/right) from the edges' headings."""
    net = read_net(str(NET))
    kinds = {}
    for i, (from_lane, to_lane, _) in links.items():
        if from_lane.startswith(":"):
            kinds[i] = "crosswalk"
        else:
            a, b = net.getLane(from_lane).getEdge(), net.getLane(to_lane).getEdge()
            kinds[i] = turn_movement(a, b)
    return kinds


def test_the_site_loads_with_its_derived_files_current():
    site = resolve_site(NAME)  # the hash check of docs/sites.md: raises on a stale site file, poles, polygons
    info = json.loads((FOLDER / f"{NAME}.site.json").read_text())
    assert site.name == NAME and info["net_sha256"]


@pytest.mark.slow
def test_the_patches_rebuild_the_committed_network(tmp_path):
    """The folder's network is what tools/build_network.py makes from the OSM clip and patches/ now."""
    out = tmp_path / NAME
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--site", NAME, "--out", str(out),
         "--osm-out", str(tmp_path / "clip.osm"), "--patches", str(FOLDER / "patches")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    rebuilt = json.loads((out / f"{NAME}.site.json").read_text())["net_sha256"]
    assert rebuilt == json.loads((FOLDER / f"{NAME}.site.json").read_text())["net_sha256"]


def _green_conflicts(phases, links, foes, kinds) -> list[str]:
    """Pairs of links in conflict (SUMO's foe matrix) green together in some phase, except a crosswalk
    against a right turn that yields (g); links leaving the same lane diverge (its vehicles pass one by
    one) and are not a conflict."""
    found = []
    for _, state in phases:
        green = [i for i in links if state[i] in "Gg"]
        for a in green:
            for b in green:
                if a >= b or links[a][0] == links[b][0] or not _conflict(foes, links, a, b):
                    continue
                vehicles = [i for i in (a, b) if kinds[i] != "crosswalk"]
                if len(vehicles) == 1 and kinds[vehicles[0]] == "right" and state[vehicles[0]] == "g":
                    continue
                found.append(f"{a} ({kinds[a]}) and {b} ({kinds[b]}) in {state}")
    return found


def test_no_two_conflicting_links_are_green_together(signal):
    """No two vehicle links from different lanes in conflict are green (G or g) together, and a crosswalk
    is green against a vehicle link only when that link is a right turn yielding (g)."""
    phases, links, foes = signal
    kinds = _kinds(links)
    assert len(phases) == 14
    assert _green_conflicts(phases, links, foes, kinds) == []


def test_the_conflict_check_finds_a_through_movement_green_with_the_crossing_one(signal):
    """The check above can fail: stage B (N-S through, phase 3) with the E approach's through links (7, 8)
    turned green too, and its walk with the N approach's right turn (link 0) turned G."""
    phases, links, foes = signal
    kinds = _kinds(links)
    duration, state = phases[3]
    assert kinds[7] == kinds[8] == "straight" and kinds[2] == "straight" and kinds[0] == "right"
    both = state[:7] + "GG" + state[9:]
    found = _green_conflicts([(duration, both)], links, foes, kinds)
    assert any(f.startswith("2 (straight) and 7 (straight)") for f in found), found
    unyielding = "G" + state[1:]
    found = _green_conflicts([(duration, unyielding)], links, foes, kinds)
    assert found and all(f.startswith("0 (right) and ") for f in found), found


def test_the_left_turns_are_protected_from_the_opposing_through_movement(signal):
    """While a left turn is green, the opposing approach's straight links are red; and every left is green
    (G, not yielding g) in some phase."""
    phases, links, foes = signal
    kinds = _kinds(links)
    net = read_net(str(NET))
    lefts = [i for i, k in kinds.items() if k == "left"]
    assert len(lefts) == 7  # N 1, E 2 (to the main road and its auxiliary), S 2 lanes, W 2
    for i in lefts:
        edge = net.getLane(links[i][0]).getEdge()
        opposing = [
            j
            for j, k in kinds.items()
            if k == "straight"
            and turn_movement(edge, net.getLane(links[j][0]).getEdge()) == "uturn"  # the approach facing it
        ]
        assert opposing, f"no opposing straight links for left link {i}"
        assert any(state[i] == "G" for _, state in phases)
        for _, state in phases:
            if state[i] in "Gg":
                assert all(state[j] == "r" for j in opposing), (i, opposing, state)


def test_every_crosswalk_gets_a_walk_long_enough_to_cross(signal):
    """Each of the ten crosswalks is green in some phase; the walk plus the following clearance (the
    crosswalk red, the vehicles still green) is at least 7 s + length / 1.2 m/s."""
    phases, links, foes = signal
    net = read_net(str(NET), withInternal=True, withPedestrianConnections=True)
    crosswalks = [i for i, (f, _, _) in links.items() if f.startswith(":")]
    assert len(crosswalks) == 10
    for i in crosswalks:
        length = net.getLane(links[i][1]).getLength()
        walks = [k for k, (_, state) in enumerate(phases) if state[i] == "G"]
        assert walks, f"crosswalk link {i} never gets green"
        last = walks[-1]
        clearance = phases[last + 1][0] if phases[last + 1][1][i] == "r" and "G" in phases[last + 1][1] else 0
        walk = sum(phases[k][0] for k in walks)
        assert walk >= 7.0 and clearance >= length / 1.2, (i, walk, clearance, length)


def test_yellow_and_all_red_cover_the_ite_clearance_of_the_movements_they_end(signal):
    """ITE: yellow >= 1 s + v / (2 x 3.05 m/s2) and all-red >= (W + 5 m) / v, with v the 85th percentile
    of the demand's desired speed on the road (the non-intersection lognormal, scaled by limit / 16.67
    m/s) and W the length of the path through the junction (its internal lanes) of each link the stage
    ends."""
    import tomllib

    phases, links, foes = signal
    traffic = tomllib.loads((REPO_ROOT / "pedsafe_sumo" / "params" / "defaults.toml").read_text())["traffic"]
    z85 = 1.0364333894937898
    v85 = math.exp(traffic["speed_nonintersection_log_mu"] + z85 * traffic["speed_nonintersection_log_sigma"])
    net = read_net(str(NET), withInternal=True)
    checked = 0
    for k, (duration, state) in enumerate(phases):
        if "y" not in state:
            continue
        ending = [i for i in links if state[i] == "y"]
        all_red_s, all_red_state = phases[(k + 1) % len(phases)]
        assert set(all_red_state) == {"r"}
        for i in ending:
            lane = net.getLane(links[i][0])
            v = v85 * lane.getSpeed() / traffic["fit_speed_limit_mps"]
            path_m = sum(net.getLane(x).getLength() for x in links[i][2])
            assert duration >= 1.0 + v / (2 * 3.05) - 1e-9, (i, duration, v)
            assert all_red_s >= (path_m + 5.0) / v - 1e-9, (i, all_red_s, path_m, v)
            checked += 1
    assert checked == sum(1 for f, _, _ in links.values() if not f.startswith(":"))  # each ends once a cycle


def _batch(*args: str, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--site", NAME, "--episodes", "1", "--workers", "1",
         "--out", str(out), *args],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=600,
    )  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scenario", "approach"),
    [("right_turn", "N"), ("crossing", "E"), ("jaywalking", "W"), ("background_blending", "E")],
)
def test_hosted_scenarios_pass_the_checks_at_batch_start_and_run(tmp_path, scenario, approach):
    proc = _batch("--scenario", scenario, "--approach", approach, out=tmp_path / "run")
    assert proc.returncode == 0, proc.stderr
    episodes = pd.read_parquet(tmp_path / "run" / "episodes.parquet")
    assert (episodes["status"] == "ok").all(), episodes["error"].tolist()
    assert set(episodes["condition"]) == {"sv", "v2i"}


def test_a_scenario_the_layout_cannot_stage_is_refused_at_batch_start(tmp_path):
    """On the N approach the lane beside the right-turn lane goes only to the auxiliary road: the straight
    scenarios cannot be staged there, and the batch says so in one line before writing anything."""
    proc = _batch("--scenario", "crossing", "--approach", "N", out=tmp_path / "run")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "has no straight movement onto 1270646950#1" in proc.stderr
    assert not (tmp_path / "run").exists()
