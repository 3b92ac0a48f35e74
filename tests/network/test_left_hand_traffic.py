"""Left-hand traffic (network.traffic_side): the traffic side read from the data, and every scenario staged
mirrored on a left-hand network.

The mirror test: one four-arm junction written as plain XML (two lanes each way, 13 m/s, netconvert's
sidewalks, crosswalks and two-phase light), built by netconvert as it is (right-hand traffic) and with
every x negated and --lefthand (left-hand traffic). netconvert builds a left-hand network by mirroring,
so the two networks are each other's mirror image, x -> 2 cx - x about the junction's centre cx (the
same edge and lane ids). Each scenario staged on both with the same seed must put the ego, the vehicles
and the pedestrian at mirrored positions, within MIRROR_TOL_M.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.network.traffic_side import (
    KEEP_LEFT,
    KEEP_RIGHT,
    LEFTHAND_MEANING,
    drawn_keep_side,
    far_turn_letter,
    lefthand_region,
    near_turn_letter,
    network_is_lefthand,
)
from pedsafe_sumo.scenarios.geometry import exit_arm, load_approach, load_turn
from pedsafe_sumo.scenarios.oncoming import load_oncoming
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.sumo_net import read_net

TOOL = REPO_ROOT / "tools" / "build_network.py"
SCENARIOS = ("crossing", "jaywalking", "background_blending", "right_turn", "left_turn")
TRAITS = {"age_years": 35.0, "gender": "f", "risk": "unaware", "walking_speed_mps": 1.4}
#: Mirrored positions agree within this [m]. netconvert writes coordinates to 0.01 m and builds a
#: left-hand network by mirroring a right-hand one, so the mirror is exact up to the float arithmetic
#: of the staging (1e-9 m); 1 mm leaves room and still catches any staging on the wrong side (metres).
MIRROR_TOL_M = 1e-3

#: Arms of the junction: (x, y) of the far node [m]; the centre C at (0, 0) carries the light.
ARMS = {"N": (0.0, 250.0), "S": (0.0, -250.0), "E": (220.0, 0.0), "W": (-220.0, 0.0)}


def _plain_xml(folder: Path, sign: float) -> tuple[Path, Path]:
    nodes = folder / "cross.nod.xml"
    edges = folder / "cross.edg.xml"
    lines = ["<nodes>", '    <node id="C" x="0.0" y="0.0" type="traffic_light"/>']
    lines += [
        f'    <node id="{arm}" x="{sign * x!r}" y="{y!r}" type="priority"/>' for arm, (x, y) in ARMS.items()
    ]
    nodes.write_text("\n".join([*lines, "</nodes>", ""]), encoding="utf-8")
    lines = ["<edges>"]
    for arm in ARMS:
        lines.append(f'    <edge id="{arm}_in" from="{arm}" to="C" numLanes="2" speed="13.0"/>')
        lines.append(f'    <edge id="{arm}_out" from="C" to="{arm}" numLanes="2" speed="13.0"/>')
    edges.write_text("\n".join([*lines, "</edges>", ""]), encoding="utf-8")
    return nodes, edges


def _site(root: Path, side: str) -> Path:
    """The junction built by netconvert (`side` "left": mirrored, --lefthand), then as a site (--net)."""
    folder = root / side
    folder.mkdir()
    nodes, edges = _plain_xml(folder, 1.0 if side == "right" else -1.0)
    net = folder / "cross.net.xml"
    subprocess.run(
        [sumo_binary("netconvert"), "-n", str(nodes), "-e", str(edges), "--sidewalks.guess",
         "--crossings.guess", "--walkingareas", "--no-turnarounds", "--tls.default-type", "static",
         "-o", str(net),
         *(["--lefthand"] if side == "left" else [])],
        check=True, capture_output=True,
    )  # fmt: skip
    out = root / f"site_{side}"
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--net", str(net), "--junction", "C", "--name", f"cross_{side}",
         "--out", str(out), "--rsu-watch", "N"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    (out / "build.txt").write_text(proc.stdout, encoding="utf-8")
    return out


@pytest.fixture(scope="module")
def pair(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("mirror")
    return _site(root, "right"), _site(root, "left")


def _draw(folder: Path, name: str, seed: int, staging: str = "fixed"):
    site = resolve_site(str(folder))
    spec = get_scenario(name)
    if staging != "fixed":
        spec = dataclasses.replace(spec, staging=staging)
    approach = load_approach(site, "N")
    turn = placement_of(spec).load_turn(site, spec, "N")
    oncoming = load_oncoming(site, "N") if spec.oncoming_vehicle else None
    setup = draw_episode(spec, approach, seed, TRAITS, 8.0, np.random.default_rng(seed), turn, oncoming)
    return approach, setup


# --- the traffic side from the data -----------------------------------------------------------------------


def test_the_sign_and_the_turn_letters_of_each_side():
    assert (KEEP_RIGHT, KEEP_LEFT) == (1.0, -1.0)
    assert (near_turn_letter(KEEP_RIGHT), far_turn_letter(KEEP_RIGHT)) == ("r", "l")
    assert (near_turn_letter(KEEP_LEFT), far_turn_letter(KEEP_LEFT)) == ("l", "r")
    # From the north arm: right-hand traffic's far-side (left) turn leaves east, left-hand traffic's west.
    assert exit_arm("N", "left", KEEP_RIGHT) == "E" and exit_arm("N", "left", KEEP_LEFT) == "W"
    assert exit_arm("N", "right", KEEP_RIGHT) == "W" and exit_arm("N", "right", KEEP_LEFT) == "E"


@pytest.mark.parametrize(
    "place, lat, lon, region",
    [
        ("Perth", -31.975, 115.898, "Australia"),
        ("Hobart", -42.88, 147.33, "Australia"),
        ("Auckland", -36.85, 174.76, "New Zealand"),
        ("Noumea (France, right-hand)", -22.27, 166.45, None),
        ("London (a box would hold Calais)", 51.51, -0.13, None),
        ("Beijing", 40.0, 116.35, None),
        ("Jakarta (left-hand, outside every box: told by the data or --lefthand)", -6.2, 106.8, None),
    ],
)
def test_the_regions_where_all_traffic_keeps_left(place, lat, lon, region):
    assert lefthand_region(lat, lon) == region, place


def test_the_side_the_lanes_are_drawn_on_is_the_networks_and_a_false_attribute_is_refused(pair, tmp_path):
    right, left = pair
    assert not network_is_lefthand(right / "cross_right.net.xml")
    assert network_is_lefthand(left / "cross_left.net.xml")
    assert drawn_keep_side(read_net(str(right / "cross_right.net.xml"))) == KEEP_RIGHT
    assert drawn_keep_side(read_net(str(left / "cross_left.net.xml"))) == KEEP_LEFT
    # lefthand="true" written into a right-hand network: its lanes say otherwise, refused in one line.
    fake = tmp_path / "fake.net.xml"
    text = (right / "cross_right.net.xml").read_text(encoding="utf-8")
    fake.write_text(text.replace("<net ", '<net lefthand="true" ', 1), encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--net", str(fake), "--junction", "C", "--out", str(tmp_path / "fake")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert 'says lefthand="true" but draws the kerb-side lane of its roads on the right' in proc.stderr
    assert not (tmp_path / "fake").exists()


def test_the_build_says_the_site_keeps_left_and_hosts_every_scenario(pair):
    right, left = pair
    said = (left / "build.txt").read_text(encoding="utf-8")
    assert 'traffic side: left-hand (the network says lefthand="true")' in said
    assert "traffic side: left-hand" not in (right / "build.txt").read_text(encoding="utf-8")
    for name in SCENARIOS:
        assert f"  {name}: hosted" in said, said


# --- the mirror -------------------------------------------------------------------------------------------


#: Approach staging of the turns: no sidewalk reaches an end of this junction's crosswalks that the turns
#: cross (netconvert's guessed sidewalks end at the walking areas), refused alike on both sides.
STAGED = [(name, "fixed") for name in SCENARIOS] + [
    (name, "approach") for name in ("crossing", "jaywalking", "background_blending")
]


@pytest.mark.parametrize("name, staging", STAGED)
def test_each_scenario_is_staged_as_the_mirror_image_of_its_right_hand_staging(pair, name, staging):
    right, left = pair
    cx = load_approach(resolve_site(str(right)), "N").junction_xy[0]
    assert load_approach(resolve_site(str(left)), "N").junction_xy[0] == pytest.approx(cx)

    def mirror(p):
        return (2 * cx - p[0], p[1])

    for seed in (1, 2, 3):
        ar, r = _draw(right, name, seed, staging)
        al, lh = _draw(left, name, seed, staging)
        assert (ar.keep_side, al.keep_side) == (KEEP_RIGHT, KEEP_LEFT)
        # The same lanes by index (0 the kerb-side lane) and the same routes by edge id.
        assert (lh.ego.lane_id, lh.ego_route) == (r.ego.lane_id, r.ego_route)
        assert lh.ego.front_pos_m == pytest.approx(r.ego.front_pos_m, abs=MIRROR_TOL_M)
        x, y, h = ar.pose(ar.lane_ids.index(r.ego.lane_id), r.ego.front_pos_m)
        xl, yl, hl = al.pose(al.lane_ids.index(lh.ego.lane_id), lh.ego.front_pos_m)
        assert math.dist(mirror((x, y)), (xl, yl)) < MIRROR_TOL_M
        assert len(lh.pedestrian.path_xy) == len(r.pedestrian.path_xy)
        for p, q in zip(r.pedestrian.path_xy, lh.pedestrian.path_xy, strict=True):
            assert math.dist(mirror(p), q) < MIRROR_TOL_M, (seed, p, q)
        assert math.dist(mirror(r.conflict_xy), lh.conflict_xy) < MIRROR_TOL_M
        assert [(v.lane_id, round(v.front_pos_m, 6), v.kerb_offset_m) for v in lh.parked] == [
            (v.lane_id, round(v.front_pos_m, 6), v.kerb_offset_m) for v in r.parked
        ]
        # In left-hand traffic the ego's lane lies left of the road's centre line (the junction's x here,
        # the road running north-south): heading south (-y), left is east (+x).
        assert abs(h + math.pi / 2) < 0.01 and abs(hl + math.pi / 2) < 0.01
        assert x < cx < xl


def _turned_by_rad(path) -> float:
    """Signed change of heading from the first to the last segment of a path (+: anticlockwise, left)."""
    (a, b), (c, d) = path[:2], path[-2:]
    first = math.atan2(b[1] - a[1], b[0] - a[0])
    last = math.atan2(d[1] - c[1], d[0] - c[0])
    return (last - first + math.pi) % (2 * math.pi) - math.pi


def test_the_near_side_turn_is_a_left_turn_and_the_far_side_turn_a_right_turn_in_left_hand_traffic(pair):
    right, left = pair
    for folder, near_sign in ((right, -1.0), (left, 1.0)):
        site = resolve_site(str(folder))
        near, far = load_turn(site, "right", "N"), load_turn(site, "left", "N")
        assert (near.lane_index, far.lane_index) == (0, 1)  # kerb lane, median lane
        assert _turned_by_rad(near.path_xy) == pytest.approx(near_sign * math.pi / 2, abs=0.2)
        assert _turned_by_rad(far.path_xy) == pytest.approx(-near_sign * math.pi / 2, abs=0.2)


# --- in SUMO ------------------------------------------------------------------------------------------------


def _batch(folder: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--site", str(folder), "--scenario", "all",
         "--episodes", "2", "--workers", "1", "--condition", "sv", "--keep-logs", "all", "--out", str(out)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=900,
    )  # fmt: skip


@pytest.mark.slow
def test_in_sumo_every_scenario_starts_as_the_mirror_of_its_right_hand_run(pair, tmp_path):
    """Both sites run every scenario (2 seeds, onboard sensors): no error rows, the signals staged, and
    SUMO's own positions of the ego and the pedestrian at the first step mirror each other."""
    right, left = pair
    runs = {}
    for side, folder in (("right", right), ("left", left)):
        proc = _batch(folder, tmp_path / side)
        assert proc.returncode == 0, proc.stderr
        meaning = LEFTHAND_MEANING.format(site=f"cross_{side}")
        assert proc.stdout.count(meaning) == (1 if side == "left" else 0), proc.stdout[:2000]
        episodes = pd.read_parquet(tmp_path / side / "episodes.parquet")
        assert sorted(set(episodes["scenario"])) == sorted(SCENARIOS)
        assert (episodes["error"] == "").all() and (episodes["ego_signal"] != "none").all(), episodes["error"]
        steps = pd.concat(
            pd.read_parquet(f) for f in sorted((tmp_path / side / "steplogs").glob("*.parquet"))
        )
        runs[side] = steps.sort_values(["scenario", "seed", "time_s"]).groupby(["scenario", "seed"]).first()
    cx = load_approach(resolve_site(str(right)), "N").junction_xy[0]
    r, lh = runs["right"], runs["left"]
    assert list(r.index) == list(lh.index)
    assert np.allclose(2 * cx - r["ego_x_m"], lh["ego_x_m"], atol=MIRROR_TOL_M)
    assert np.allclose(r["ego_y_m"], lh["ego_y_m"], atol=MIRROR_TOL_M)
    present = r["ped_x_m"].notna()
    assert np.allclose(2 * cx - r["ped_x_m"][present], lh["ped_x_m"][present], atol=MIRROR_TOL_M)
    assert np.allclose(r["ped_y_m"][present], lh["ped_y_m"][present], atol=MIRROR_TOL_M)


def test_the_euro_ncap_suite_is_refused_on_a_left_hand_site_in_one_line(pair, tmp_path):
    _, left = pair
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.ncap", "--site", str(left), "--out", str(tmp_path / "ncap")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert (
        "keeps left (left-hand traffic): the Euro NCAP tests are staged for right-hand traffic" in proc.stderr
    )
    assert not (tmp_path / "ncap").exists()
